"""The mutant set: the reference with ONE realistic mistake each (spec §16.8.3).

Each :class:`Mutant` is a choice a lab engineer could plausibly make while reading the spec — averaging
where the spec says something else, another filter, another frame, another unit — written as one or more
:class:`Patch` es that replace a piece of the reference (``haptify.*``) for the duration of a run
(``unittest.mock``; nothing is changed on disk). Every mutant names the spec section it violates, the rule
in one line, the wrong reading in one line, and the metric(s) whose cases are expected to catch it.

A mutant is an implementation in the sense of spec §16.4.3::

    haptify-conform --python haptify_mutants.catalogue:hann_window_centroid

``make mutants`` (:mod:`haptify_mutants.run`) runs the whole suite against every mutant; ``make test`` runs
the ``cheap`` ones against the cases of the metrics they break (``tests/test_conformance_suite.py``).
Mistakes whose outcome no metric can see (e.g. the phase DFT321 gives the combined signal: RMS and centroid
depend on magnitudes only) are not mutants: nothing could catch them and nothing depends on them.

:mod:`~haptify_mutants.catalogue.model` defines :class:`Patch` and :class:`Mutant`; one module per family
holds its mutants (``MUTANTS``) and the replacements they patch in: repetitions (§15.3), vibration (chapter
10), filtering (chapter 7), frames (chapters 1 and 6), motion capture (§7.4), free space (chapter 9 and the
plate), surface (12), workspace (8), rig (14), local dynamics (11), stiffness (13) and uncertainty (19).
"""

from __future__ import annotations

from typing import Callable

from haptify_mutants.catalogue import (
    filtering,
    frames,
    free_space,
    local_dynamics,
    motion_capture,
    repetitions,
    rig,
    stiffness,
    surface,
    uncertainty,
    vibration,
    workspace,
)
from haptify_mutants.catalogue.model import Mutant, Patch

__all__ = ["BY_NAME", "MUTANTS", "Mutant", "Patch", "cheap_mutants"]

MUTANTS: tuple[Mutant, ...] = (
    *repetitions.MUTANTS,
    *vibration.MUTANTS,
    *filtering.MUTANTS,
    *frames.MUTANTS,
    *motion_capture.MUTANTS,
    *free_space.MUTANTS,
    *surface.MUTANTS,
    *workspace.MUTANTS,
    *rig.MUTANTS,
    *local_dynamics.MUTANTS,
    *stiffness.MUTANTS,
    *uncertainty.MUTANTS,
)

BY_NAME: dict[str, Mutant] = {m.name: m for m in MUTANTS}


def cheap_mutants() -> list[Mutant]:
    """The fast subset that ``make test`` runs against the cases of the metrics each one breaks."""
    return [m for m in MUTANTS if m.cheap]


def __getattr__(name: str) -> Callable[[str, str, dict | None], dict]:
    """``haptify_mutants.catalogue:<mutant name>`` as a ``--python`` implementation (spec §16.4.3)."""
    if name in BY_NAME:
        return BY_NAME[name].analyse
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
