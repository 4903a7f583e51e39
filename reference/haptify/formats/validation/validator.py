"""The session validator (spec chapter 4): the two phases — the manifest, then the streams — run in the
order of spec §4.3, and :func:`validate_session`, which runs both and never raises for bad input."""

from __future__ import annotations

import os
from typing import Any, Callable

from haptify.codes import Code
from haptify.errors import Finding
from haptify.formats.validation.manifest import ManifestChecks
from haptify.formats.validation.report import ValidationReport
from haptify.formats.validation.streams import StreamChecks


class SessionValidator(ManifestChecks, StreamChecks):
    """Validate one session folder in two phases: :meth:`check_manifest`, then :meth:`check_streams`.

    The split lets a caller show progress over the streams (their number is known after the first
    phase); :func:`validate_session` runs both. ``chunk_rows`` forces the rows per chunk in which stream
    files are read (:meth:`chunk_rows_for`); the findings do not depend on it.
    """


def validate_session(
    path: str | os.PathLike[str], advance: Callable[[int], Any] | None = None, chunk_rows: int | None = None
) -> ValidationReport:
    """Validate a session folder and return every finding (spec chapter 4); never raises for bad input.

    ``advance(n)`` is called after each stream (for a progress bar). Stream files are read in chunks
    (``chunk_rows`` rows each when given), so memory does not grow with a stream's length. The report's
    ``exit_code`` is 0 when valid (warnings allowed), 1 when invalid, 2 when validation could not run.
    """
    v = SessionValidator(path, chunk_rows)
    try:
        v.check_manifest()
        v.check_streams(advance)
    except Exception as exc:  # the last guard: a validator bug is a coded finding, never a traceback
        v.add(Finding(Code.INTERNAL_ERROR, f"{type(exc).__name__}: {exc}"))
    return v.finish()
