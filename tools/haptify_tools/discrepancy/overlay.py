"""``overlay.rrd``: the measured session with the updated twin's hand force overlaid, for ``haptify view``
(discrepancy README §4). Built on the viewer's own recording plan (:mod:`haptify_tools.viewer.recording`): the
measured session's compared trials are planned as usual and, for every compared trial, the twin's force (after the update)
is added as the ``compare`` role of ``hand_force/calibrated`` — so the viewer's hand-force views overlay
measured and simulated; a markdown note ``/discrepancy`` says what the compared lines are.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from haptify.formats.storage import SessionFolder
from haptify_tools.discrepancy.data import MeasuredTrial
from haptify_tools.discrepancy.model import DiscrepancyFile


def overlay_plan(session: SessionFolder, trials: list[MeasuredTrial], twin_force: dict[str, np.ndarray]):
    """The viewer's recording plan of the compared trials with the updated twin's hand force (N) as the ``compare``
    role (discrepancy README §4); :func:`write_overlay` adds the note and writes it."""
    from haptify_tools.viewer.recording import plan_recording
    from haptify_tools.viewer.trial_planner import series_entry

    plan = plan_recording(
        session, trial_ids={tr.trial_id for tr in trials}, derived="full"
    )  # the compared trials, with the calibrated force
    by_id = {tp.trial.id: tp for tp in plan.trials}
    for tr in trials:
        tp = by_id.get(tr.trial_id)
        if tp is None:
            continue
        tp.counterpart["compare"] = f"{tr.trial_id} (twin after the update)"
        force = np.where(tr.valid[:, None], twin_force[tr.trial_id], np.nan)
        plan.add(
            series_entry(
                f"/series/{tp.key}/compare/hand_force/calibrated",
                "hand_force/calibrated",
                tr.t,
                force,
                ["fx", "fy", "fz"],
                "compare",
                "haptify discrepancy",
            )
        )
    return plan


def write_overlay(plan, result: DiscrepancyFile, path: Path) -> Path:
    """Write the overlay recording of :func:`overlay_plan` with a markdown note ``/discrepancy`` (effects added, verdict,
    gap) to ``path`` (atomically, by the viewer's :func:`write_rrd`) (discrepancy README §4).
    """
    import rerun as rr

    from haptify_tools.viewer.blueprints import blueprint_for
    from haptify_tools.viewer.plan import Entry
    from haptify_tools.viewer.recording import write_rrd

    named = ", ".join(f"{a.effect_id} {a.parameter} = {a.value:.4g} {a.unit}" for a in result.accepted) or "none"
    note = (
        "# Twin versus measurement\n\nLines marked *(compare)* in the hand-force views are the updated twin's "
        f"force along the measured path (low-passed at the workflow's comparison band).\n\nEffects added: {named}.\n\n"
        f"Verdict: {result.verdict}; {result.gap_summary()}."
    )
    plan.add(Entry("/discrepancy", static=[rr.TextDocument(note, media_type=rr.MediaType.MARKDOWN)]))
    return write_rrd(plan, path, blueprint_for(plan))
