"""Workspace shapes with known volumes (spec chapter 8): point clouds on spheres and rotated boxes, the
lens volume, pose clouds written as trials, scaled DH devices, their joint limits, the Pappus volume of
the DH model's swept workspace (§8.5) and placements."""

from __future__ import annotations

import copy
import math

import numpy as np

from haptify.formats.conventions import quat_from_axis_angle, quat_multiply, quat_rotate
from haptify.formats.storage import SessionWriter
from haptify_tools.conformance_fixtures.truth import Z
from haptify_tools.example_session import TOUCH_DEVICE


def sphere_cloud(n: int, radius: float, centre, rng) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True) + np.asarray(centre, float)


def sphere_spiral(n: int, radius: float, centre) -> np.ndarray:
    """A sweep path on a sphere: the generalised spiral (points in sweep order, ~equal spacing)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = math.pi * (3 - math.sqrt(5)) * k
    r = np.sqrt(1 - z**2)
    return radius * np.column_stack([r * np.cos(phi), r * np.sin(phi), z]) + np.asarray(centre, float)


def sphere_sweep(n: int, turns: float, radius: float, centre, phase: float) -> np.ndarray:
    """A boundary sweep of a sphere in time order: a spiral from pole to pole of ``turns`` turns, starting at
    azimuth ``phase`` (rad); n samples equally spaced in polar angle."""
    theta = np.linspace(0.0, math.pi, n)
    phi = phase + 2 * math.pi * turns * theta / math.pi
    unit = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    return radius * unit + np.asarray(centre, float)


def box_cloud(n: int, edges, rng, rotation, centre) -> np.ndarray:
    a = np.asarray(edges, float)
    areas = np.array([a[1] * a[2], a[0] * a[2], a[0] * a[1]] * 2)
    face = rng.choice(6, size=n, p=areas / areas.sum())
    u = rng.random((n, 3)) * a
    axis = face % 3
    u[np.arange(n), axis] = np.where(face < 3, 0.0, a[axis])
    return quat_rotate(rotation, u - a / 2) + np.asarray(centre, float)


def lens_volume(radius: float, d: float) -> float:
    """Volume of the intersection of two balls of equal radius whose centres are d apart."""
    return math.pi * (4 * radius + d) * (2 * radius - d) ** 2 / 12 if d < 2 * radius else 0.0


def pose_cloud(w: SessionWriter, tid: str, cloud: np.ndarray, fmt: str, repetition: int = 1, rate: float = 100.0) -> None:
    w.add_trial(tid, "workspace", powered=False, repetition=repetition)
    t = np.arange(len(cloud)) / rate
    seen = np.where(np.all(np.isfinite(cloud), axis=1), 1.0, np.nan)  # an occluded frame has no orientation either
    w.add_stream(
        tid,
        "handle_pose",
        {
            "t": t,
            "px": cloud[:, 0],
            "py": cloud[:, 1],
            "pz": cloud[:, 2],
            "qw": seen,
            "qx": 0 * seen,
            "qy": 0 * seen,
            "qz": 0 * seen,
        },
        rate_hz=rate,
        fmt=fmt,
    )


def scaled_device(scale: float, box=None) -> dict:
    """The Touch with its links scaled (same shape; a smaller voxel grid keeps the fixtures fast)."""
    dev = copy.deepcopy(TOUCH_DEVICE)
    dev["model"] = f"Touch x{scale:g} (conformance)"
    for j in dev["kinematics"]["joints"]:
        j["a"] *= scale
    if box is not None:
        dev["datasheet"]["workspace_box_m"] = list(box)
    return dev


def limits(dev: dict) -> tuple:
    j1, j2, j3 = dev["kinematics"]["joints"]
    c = j3["upper"].get("coefficients", {}).get("q2", 0.0)
    return (
        j1["lower"]["constant"],
        j1["upper"]["constant"],
        j2["lower"]["constant"],
        j2["upper"]["constant"],
        j3["lower"]["constant"],
        j3["upper"]["constant"],
        c,
        j2["a"],
        j3["a"],
    )


def pappus_volume(dev: dict, q1_range: tuple[float, float] | None = None, n: int = 2000) -> float:
    """Exact volume of the Touch-type reachable set (spec §8.3) as a solid of revolution about the q1 axis:
    V = Δq1 · ∬ |r| a2 a3 |sin q3| dq2 dq3 over the coupled (q2, q3) limits (midpoint rule, n² cells)."""
    q1lo, q1hi, q2lo, q2hi, q3lo, q3hi0, c, a2, a3 = limits(dev)
    if q1_range is not None:
        q1lo, q1hi = q1_range
    q2 = q2lo + (np.arange(n) + 0.5) / n * (q2hi - q2lo)
    s = (np.arange(n) + 0.5) / n
    hi3 = q3hi0 + c * q2
    q3 = q3lo + s[None, :] * (hi3 - q3lo)[:, None]
    r = a2 * np.cos(q2)[:, None] + a3 * np.cos(q2[:, None] + q3)
    area = a2 * a3 * np.abs(np.sin(q3)) * ((q2hi - q2lo) / n) * ((hi3 - q3lo) / n)[:, None]
    return (q1hi - q1lo) * float(np.sum(np.abs(r) * area))


def joint_box_sweep(dev: dict, n: int, rng, q1_range: tuple[float, float] | None = None) -> np.ndarray:
    """Gimbal-centre positions (device frame) on the faces of the coupled joint-limit box: one joint at a
    limit, the others uniform — the examiner's boundary sweep (paper §IV-A). Forward kinematics of the
    Touch-type DH chain written out: p = (r cos q1, r sin q1, s), r = a2 cos q2 + a3 cos(q2+q3), s = a2 sin q2 + a3 sin(q2+q3)."""
    q1lo, q1hi, q2lo, q2hi, q3lo, q3hi0, c, a2, a3 = limits(dev)
    if q1_range is not None:
        q1lo, q1hi = q1_range
    u = rng.random((n, 3))
    u[np.arange(n), rng.integers(0, 3, n)] = rng.integers(0, 2, n)
    q1 = q1lo + u[:, 0] * (q1hi - q1lo)
    q2 = q2lo + u[:, 1] * (q2hi - q2lo)
    q3 = q3lo + u[:, 2] * (q3hi0 + c * q2 - q3lo)
    r = a2 * np.cos(q2) + a3 * np.cos(q2 + q3)
    s = a2 * np.sin(q2) + a3 * np.sin(q2 + q3)
    return np.column_stack([r * np.cos(q1), r * np.sin(q1), s])


def placement_of(position, yaw: float, tilt: float = 0.0) -> dict:
    q = quat_multiply(quat_from_axis_angle(Z, np.array(yaw)), quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), np.array(tilt)))
    return {"position": [float(v) for v in position], "quaternion": [float(v) for v in q]}
