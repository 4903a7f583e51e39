"""A small, valid, analytic example session (spec chapter 2 by example).

Used by the tests, the invalid-fixture builder and, until the simulator exists for a protocol, by
``make demo``. Every signal is an analytic function of time, so tests can state the expected values.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from haptify.formats.storage import SessionWriter

DEG = math.pi / 180.0

# The Touch as in the paper's Table II; the upper limit of q3 is -10° - 0.85·q2 (see spec §8).
TOUCH_DEVICE: dict[str, Any] = {
    "manufacturer": "3D Systems",
    "model": "Touch",
    "dof": 6,
    "mechanism": "hybrid",
    "kinematics": {
        "convention": "dh_standard",
        "base": {"position": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]},
        "joints": [
            {
                "name": "q1",
                "a": 0.0,
                "alpha": 90 * DEG,
                "d": 0.0,
                "lower": {"constant": -56 * DEG},
                "upper": {"constant": 56 * DEG},
            },
            {"name": "q2", "a": 0.135, "alpha": 0.0, "d": 0.0, "lower": {"constant": 0.0}, "upper": {"constant": 101 * DEG}},
            {
                "name": "q3",
                "a": 0.135,
                "alpha": 0.0,
                "d": 0.0,
                "lower": {"constant": -140 * DEG},
                "upper": {"constant": -10 * DEG, "coefficients": {"q2": -0.85}},
            },
        ],
    },
    "gimbal": {"dof": 3, "tip_offset_m": 0.039},
    "datasheet": {
        "workspace_box_m": [0.16, 0.12, 0.07],
        "peak_force_N": 3.3,
        "friction_N": 0.26,
        "source": "paper Table II; Haptipedia",
    },
}

IDENTITY = {"position": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]}


def example_rig(plate_half_side: float = 0.3) -> dict:
    """A Haptify-like rig: a 60 cm plate with four corner sensors, handle F/T and accelerometer, mocap."""
    h = plate_half_side
    corners = [
        {"id": f"c{i + 1}", "pose": {"position": [x, y, -0.02], "quaternion": [1.0, 0.0, 0.0, 0.0]}}
        for i, (x, y) in enumerate([(h, h), (-h, h), (-h, -h), (h, -h)])
    ]
    return {
        "name": "example rig",
        "force_plate": {
            "size_m": [2 * h, 2 * h],
            "corners": corners,
            "corner_range": {"force_N": [40.0, 40.0, 120.0], "torque_Nm": [2.0, 2.0, 2.0]},
        },
        "handle": {
            "ft_sensor": {
                "pose": {"position": [0.0, 0.0, -0.03], "quaternion": [1.0, 0.0, 0.0, 0.0]},
                "range": {"force_N": [80.0, 80.0, 160.0], "torque_Nm": [4.0, 4.0, 2.0]},
                "model": "ATI Mini27 SI-80-4",
            },
            "accelerometer": {
                "pose": {"position": [0.0, 0.0, -0.05], "quaternion": [1.0, 0.0, 0.0, 0.0]},
                "range": {"accel_m_per_s2": [40.0, 40.0, 40.0]},
                "model": "MPU-9250",
            },
        },
        "motion_capture": {
            "system": "Vicon",
            "rate_hz": 100.0,
            "rigid_bodies": [{"name": "handle", "markers": ["h1", "h2", "h3"]}],
            "markers": ["h1", "h2", "h3"],
        },
    }


def example_writer(session_id: str = "example-0001", duration_s: float = 2.0, fmt: str = "parquet") -> SessionWriter:
    """A writer holding one analytic free-space trial with every stream the protocol needs."""
    w = SessionWriter(
        manifest={
            "session_id": session_id,
            "date": "2026-11-22",
            "lab": {"id": "lab-example"},
            "examiner": {"id": "ex-01"},
            "device": TOUCH_DEVICE,
            "device_placement": IDENTITY,
            "rig": example_rig(),
            "recorder": "haptify example_session",
        }
    )
    w.add_trial("free_space-1", "free_space", powered=False, repetition=1)
    t1k = np.arange(int(duration_s * 1000)) / 1000.0
    t2k = np.arange(int(duration_s * 2000)) / 2000.0
    t100 = np.arange(int(duration_s * 100)) / 100.0
    wrench = {
        "t": t1k,
        "fx": 0.5 * np.sin(2 * np.pi * t1k),
        "fy": 0.2 + 0 * t1k,
        "fz": -1.0 + 0 * t1k,
        "tx": 0 * t1k,
        "ty": 0.01 + 0 * t1k,
        "tz": 0 * t1k,
    }
    w.add_stream("free_space-1", "handle_wrench", wrench, rate_hz=1000, fmt=fmt)
    accel = {"t": t2k, "ax": 0.05 * np.sin(2 * np.pi * 150 * t2k), "ay": 0 * t2k, "az": 9.81 + 0 * t2k}
    w.add_stream("free_space-1", "handle_accel", accel, rate_hz=2000, fmt=fmt)
    ang = 0.1 * np.sin(2 * np.pi * 0.5 * t100)
    pose = {
        "t": t100,
        "px": 0.05 * np.cos(t100),
        "py": 0.05 * np.sin(t100),
        "pz": 0.1 + 0 * t100,
        "qw": np.cos(ang / 2),
        "qx": 0 * t100,
        "qy": 0 * t100,
        "qz": np.sin(ang / 2),
    }
    w.add_stream("free_space-1", "handle_pose", pose, rate_hz=100, fmt=fmt)
    plate = {"t": t1k}
    for i in range(1, 5):
        for c in ("fx", "fy", "tx", "ty", "tz"):
            plate[f"c{i}_{c}"] = 0 * t1k
        plate[f"c{i}_fz"] = -18.5 / 4 + 0 * t1k
    w.add_stream("free_space-1", "plate_wrench", plate, rate_hz=1000, fmt=fmt)
    return w


def write_example(target: str | Path, **kw) -> Path:
    """Write the example session to ``target`` and return its path."""
    return example_writer(**kw).write(target)
