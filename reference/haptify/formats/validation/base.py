"""The validator's state and bookkeeping (spec §4.1): the streams it checks, the findings it records, and
the guard that turns a coded error into findings and anything unexpected into E999 — never a traceback."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError
from haptify.formats.session_format import Rig, Session, Stream, Trial
from haptify.formats.validation.report import ReportItem, ValidationReport


@dataclass
class StreamEntry:
    """One stream of the manifest as the validator checks it: where it is declared, and what its checks found."""

    trial: str | None
    pointer: str
    stream: Stream
    span: tuple[float, float] | None = None  # first and last time on the session clock, when its time is sound
    declared: bool = False  # its declaration has been checked
    names_ok: bool = False  # its declared columns are its kind's, each once
    path: Path | None = None  # its file, once found inside the folder within its size bound
    footer_rows: int | None = None  # the rows a Parquet file's footer declares, once read


def collect(step: Callable[[], None], file: str | None) -> list[Finding]:
    """Run ``step``; the findings of a coded error it raises, E112 when the input exhausts memory or
    nesting, E999 for anything else (a validator bug, reported rather than raised)."""
    try:
        step()
    except HaptifyError as err:
        return list(err.findings)
    except (MemoryError, RecursionError) as exc:
        return [
            Finding(
                Code.STREAM_UNREADABLE,
                f"{file or 'the input'} is too large or too deeply nested to check: {type(exc).__name__}",
                file=file,
            )
        ]
    except Exception as exc:  # a bug in the validator: report it, coded, and go on
        return [Finding(Code.INTERNAL_ERROR, f"{type(exc).__name__}: {exc}", file=file)]
    return []


class ValidatorBase:
    """What both phases of :class:`~haptify.formats.validation.validator.SessionValidator` share: the folder, the
    manifest as parsed so far, the stream entries, and the report the findings go into (spec §4.1)."""

    def __init__(self, path: str | os.PathLike[str], chunk_rows: int | None = None) -> None:
        self.root = Path(path)
        self.chunk_rows = chunk_rows
        self.report = ValidationReport(session=str(path))
        self.raw: Any = None
        self.manifest: Session | None = None  # the parsed session.json, when it validates whole
        self.rig: Rig | None = None
        self.trials: list[tuple[int, dict[str, Any], Trial | None]] = []
        self.entries: list[StreamEntry] = []
        self.offsets: dict[str, float] = {}
        self._manifest_ok = False

    # -- bookkeeping --------------------------------------------------------------------------
    def add(self, finding: Finding, trial: str | None = None) -> None:
        """Record one finding, attributed to ``trial`` (None: the session as a whole)."""
        self.report.items.append(ReportItem(finding, trial))

    def add_all(self, findings: Iterable[Finding], trial: str | None = None) -> None:
        for f in findings:
            self.add(f, trial)

    @property
    def stream_count(self) -> int:
        return len(self.entries)

    def _guard(self, step: Callable[[], None], trial: str | None = None, file: str | None = None) -> None:
        """Run one check; coded errors become findings, anything unexpected becomes E999 (never a traceback)."""
        self.add_all(collect(step, file), trial)

    def finish(self) -> ValidationReport:
        """The report of everything checked so far (spec §4.6)."""
        return self.report
