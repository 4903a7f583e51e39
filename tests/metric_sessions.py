"""Sessions built from analytic truth for the benchmark-metric tests (spec chapters 9, 12, 13).

The truth is the force the device applies to the hand in W, the handle pose, and (active trials) the
commanded wrench; the raw streams are made from it by inverting the calibration model of chapter 6
(bias, connector weight and gravity added in the sensor frames) and the plate model of chapter 14.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from haptify.formats.conventions import STANDARD_GRAVITY, quat_conjugate, quat_from_axis_angle, quat_rotate, quat_to_matrix
from haptify.formats.storage import SessionWriter
from haptify.processing.calibration import gravity_in_sensor
from haptify_tools.example_session import IDENTITY, TOUCH_DEVICE, example_rig

Fn = Callable[[np.ndarray], np.ndarray]

CAL = {
    "kind": "handle_gravity",
    "id": "cal-1",
    "force_bias_N": [0.3, -0.2, 0.5],
    "connector_mass_kg": 0.02,
    "connector_com_m": [0.0, 0.0, 0.01],
    "torque_bias_Nm": [0.01, 0.0, -0.02],
    "accel_bias_m_per_s2": [0.05, -0.03, 0.1],
    "gravity_m_per_s2": STANDARD_GRAVITY,
}
PLATE_BIAS = [0.1 * (i % 7) - 0.3 for i in range(24)]


def circle(radius: float = 0.05, omega: float = 1.0, centre=(0.0, 0.05, 0.12)) -> Fn:
    """Gimbal centre on a horizontal circle: speed radius·omega (m/s) exactly."""
    c = np.asarray(centre, float)
    return lambda t: c + np.column_stack([radius * np.cos(omega * t), radius * np.sin(omega * t), 0 * t])


def spin(rate: float = 0.07, axis=(0.3, -0.2, 1.0), tilt: float = 0.4) -> Fn:
    """Handle orientation turning at a constant ``rate`` (rad/s) about a fixed world axis, from a tilted start."""
    q0 = quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), np.array(tilt))
    ax = np.asarray(axis, float)

    def q(t: np.ndarray) -> np.ndarray:
        from haptify.formats.conventions import quat_multiply

        return quat_multiply(quat_from_axis_angle(np.broadcast_to(ax, (len(t), 3)), rate * t), np.broadcast_to(q0, (len(t), 4)))

    return q


def writer(session_id: str = "metrics", device: dict | None = None, placement: dict | None = None) -> SessionWriter:
    return SessionWriter(
        manifest={
            "session_id": session_id,
            "date": "2026-11-22",
            "lab": {"id": "lab"},
            "examiner": {"id": "ex"},
            "device": device or TOUCH_DEVICE,
            "device_placement": placement or IDENTITY,
            "rig": example_rig(),
            "calibration": [CAL, {"kind": "plate_bias", "id": "plate-bias-1", "bias": PLATE_BIAS}],
        }
    )


def add_handle_trial(
    w: SessionWriter,
    trial_id: str,
    protocol: str,
    *,
    duration_s: float,
    position: Fn,
    quaternion: Fn,
    force_w: Fn,
    repetition: int = 1,
    powered: bool = False,
    rendering: dict | None = None,
    commanded_w: Fn | None = None,
    plate_force_w: Fn | None = None,
    accel: bool = True,
) -> None:
    """Add a trial whose raw streams realise the given truth (forces in N on the hand, W)."""
    rig = example_rig()
    w.add_trial(trial_id, protocol, powered=powered, repetition=repetition, rendering=rendering)
    t100 = np.arange(int(round(duration_s * 100)) + 1) / 100.0
    p, q = position(t100), quaternion(t100)
    w.add_stream(
        trial_id,
        "handle_pose",
        {"t": t100, "px": p[:, 0], "py": p[:, 1], "pz": p[:, 2], "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]},
        rate_hz=100,
    )
    t1k = np.arange(int(round(duration_s * 1000)) + 1) / 1000.0
    qk = quaternion(t1k)
    r_hs = quat_to_matrix(np.asarray(rig["handle"]["ft_sensor"]["pose"]["quaternion"], float))
    f_h = quat_rotate(quat_conjugate(qk), force_w(t1k))
    f_s = f_h @ r_hs  # R_HSᵀ f_H per row
    mg = CAL["connector_mass_kg"] * gravity_in_sensor(qk, r_hs)
    raw_f = f_s + np.asarray(CAL["force_bias_N"]) + mg
    raw_t = np.asarray(CAL["torque_bias_Nm"]) + np.cross(np.asarray(CAL["connector_com_m"]), mg)
    w.add_stream(
        trial_id,
        "handle_wrench",
        {
            "t": t1k,
            "fx": raw_f[:, 0],
            "fy": raw_f[:, 1],
            "fz": raw_f[:, 2],
            "tx": raw_t[:, 0],
            "ty": raw_t[:, 1],
            "tz": raw_t[:, 2],
        },
        rate_hz=1000,
    )
    if accel:
        r_ha = quat_to_matrix(np.asarray(rig["handle"]["accelerometer"]["pose"]["quaternion"], float))
        a_s = -gravity_in_sensor(qk, r_ha) + np.asarray(CAL["accel_bias_m_per_s2"])
        w.add_stream(trial_id, "handle_accel", {"t": t1k, "ax": a_s[:, 0], "ay": a_s[:, 1], "az": a_s[:, 2]}, rate_hz=1000)
    if commanded_w is not None:
        c = commanded_w(t1k)
        w.add_stream(
            trial_id,
            "commanded_wrench",
            {"t": t1k, "fx": c[:, 0], "fy": c[:, 1], "fz": c[:, 2], "tx": 0 * t1k, "ty": 0 * t1k, "tz": 0 * t1k},
            rate_hz=1000,
        )
    if plate_force_w is not None:
        pf = plate_force_w(t1k) / 4.0  # corner frames are parallel to W in the example rig
        cols = {"t": t1k}
        for i in range(4):
            for k, name in enumerate(("fx", "fy", "fz", "tx", "ty", "tz")):
                cols[f"c{i + 1}_{name}"] = (pf[:, k] if k < 3 else 0 * t1k) + PLATE_BIAS[6 * i + k]
        w.add_stream(trial_id, "plate_wrench", cols, rate_hz=1000)
