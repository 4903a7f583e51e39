"""Handle gravity calibration: paper eqs. 1–3 fitted and applied (spec chapter 6).

Sign conventions (spec §6.1). The handle F/T sensor sits between the connector (device side) and the
handle (hand side). Its raw reading, in its own frame S, is the force and torque the **connector side
exerts on the sensor**, torque about the origin of S, plus a constant bias. With the unattached
end-effector held in the air the connector's weight is the only load, so (paper eq. 1, eq. 3)

    F_S = b_F + m g_S(t),        τ_S = b_τ + r_S × m g_S(t),

with g_S the gravitational acceleration (pointing down) expressed in S. With the device attached, the
connector transmits the device's force: F_S − b_F − m g_S is the force the device applies, through the
handle, to the hand. The accelerometer reads specific force in its frame A: a_A = b_a + R_AWᵀ(a − g_W),
so at rest it reads +g upward (paper eq. 2 writes the sphere as b_a + g; only the radius enters).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.conventions import GRAVITY_W, STANDARD_GRAVITY, quat_conjugate, quat_rotate, quat_to_matrix
from haptify.formats.session_format import HandleGravityCalibration, Pose
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters
from haptify.processing import preprocessing
from haptify.processing.caching import cached, session_of

FAMILY = "calibration"


class CalibrationParameters(FamilyParameters):
    """The parameters of ``metrics/calibration.json`` (spec chapter 6), in the units its definition file states."""

    fit_rate_hz: float
    torque_loss: Literal["linear", "soft_l1", "huber", "cauchy", "arctan"]
    torque_f_scale_Nm: float
    min_coverage: float
    offset_batches: int
    min_samples: int


#: The calibration family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = load_parameters(FAMILY, CalibrationParameters)


@dataclass(frozen=True)
class SphereFit:
    """A fitted sphere: ``centre`` (input units), ``radius`` and the RMS of the radial residuals.
    Spec §6.2 steps 1–4."""

    centre: np.ndarray
    radius: float
    rms: float
    coverage: float  # smallest eigenvalue of the mean outer product of unit directions (1/3 = full sphere)
    covariance: np.ndarray  # (4, 4) of (centre x, y, z, radius), input units squared: :func:`batch_means_covariance`

    @property
    def offset_u(self) -> float:
        """Standard uncertainty (input units) of a common offset of what the fit removes (spec §6.2, §14.7):
        √(largest per-axis variance of the centre + variance of the radius)."""
        return float(np.sqrt(np.max(np.diag(self.covariance)[:3]) + self.covariance[3, 3]))


@dataclass(frozen=True)
class HandleCalibration:
    """Parameters of paper eqs. 1–3 (spec §6.1), in the sensor frames S (F/T) and A (accelerometer).

    ``connector_mass_kg`` is the fitted weight divided by standard gravity; the weight removed from
    each reading is ``connector_mass_kg · g0`` along g, so the fitted weight is removed exactly.
    The ``rms_*`` fields, ``force_offset_u_N`` (:attr:`SphereFit.offset_u` of the force sphere) and
    ``n_samples`` are set when the parameters were fitted from a trial.
    """

    force_bias_N: np.ndarray
    connector_mass_kg: float
    connector_com_m: np.ndarray
    torque_bias_Nm: np.ndarray
    accel_bias_m_per_s2: np.ndarray
    gravity_m_per_s2: float
    source: str = ""
    rms_force_N: float | None = None
    rms_accel_m_per_s2: float | None = None
    rms_torque_Nm: float | None = None
    force_offset_u_N: float | None = None
    n_samples: int = 0
    diagnostics: dict[str, Any] = field(default_factory=dict)

    @property
    def connector_weight_N(self) -> float:
        return self.connector_mass_kg * STANDARD_GRAVITY

    @classmethod
    def from_record(cls, rec: HandleGravityCalibration) -> "HandleCalibration":
        """The parameters of a ``handle_gravity`` calibration record (spec §2.8)."""
        return cls(
            force_bias_N=np.asarray(rec.force_bias_N, float),
            connector_mass_kg=float(rec.connector_mass_kg),
            connector_com_m=np.asarray(rec.connector_com_m, float),
            torque_bias_Nm=np.asarray(rec.torque_bias_Nm, float),
            accel_bias_m_per_s2=np.asarray(rec.accel_bias_m_per_s2, float),
            gravity_m_per_s2=float(rec.gravity_m_per_s2),
            source=f"record:{rec.id}",
        )

    def to_record(self, record_id: str, source_trial: str | None = None) -> dict[str, Any]:
        """A ``handle_gravity`` record (JSON-ready dict) holding these parameters (spec §2.8)."""
        rec = {
            "kind": "handle_gravity",
            "id": record_id,
            "force_bias_N": self.force_bias_N.tolist(),
            "connector_mass_kg": float(self.connector_mass_kg),
            "connector_com_m": self.connector_com_m.tolist(),
            "torque_bias_Nm": self.torque_bias_Nm.tolist(),
            "accel_bias_m_per_s2": self.accel_bias_m_per_s2.tolist(),
            "gravity_m_per_s2": float(self.gravity_m_per_s2),
        }
        if source_trial:
            rec["source_trial"] = source_trial
        return rec


# --- fits (spec §6.2, §6.3) ---------------------------------------------------------------------


def fit_sphere(
    points: np.ndarray, *, min_coverage: float | None = None, min_samples: int | None = None, label: str = "calibration"
) -> SphereFit:
    """Least-squares sphere through ``points (N, 3)`` (spec §6.2).

    Algebraic (Kåsa) solution of ``|x|² = 2c·x + (r² − |c|²)`` as the start, then the geometric fit
    minimising Σ(|x_i − c| − r)² (scipy least_squares, linear loss). Raises E602 when there are fewer
    than ``min_samples`` points or the directions do not span the sphere (coverage < ``min_coverage``).
    """
    x = np.asarray(points, dtype=float)
    x = x[np.all(np.isfinite(x), axis=1)]
    min_samples = PARAMETERS.min_samples if min_samples is None else min_samples
    min_coverage = PARAMETERS.min_coverage if min_coverage is None else min_coverage
    if len(x) < max(min_samples, 4):
        raise fail(
            Code.HANDLE_CALIBRATION_DEGENERATE,
            f"{label}: {len(x)} samples, too few for a sphere fit",
            expected=f">= {min_samples}",
            found=len(x),
        )
    design = np.column_stack([2.0 * x, np.ones(len(x))])
    sol, *_ = np.linalg.lstsq(design, np.sum(x * x, axis=1), rcond=None)
    c0 = sol[:3]
    r0 = float(np.sqrt(max(sol[3] + c0 @ c0, 1e-300)))

    def resid(p: np.ndarray) -> np.ndarray:
        out: np.ndarray = np.linalg.norm(x - p[:3], axis=1) - p[3]
        return out

    res = least_squares(resid, np.concatenate([c0, [r0]]), method="lm", x_scale="jac")
    centre, radius = res.x[:3], float(abs(res.x[3]))
    d = x - centre
    u = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    coverage = float(np.linalg.eigvalsh(u.T @ u / len(u))[0])
    if not np.isfinite(radius) or coverage < min_coverage:
        raise fail(
            Code.HANDLE_CALIBRATION_DEGENERATE,
            f"{label}: orientations cover too little of the sphere (coverage {coverage:.3f})",
            expected=f"coverage >= {min_coverage}",
            found=round(coverage, 4),
        )
    r = resid(np.concatenate([centre, [radius]]))
    jac = -np.column_stack([u, np.ones(len(u))])
    cov = batch_means_covariance(jac, r, PARAMETERS.offset_batches)
    return SphereFit(centre=centre, radius=radius, rms=float(np.sqrt(np.mean(r**2))), coverage=coverage, covariance=cov)


def batch_means_covariance(jac: np.ndarray, resid: np.ndarray, batches: int) -> np.ndarray:
    """Covariance of least-squares parameters whose time-ordered residuals are correlated (spec §6.2).

    The sandwich (JᵀJ)⁻¹ S (JᵀJ)⁻¹ with S the batch-means long-run covariance of the scores Jᵢᵀrᵢ: the
    samples cut into ``batches`` contiguous blocks, Gᵦ = Σ over block β of Jᵢᵀrᵢ, S = B/(B − 1)·Σᵦ (Gᵦ − Ḡ)(Gᵦ − Ḡ)ᵀ.
    Blocks longer than the residuals' correlation time make it consistent where the per-sample formula
    σ²(JᵀJ)⁻¹ would understate a correlated residual's effect and overstate an independent one's RMS.
    """
    scores = jac * resid[:, None]
    sums = np.array([blk.sum(axis=0) for blk in np.array_split(scores, batches)])
    dev = sums - sums.mean(axis=0)
    s = batches / (batches - 1) * dev.T @ dev
    inv = np.linalg.inv(jac.T @ jac)
    out: np.ndarray = inv @ s @ inv
    return out


def _cross_matrix(v: np.ndarray) -> np.ndarray:
    """Skew matrices ``[v]×`` of vectors ``(N, 3)`` → ``(N, 3, 3)`` with ``[v]× w = v × w``."""
    z = np.zeros(len(v))
    return np.stack(
        [np.stack([z, -v[:, 2], v[:, 1]], -1), np.stack([v[:, 2], z, -v[:, 0]], -1), np.stack([-v[:, 1], v[:, 0], z], -1)],
        axis=-2,
    )


#: The robust losses of scipy's least_squares a calibration parameter may name (spec §6.3).
RobustLoss = Literal["linear", "soft_l1", "huber", "cauchy", "arctan"]


def fit_torque(
    torque: np.ndarray, load: np.ndarray, *, loss: RobustLoss | None = None, f_scale: float | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """Robust fit of paper eq. 3, ``τ_i = b_τ + r × L_i`` (spec §6.3).

    ``torque (N, 3)`` in N·m and ``load (N, 3)`` = the connector's weight in S (``F_i − b_F``), N.
    scipy least_squares with the calibration family's loss (``soft_l1``) and ``f_scale``, started
    from the ordinary least-squares solution. Returns ``(b_τ, r, rms)``; ``rms`` is the per-component
    RMS of the residuals ``sqrt(Σ|e_i|² / 3N)`` in N·m.
    """
    tau = np.asarray(torque, float)
    L = np.asarray(load, float)
    loss = PARAMETERS.torque_loss if loss is None else loss
    f_scale = PARAMETERS.torque_f_scale_Nm if f_scale is None else f_scale
    # τ = b − [L]× r  (since r × L = −L × r)
    A = np.concatenate([np.broadcast_to(np.eye(3), (len(L), 3, 3)), -_cross_matrix(L)], axis=2).reshape(-1, 6)
    y = tau.reshape(-1)
    p0, *_ = np.linalg.lstsq(A, y, rcond=None)

    def residual(p: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        r: npt.NDArray[np.float64] = A @ p - y
        return r

    res = least_squares(residual, p0, loss=loss, f_scale=f_scale, method="trf", x_scale="jac")
    e = A @ res.x - y
    return res.x[:3].copy(), res.x[3:].copy(), float(np.sqrt(np.mean(e**2)))


def fit_from_samples(force: np.ndarray, torque: np.ndarray, accel: np.ndarray, *, source: str = "") -> HandleCalibration:
    """Fit every parameter of eqs. 1–3 from resampled calibration samples (spec §6.2–6.3).

    ``force``/``torque`` ``(N, 3)`` in the F/T sensor frame S, ``accel (M, 3)`` in the accelerometer
    frame A (the two need not share a time base).
    """
    fs = fit_sphere(force, label=f"{source} force")
    acc = fit_sphere(accel, label=f"{source} acceleration")
    b_tau, com, rms_tau = fit_torque(torque, np.asarray(force, float) - fs.centre)
    return HandleCalibration(
        force_bias_N=fs.centre,
        connector_mass_kg=fs.radius / STANDARD_GRAVITY,
        connector_com_m=com,
        torque_bias_Nm=b_tau,
        accel_bias_m_per_s2=acc.centre,
        gravity_m_per_s2=acc.radius,
        source=source,
        rms_force_N=fs.rms,
        rms_accel_m_per_s2=acc.rms,
        rms_torque_Nm=rms_tau,
        force_offset_u_N=fs.offset_u,
        n_samples=int(len(force)),
        diagnostics={"force_coverage": fs.coverage, "accel_coverage": acc.coverage},
    )


def fit_trial(ctx_or_session: Any, trial_id: str) -> HandleCalibration:
    """Fit eqs. 1–3 from a ``rig.handle_calibration`` trial (spec §6.2–6.3).

    The raw wrench and acceleration are low-passed as in spec §7.2 and resampled (linear interpolation)
    to ``fit_rate_hz`` over their common time span; the fits need no motion capture. When the trial
    has a usable ``handle_pose`` the diagnostic ``orientation_error_deg`` (RMS angle between the fitted
    connector-weight direction and the direction motion capture predicts) checks the rig's sensor pose.
    """
    session = session_of(ctx_or_session)
    rate = PARAMETERS.fit_rate_hz
    w = session.read(trial_id, "handle_wrench")
    a = session.read(trial_id, "handle_accel")
    t0 = max(w["t"].iloc[0], a["t"].iloc[0])
    t1 = min(w["t"].iloc[-1], a["t"].iloc[-1])
    grid = preprocessing.uniform_grid(t0, t1, rate)
    if len(grid) < 2:
        raise fail(
            Code.STREAMS_DO_NOT_OVERLAP,
            f"handle_wrench and handle_accel of trial {trial_id!r} do not overlap",
            expected="overlapping streams",
        )
    wr = preprocessing.lowpass_resample(
        w["t"].to_numpy(), w[["fx", "fy", "fz", "tx", "ty", "tz"]].to_numpy(), grid, preprocessing.PARAMETERS.wrench_cutoff_hz
    )
    ac = preprocessing.lowpass_resample(
        a["t"].to_numpy(), a[["ax", "ay", "az"]].to_numpy(), grid, preprocessing.PARAMETERS.accel_cutoff_hz
    )
    cal = fit_from_samples(wr[:, :3], wr[:, 3:], ac, source=f"trial:{trial_id}")
    if session.stream(trial_id, "handle_pose") is not None:
        try:
            err = orientation_error_deg(ctx_or_session, trial_id, grid, wr[:, :3] - cal.force_bias_N)
        except HaptifyError as exc:  # the diagnostic is optional; the fit stands without it
            # no usable motion capture, or no sensor pose in the rig
            if exc.code not in (Code.MOTION_CAPTURE_UNUSABLE, Code.RIG_PART_MISSING):
                raise
        else:
            cal.diagnostics["orientation_error_deg"] = err
    return cal


def orientation_error_deg(ctx_or_session: Any, trial_id: str, grid: np.ndarray, load_s: np.ndarray) -> float:
    """RMS angle (deg) between the measured connector load ``load_s (N, 3)`` (F − b_F, frame S, on ``grid``)
    and the gravity direction motion capture predicts in S at the same times (spec §6.3 diagnostic).

    E611 without usable motion capture, E603 without the sensor pose in the rig.
    """
    session = session_of(ctx_or_session)
    mocap = preprocessing.pose_on_grid(ctx_or_session, trial_id, grid)
    g_s = gravity_in_sensor(mocap.quaternion[mocap.valid], sensor_rotation(session, "ft_sensor"))
    load = load_s[mocap.valid]
    cosang = np.sum(g_s * load, axis=1) / (np.linalg.norm(g_s, axis=1) * np.linalg.norm(load, axis=1))
    return float(np.sqrt(np.mean(np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0))) ** 2)))


# --- which parameters apply (spec §6.4) ----------------------------------------------------------


def handle_calibration(ctx_or_session: Any) -> HandleCalibration:
    """The handle calibration that applies to the session (spec §6.4).

    The last ``handle_gravity`` record in manifest order; otherwise a fit of the last
    ``rig.handle_calibration`` trial (highest repetition); otherwise E601. Cached on a ComputeContext.
    """

    def build() -> HandleCalibration:
        session = session_of(ctx_or_session)
        records = [c for c in session.manifest.calibration if c.kind == "handle_gravity"]
        if records:
            return HandleCalibration.from_record(records[-1])
        trials = session.trials_of("rig.handle_calibration")
        if not trials:
            raise fail(
                Code.HANDLE_CALIBRATION_MISSING,
                f"session {session.session_id!r} has no handle_gravity record and no rig.handle_calibration trial",
                file="session.json",
                pointer="/calibration",
                expected="a handle_gravity record or a rig.handle_calibration trial",
                found=None,
            )
        return trial_fit(ctx_or_session, trials[-1].id)

    return cached(ctx_or_session, ("handle_calibration",), build)


def trial_fit(ctx_or_session: Any, trial_id: str) -> HandleCalibration:
    """:func:`fit_trial`, cached on a context under ``("handle_calibration_fit", trial_id)``.
    Spec §6.2–6.3."""
    return cached(ctx_or_session, ("handle_calibration_fit", trial_id), lambda: fit_trial(ctx_or_session, trial_id))


# --- applying it (spec §6.5, §6.6) ---------------------------------------------------------------


def sensor_pose(session: Any, part: str) -> Pose:
    """Pose of the handle's ``ft_sensor`` or ``accelerometer`` frame in the handle body frame (E603 if absent).
    Position in m; spec §1.2, §2.4."""
    handle = session.manifest.rig.handle
    if handle is None:
        raise fail(
            Code.RIG_PART_MISSING,
            f"the rig of session {session.session_id!r} does not describe the handle sensors",
            file="session.json",
            pointer="/rig/handle",
            expected="rig.handle with ft_sensor and accelerometer poses",
            found=None,
        )
    out: Pose = getattr(handle, part).pose
    return out


def sensor_rotation(session: Any, part: str) -> np.ndarray:
    """Rotation matrix (3, 3) of a handle sensor frame → handle body frame.
    ``R_HS`` or ``R_HA`` of spec §6.1."""
    return quat_to_matrix(np.asarray(sensor_pose(session, part).quaternion, float))


def gravity_in_sensor(q_handle: np.ndarray, r_sensor: np.ndarray) -> np.ndarray:
    """Standard gravitational acceleration g_W = (0, 0, −g0) expressed in a sensor frame, ``(N, 3)`` m/s².
    ``g_X = R_WXᵀ g_W`` of spec §6.1.

    ``q_handle (N, 4)`` handle body → world; ``r_sensor (3, 3)`` sensor → handle body.
    """
    g_h = quat_rotate(quat_conjugate(q_handle), np.broadcast_to(GRAVITY_W, np.shape(q_handle)[:-1] + (3,)))
    out: np.ndarray = g_h @ r_sensor  # r_sensorᵀ · g_h for each row
    return out


def compensate_wrench(raw: np.ndarray, q_handle: np.ndarray, cal: HandleCalibration, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """Force (N) and torque (N·m) the device applies to the hand, world frame, torque about the gimbal centre (spec §6.5).

    ``raw (N, 6)`` = fx, fy, fz, tx, ty, tz as the sensor reports them in S; ``q_handle (N, 4)`` the
    handle orientation at the same instants; ``pose`` the sensor frame in the handle body frame H
    (its position is the sensor origin relative to the gimbal centre, the origin of H).

        F_S = raw_F − b_F − m g_S,   τ_S = raw_τ − b_τ − r × m g_S,
        F_H = R_HS F_S,   τ_H = R_HS τ_S + p_S × F_H,   F_W = R_WH F_H,   τ_W = R_WH τ_H.
    """
    raw = np.asarray(raw, float)
    r_hs = quat_to_matrix(np.asarray(pose.quaternion, float))
    mg = cal.connector_mass_kg * gravity_in_sensor(q_handle, r_hs)
    f_s = raw[:, :3] - cal.force_bias_N - mg
    t_s = raw[:, 3:6] - cal.torque_bias_Nm - np.cross(cal.connector_com_m, mg)
    f_h = f_s @ r_hs.T
    t_h = t_s @ r_hs.T + np.cross(np.asarray(pose.position, float), f_h)
    return quat_rotate(q_handle, f_h), quat_rotate(q_handle, t_h)


def compensate_accel(raw: np.ndarray, q_handle: np.ndarray, cal: HandleCalibration, pose: Pose) -> np.ndarray:
    """Handle acceleration in the world frame with bias and gravity removed, m/s² (spec §6.6).

    ``a_W = R_WH R_HA (raw − b_a) − (0, 0, g_fit)``, where ``g_fit`` is the fitted sphere radius (the
    accelerometer's own reading of g), so a handle at rest reads zero whatever the sensor's scale.
    """
    r_ha = quat_to_matrix(np.asarray(pose.quaternion, float))
    a_h = (np.asarray(raw, float) - cal.accel_bias_m_per_s2) @ r_ha.T
    a_w = quat_rotate(q_handle, a_h)
    a_w[:, 2] -= cal.gravity_m_per_s2
    return a_w
