"""Measured trials on the residual grid and their re-simulation with a twin (discrepancy README §1, "where").

Every trial with a ``handle_wrench`` stream is read once through the reference's calibrated handle
signals (spec §7.5, default 100 Hz grid). The hand path that drives the twin blends motion capture
with the handle accelerometer (:mod:`.hand_path`), and every trial is simulated on a 1 kHz grid (the
rendering loop's rate, CHAI3D, at which the twin's drive model is defined) from a cubic spline of that
path: the drive's sharp friction reversals make the model converge only to first order in its
step, and a hidden 5·10⁻⁷ kg·m² rotor inertia came out 20 % high with the passive trials at 250 Hz, 1 %
at 1 kHz. The calibrated force still holds the sensing handle's connector inertia (the paper's
eqs. 1–3 remove only its weight; spec §6.1), so the twin's prediction of the measured signal is the
device's force minus ``m_c·a`` when the twin's ``handle.connector_mass`` is on. Measured and simulated forces are then low-passed alike at
:data:`RESIDUAL_CUTOFF_HZ` so that both carry the same filter; the residual is their difference.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np
from scipy.interpolate import CubicSpline

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.storage import SessionFolder
from haptify.metrics.surface import contact_of, unit_normal
from haptify.pipeline.compute import ComputeContext
from haptify.processing.preprocessing import lowpass
from haptify.processing.signals import handle_signals
from haptify_tools.discrepancy.drive_rest import hold_resting_drives
from haptify_tools.discrepancy.hand_path import FROM_MOCAP, fill_gaps, hand_path, second_derivative
from haptify_tools.discrepancy.model import PathSource
from haptify_tools.twin.model import TwinFile
from haptify_tools.twin.physics import ActiveResult, PassiveResult, simulate_active, simulate_passive

RESIDUAL_CUTOFF_HZ = 5.0  # both forces are compared below this frequency
EDGE_S = 0.5  # the first and last half second of a trial are not compared: there the path's
# velocity rests on one side's data only (a hand at rest started 4 mm/s fast, its
# friction 0.9 N off) and the low-passes are held at the ends
SIM_RATE_HZ = 1000.0  # the rendering loop's rate (paper §V-D), active and passive trials alike
FORCE_PROTOCOLS = ("free_space", "local_dynamic", "other", "frictionless_surface", "stiffness")


class Pool(Protocol):
    """Workers that run ``fn(*args)`` and hand back its future: a process pool initialised by :func:`share_trials`,
    or a Dask cluster's (:class:`.cluster_pool.ClusterPool`)."""

    def submit(self, fn: Callable[..., Any], /, *args: Any) -> Any: ...


@dataclass
class MeasuredTrial:
    """One trial on its uniform residual grid (W frame, SI units).

    ``position``/``quaternion``: the smoothed, gap-free hand path that drives the twin; ``force``:
    the measured calibrated hand force, low-passed; ``valid``: rows whose measured force and motion
    capture are usable, :data:`EDGE_S` or more from the trial's ends and not near a clipped accelerometer
    reading or a capture gap (:attr:`.hand_path.HandPath.unreliable`); ``contact``: rows in contact with the rendered plane (active trials, from the
    commanded force, spec §12.2); ``speed``: gimbal-centre speed, m/s;
    ``commanded_max_N``: largest commanded force magnitude (active trials), N; ``path_source``: what the
    position came from (:data:`.hand_path.FROM_BOTH` or :data:`.hand_path.FROM_MOCAP`).
    """

    trial_id: str
    protocol: str
    rendering: dict | None
    t: np.ndarray
    rate_hz: float
    position: np.ndarray
    quaternion: np.ndarray
    force: np.ndarray
    valid: np.ndarray
    contact: np.ndarray
    speed: np.ndarray
    commanded_max_N: float = 0.0
    path_source: PathSource = FROM_MOCAP

    @property
    def active(self) -> bool:
        return self.rendering is not None

    def penetration(self) -> tuple[np.ndarray, np.ndarray]:
        """Depth of the hand below the rendered plane ``(N,)``, m, and the plane's unit normal (active trials,
        spec §12.2); ValueError for a passive trial, which rendered no plane."""
        if self.rendering is None:
            raise ValueError(f"trial {self.trial_id!r} is passive: it rendered no plane")
        n = np.asarray(self.rendering["surface_normal"], dtype=np.float64)
        n = n / np.linalg.norm(n)
        return (np.asarray(self.rendering["surface_point_m"], dtype=np.float64) - self.position) @ n, n


def load_measured(session: SessionFolder, ctx: ComputeContext | None = None, required: bool = True) -> list[MeasuredTrial]:
    """The measured session's force trials (protocols :data:`FORCE_PROTOCOLS`) ready for re-simulation: calibrated
    handle signals on the 100 Hz grid of spec §7.5, forces in N, W frame (discrepancy README §1).

    E302 when the session has no trial with a ``handle_wrench`` stream and ``required``.
    """
    ctx = ctx or ComputeContext(session=session)
    out = []
    for trial in session.trials:
        if trial.protocol not in FORCE_PROTOCOLS or session.stream(trial.id, "handle_wrench") is None:
            continue
        hs = handle_signals(ctx, trial.id)
        if hs.force is None:  # (none without a handle_wrench stream, left out above)
            continue
        ok = hs.valid & np.all(np.isfinite(hs.force), axis=1) & np.all(np.isfinite(hs.position), axis=1)
        if ok.sum() < 20:
            continue
        path = hand_path(session, ctx, hs, ok, trial.protocol)
        usable = ok & ~path.unreliable & (hs.t >= hs.t[0] + EDGE_S) & (hs.t <= hs.t[-1] - EDGE_S)
        if usable.sum() < 20:
            continue
        rate = hs.rate_hz
        force = lowpass(fill_gaps(hs.t, hs.force, ok), rate, RESIDUAL_CUTOFF_HZ)
        speed = np.linalg.norm(np.gradient(path.position, hs.t, axis=0), axis=1)
        rendering = trial.rendering.model_dump(mode="json") if trial.powered and trial.rendering is not None else None
        contact = np.zeros(len(hs.t), bool)
        cmd_max = 0.0
        if rendering is not None and session.stream(trial.id, "commanded_wrench") is not None:
            cmd = session.read(trial.id, "commanded_wrench")
            n = unit_normal(rendering["surface_normal"], trial.id)
            cmd_n = cmd[["fx", "fy", "fz"]].to_numpy() @ n
            contact = contact_of(np.interp(hs.t, cmd["t"].to_numpy(), cmd_n))
            cmd_max = float(np.max(np.linalg.norm(cmd[["fx", "fy", "fz"]].to_numpy(), axis=1)))
        out.append(
            MeasuredTrial(
                trial.id,
                trial.protocol,
                rendering,
                hs.t,
                rate,
                path.position,
                path.quaternion,
                force,
                usable,
                contact,
                speed,
                cmd_max,
                path.source,
            )
        )
    if not out and required:
        raise fail(
            Code.REQUIRED_STREAM_MISSING,
            "the measured session has no trial with a handle_wrench stream to compare with the twin",
            file="session.json",
            expected="a free-space, local-dynamic, figure-eight, surface or stiffness trial",
            found=[t.id for t in session.trials],
        )
    return out


def fine_path(twin: TwinFile, trial: MeasuredTrial) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The trial's smoothed hand path with ``twin``'s resting drives held (``drive_rest.py``) on its simulation grid
    (cubic spline): ``t`` (s), position (m, W), quaternion (wxyz) (discrepancy README §1)."""
    dt = 1.0 / SIM_RATE_HZ
    fine = np.arange(trial.t[0], trial.t[-1] + 0.5 * dt, dt)
    fine = fine[fine <= trial.t[-1]]
    pos = CubicSpline(trial.t, hold_resting_drives(twin, trial.t, trial.position), axis=0)(fine)
    quat = CubicSpline(trial.t, trial.quaternion, axis=0)(fine)
    return fine, pos, quat / np.linalg.norm(quat, axis=1)[:, None]


def simulate_trial(twin: TwinFile, trial: MeasuredTrial) -> np.ndarray:
    """The force ``(N, 3)`` the twin applies to the hand along the measured path, on the trial's grid,
    low-passed like the measured force (N, W frame) (discrepancy README §1).
    """
    fine, pos, quat = fine_path(twin, trial)
    res: ActiveResult | PassiveResult
    if trial.rendering is not None:
        res = simulate_active(twin, fine, pos, quat, trial.rendering)
    else:
        res = simulate_passive(twin, fine, pos, quat)
    force = lowpass(res.force_W - connector_force(twin, fine, pos), SIM_RATE_HZ, RESIDUAL_CUTOFF_HZ)
    return np.stack([np.interp(trial.t, fine, force[:, k]) for k in range(3)], axis=1)


def connector_force(twin: TwinFile, t: np.ndarray, position: np.ndarray) -> np.ndarray:
    """``m_c·a`` (N, W): the connector's inertial force that the handle calibration leaves in the measured
    force (zero when the twin's ``handle.connector_mass`` is off); ``a`` from the path, m/s² (discrepancy README §1; paper eqs. 1–3).
    """
    c = twin.rig.connector_mass
    if not c.enabled or c.mass_kg == 0:
        return np.zeros_like(position)
    return c.mass_kg * second_derivative(position, t)


def simulate_all(
    twin: TwinFile, trials: list[MeasuredTrial], only_active: bool = False, base: dict[str, np.ndarray] | None = None
) -> dict[str, np.ndarray]:
    """:func:`simulate_trial` for every trial (trial id → force, N); with ``only_active`` the passive trials
    are copied from ``base`` (effects that act only while the motors render) (discrepancy README §1, §2).
    """
    return simulate_many([twin], trials, only_active, base)[0]


#: The trials a worker process simulates, by id (set once per worker by :func:`share_trials`).
_WORKER_TRIALS: dict[str, MeasuredTrial] = {}


def share_trials(trials: list[MeasuredTrial]) -> None:
    """Worker initializer: keep the measured trials in the worker, so that a job names its trial by id."""
    _WORKER_TRIALS.clear()
    _WORKER_TRIALS.update({tr.trial_id: tr for tr in trials})


def _simulate_shared(twin: TwinFile, trial_id: str) -> np.ndarray:
    return simulate_trial(twin, _WORKER_TRIALS[trial_id])


def simulate_many(
    twins: list[TwinFile],
    trials: list[MeasuredTrial],
    only_active: bool = False,
    base: dict[str, np.ndarray] | None = None,
    pool: Pool | None = None,
) -> list[dict[str, np.ndarray]]:
    """:func:`simulate_all` for several twins; with ``pool`` (workers initialised by :func:`share_trials` with
    these trials) every (twin, trial) pair is one job, the longest trials first (discrepancy README §1, §2)."""
    out: list[dict[str, np.ndarray]] = [{} for _ in twins]
    jobs = []
    for i in range(len(twins)):
        for tr in trials:
            if only_active and not tr.active and base is not None:
                out[i][tr.trial_id] = base[tr.trial_id]
            else:
                jobs.append((i, tr))
    if pool is None:
        for i, tr in jobs:
            out[i][tr.trial_id] = simulate_trial(twins[i], tr)
    else:
        futures = {
            (i, tr.trial_id): pool.submit(_simulate_shared, twins[i], tr.trial_id)
            for i, tr in sorted(jobs, key=lambda job: -len(job[1].t))
        }
        for (i, trial_id), future in futures.items():
            out[i][trial_id] = future.result()
    return [{tr.trial_id: o[tr.trial_id] for tr in trials} for o in out]
