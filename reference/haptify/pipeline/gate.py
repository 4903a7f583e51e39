"""The validation gate (spec §4.8): no command computes, draws or sends anything from a session that
does not validate.

:func:`open_checked_session` runs the manifest checks of §4.3.1–4.3.4 and, for every stream, the checks of
its declaration and file that read nothing of the file (§4.2, §4.3.5), and returns a
:class:`CheckedSession`. Each stream's contents are checked (§4.3.5) the first time it is read — the file is read
once, hashed as it is read and decoded, so the checksum costs no second pass — and :meth:`CheckedSession.finish`
checks the streams no one read and the overlap of §4.3.6. The first error refuses the session with
:class:`SessionRefused`, which carries the complete validation report (the same findings and codes as
``haptify validate``) and exit status 1. Warnings are kept for the results file (§15.1).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import pandas as pd

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError
from haptify.formats.session_format import Stream
from haptify.formats.storage import SessionFolder
from haptify.formats.validation import ReportItem, SessionValidator, StreamEntry, validate_session

if TYPE_CHECKING:
    from haptify.pipeline.results import ResultWarning

EXIT_REFUSED = 1


class SessionRefused(HaptifyError):
    """The session does not validate: every finding of its validation report, errors and warnings
    (spec §4.8). Commands exit with status 1 and write no result."""

    exit_code = EXIT_REFUSED


class CheckedSession(SessionFolder):
    """A session folder whose streams are validated as they are read (spec §4.8)."""

    def __init__(self, folder: SessionFolder, validator: SessionValidator) -> None:
        super().__init__(folder.root, folder.manifest, folder.raw)
        self._validator = validator
        self._unchecked: dict[str, StreamEntry] = {e.stream.file: e for e in validator.entries}

    def read_stream(self, stream: Stream, *, verify: bool = False, session_clock: bool = True) -> pd.DataFrame:
        """The stream's table (spec §3.2); its first read is also its validation (§4.3.5), and an
        invalid stream refuses the whole session."""
        entry = self._unchecked.pop(stream.file, None)
        if entry is None:
            return super().read_stream(stream, verify=verify, session_clock=session_clock)
        table = self._validator.check_stream(entry, keep=True)
        self.refuse_on_errors()
        assert table is not None  # a stream whose file could not be read has an error finding
        if session_clock:
            offset = self.clock_offset(stream)
            if offset:
                table["t"] = table["t"] + offset
        return table

    def finish(self, advance: Callable[[int], Any] | None = None) -> list[ReportItem]:
        """Check every stream not read yet and the time overlap (§4.3.5–4.3.6); refuse on an error.
        Returns the warnings of the whole validation, each with its trial."""
        for file in list(self._unchecked):
            self._validator.check_stream(self._unchecked.pop(file))
            self.refuse_on_errors()
            if advance is not None:
                advance(1)
        self._validator.check_overlap()
        self.refuse_on_errors()
        return [item for item in self._validator.report.items if not item.finding.is_error]

    def refuse_on_errors(self) -> None:
        """Refuse the session (:class:`SessionRefused`) when a stream checked so far has an error: a caller
        that carries on after a failed read (a family marks the trial's metrics unavailable) stops here."""
        if self._validator.report.errors:
            raise refusal(self.root, self._validator.report.findings)


def refusal(path: str | os.PathLike[str], found_so_far: list[Finding]) -> SessionRefused:
    """The refusal of a session with its complete validation report (spec §4.8): the gate stops at the
    first error, so the rest of the folder is validated now, once, to report everything."""
    report = validate_session(path)
    return SessionRefused(*(report.findings if report.errors else found_so_far))


def open_checked_session(path: str | os.PathLike[str]) -> CheckedSession:
    """Open a session through the gate (spec §4.8): the manifest and every stream's declaration and file
    (present, inside the folder, within its size bound) now, each stream's contents when read.

    Raises :class:`SessionRefused` (exit 1) when the manifest does not validate, and a coded error with
    exit status 2 when the folder cannot be validated at all (E101, E999; spec §4.1).
    """
    validator = SessionValidator(path)
    validator.check_manifest()
    for entry in validator.entries:  # what the manifest declares of each stream, and that its file is there
        validator.check_declaration(entry)
    if validator.report.errors:
        could_not_run = (Code.SESSION_NOT_FOUND, Code.INTERNAL_ERROR)  # spec §4.1
        if any(f.code in could_not_run for f in validator.report.errors):
            raise HaptifyError(*validator.report.errors)
        raise refusal(path, validator.report.findings)
    assert validator.manifest is not None  # a manifest without errors was parsed whole
    return CheckedSession(SessionFolder(Path(path), validator.manifest, validator.raw), validator)


def require_valid_session(
    path: str | os.PathLike[str], advance: Callable[[int], Any] | None = None
) -> tuple[CheckedSession, list[ReportItem]]:
    """Validate the whole session before anything is done with it (spec §4.8) — for commands that
    read streams through other means or must not start on a session that will be refused. Returns the
    checked session and the validation warnings."""
    session = open_checked_session(path)
    return session, session.finish(advance)


def as_result_warnings(items: list[ReportItem]) -> list[ResultWarning]:
    """Validation warnings as a results file carries them, each with its trial (spec §4.8, §15.1)."""
    from haptify.pipeline.results import ResultWarning  # imported here: commands that write no results file skip its models

    return [ResultWarning(code=i.finding.code, message=i.finding.message, trial=i.trial) for i in items]
