"""The gap and its floor (discrepancy README §4, the floor): how far the twin is from the measurement on held-out
rows, and how far the right twin would still be.

No twin closes the whole gap. The hand path the twin is driven along is rebuilt from motion capture and the handle
accelerometer (:mod:`.hand_path`) — its velocity is off by a fraction of a mm/s, and the twin's friction is not
linear in it — and the sensors add noise: on simulated Touch sessions the twin that generated the data still leaves
≈ 0.004 N on the figure eight, 0.008–0.018 N in free space, 0.0035–0.019 N in stiffness presses and 0.007–0.009 N
in the local-dynamic trial (its drives at rest held, :mod:`.drive_rest`). The floor is measured, not assumed: the
updated twin plays the measured session's protocols through the virtual rig
(:func:`haptify_tools.twin.simulate.simulate_dossier`, one trial per protocol at the measured duration), each replay
is analysed exactly like the measured session, and its held-out gap is one draw of the floor. The floor depends on
the path (how often and how slowly the hand reverses): between simulated sessions of the same twin it varies by a
factor of two to five (0.008–0.018 N in 16 s of free space, 0.0035–0.019 N in 12 s of stiffness presses), so one
replay can fall below what the true twin leaves on another session. So
:data:`FLOOR_REPLAYS` replays with their own paths (seeds 0, 1, …) are made, and the floor is the one-sided upper
prediction bound of their log gaps (:class:`Floor`): the held-out gap one more session of the same twin stays under
with probability 1 − :data:`GAP_ALPHA`. A gap above it is significant and the verdict is never "no discrepancy"; the
floor never accepts an effect.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats as sps

from haptify.formats.storage import SessionFolder, open_session
from haptify_tools.discrepancy import data as dt
from haptify_tools.discrepancy import stats as st
from haptify_tools.discrepancy.library import Candidate
from haptify_tools.twin.dossier_plan import SimulationOptions
from haptify_tools.twin.model import TwinFile, set_param
from haptify_tools.twin.simulate import simulate_dossier

REPLAY_SEED = 0  # the replays are deterministic (seeds 0, 1, …), like the rest of the workflow
FLOOR_REPLAYS = 6  # replays whose spread makes the floor's prediction bound
GAP_ALPHA = 0.05  # a held-out gap above the floor's one-sided 95 % prediction bound is significant
#: the log scale is never taken below 0.4, the spread of the true twin's log gap between paths: six replays cannot see a
#: heavy tail — a gap is mostly a few slow reversals, where the path's velocity error flips the friction, and one
#: session in five to ten has one or two and a gap 2–2.5× the median (the true Touch X twin over 24 sessions of 16 s
#: free space: 0.0027–0.0084 N, median 0.0032; 24 of 4 s: 0.0019–0.0054 N, median 0.0024 N). At 0.15 its gap would
#: exceed a six-replay bound in 13–14 % of such sessions, at 0.4 in 6.4 % (16 s) and 0.5 % (4 s) (benchmarks/RESULTS.md)
#: — a null session must not read "unexplained residual"
MIN_LOG_SCALE = 0.4
#: session protocols (spec §2.5) the simulator's examiner can replay; ``other`` only with its label
REPLAYABLE = ("free_space", "local_dynamic", "frictionless_surface", "stiffness")
REPLAYABLE_OTHER_LABELS = ("figure_eight",)


def heldout_gap(trials: list[dt.MeasuredTrial], sim: dict) -> float:
    """RMS force residual (N, three axes pooled) over the validation and test blocks of every trial (discrepancy README §3, §4)."""
    parts = [(tr.force - sim[tr.trial_id])[st.heldout_rows(tr)] for tr in trials]
    r = np.concatenate(parts) if parts else np.zeros((0, 3))
    return float(np.sqrt(np.mean(r**2))) if len(r) else 0.0


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


def replay_durations(session: SessionFolder, trials: list[dt.MeasuredTrial]) -> dict[str, float]:
    """Simulator protocol → the longest measured duration (s) of the trials it replays (discrepancy README §4, the floor)."""
    durations: dict[str, float] = {}
    for tr in trials:
        name = replay_protocol(session, tr.trial_id)
        if name is not None:
            durations[name] = max(durations.get(name, 0.0), float(tr.t[-1] - tr.t[0]))
    return durations


@dataclass(frozen=True)
class Parameter:
    """One identified value the replays estimate again: the library candidate, the drive (None: the value shared by
    every drive) and the value (discrepancy README §3, uncertainty)."""

    candidate: Candidate
    drive: int | None
    value: float

    def set(self, twin: TwinFile, value: float) -> TwinFile:
        if self.drive is None:
            return self.candidate.apply(twin, value)
        return set_param(twin, f"{self.candidate.effect_id}.{self.candidate.parameter}[{self.drive}]", value)


def gauss_newton_step(
    twin: TwinFile, params: tuple[Parameter, ...], trials: list[dt.MeasuredTrial], residual: dict, simulate=None
) -> list[float]:
    """One Gauss–Newton step for ``params`` from the values ``twin`` holds, fitted to ``residual`` (N, measured − the
    twin's prediction): the residual's slope in each parameter by central differences at ±2 % (two simulations a
    parameter; ``simulate(twins)`` → their predictions, default :func:`.data.simulate_many` on ``trials``), all
    parameters together by least squares on the training rows (discrepancy README §2, joint refinement; §3); NaN for a
    value the rows do not determine."""
    simulate = simulate or (lambda twins: dt.simulate_many(twins, trials))
    design = st.make_design(trials, residual)
    steps = [st.SLOPE_STEP * abs(q.value) for q in params]
    twins = [q.set(twin, q.value + f * h) for q, h in zip(params, steps) for f in (-1, 1)]
    sims = iter(simulate(twins))
    slopes = []
    for h in steps:
        lo, hi = next(sims), next(sims)
        slopes.append({k: (hi[k] - lo[k]) / (2 * h) for k in residual})
    zero = {k: np.zeros_like(v) for k, v in residual.items()}
    step, se = st.affine_fit_many(design, residual, zero, slopes)
    return [q.value + float(d) if np.isfinite(e) else float("nan") for q, d, e in zip(params, step, se)]


def reestimate(twin: TwinFile, params: tuple[Parameter, ...], trials: list[dt.MeasuredTrial], sim: dict) -> list[float]:
    """The values ``params`` would be identified at on ``trials`` (simulated ``sim`` by ``twin``, which holds them): one
    :func:`gauss_newton_step` from the twin's values, all parameters together (discrepancy README §3)."""
    return gauss_newton_step(twin, params, trials, {tr.trial_id: tr.force - sim[tr.trial_id] for tr in trials})


def replay_floor(
    twin: TwinFile, durations: dict[str, float], seed: int = REPLAY_SEED, params: tuple[Parameter, ...] = ()
) -> tuple[float, list[float]] | None:
    """One replay (``seed``) of the protocols in ``durations`` (simulator protocol → s) that ``twin`` itself generated:
    the held-out gap (N) ``twin`` leaves on it (module docstring; discrepancy README §4, the floor) and the values of
    ``params`` identified again on it (:func:`reestimate`); None when there is nothing to replay."""
    return _replay(twin, durations, seed, params) if durations else None


def _replay(twin: TwinFile, durations: dict[str, float], seed: int, params: tuple[Parameter, ...]) -> tuple[float, list[float]]:
    """:func:`replay_floor` of at least one protocol."""
    options = SimulationOptions(
        protocols=(*durations, "rig.handle_calibration"), reps=1, seed=seed, durations=durations, rig_trials=False, workers=1
    )
    with tempfile.TemporaryDirectory(prefix="haptify-floor-") as tmp:
        replay = dt.load_measured(open_session(simulate_dossier(twin, Path(tmp) / "replay", options).session))
        sim = dt.simulate_all(twin, replay)
        return heldout_gap(replay, sim), (reestimate(twin, params, replay, sim) if params else [])


@dataclass(frozen=True)
class Floor:
    """The floor from :data:`FLOOR_REPLAYS` replays with their own examiner paths and rig noise (seeds 0, 1, …): each
    replay's held-out gap (N), and the one-sided upper prediction bound at level 1 − :data:`GAP_ALPHA` for the held-out
    gap of one more session of the same twin — the floor the gap is compared with (discrepancy README §3, §4)."""

    replays_N: tuple[float, ...]
    #: per replay, the identified values estimated again on it (:func:`reestimate`), in the order of ``params``
    estimates: tuple[tuple[float, ...], ...] = ()
    params: tuple[Parameter, ...] = ()

    @property
    def log_centre_scale(self) -> tuple[float, float]:
        """Median and robust standard deviation (1.4826 × the median absolute deviation) of the replays' log gaps: one
        replay of a twin with a longer link reached 0.077 N where five others left 0.0055–0.0126 N (its path touched
        the workspace's edge, where the replay along the path does not reproduce the hard stops), and the plain mean and
        standard deviation would have lifted the bound ninefold on one such draw."""
        x = np.log(self.replays_N)
        m = float(np.median(x))
        return m, max(1.4826 * float(np.median(np.abs(x - m))), MIN_LOG_SCALE)

    @property
    def median_N(self) -> float:
        return float(np.median(self.replays_N))

    @property
    def bound_N(self) -> float:
        """``exp(m + t₁₋α,K−1 · s · √(1 + 1/K))``: ``m``, ``s`` the centre and scale of the K replays' log gaps
        (:attr:`log_centre_scale`; the floor varies by a factor of two to five between paths, closer to log-normal than normal)."""
        m, s = self.log_centre_scale
        k = len(self.replays_N)
        return float(np.exp(m + sps.t.ppf(1 - GAP_ALPHA, k - 1) * s * np.sqrt(1 + 1 / k)))

    def p_value(self, gap: float) -> float:
        """One-sided p-value of "``gap`` (N) is one more draw of the floor": the Student-t predictive test on the log gap;
        ``p < GAP_ALPHA`` ⇔ ``gap > bound_N``."""
        m, s = self.log_centre_scale
        k = len(self.replays_N)
        if gap <= 0:
            return 1.0
        return float(sps.t.sf((np.log(gap) - m) / (s * np.sqrt(1 + 1 / k)), k - 1))

    def uncertainty(self, j: int) -> tuple[float, tuple[float, float]]:
        """The ``j``-th parameter's standard error and 95 % interval from the replays (a parametric bootstrap: the replays
        are sessions of the updated twin, so each re-estimate's error is one draw of the identification's error, path
        reconstruction included): ``s = √(mean (p*ₖ − p̂)²)`` over the K replays (bias included) and
        ``p̂ ± t₀.₉₇₅,K · s`` (discrepancy README §3, uncertainty)."""
        v = self.params[j].value
        err = np.array([e[j] for e in self.estimates]) - v
        if not np.all(np.isfinite(err)):  # a replay that cannot determine the value: no honest interval
            return float("inf"), (-float("inf"), float("inf"))
        s = float(np.sqrt(np.mean(err**2)))
        half = float(sps.t.ppf(0.975, len(err))) * s
        return s, (v - half, v + half)


def replay_floors(
    twin: TwinFile, durations: dict[str, float], replays: int = FLOOR_REPLAYS, params: tuple[Parameter, ...] = ()
) -> Floor | None:
    """:func:`replay_floor` for seeds ``0 … replays − 1`` (discrepancy README §4, the floor); None when nothing can be replayed."""
    if not durations:
        return None
    runs = [_replay(twin, durations, seed, params) for seed in range(replays)]
    return Floor(tuple(g for g, _ in runs), tuple(tuple(e) for _, e in runs), params)
