"""Saving a session's recording (spec §4.8): the recording plan of :mod:`.recording` streamed entry by
entry into an .rrd, then the blueprint of :mod:`.blueprints` — the one module that needs both, so neither
imports the other."""

from __future__ import annotations

import os
from typing import Any, Callable

import rerun as rr

from haptify.formats.storage import SessionFolder
from haptify.pipeline.results import ResultsFile
from haptify_tools.viewer.blueprints import blueprint_for
from haptify_tools.viewer.plan import CHUNK_ROWS, DEFAULT_DERIVED, Plan, RrdWriter
from haptify_tools.viewer.recording import atomic_rrd, plan_recording, recording_id


def build(
    session: SessionFolder,
    out: str | os.PathLike,
    *,
    trial_id: str | None = None,
    results: ResultsFile | None = None,
    other: SessionFolder | None = None,
    derived: str = DEFAULT_DERIVED,
    chunk_rows: int = CHUNK_ROWS,
    before_commit: Callable[[], Any] | None = None,
) -> Plan:
    """Stream the recording of ``session`` to ``out`` entry by entry, then its blueprint; returns the plan's
    metadata (for summaries and tests). ``before_commit`` runs after everything was logged and before the
    file is renamed into place (the gate's final checks, spec §4.8): when it raises, nothing is written."""
    done: list[Plan] = []

    def fill(rec: rr.RecordingStream) -> None:
        plan = plan_recording(
            session, trial_id=trial_id, results=results, other=other, derived=derived, writer=RrdWriter(rec, chunk_rows)
        )
        rec.send_blueprint(blueprint_for(plan), make_active=True, make_default=True)
        if before_commit is not None:
            before_commit()
        done.append(plan)

    atomic_rrd(out, recording_id(session, trial_id, other), fill)
    return done[0]
