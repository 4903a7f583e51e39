"""What a mutant is (spec §16.8.3): a :class:`Patch` replaces one object of the reference (``haptify.*``) for
the duration of a run, a :class:`Mutant` is one wrong reading of the spec made of patches and is an
implementation in the sense of spec §16.4.3; and the building blocks of replacements (``_replace``,
``_parameters``, ``_post``)."""

from __future__ import annotations

import sys
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Iterator
from unittest import mock

from haptify import conform_adapter as reference

Make = Callable[[Any], Any]  # the real object → its replacement


@dataclass(frozen=True)
class Patch:
    """Replace ``owner.name`` (or the item ``owner[name]`` of a dict such as a dispatch table) by ``make(real)``
    while a mutant is applied.

    With ``everywhere`` the replacement also goes into every ``haptify`` module that bound the same object
    by name (``from haptify.processing.preprocessing import lowpass_resample``), so the whole reference sees one mistake.
    """

    owner: Any
    name: str
    make: Make
    everywhere: bool = False

    def real(self) -> Any:
        """The object replaced (looked up before anything is patched)."""
        return self.owner[self.name] if isinstance(self.owner, dict) else getattr(self.owner, self.name)

    def targets(self) -> list[Any]:
        """The objects whose attribute ``name`` is replaced (looked up before anything is patched)."""
        if not self.everywhere:
            return [self.owner]
        real = self.real()
        loaded = [m for n, m in sorted(sys.modules.items()) if n == "haptify" or n.startswith("haptify.")]
        return [self.owner] + [m for m in loaded if m is not self.owner and getattr(m, self.name, None) is real]

    def patchers(self) -> list[Any]:
        """The ``unittest.mock`` patchers that apply it."""
        new = self.make(self.real())
        if isinstance(self.owner, dict):
            return [mock.patch.dict(self.owner, {self.name: new})]
        return [mock.patch.object(target, self.name, new) for target in self.targets()]


@dataclass(frozen=True)
class Mutant:
    """One wrong variant of the reference: what it violates, how it reads the spec, how it is patched in.

    ``section``: the spec section whose rule it breaks; ``requirement``: the id of that rule
    (``schemas/<v>/requirements.json``, spec §16.7); ``metrics``: the metric ids whose cases are
    expected to catch it; ``cheap``: part of the fast subset run by ``make test``.
    """

    name: str
    section: str
    requirement: str
    rule: str
    wrong: str
    patches: tuple[Patch, ...]
    metrics: tuple[str, ...]
    cheap: bool = False

    @contextmanager
    def applied(self) -> Iterator[None]:
        """The reference with this mistake, for the duration of the ``with`` block."""
        with ExitStack() as stack:
            for patcher in [q for p in self.patches for q in p.patchers()]:
                stack.enter_context(patcher)
            yield

    def analyse(self, session: str, metric: str = "", parameters: dict | None = None) -> dict:
        """The ``--python`` entry point (spec §16.4.3): the reference's answer with the mistake, computed afresh."""
        with self.applied():
            return reference.analyse(session, metric, parameters, cache=False)


def _replace(fn: Callable) -> Make:
    """A replacement that ignores the real object."""
    return lambda real: fn


def _parameters(**values: Any) -> Make:
    """A family's typed parameters (the owning module's ``PARAMETERS``, e.g. ``vibration.PARAMETERS``) with
    some values changed: ``Patch(vibration, "PARAMETERS", _parameters(edge_trim_s=0.0))``."""
    return lambda real: real.model_copy(update=values)


def _post(fn: Callable) -> Make:
    """The real function, its result passed through ``fn(result, *args)`` (positional arguments only)."""

    def make(real: Callable) -> Callable:
        def wrapped(*args: Any, **kw: Any) -> Any:
            return fn(real(*args, **kw), *args)

        return wrapped

    return make
