"""Sessions with known answers for the calibration, signal, force-plate and rig tests.

Shared by the unit tests and the conformance fixture builder. Every stream is generated from stated
truth (bias, connector mass and centre of mass, plate mode frequencies, weight positions, recorder
delays) with the sign conventions of spec §6.1 and §14.1, so the tests can state the expected values.
Independent of the simulator on purpose.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from haptify.formats.conventions import (
    GRAVITY_W,
    STANDARD_GRAVITY,
    quat_conjugate,
    quat_from_axis_angle,
    quat_multiply,
    quat_rotate,
)
from haptify.formats.storage import SessionWriter
from haptify_tools.example_session import IDENTITY, TOUCH_DEVICE, example_rig


@dataclass
class HandleTruth:
    force_bias: np.ndarray = field(default_factory=lambda: np.array([0.31, -0.12, 0.45]))
    mass: float = 0.052
    com: np.ndarray = field(default_factory=lambda: np.array([0.004, -0.003, 0.021]))
    torque_bias: np.ndarray = field(default_factory=lambda: np.array([0.011, -0.007, 0.003]))
    accel_bias: np.ndarray = field(default_factory=lambda: np.array([0.08, -0.05, 0.12]))
    gravity: float = STANDARD_GRAVITY
    force_noise: float = 0.004
    torque_noise: float = 0.0001
    accel_noise: float = 0.05

    def record(self, rid: str = "hg-1") -> dict:
        return {
            "kind": "handle_gravity",
            "id": rid,
            "force_bias_N": self.force_bias.tolist(),
            "connector_mass_kg": self.mass,
            "connector_com_m": self.com.tolist(),
            "torque_bias_Nm": self.torque_bias.tolist(),
            "accel_bias_m_per_s2": self.accel_bias.tolist(),
            "gravity_m_per_s2": self.gravity,
        }


def tumbling_orientation(t: np.ndarray) -> np.ndarray:
    """A slow tumble that points the handle in every direction within ~20 s: Rz(0.7t)·Rx(0.43t)·Rz(0.29t)."""
    z = np.array([0.0, 0.0, 1.0])
    x = np.array([1.0, 0.0, 0.0])
    n = len(t)
    q = quat_multiply(
        quat_from_axis_angle(np.broadcast_to(z, (n, 3)), 0.7 * t),
        quat_multiply(
            quat_from_axis_angle(np.broadcast_to(x, (n, 3)), 0.43 * t), quat_from_axis_angle(np.broadcast_to(z, (n, 3)), 0.29 * t)
        ),
    )
    return q * np.where(q[:, :1] < 0, -1.0, 1.0)


def _pose_quat(pose: dict) -> np.ndarray:
    return np.asarray(pose["quaternion"], float)


def raw_handle(
    truth: HandleTruth,
    rig: dict,
    t_ft: np.ndarray,
    q_ft: np.ndarray,
    t_acc: np.ndarray,
    q_acc: np.ndarray,
    rng: np.random.Generator,
    hand_force_w: np.ndarray | None = None,
    hand_torque_g_w: np.ndarray | None = None,
    lin_acc_w: np.ndarray | None = None,
) -> tuple[dict, dict]:
    """Raw handle_wrench and handle_accel columns (spec §6.1 sign convention).

    ``hand_force_w``/``hand_torque_g_w``: the wrench the device applies to the hand (world, torque about
    the gimbal centre) at the F/T times; ``lin_acc_w`` the handle's acceleration at the accelerometer times.
    """
    ft = rig["handle"]["ft_sensor"]["pose"]
    ac = rig["handle"]["accelerometer"]["pose"]
    q_hs = _pose_quat(ft)
    p_s = np.asarray(ft["position"], float)
    q_ws = quat_multiply(q_ft, np.broadcast_to(q_hs, q_ft.shape))
    g_s = quat_rotate(quat_conjugate(q_ws), np.broadcast_to(GRAVITY_W, (len(t_ft), 3)))
    f = truth.force_bias + truth.mass * g_s
    tau = truth.torque_bias + np.cross(truth.com, truth.mass * g_s)
    if hand_force_w is not None:
        if hand_torque_g_w is None:
            raise ValueError("the hand's force needs its torque about the gimbal centre (hand_torque_g_w)")
        f_s = quat_rotate(quat_conjugate(q_ws), hand_force_w)
        # torque about the sensor origin: τ_S = τ_G − p × F  (in H), then into S
        t_h = quat_rotate(quat_conjugate(q_ft), hand_torque_g_w) - np.cross(p_s, quat_rotate(quat_conjugate(q_ft), hand_force_w))
        f = f + f_s
        tau = tau + quat_rotate(np.broadcast_to(quat_conjugate(q_hs), q_ft.shape), t_h)
    f = f + rng.normal(0, truth.force_noise, f.shape)
    tau = tau + rng.normal(0, truth.torque_noise, tau.shape)
    q_wa = quat_multiply(q_acc, np.broadcast_to(_pose_quat(ac), q_acc.shape))
    acc_w = np.zeros((len(t_acc), 3)) if lin_acc_w is None else lin_acc_w
    specific_w = acc_w - np.array([0.0, 0.0, -truth.gravity])
    a = truth.accel_bias + quat_rotate(quat_conjugate(q_wa), specific_w) + rng.normal(0, truth.accel_noise, (len(t_acc), 3))
    wrench = {"t": t_ft, "fx": f[:, 0], "fy": f[:, 1], "fz": f[:, 2], "tx": tau[:, 0], "ty": tau[:, 1], "tz": tau[:, 2]}
    accel = {"t": t_acc, "ax": a[:, 0], "ay": a[:, 1], "az": a[:, 2]}
    return wrench, accel


def rotated_rig() -> dict:
    """The example rig with the handle sensors turned (so frames S, A and H differ)."""
    rig = example_rig()
    s = np.sqrt(0.5)
    rig["handle"]["ft_sensor"]["pose"] = {"position": [0.002, -0.001, -0.03], "quaternion": [s, 0.0, 0.0, s]}
    rig["handle"]["accelerometer"]["pose"] = {"position": [0.0, 0.004, -0.05], "quaternion": [0.0, 1.0, 0.0, 0.0]}
    return rig


def writer(rig: dict | None = None, calibration: list | None = None, sid: str = "rigtest") -> SessionWriter:
    manifest = {
        "session_id": sid,
        "date": "2026-11-22",
        "lab": {"id": "lab-test"},
        "examiner": {"id": "ex-01"},
        "device": TOUCH_DEVICE,
        "device_placement": IDENTITY,
        "rig": rig or rotated_rig(),
    }
    if calibration:
        manifest["calibration"] = calibration
    return SessionWriter(manifest=manifest)


def add_calibration_trial(
    w: SessionWriter,
    truth: HandleTruth,
    rng: np.random.Generator,
    *,
    trial_id: str = "cal-1",
    duration_s: float = 24.0,
    accel_delay_s: float = 0.0,
    mocap_delay_s: float = 0.0,
    repetition: int = 1,
) -> None:
    """A rig.handle_calibration trial: the tumble above, F/T 1 kHz, accelerometer 2 kHz, mocap 100 Hz.

    ``*_delay_s``: that recorder's time stamps are late by this much (its clock runs behind).
    """
    rig = w.manifest["rig"]
    t_ft = np.arange(int(duration_s * 1000)) / 1000.0
    t_acc = np.arange(int(duration_s * 2000)) / 2000.0
    t_m = np.arange(int(duration_s * 100)) / 100.0
    wrench, accel = raw_handle(truth, rig, t_ft, tumbling_orientation(t_ft), t_acc, tumbling_orientation(t_acc), rng)
    accel["t"] = t_acc + accel_delay_s
    q = tumbling_orientation(t_m)
    pos = np.column_stack([0.01 * np.sin(0.3 * t_m), 0.0 * t_m, 0.2 + 0.0 * t_m])
    w.add_trial(trial_id, "rig.handle_calibration", powered=False, repetition=repetition)
    w.add_stream(trial_id, "handle_wrench", wrench, rate_hz=1000)
    w.add_stream(trial_id, "handle_accel", accel, rate_hz=2000)
    w.add_stream(
        trial_id,
        "handle_pose",
        {
            "t": t_m + mocap_delay_s,
            "px": pos[:, 0],
            "py": pos[:, 1],
            "pz": pos[:, 2],
            "qw": q[:, 0],
            "qx": q[:, 1],
            "qy": q[:, 2],
            "qz": q[:, 3],
        },
        rate_hz=100,
    )


# --- force plate ---------------------------------------------------------------------------------


def corner_readings(rig: dict, force_w: np.ndarray, point_w: np.ndarray, bias: np.ndarray | None = None) -> np.ndarray:
    """Corner readings ``(N, 24)`` for a load ``force_w (N, 3)`` acting at ``point_w (N, 3)`` (spec §14.1).

    Statically determinate split: vertical force by bilinear (lever-rule) weights of the load's x, y
    position; horizontal force equally; the moment the horizontal force makes about the corner plane
    is carried by extra vertical forces, the vertical moment by tangential forces. Each corner reports the force the plate exerts on it in its own
    frame (moment about its origin zero: pin supports). The four readings reproduce the total wrench.
    """
    from haptify.formats.session_format import Rig
    from haptify.processing.force_plate import corner_geometry

    pos, rot = corner_geometry(Rig.model_validate(rig))
    n = len(force_w)
    hx, hy = np.max(np.abs(pos[:, 0])), np.max(np.abs(pos[:, 1]))
    zc = pos[0, 2]
    out = np.zeros((n, 4, 3))
    # Moment about the corner-plane centre (0, 0, zc) that the corners' vertical forces must carry.
    arm = point_w - np.array([0.0, 0.0, zc])
    m = np.cross(arm, force_w)
    for i in range(4):
        sx, sy = np.sign(pos[i, 0]), np.sign(pos[i, 1])
        fz = force_w[:, 2] / 4 + sy * m[:, 0] / (4 * hy) - sx * m[:, 1] / (4 * hx)
        r_xy = np.hypot(pos[i, 0], pos[i, 1])
        tangent = np.array([-pos[i, 1], pos[i, 0], 0.0]) / r_xy
        f_w = np.column_stack([force_w[:, 0] / 4, force_w[:, 1] / 4, fz]) + np.outer(m[:, 2] / (4 * r_xy), tangent)
        out[:, i] = f_w @ rot[i]  # R_iᵀ f for each row
    raw = np.concatenate([out, np.zeros((n, 4, 3))], axis=2).reshape(n, 24)
    return raw if bias is None else raw + bias


def plate_stream(t: np.ndarray, raw: np.ndarray) -> dict:
    from haptify.processing.force_plate import PLATE_COLUMNS

    return {"t": t, **{c: raw[:, j] for j, c in enumerate(PLATE_COLUMNS)}}


def write(w: SessionWriter, tmp: Path, name: str = "s") -> Path:
    return w.write(tmp / name)


PLATE_BIAS_WEIGHT_N = 160.0  # the paper's plate weight, carried equally by the corners


def plate_bias_vector(rig: dict) -> np.ndarray:
    """Corner readings of the unloaded plate: its weight on the four corners plus a small offset per channel."""
    raw = corner_readings(rig, np.array([[0.0, 0.0, -PLATE_BIAS_WEIGHT_N]]), np.zeros((1, 3)))[0]
    return raw + 0.01 * np.arange(24)


def add_plate_bias_trial(w: SessionWriter, rng: np.random.Generator, trial_id: str = "plate-bias-1") -> np.ndarray:
    rig = w.manifest["rig"]
    bias = plate_bias_vector(rig)
    t = np.arange(2000) / 1000.0
    raw = bias + rng.normal(0, 0.01, (len(t), 24))
    w.add_trial(trial_id, "rig.plate_bias", powered=False)
    w.add_stream(trial_id, "plate_wrench", plate_stream(t, raw), rate_hz=1000)
    return bias


def damped(t: np.ndarray, f_hz: float, zeta: float, t0: float, amp: float) -> np.ndarray:
    """``amp · e^{−ζω(t−t0)} sin(ω_d (t − t0))`` after ``t0``, zero before (ω = 2π f, ω_d = ω√(1−ζ²))."""
    w = 2 * np.pi * f_hz
    tau = t - t0
    return np.where(
        tau >= 0, amp * np.exp(-zeta * w * np.maximum(tau, 0)) * np.sin(w * np.sqrt(1 - zeta**2) * np.maximum(tau, 0)), 0.0
    )


def add_impact_trial(
    w: SessionWriter,
    rng: np.random.Generator,
    modes=(205.0, 206.0, 182.0),
    zeta: float = 0.03,
    trial_id: str = "impact-1",
    repetition: int = 1,
    noise: float = 0.01,
) -> None:
    """A ball dropped at the plate centre: each axis rings at its mode frequency (plus the plate bias and white noise
    of ``noise`` N per channel)."""
    rig = w.manifest["rig"]
    t = np.arange(3000) / 1000.0
    force = np.column_stack(
        [damped(t, modes[0], zeta, 1.0, 4.0), damped(t, modes[1], zeta, 1.0, 3.0), damped(t, modes[2], zeta, 1.0, 20.0)]
    )
    raw = corner_readings(rig, force, np.zeros_like(force), plate_bias_vector(rig)) + rng.normal(0, noise, (len(t), 24))
    w.add_trial(trial_id, "rig.plate_impact", powered=False, repetition=repetition)
    w.add_stream(trial_id, "plate_wrench", plate_stream(t, raw), rate_hz=1000)


def add_cop_trial(
    w: SessionWriter,
    rng: np.random.Generator,
    positions: np.ndarray,
    offsets: np.ndarray,
    weight_N: float = 9.81,
    trial_id: str = "cop-1",
) -> None:
    """A weight put down at each of ``positions`` (m, plate plane) for 1 s, with 0.3 s unloaded between.

    Motion capture sees the weight's marker at position + ``offsets`` (the COP error by construction);
    the marker is occluded (NaN) while the weight is lifted.
    """
    rig = w.manifest["rig"]
    t = np.arange(int((0.3 + 1.3 * len(positions)) * 1000)) / 1000.0
    tm = np.arange(int(t[-1] * 100) + 1) / 100.0
    force = np.zeros((len(t), 3))
    point = np.zeros((len(t), 3))
    marker = np.full((len(tm), 3), np.nan)
    for k, (p, o) in enumerate(zip(positions, offsets)):
        a = 0.3 + 1.3 * k
        on = (t >= a) & (t < a + 1.0)
        force[on, 2] = -weight_N
        point[on, :2] = p
        onm = (tm >= a) & (tm < a + 1.0)
        marker[onm] = [p[0] + o[0], p[1] + o[1], 0.05]
    raw = corner_readings(rig, force, point, plate_bias_vector(rig)) + rng.normal(0, 0.005, (len(t), 24))
    w.add_trial(trial_id, "rig.plate_cop", powered=False)
    w.add_stream(trial_id, "plate_wrench", plate_stream(t, raw), rate_hz=1000)
    w.add_stream(
        trial_id,
        "markers",
        {"t": tm, "w1_x": marker[:, 0], "w1_y": marker[:, 1], "w1_z": marker[:, 2]},
        rate_hz=100,
        entities=["w1"],
    )


def full_rig_session(
    tmp: Path,
    rng: np.random.Generator,
    *,
    accel_delay_s: float = 0.0,
    mocap_delay_s: float = 0.0,
    cop_offset_m: float = 0.005,
    rig: dict | None = None,
) -> Path:
    """Every rig trial: handle calibration, plate bias, impact, COP (5 placements, each off by cop_offset_m)."""
    rig = rig or rotated_rig()
    rig["motion_capture"]["markers"] = sorted(set(rig["motion_capture"]["markers"]) | {"w1"})
    w = writer(rig=rig)
    add_calibration_trial(w, HandleTruth(), rng, duration_s=16.0, accel_delay_s=accel_delay_s, mocap_delay_s=mocap_delay_s)
    add_plate_bias_trial(w, rng)
    add_impact_trial(w, rng)
    pos = np.array([[0.0, 0.0], [0.2, 0.1], [-0.15, 0.2], [-0.2, -0.2], [0.1, -0.25]])
    ang = np.linspace(0, 2 * np.pi, len(pos), endpoint=False)
    off = cop_offset_m * np.column_stack([np.cos(ang), np.sin(ang)])
    add_cop_trial(w, rng, pos, off)
    return w.write(tmp / "rig-session")
