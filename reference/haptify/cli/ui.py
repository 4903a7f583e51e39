"""The output policy of one ``haptify`` invocation (spec §0.5): human text, ``--json`` or ``--quiet``, and
progress bars; what every sub-command's ``run(args, ui)`` receives. Kept apart from :mod:`haptify.cli.main`, which
imports the sub-commands, so that they can name it without importing the command back."""

from __future__ import annotations

import argparse
import json
import sys
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, Iterator, Protocol

if TYPE_CHECKING:  # argparse's class is generic in its stubs only
    #: What a plugin's ``register`` receives: the sub-command parsers of ``haptify`` (spec §0.5).
    Subcommands = argparse._SubParsersAction[argparse.ArgumentParser]


class Advance(Protocol):
    """What :meth:`UI.progress` yields: ``n`` more units of work done; ``total`` sets the bar's length once known."""

    def __call__(self, n: float = 1, total: float | None = None) -> None: ...


class UI:
    """Output policy of one invocation: human text (rich), ``--json`` or ``--quiet`` (spec §0.5)."""

    def __init__(self, json_mode: bool = False, quiet: bool = False) -> None:
        self.json_mode = json_mode
        self.quiet = quiet

    def say(self, text: str) -> None:
        """A human line on stdout (suppressed by --quiet and --json)."""
        if not (self.quiet or self.json_mode):
            print(text)

    def emit_json(self, payload: Any) -> None:
        """The machine-readable result on stdout (only with --json)."""
        if self.json_mode:
            print(json.dumps(payload, indent=2, default=_json_default))

    def warn(self, text: str) -> None:
        if not self.quiet:
            print(text, file=sys.stderr)

    @contextmanager
    def progress(self, description: str, total: float | None) -> Iterator[Advance]:
        """A progress bar on stderr for work that can take more than ~2 s; yields ``advance(n=1, total=None)``
        (``total`` sets the bar's length once the work knows it)."""
        if self.quiet or self.json_mode or not sys.stderr.isatty():
            yield lambda n=1, total=None: None
            return
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(), transient=True) as bar:
            task = bar.add_task(description, total=total)
            yield lambda n=1, total=None: bar.update(task, advance=n, **({} if total is None else {"total": total}))


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "to_dict"):
        return obj.to_dict()
    if hasattr(obj, "tolist"):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
