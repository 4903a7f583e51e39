"""The gap and its floor (issue 8, step 4 "show"): how far the twin is from the measurement on held-out
rows, and how far the right twin would still be.

No twin closes the whole gap. The hand path the twin is driven along is rebuilt from motion capture and the handle
accelerometer (:mod:`.hand_path`) — its velocity is off by a fraction of a mm/s, and the twin's friction is not
linear in it — and the sensors add noise: on simulated Touch sessions the twin that generated the data still leaves
≈ 0.004 N on the figure eight, 0.008–0.018 N in free space, 0.0035–0.019 N in stiffness presses and 0.007–0.009 N
in the local-dynamic trial (its drives at rest held, :mod:`.drive_rest`). The floor is measured, not assumed: the
updated twin plays the measured session's protocols through the virtual rig
(:func:`haptify_tools.twin.simulate.simulate_dossier`, one trial per protocol at the measured duration, a fixed
seed), the replay is analysed exactly like the measured session, and its held-out gap is the floor. It is the floor
under the simulator's own examiner and rig, and along the examiner's paths, not the measured ones: the floor
depends on the path (how often and how slowly the hand reverses), and between simulated sessions of the same twin
it varies by a factor of two to five (0.008–0.018 N in 16 s of free space, 0.0035–0.019 N in 12 s of stiffness
presses). It is reported beside the gap as the method's resolution, never used to accept an effect.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from haptify.storage import SessionFolder, open_session

from haptify_tools.discrepancy import data as dt
from haptify_tools.discrepancy import stats as st
from haptify_tools.twin.model import TwinFile
from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

REPLAY_SEED = 0          # the replay is deterministic, like the rest of the workflow
#: session protocols (spec §2.5) the simulator's examiner can replay; ``other`` only with its label
REPLAYABLE = ("free_space", "local_dynamic", "frictionless_surface", "stiffness")
REPLAYABLE_OTHER_LABELS = ("figure_eight",)


def heldout_gap(trials: list[dt.MeasuredTrial], sim: dict) -> float:
    """RMS force residual (N, three axes pooled) over the validation and test blocks of every trial (discrepancy README §3, §4)."""
    parts = [(tr.force - sim[tr.trial_id])[st.heldout_rows(tr)] for tr in trials]
    r = np.concatenate(parts) if parts else np.zeros((0, 3))
    return float(np.sqrt(np.mean(r ** 2))) if len(r) else 0.0


def gap_above_floor(gap: float, floor: float) -> float:
    """The part of a held-out gap (N) above a floor (N): ``√max(gap² − floor², 0)`` — residuals that add in
    energy make the difference of squares the gap a better twin can still close (discrepancy README §4, the floor).
    """
    return float(np.sqrt(max(gap * gap - floor * floor, 0.0)))


def replay_protocol(session: SessionFolder, trial_id: str) -> str | None:
    """The simulator protocol that replays a measured trial, or None when the examiner has none for it (discrepancy README §4, the floor)."""
    trial = next(t for t in session.trials if t.id == trial_id)
    if trial.protocol in REPLAYABLE:
        return trial.protocol
    if trial.protocol == "other" and trial.label in REPLAYABLE_OTHER_LABELS:
        return trial.label
    return None


def replay_floor(twin: TwinFile, session: SessionFolder, trials: list[dt.MeasuredTrial]) -> float | None:
    """The held-out gap (N) of ``twin`` against a replay of the session's force protocols that ``twin``
    itself generated (module docstring; discrepancy README §4, the floor); None when no trial can be replayed.
    """
    durations: dict[str, float] = {}
    for tr in trials:
        name = replay_protocol(session, tr.trial_id)
        if name is not None:
            durations[name] = max(durations.get(name, 0.0), float(tr.t[-1] - tr.t[0]))
    if not durations:
        return None
    options = SimulationOptions(protocols=(*durations, "rig.handle_calibration"), reps=1, seed=REPLAY_SEED,
                                durations=durations, rig_trials=False, workers=1)
    with tempfile.TemporaryDirectory(prefix="haptify-floor-") as tmp:
        replay = dt.load_measured(open_session(simulate_dossier(twin, Path(tmp) / "replay", options).session))
        return heldout_gap(replay, dt.simulate_all(twin, replay))
