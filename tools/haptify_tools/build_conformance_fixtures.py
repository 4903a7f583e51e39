"""Build the conformance suite's metric fixtures and case files (spec chapter 16) from seeds.

Every session under ``fixtures/conformance/<name>/`` is generated from stated truth — analytic shapes,
analytic signals, springs, damped plate modes, a known Hammerstein–Wiener model — and every expected
value in ``conformance/cases/*.json`` is computed HERE from that truth (closed forms, the spec's own
formulas applied to exactly known inputs, quadratures of analytic integrals), never by running the
reference implementation. ``validate.json`` turns every fixture of ``fixtures/invalid`` and
``fixtures/valid`` into a validate case with the codes of its sidecar.

    python -m haptify_tools.build_conformance_fixtures           # (re)build fixtures and case files
    python -m haptify_tools.build_conformance_fixtures --check   # exit 1 when committed files are stale

``--check`` compares logical content (parsed JSON, Parquet column bits, CSV bytes), not timestamps or
the Parquet writer's byte layout.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import shutil
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy.signal import butter, lfilter, sosfiltfilt

from haptify.conventions import GRAVITY_W, quat_conjugate, quat_from_axis_angle, quat_multiply, quat_rotate
from haptify.metric_definitions import param
from haptify.storage import SessionWriter
from haptify.versions import SPEC_VERSION
from haptify_conform.fixture_digest import DIGESTS, snapshot_digest, trees_agree, values_agree
from haptify_tools import rig_builders as rb
from haptify_conform.requirements import requirements_for_case
from haptify_tools.example_session import IDENTITY, TOUCH_DEVICE, example_rig
from haptify_tools.tolerance_budgets import budget_record

REPO = Path(__file__).resolve().parents[2]

FIXTURE_DIR = "conformance"
CASES_DIR = REPO / "conformance" / "cases"
SEED = 20261122
Z = np.array([0.0, 0.0, 1.0])
Fn = Callable[[np.ndarray], np.ndarray]


# --- case records ----------------------------------------------------------------------------------


@dataclass
class Fixture:
    """One fixture: its folder name, the function that writes it, and the cases that run on it."""

    name: str
    build: Callable[[Path], None]
    cases: list[dict] = field(default_factory=list)


def case(
    cid: str,
    metric: str,
    section: str,
    fixture: str,
    value: Any,
    unit: str,
    kind: str,
    note: str,
    description: str,
    parameters: dict | None = None,
    level: str = "MUST",
    quantity: str = "value",
) -> dict:
    """A metric case (spec §16.2) whose tolerance is the sum of its budget (:mod:`haptify_tools.tolerance_budgets`);
    ``quantity`` u, U or k judges the metric's uncertainty record instead of its value (§19.4)."""
    value = [float(v) for v in value] if isinstance(value, (list, tuple, np.ndarray)) else float(value)
    budget = budget_record(cid)
    head = {"id": cid, "metric": metric} | ({"quantity": quantity} if quantity != "value" else {})
    return {
        **head,
        "spec_section": section,
        "level": level,
        "fixture": f"{FIXTURE_DIR}/{fixture}",
        "parameters": parameters or {},
        "expected": {"value": value, "unit": unit},
        "tolerance": {"abs": math.fsum(t["abs"] for t in budget), "rel": math.fsum(t["rel"] for t in budget)},
        "provenance": {"kind": kind, "note": note, "budget": budget},
        "spec_versions": [SPEC_VERSION],
        "description": description,
    }


# --- shared truth helpers ----------------------------------------------------------------------------

QUIET = rb.HandleTruth(force_noise=0.0, torque_noise=0.0, accel_noise=0.0)


def rotated_rig_full() -> dict:
    """The rotated handle rig of the unit tests, with the four plate sensors yawed by 0°, 90°, 180°, 270° too."""
    rig = rb.rotated_rig()
    for k, corner in enumerate(rig["force_plate"]["corners"]):
        q = quat_from_axis_angle(Z, np.array(k * math.pi / 2))
        corner["pose"]["quaternion"] = [float(v) for v in q]
    return rig


def manifest(
    sid: str,
    rig: dict,
    *,
    device: dict | None = None,
    placement: dict | None = None,
    truth: rb.HandleTruth = QUIET,
    plate_bias: np.ndarray | None = None,
    superseded: rb.HandleTruth | None = None,
) -> SessionWriter:
    """A session writer whose handle_gravity record holds ``truth`` — after a ``superseded`` record, when given,
    which §6.4 (the last record applies) sets aside."""
    cal: list = ([superseded.record("hg-0")] if superseded else []) + [truth.record("hg-1")]
    if plate_bias is not None:
        cal.append({"kind": "plate_bias", "id": "plate-bias-1", "bias": [float(v) for v in plate_bias]})
    return SessionWriter(
        manifest={
            "session_id": sid,
            "date": "2026-11-22",
            "lab": {"id": "lab-conformance"},
            "examiner": {"id": "ex-conformance"},
            "device": device or TOUCH_DEVICE,
            "device_placement": placement or IDENTITY,
            "rig": rig,
            "calibration": cal,
            "recorder": "haptify_tools.build_conformance_fixtures",
        }
    )


def clock(duration_s: float, rate: float) -> np.ndarray:
    return np.arange(int(round(duration_s * rate)) + 1) / rate


def fixed(q: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    return lambda t: np.tile(np.asarray(q, float), (len(t), 1))


def spin(rate: float, axis=(0.3, -0.2, 1.0), tilt: float = 0.4) -> Fn:
    """Orientation turning at ``rate`` rad/s about a fixed world axis from a tilted start (exact angular speed)."""
    q0 = quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), np.array(tilt))
    ax = np.asarray(axis, float)
    return lambda t: quat_multiply(
        quat_from_axis_angle(np.broadcast_to(ax, (len(t), 3)), rate * t), np.broadcast_to(q0, (len(t), 4))
    )


def circle(radius: float, omega: float, centre=(0.0, 0.05, 0.12)) -> Fn:
    c = np.asarray(centre, float)
    return lambda t: c + np.column_stack([radius * np.cos(omega * t), radius * np.sin(omega * t), 0 * t])


def handle_trial(
    w: SessionWriter,
    tid: str,
    protocol: str,
    *,
    duration_s: float,
    position: Fn,
    quaternion: Fn,
    force_w: Fn,
    truth: rb.HandleTruth = QUIET,
    rates=(500.0, 500.0, 100.0),
    fmt: str = "parquet",
    repetition: int = 1,
    powered: bool = False,
    rendering: dict | None = None,
    commanded_w: Fn | None = None,
    occluded: Callable[[np.ndarray], np.ndarray] | None = None,
    accel_extra: Fn | None = None,
    plate_force_w: Fn | None = None,
    plate_bias: np.ndarray | None = None,
    rng=None,
    start_s: float = 0.0,
    clock_offsets: dict[str, float] | None = None,
) -> None:
    """A trial whose raw streams realise the truth: ``force_w`` (N, on the hand, W; zero torque about the
    gimbal centre), the pose, and ``accel_extra`` (m/s², added in the accelerometer frame: vibrations).

    Every stream starts at ``start_s`` on the session clock; a stream kind named in ``clock_offsets`` is stored
    with ``t − offset`` and gets a ``clock_offset`` record of ``offset`` (spec §2.8) that puts it back."""
    rig = w.manifest["rig"]
    rng = rng or np.random.default_rng(SEED)
    ft_rate, acc_rate, mocap_rate = rates
    w.add_trial(tid, protocol, powered=powered, repetition=repetition, rendering=rendering)
    t_ft, t_acc, t_m = (start_s + clock(duration_s, r) for r in rates)

    def add(kind: str, data: dict, rate: float) -> None:
        offset = (clock_offsets or {}).get(kind)
        stream = w.add_stream(tid, kind, {**data, "t": data["t"] - offset} if offset else data, rate_hz=rate, fmt=fmt)
        if offset:
            w.manifest["calibration"].append(
                {
                    "kind": "clock_offset",
                    "id": f"offset-{tid}-{kind}".replace("_", "-"),
                    "stream_file": stream["file"],
                    "offset_s": offset,
                }
            )

    f_w = force_w(t_ft)
    wrench, accel = rb.raw_handle(
        truth, rig, t_ft, quaternion(t_ft), t_acc, quaternion(t_acc), rng, hand_force_w=f_w, hand_torque_g_w=np.zeros_like(f_w)
    )
    if accel_extra is not None:
        extra = accel_extra(t_acc)
        for k, col in enumerate(("ax", "ay", "az")):
            accel[col] = accel[col] + extra[:, k]
    add("handle_wrench", wrench, ft_rate)
    add("handle_accel", accel, acc_rate)
    p, q = position(t_m), quaternion(t_m)
    if occluded is not None:
        gone = occluded(t_m)
        p, q = p.copy(), q.copy()
        p[gone], q[gone] = np.nan, np.nan
    add(
        "handle_pose",
        {"t": t_m, "px": p[:, 0], "py": p[:, 1], "pz": p[:, 2], "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]},
        mocap_rate,
    )
    if commanded_w is not None:
        c = commanded_w(t_ft)
        add(
            "commanded_wrench",
            {"t": t_ft, "fx": c[:, 0], "fy": c[:, 1], "fz": c[:, 2], "tx": 0 * t_ft, "ty": 0 * t_ft, "tz": 0 * t_ft},
            ft_rate,
        )
    if plate_force_w is not None:
        pf = plate_force_w(t_ft)
        add("plate_wrench", rb.plate_stream(t_ft, rb.corner_readings(rig, pf, np.zeros_like(pf), plate_bias)), ft_rate)


def active_session(
    name: str,
    rig_kind: str,
    tid: str,
    protocol: str,
    duration_s: float,
    spin_rate: float,
    position: Fn,
    force: Fn,
    commanded: Fn,
    rendering: dict,
    rates,
    fmt: str,
) -> Callable[[Path], None]:
    """The builder of a one-trial session of a rendering protocol (surface, stiffness): powered, with the
    commanded wrench, in the example rig or the fully rotated one."""

    def build(path: Path) -> None:
        rig = example_rig() if rig_kind == "example" else rotated_rig_full()
        w = manifest(f"conf-{name}", rig)
        handle_trial(
            w,
            tid,
            protocol,
            duration_s=duration_s,
            position=position,
            quaternion=spin(spin_rate),
            force_w=force,
            powered=True,
            rendering=rendering,
            commanded_w=commanded,
            rates=rates,
            fmt=fmt,
        )
        w.write(path)

    return build


def grid(duration_s: float, rate: float = 100.0) -> np.ndarray:
    """The common grid of spec §7.3 for streams that all start at 0 and end at ``duration_s``."""
    return clock(duration_s, rate)


def lowpass_pair_gain(f: float, fs: float, fc: float) -> float:
    """Amplitude gain at f of the forward-backward Butterworth low-pass of spec §7.2: |H|² = 1 / (1 + Ω^(2N))."""
    fc = min(fc, param("signals", "max_cutoff_fraction") * fs / 2.0)
    omega = math.tan(math.pi * f / fs) / math.tan(math.pi * fc / fs)
    return 1.0 / (1.0 + omega ** (2 * int(param("signals", "filter_order"))))


def pair_step(t: np.ndarray, fs: float, fc: float | None = None) -> np.ndarray:
    """Response at times ``t`` (s) of the zero-phase Butterworth low-pass of spec §7.2 (order ``filter_order``, cut-off
    ``fc``, default ``wrench_cutoff_hz``, at rate ``fs``) to a unit step whose first sample of 1 is at t = 0: it rises
    0 → 1 symmetrically about the step, ringing on both sides. scipy's butter + sosfiltfilt, as §7.2 names them."""
    fc = float(param("signals", "wrench_cutoff_hz") if fc is None else fc)
    k = np.arange(-4 * int(fs), 4 * int(fs) + 1)
    y = sosfiltfilt(butter(int(param("signals", "filter_order")), fc, fs=fs, output="sos"), (k >= 0).astype(float))
    return np.interp(np.asarray(t, float) * fs, k, y)


def lowpass_noise_ratio(fc: float, fs: float, order: int) -> float:
    """Variance gain of white noise through the zero-phase Butterworth low-pass of spec §7.2:
    (2/fs)·∫₀^{fs/2} |H(f)|⁴ df with |H|² = 1 / (1 + Ω^(2N)), Ω = tan(πf/fs) / tan(πfc/fs) (midpoint rule)."""
    f = (np.arange(200_000) + 0.5) / 200_000 * fs / 2
    omega = np.tan(np.pi * f / fs) / np.tan(np.pi * fc / fs)
    return float(np.mean((1.0 / (1.0 + omega ** (2 * order))) ** 2))


# --- workspace (spec chapter 8) ---------------------------------------------------------------------


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


def workspace_fixtures() -> list[Fixture]:
    out: list[Fixture] = []
    pitch = param("workspace", "voxel_pitch_m")
    cr = param("workspace", "closing_radius_m")
    model_bias = (
        "the operator reproduces the full-size Touch models' Pappus volumes closely (spec §8.8); the links here "
        "are scaled by 0.45, so the voxels are 2.2× coarser relative to the solid"
    )
    bias = f"the operator's stated bias (spec §8.8: sub-voxel boundary within 0.5 %; h = {pitch} m, r = {cr} m)"
    tiny = scaled_device(0.45)

    # Sphere, Parquet, the Touch's datasheet box.
    R, C = 0.07, (0.013, -0.021, 0.16)

    def sphere(path: Path) -> None:
        w = manifest("conf-ws-sphere", example_rig(), device=tiny)
        pose_cloud(w, "workspace-1", sphere_cloud(6000, R, C, np.random.default_rng(SEED)), "parquet")
        w.write(path)

    fx = Fixture("ws-sphere", sphere)
    v_sphere = 4 / 3 * math.pi * R**3
    fx.cases += [
        case(
            "workspace.measured_volume.sphere",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            v_sphere,
            "m^3",
            "analytic",
            f"4/3·π·R³ of the sphere (R = {R} m) whose surface the 6 000 positions sample; " + bias,
            "Typical: a convex cloud sampled on its boundary.",
        ),
        case(
            "workspace.spec_box_volume.touch",
            "workspace.spec_box_volume",
            "8.6",
            fx.name,
            0.16 * 0.12 * 0.07,
            "m^3",
            "paper",
            "product of the Touch's datasheet box 16 × 12 × 7 cm (paper §IV-A, Table II)",
            "Typical: the manufacturer's box.",
        ),
        case(
            "workspace.modeled_volume.touch-0.45",
            "workspace.modeled_volume",
            "8.3",
            fx.name,
            pappus_volume(tiny),
            "m^3",
            "analytic",
            "Pappus integral of the coupled joint limits of the Touch with links × 0.45 "
            "(V = Δq1·∬|r| a2 a3 |sin q3| dq2 dq3); " + model_bias,
            "Typical: the DH model's reachable set within coupled joint limits.",
        ),
    ]
    out.append(fx)

    # Rotated box, CSV, another datasheet box.
    edges, q_box = (0.12, 0.09, 0.06), quat_from_axis_angle(np.array([0.3, -0.5, 0.8]), np.array(0.7))
    box_dev = scaled_device(0.45, box=(0.16, 0.12, 0.12))

    def box(path: Path) -> None:
        w = manifest("conf-ws-box", rotated_rig_full(), device=box_dev)
        pose_cloud(w, "workspace-1", box_cloud(12_000, edges, np.random.default_rng(SEED + 1), q_box, (0.02, 0.01, 0.15)), "csv")
        w.write(path)

    fx = Fixture("ws-box-rotated-csv", box)
    fx.cases += [
        case(
            "workspace.measured_volume.box-rotated-csv",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            math.prod(edges),
            "m^3",
            "analytic",
            f"edges {edges} m multiplied; the box is turned 0.7 rad about (0.3, −0.5, 0.8) so no face "
            "is parallel to the voxel lattice; " + bias,
            "Tricky: rotated faces, CSV streams.",
        ),
        case(
            "workspace.spec_box_volume.touch-x",
            "workspace.spec_box_volume",
            "8.6",
            fx.name,
            0.16 * 0.12 * 0.12,
            "m^3",
            "paper",
            "product of the Touch X box 16 × 12 × 12 cm (paper §IV-A)",
            "Typical: another datasheet box.",
        ),
    ]
    out.append(fx)

    # Two lobes: non-convex (a convex hull bridges the waist).
    RL, D = 0.05, 0.08

    def lobes(path: Path) -> None:
        rng = np.random.default_rng(SEED + 2)
        a = np.array([0.0, 0.0, 0.15])
        b = a + [D, 0.0, 0.0]
        pts = np.concatenate([sphere_cloud(9000, RL, a, rng), sphere_cloud(9000, RL, b, rng)])
        keep = (np.linalg.norm(pts - a, axis=1) >= RL - 1e-12) & (np.linalg.norm(pts - b, axis=1) >= RL - 1e-12)
        w = manifest("conf-ws-lobes", example_rig(), device=scaled_device(0.45, box=(0.1, 0.1, 0.1)))
        pose_cloud(w, "workspace-1", pts[keep], "parquet")
        w.write(path)

    fx = Fixture("ws-two-lobes", lobes)
    fx.cases += [
        case(
            "workspace.measured_volume.two-lobes",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            2 * 4 / 3 * math.pi * RL**3 - lens_volume(RL, D),
            "m^3",
            "analytic",
            f"union of two balls R = {RL} m, centres {D} m apart: 2·(4/3)πR³ − π(4R+d)(2R−d)²/12; the closing fills the "
            "waist's crease with a fillet of radius r (spec §8.8: +0.5 % on two R = 6 cm lobes); the convex hull is ~9 % larger",
            "Tricky: a non-convex workspace.",
        ),
        case(
            "workspace.spec_box_volume.cube",
            "workspace.spec_box_volume",
            "8.6",
            fx.name,
            1e-3,
            "m^3",
            "analytic",
            "the datasheet box of this device is a 10 cm cube: 0.1³ m³",
            "Edge: a cubic datasheet box.",
        ),
    ]
    out.append(fx)

    # Occluded sweep: long runs of NaN rows (occlusion) must be dropped, nothing interpolated.
    RO, CO = 0.06, (0.0, 0.03, 0.14)

    def occluded(path: Path) -> None:
        pts = sphere_spiral(9000, RO, CO)
        k = np.arange(len(pts))
        pts[(k % 600) < 90] = np.nan  # 15 % of the sweep occluded, in runs of 90 frames
        w = manifest("conf-ws-occluded", example_rig(), device=tiny)
        pose_cloud(w, "workspace-1", pts, "parquet", rate=120.0)
        w.write(path)

    fx = Fixture("ws-sphere-occluded", occluded)
    fx.cases += [
        case(
            "workspace.measured_volume.occluded",
            "workspace.measured_volume",
            "8.7",
            fx.name,
            4 / 3 * math.pi * RO**3,
            "m^3",
            "analytic",
            f"sphere R = {RO} m swept along a spiral at 120 Hz; 15 % of the frames are NaN in runs "
            "of 90; the finite rows still sample the whole surface more densely than 2r; " + bias,
            "Tricky: occlusion gaps (NaN rows are dropped, never interpolated).",
        ),
    ]
    out.append(fx)

    # Two repetitions of a spiral sweep; the first lost a 4 cm band around the equator to one occlusion gap,
    # which the other repetition's positions repair (spec §8.7).
    RR, CR, band_half = 0.06, (0.01, -0.02, 0.15), 0.02

    def repaired(path: Path) -> None:
        w = manifest("conf-ws-repaired", example_rig(), device=tiny)
        first = sphere_sweep(8000, 24, RR, CR, 0.0)
        first[np.abs(first[:, 2] - CR[2]) < band_half] = np.nan
        pose_cloud(w, "workspace-1", first, "parquet", repetition=1)
        pose_cloud(w, "workspace-2", sphere_sweep(8000, 24, RR, CR, math.pi), "parquet", repetition=2)
        w.write(path)

    fx = Fixture("ws-sphere-repaired", repaired)
    fx.cases += [
        case(
            "workspace.measured_volume.occlusion-repaired",
            "workspace.measured_volume",
            "8.7",
            fx.name,
            4 / 3 * math.pi * RR**3,
            "m^3",
            "analytic",
            f"two sweeps of a sphere R = {RR} m along a spiral of 24 turns (1 mm steps at 100 Hz); the first lost the "
            f"band |z − z_c| < {band_half} m to one occlusion gap (4 cm, narrower than 2r: without the repair the closing "
            "bridges it with a groove of about 8 % of that trial's volume, 4 % of the mean). The gap lasts about a third of "
            "the sweep, so its region holds the whole other sweep; the donors farther than 1 cm from the first sweep's "
            "own positions fill the band but for two 1 cm strips, which the closing bridges flat. Both trials are the "
            "sphere: " + bias,
            "Tricky: an occlusion gap repaired from the other repetition.",
        ),
    ]
    out.append(fx)

    # A sweep that missed a cap of the workspace: its 4 cm hole is narrower than 2r, so the closing bridges it.
    RC, CC, rim = 0.07, (0.0, -0.02, 0.15), 0.02

    def capless(path: Path) -> None:
        pts = sphere_cloud(7000, RC, CC, np.random.default_rng(SEED + 6))
        pts = pts[pts[:, 2] - CC[2] <= math.sqrt(RC**2 - rim**2)]
        w = manifest("conf-ws-capless", example_rig(), device=tiny)
        pose_cloud(w, "workspace-1", pts, "csv")
        w.write(path)

    fx = Fixture("ws-sphere-capless-csv", capless)
    h_sphere, h_ball = RC - math.sqrt(RC**2 - rim**2), cr - math.sqrt(cr**2 - rim**2)
    dented = (
        4 / 3 * math.pi * RC**3 - math.pi * h_sphere**2 * (3 * RC - h_sphere) / 3 - math.pi * h_ball**2 * (3 * cr - h_ball) / 3
    )
    fx.cases += [
        case(
            "workspace.measured_volume.capless",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            dented,
            "m^3",
            "analytic",
            f"sphere R = {RC} m sampled on its surface except a polar cap whose rim has radius {rim} m: the hole "
            f"(4 cm across) is narrower than 2r = {2 * cr:g} m, so the closing by a ball of radius r bridges it (§8.4 steps 2–4) "
            "and the solid is the sphere minus its cap above the rim and minus the part of an r-ball resting on the rim "
            "that dips below it (πh²(3R − h)/3 each: 0.5 % of the sphere in all); the dent has no boundary samples, so "
            "it is resolved on the coarse lattice only (≤ 0.2 %); " + bias,
            "Tricky: a sweep that missed a cap.",
        ),
    ]
    out.append(fx)

    # A thin slab, four voxels thick: near the operator's resolution limit of about 2 h (spec §8.8).
    slab, q_slab = (0.12, 0.12, 0.01), quat_from_axis_angle(np.array([0.3, -0.5, 0.8]), np.array(0.7))

    def thin(path: Path) -> None:
        w = manifest("conf-ws-slab", example_rig(), device=tiny)
        pose_cloud(
            w, "workspace-1", box_cloud(20_000, slab, np.random.default_rng(SEED + 7), q_slab, (0.02, 0.01, 0.15)), "parquet"
        )
        w.write(path)

    fx = Fixture("ws-thin-slab", thin)
    fx.cases += [
        case(
            "workspace.measured_volume.thin-slab",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            math.prod(slab),
            "m^3",
            "analytic",
            f"a box of edges {slab} m turned 0.7 rad about (0.3, −0.5, 0.8), 20 000 samples on its faces; "
            f"1 cm is four voxels of h = {pitch} m, twice the operator's resolution limit of about 2 h (spec §8.8): both "
            "faces' samples lie within every band voxel's search radius, so the sub-voxel ramps place both faces; "
            "tolerance 2 %, the bias allowed for a non-convex or thin solid",
            "Edge: a thin workspace.",
        ),
    ]
    out.append(fx)

    # The model swept through its whole boundary, device placed turned and moved (rotated frames).
    mid = scaled_device(0.45)
    placement = placement_of((0.04, -0.03, 0.01), yaw=2.2, tilt=0.15)

    def swept(path: Path) -> None:
        pts = joint_box_sweep(mid, 20_000, np.random.default_rng(SEED + 3))
        pts = quat_rotate(np.asarray(placement["quaternion"]), pts) + np.asarray(placement["position"])
        w = manifest("conf-ws-swept", rotated_rig_full(), device=mid, placement=placement)
        pose_cloud(w, "workspace-1", pts, "parquet")
        w.write(path)

    fx = Fixture("ws-model-swept-placed", swept)
    fx.cases += [
        case(
            "workspace.modeled_volume.placed",
            "workspace.modeled_volume",
            "8.3",
            fx.name,
            pappus_volume(mid),
            "m^3",
            "analytic",
            "Pappus integral of the model's joint limits; a placement (turned 2.2 rad about z, tilted 0.15 rad) "
            "moves the solid, not its volume; " + model_bias,
            "Tricky: rotated device placement.",
        ),
        case(
            "workspace.volume_ratio.full-sweep",
            "workspace.volume_ratio",
            "8.5",
            fx.name,
            1.0,
            "1",
            "analytic",
            "the measured positions are the model's own boundary (joint-limit faces) placed by device_placement; both "
            "solids come from the same operator, so the ratio is 1 within the two samplings' biases (each below 0.5 % "
            "at this scale)",
            "Typical: a complete boundary sweep.",
        ),
        case(
            "workspace.coverage.full-sweep",
            "workspace.coverage",
            "8.5",
            fx.name,
            1.0,
            "1",
            "analytic",
            "the measured sweep covers the placed model entirely; an implementation that ignores device_placement "
            "(turned 2.2 rad) finds far less overlap",
            "Tricky: coverage needs the placement applied.",
        ),
        case(
            "workspace.measured_volume.model-sweep",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            pappus_volume(mid),
            "m^3",
            "analytic",
            "the measured sweep of the model's boundary encloses the model's reachable set (Pappus); "
            "non-convex (the coupled q3 limit carves the inner side)",
            "Typical: a device-shaped, non-convex sweep.",
        ),
    ]
    out.append(fx)

    # Half the model swept (q1 ≥ 0): by Pappus the volume is exactly Δq1-proportional, so ratio = coverage = 1/2.
    def half(path: Path) -> None:
        q1hi = limits(mid)[1]
        pts = joint_box_sweep(mid, 14_000, np.random.default_rng(SEED + 4), q1_range=(0.0, q1hi))
        w = manifest("conf-ws-half", example_rig(), device=mid)
        pose_cloud(w, "workspace-1", pts, "csv")
        w.write(path)

    fx = Fixture("ws-model-half-csv", half)
    q1lo, q1hi = limits(mid)[:2]
    half_share = q1hi / (q1hi - q1lo)
    fx.cases += [
        case(
            "workspace.volume_ratio.half",
            "workspace.volume_ratio",
            "8.5",
            fx.name,
            half_share,
            "1",
            "analytic",
            "the examiner swept only q1 ∈ [0, 56°] of [−56°, 56°]; the volume of a solid of revolution is proportional to "
            "its angle (Pappus), so measured/modeled = 1/2",
            "Edge: half of the workspace reached.",
        ),
        case(
            "workspace.coverage.half",
            "workspace.coverage",
            "8.5",
            fx.name,
            half_share,
            "1",
            "analytic",
            "the half solid lies inside the model: the overlap is the half solid itself, 1/2 of the model",
            "Edge: partial coverage.",
        ),
        case(
            "workspace.modeled_volume.csv",
            "workspace.modeled_volume",
            "8.3",
            fx.name,
            pappus_volume(mid),
            "m^3",
            "analytic",
            "Pappus integral of the model's joint limits (identity placement, CSV session); " + model_bias,
            "Edge: the model of a CSV session.",
        ),
    ]
    out.append(fx)

    def ball_session(sid: str, n: int, radius: float, centre: tuple, seed: int) -> Callable[[Path], None]:
        """A workspace trial whose cloud samples the surface of one ball, with the mid-size model."""

        def build(path: Path) -> None:
            w = manifest(sid, example_rig(), device=mid)
            pose_cloud(w, "workspace-1", sphere_cloud(n, radius, centre, np.random.default_rng(seed)), "parquet")
            w.write(path)

        return build

    # Ratio below and above 1 by construction: a ball inside the model of known volume.
    fx = Fixture("ws-ball-in-model", ball_session("conf-ws-ball", 6000, 0.02, (0.07, 0.0, 0.02), SEED + 5))
    v_ball = 4 / 3 * math.pi * 0.02**3
    fx.cases += [
        case(
            "workspace.volume_ratio.ball",
            "workspace.volume_ratio",
            "8.5",
            fx.name,
            v_ball / pappus_volume(mid),
            "1",
            "analytic",
            "a ball R = 2 cm (4/3πR³) divided by the model's Pappus volume; tolerance = both operators' biases",
            "Tricky: a small measured solid against the model.",
        ),
        case(
            "workspace.coverage.ball",
            "workspace.coverage",
            "8.5",
            fx.name,
            v_ball / pappus_volume(mid),
            "1",
            "analytic",
            "the ball (centre (7, 0, 2) cm, R = 2 cm) lies inside the reachable set, so the overlap is the ball",
            "Tricky: coverage of an interior solid.",
        ),
    ]
    out.append(fx)

    # A solid outside the model: coverage (the overlap, §8.5) is 0 while the volume ratio is not.
    fx = Fixture("ws-ball-outside-model", ball_session("conf-ws-ball-outside", 8000, 0.03, (0.0, 0.0, 0.45), SEED + 6))
    v_out = 4 / 3 * math.pi * 0.03**3
    fx.cases += [
        case(
            "workspace.volume_ratio.ball-outside",
            "workspace.volume_ratio",
            "8.5",
            fx.name,
            v_out / pappus_volume(mid),
            "1",
            "analytic",
            "a ball R = 3 cm (4/3πR³) divided by the model's Pappus volume",
            "Tricky: a solid the model does not contain.",
        ),
        case(
            "workspace.coverage.ball-outside",
            "workspace.coverage",
            "8.5",
            fx.name,
            0.0,
            "1",
            "analytic",
            "the ball (centre (0, 0, 45) cm, R = 3 cm) lies far outside the reachable set (under 15 cm from the base): no "
            "overlap; the volume ratio would be 0.093",
            "Tricky: coverage of a solid outside the model.",
        ),
    ]
    out.append(fx)
    return out


# --- free space (spec chapter 9) ---------------------------------------------------------------------


def felt(t: np.ndarray) -> np.ndarray:
    """|F| = √(0.5² + 0.4² + (0.3 + 0.2 sin 0.5t)²): min at sin = −1, max at sin = +1 (both reached in 12 s)."""
    return np.column_stack([0.5 + 0 * t, -0.4 + 0 * t, 0.3 + 0.2 * np.sin(0.5 * t)])


def plate_truth(t: np.ndarray) -> np.ndarray:
    return np.column_stack([0.2 * np.cos(0.3 * t), 0 * t, -17.4 + 0.3 * np.sin(0.5 * t)])


def free_space_fixtures() -> list[Fixture]:
    out: list[Fixture] = []
    sec_f, sec_p, sec_s = "9.2", "9.3", "9.4"
    truth = rb.HandleTruth(force_noise=0.0, torque_noise=0.0, accel_noise=0.0, mass=0.06)
    T = 12.0
    tg = grid(T)
    mag = np.linalg.norm(felt(tg), axis=1)
    P = plate_truth(tg)
    plate_dev = np.linalg.norm(P - np.array([0.0, 0.0, P[:, 2].mean()]), axis=1)

    def typical(path: Path) -> None:
        rig = example_rig()
        bias = rb.plate_bias_vector(rig)
        w = manifest("conf-fs-typical", rig, truth=truth, plate_bias=bias)
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=T,
            position=circle(0.05, 1.0),
            quaternion=spin(0.07),
            force_w=felt,
            truth=truth,
            plate_force_w=plate_truth,
            plate_bias=bias,
        )
        w.write(path)

    fx = Fixture("fs-typical", typical)
    weight = (
        f"the raw F/T stream holds a {truth.mass} kg connector's weight and a bias, removed by the handle_gravity record "
        "(spec §6.5)"
    )
    fx.cases += [
        case(
            "free_space.force_mean.typical",
            "free_space.force_mean",
            sec_f,
            fx.name,
            mag.mean(),
            "N",
            "analytic",
            "mean over the 100 Hz grid (t = 0 … 12 s) of |(0.5, −0.4, 0.3 + 0.2 sin 0.5t)| N; " + weight,
            "Typical: a slowly varying force on the hand.",
        ),
        case(
            "free_space.force_sd.typical",
            "free_space.force_sd",
            sec_f,
            fx.name,
            mag.std(ddof=1),
            "N",
            "analytic",
            "sample SD (ddof 1) of the same magnitudes on the grid",
            "Typical.",
        ),
        case(
            "free_space.force_min.typical",
            "free_space.force_min",
            sec_f,
            fx.name,
            math.hypot(0.5, 0.4, 0.1),
            "N",
            "analytic",
            "|(0.5, −0.4, 0.1)|: sin 0.5t reaches −1 at t = 3π",
            "Typical.",
        ),
        case(
            "free_space.force_max.typical",
            "free_space.force_max",
            sec_f,
            fx.name,
            math.hypot(0.5, 0.4, 0.5),
            "N",
            "analytic",
            "|(0.5, −0.4, 0.5)|: sin 0.5t reaches +1 at t = π",
            "Typical.",
        ),
        case(
            "free_space.plate_force_mean.typical",
            "free_space.plate_force_mean",
            sec_p,
            fx.name,
            plate_dev.mean(),
            "N",
            "analytic",
            "mean on the grid of |P − (0, 0, mean P_z)| for P = (0.2 cos 0.3t, 0, −17.4 + 0.3 sin 0.5t) N, "
            "split over the four corner sensors (statically determinate) on top of the recorded plate bias",
            "Typical.",
        ),
        case(
            "free_space.speed_mean.typical",
            "free_space.speed_mean",
            sec_s,
            fx.name,
            0.05,
            "m/s",
            "analytic",
            "gimbal centre on a circle of radius 0.05 m at 1 rad/s: speed r·ω",
            "Typical: uniform circular motion.",
        ),
        case(
            "free_space.angular_speed_mean.typical",
            "free_space.angular_speed_mean",
            sec_s,
            fx.name,
            0.07,
            "rad/s",
            "analytic",
            "handle turning at a constant 0.07 rad/s about a fixed axis",
            "Typical.",
        ),
    ]
    out.append(fx)

    # Rotated rig frames, CSV, unusual rates, constant force (SD zero, min = max = mean).
    F0 = np.array([0.3, 0.6, -0.9])

    def rotated(path: Path) -> None:
        rig = rotated_rig_full()
        bias = rb.plate_bias_vector(rig)
        w = manifest("conf-fs-rotated", rig, truth=truth, plate_bias=bias, placement=placement_of((0.02, 0.0, 0.0), yaw=1.0))
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=10.0,
            position=circle(0.04, 2.0, (0.01, 0.0, 0.15)),
            quaternion=spin(0.11, axis=(1.0, 0.4, 0.2), tilt=2.5),
            force_w=lambda t: np.tile(F0, (len(t), 1)),
            truth=truth,
            rates=(400.0, 250.0, 120.0),
            fmt="csv",
            plate_force_w=lambda t: np.column_stack([0 * t, 0.4 + 0 * t, -15.0 + 0 * t]),
            plate_bias=bias,
        )
        w.write(path)

    fx = Fixture("fs-rotated-csv", rotated)
    f0 = float(np.linalg.norm(F0))
    rot = "handle F/T and accelerometer frames turned (90° about z, 180° about x), corner sensors yawed 0/90/180/270°"
    fx.cases += [
        case(
            "free_space.force_mean.rotated-csv",
            "free_space.force_mean",
            sec_f,
            fx.name,
            f0,
            "N",
            "analytic",
            f"constant force (0.3, 0.6, −0.9) N on the hand in W; {rot}; F/T at 500 Hz, mocap at 120 Hz",
            "Tricky: rotated rig frames, CSV, unusual rates.",
        ),
        case(
            "free_space.force_sd.constant",
            "free_space.force_sd",
            sec_f,
            fx.name,
            0.0,
            "N",
            "analytic",
            "a constant force has SD 0 (tolerance: the rounding of the calibration under rotation)",
            "Edge: zero spread.",
        ),
        case(
            "free_space.force_min.constant",
            "free_space.force_min",
            sec_f,
            fx.name,
            f0,
            "N",
            "analytic",
            "min of |F| over the trial equals |F| = |(0.3, 0.6, −0.9)| N of the constant force",
            "Edge.",
        ),
        case(
            "free_space.force_max.constant",
            "free_space.force_max",
            sec_f,
            fx.name,
            f0,
            "N",
            "analytic",
            "max of |F| over the trial equals |F| = |(0.3, 0.6, −0.9)| N of the constant force",
            "Edge.",
        ),
        case(
            "free_space.plate_force_mean.rotated-corners",
            "free_space.plate_force_mean",
            sec_p,
            fx.name,
            0.4,
            "N",
            "analytic",
            "constant plate force (0, 0.4, −15) N; removing the mean vertical leaves |(0, 0.4, 0)|; corner sensors "
            "yawed by 0/90/180/270° must be rotated into W",
            "Tricky: rotated corner frames.",
        ),
        case(
            "free_space.speed_mean.rotated-csv",
            "free_space.speed_mean",
            sec_s,
            fx.name,
            0.08,
            "m/s",
            "analytic",
            "circle r = 0.04 m at 2 rad/s sampled at 120 Hz: speed 0.08 m/s",
            "Tricky: unusual mocap rate.",
        ),
        case(
            "free_space.angular_speed_mean.rotated-csv",
            "free_space.angular_speed_mean",
            sec_s,
            fx.name,
            0.11,
            "rad/s",
            "analytic",
            "constant rotation at 0.11 rad/s about (1, 0.4, 0.2) from a 2.5 rad tilt",
            "Tricky: large tilt.",
        ),
    ]
    out.append(fx)

    # Occlusion gaps: one long gap (never interpolated across) and short ones (bridged).
    def occlusion(path: Path) -> None:
        rig = example_rig()
        bias = rb.plate_bias_vector(rig)
        w = manifest("conf-fs-occluded", rig, truth=truth, plate_bias=bias)

        def gone(t: np.ndarray) -> np.ndarray:
            k = np.round(t * 100).astype(int)
            return ((t > 3.0) & (t < 6.0)) | (k % 150 == 77) | (k % 150 == 78)

        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=12.0,
            position=circle(0.05, 1.0),
            quaternion=spin(0.2),
            force_w=lambda t: np.column_stack([0.2 + 0 * t, 0.1 * np.sin(t), 0 * t]),
            truth=truth,
            occluded=gone,
            plate_force_w=lambda t: np.column_stack([0 * t, 0 * t, -16.0 + 0.5 * np.sin(2 * t)]),
            plate_bias=bias,
        )
        w.write(path)

    fx = Fixture("fs-occlusion-gaps", occlusion)
    tg = grid(12.0)
    usable = ~((tg > 3.0 + 1e-9) & (tg < 6.0 - 1e-9))  # the samples at 3.00 s and 6.00 s are valid
    m_occ = np.hypot(0.2, 0.1 * np.sin(tg[usable]))
    fx.cases += [
        case(
            "free_space.speed_mean.occlusion",
            "free_space.speed_mean",
            sec_s,
            fx.name,
            0.05,
            "m/s",
            "analytic",
            "circle r = 0.05 m at 1 rad/s; motion capture lost for 3 s (t = 3 … 6 s: a 3 rad arc whose chord is 30 % shorter) "
            "and for two frames every 1.5 s; only the short gaps may be bridged (spec §7.4), so the speed is r·ω",
            "Tricky: occlusion gaps (interpolating across the long one lowers the speed).",
        ),
        case(
            "free_space.angular_speed_mean.occlusion",
            "free_space.angular_speed_mean",
            sec_s,
            fx.name,
            0.2,
            "rad/s",
            "analytic",
            "constant rotation at 0.2 rad/s; the rows of the 3 s gap are excluded, the two-frame gaps bridged by slerp",
            "Tricky: occlusion gaps.",
        ),
        case(
            "free_space.force_mean.occlusion",
            "free_space.force_mean",
            sec_f,
            fx.name,
            m_occ.mean(),
            "N",
            "analytic",
            "mean of |(0.2, 0.1 sin t, 0)| over the grid rows where motion capture is usable (t outside the 3 s gap): the "
            "force is used only where the handle orientation is known (spec §7.5)",
            "Tricky: usable samples only.",
        ),
        case(
            "free_space.force_sd.occlusion",
            "free_space.force_sd",
            sec_f,
            fx.name,
            m_occ.std(ddof=1),
            "N",
            "analytic",
            "sample SD (ddof 1) of |(0.2, 0.1 sin t, 0)| over the usable grid rows",
            "Tricky: usable samples only.",
        ),
        case(
            "free_space.force_min.occlusion",
            "free_space.force_min",
            sec_f,
            fx.name,
            m_occ.min(),
            "N",
            "analytic",
            "minimum of |(0.2, 0.1 sin t, 0)| over the usable rows (0.2 N where sin t = 0)",
            "Tricky: usable samples only.",
        ),
        case(
            "free_space.force_max.occlusion",
            "free_space.force_max",
            sec_f,
            fx.name,
            m_occ.max(),
            "N",
            "analytic",
            "maximum of |(0.2, 0.1 sin t, 0)| over the usable rows (√0.05 N where sin t = ±1)",
            "Tricky: usable samples only.",
        ),
        case(
            "free_space.plate_force_mean.sinusoid",
            "free_space.plate_force_mean",
            sec_p,
            fx.name,
            float(np.mean(np.abs(0.5 * np.sin(2 * grid(12.0)) - np.mean(0.5 * np.sin(2 * grid(12.0)))))),
            "N",
            "analytic",
            "vertical plate force −16 + 0.5 sin 2t N: mean of |P_z − mean P_z| over the grid; the plate stream has no occlusion",
            "Edge: a purely vertical oscillation.",
        ),
    ]
    out.append(fx)
    out.append(jitter_fixture(truth))
    out.append(glimpse_fixture(truth))
    out.append(pushes_fixture(truth))
    return out


def glimpse_fixture(truth: rb.HandleTruth) -> Fixture:
    """Motion capture sees the handle for 0.3 s only (31 rows of the 100 Hz grid): the force statistics rest on few
    samples, where the sample SD (ddof = 1, §9.2) and the population SD differ by 1.6 %."""
    name, T = "fs-glimpse-csv", 6.0

    def force(t: np.ndarray) -> np.ndarray:
        return np.column_stack([0.3 + 0.4 * t, -0.2 + 0 * t, 0.1 + 0 * t])

    def seen(t: np.ndarray) -> np.ndarray:
        k = np.round(t * 100).astype(int)
        return (k >= 200) & (k <= 230)

    def build(path: Path) -> None:
        w = manifest(f"conf-{name}", example_rig(), truth=truth)
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=T,
            position=circle(0.05, 1.0),
            quaternion=spin(0.07),
            force_w=force,
            truth=truth,
            fmt="csv",
            occluded=lambda t: ~seen(t),
        )
        w.write(path)

    fx = Fixture(name, build)
    tg = grid(T)
    mag = np.linalg.norm(force(tg[seen(tg)]), axis=1)
    how = (
        f"|(0.3 + 0.4t, −0.2, 0.1)| N over the {len(mag)} grid rows t = 2.00 … 2.30 s, the only time motion capture "
        "sees the handle (§7.5: the force counts only where the orientation is known); a force linear in time passes "
        "the §7.2 low-pass exactly (chord removed), so the values are exact: tolerance 1e-4"
    )
    desc = "Edge: a trial whose motion capture is usable for 0.3 s only (sample statistics of 31 values)."
    fx.cases += [
        case(
            "free_space.force_sd.glimpse",
            "free_space.force_sd",
            "9.2",
            name,
            mag.std(ddof=1),
            "N",
            "analytic",
            "sample SD (ddof = 1) of " + how + f"; ddof = 0 gives {mag.std():.6g} N (1.6 % less)",
            desc,
        ),
        case(
            "free_space.force_mean.glimpse",
            "free_space.force_mean",
            "9.2",
            name,
            mag.mean(),
            "N",
            "analytic",
            "mean of " + how,
            desc,
        ),
        case(
            "free_space.force_min.glimpse",
            "free_space.force_min",
            "9.2",
            name,
            mag.min(),
            "N",
            "analytic",
            "minimum (at t = 2.00 s) of " + how,
            desc,
        ),
        case(
            "free_space.force_max.glimpse",
            "free_space.force_max",
            "9.2",
            name,
            mag.max(),
            "N",
            "analytic",
            "maximum (at t = 2.30 s) of " + how,
            desc,
        ),
    ]
    return fx


def pushes_fixture(truth: rb.HandleTruth) -> Fixture:
    """The examiner's hand hides the markers while it pushes: four gaps of seven frames at 150 Hz (t_j − t_i = 53 ms,
    bridged by §7.4 since max_gap_s + Δ = 56.7 ms), each centred on a force pulse. Leaving such a gap open drops the
    rows around each pulse's peak."""
    name, T, rate, centres, width = "fs-occluded-pushes", 10.0, 150.0, (2.0, 4.0, 6.0, 8.0), 0.6
    F0, push = np.array([0.3, 0.1, 0.2]), np.array([0.6, 0.0, 0.0])

    def pulses(t: np.ndarray) -> np.ndarray:
        pulse = (np.where(np.abs(t - c) <= width / 2, np.sin(np.pi * (t - c + width / 2) / width) ** 2, 0.0) for c in centres)
        return sum(pulse, np.zeros_like(t))

    def force(t: np.ndarray) -> np.ndarray:
        return F0 + np.outer(pulses(t), push)

    def hidden(t: np.ndarray) -> np.ndarray:
        k = np.round(t * rate).astype(int)
        return np.any([np.abs(k - round(c * rate)) <= 3 for c in centres], axis=0)

    def build(path: Path) -> None:
        w = manifest(f"conf-{name}", example_rig(), truth=truth)
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=T,
            position=circle(0.05, 1.0),
            quaternion=spin(0.07),
            force_w=force,
            truth=truth,
            rates=(1000.0, 500.0, rate),
            occluded=hidden,
        )
        w.write(path)

    fx = Fixture(name, build)
    mag = np.linalg.norm(force(grid(T)), axis=1)
    how = (
        f"|(0.3, 0.1, 0.2) + p(t)·(0.6, 0, 0)| N with p four sin² pulses {width} s wide centred on t = {centres} s; "
        f"motion capture at {rate:g} Hz misses 7 frames around each centre (t_j − t_i = 8/150 s = 53.3 ms ≤ max_gap_s + Δ "
        "= 56.7 ms: bridged, §7.4), so every grid row counts; the pulses pass the §7.2 low-pass (flat to order 8) to "
        "better than 1e-5: tolerance 1e-3"
    )
    desc = "Tricky: short occlusions exactly where the force peaks (bridged by §7.4's rule, Δ included)."
    fx.cases += [
        case(
            "free_space.force_max.occluded-pushes",
            "free_space.force_max",
            "7.4",
            name,
            mag.max(),
            "N",
            "analytic",
            "maximum (at each pulse's peak, inside a gap) of " + how,
            desc,
        ),
        case(
            "free_space.force_mean.occluded-pushes",
            "free_space.force_mean",
            "7.4",
            name,
            mag.mean(),
            "N",
            "analytic",
            "mean over the grid of " + how,
            desc,
        ),
    ]
    return fx


def envelope(t: np.ndarray, start: float, stop: float, ramp: float = 0.5) -> np.ndarray:
    """0 before ``start`` and after ``stop``, 1 between the two sin² ramps of ``ramp`` s: switches a vibration on
    away from a trial's ends (its spectrum stays within ~2/ramp Hz of the vibration's frequency)."""
    up = np.clip((t - start) / ramp, 0.0, 1.0)
    down = np.clip((stop - t) / ramp, 0.0, 1.0)
    return np.sin(0.5 * np.pi * up) ** 2 * np.sin(0.5 * np.pi * down) ** 2


SUPERSEDED = rb.HandleTruth(mass=0.09, force_bias=np.array([0.1, 0.2, -0.3]), force_noise=0.0, torque_noise=0.0, accel_noise=0.0)
JITTER = {
    "position_m": 3e-4,
    "position_hz": 30.0,
    "angle_rad": math.radians(0.1),
    "angle_hz": 30.0,
    "force_N": 0.5,
    "force_hz": 180.0,
    "plate_N": 2.0,
    "plate_hz": 130.0,
}


def jitter_fixture(truth: rb.HandleTruth) -> Fixture:
    """Free space with vibrations every low-pass of §7.2 removes: 30 Hz marker jitter in position and about the
    vertical, a 180 Hz force on the hand, a 130 Hz plate force. The spec's values are those of the smooth motion and
    forces; a velocity or angular velocity differentiated without the low-pass, a force resampled before filtering
    (180 Hz aliases to 20 Hz on the 100 Hz grid) or an unfiltered plate force are far off."""
    name, T, j = "fs-jitter", 12.0, JITTER
    F0, P0 = np.array([0.4, -0.2, 0.3]), np.array([0.3, 0.0, -16.0])

    def on(t: np.ndarray) -> np.ndarray:
        return envelope(t, 1.0, T - 1.0)

    def position(t: np.ndarray) -> np.ndarray:
        return circle(0.05, 1.0)(t) + np.outer(j["position_m"] * on(t) * np.sin(2 * np.pi * j["position_hz"] * t), Z)

    def quaternion(t: np.ndarray) -> np.ndarray:
        wobble = quat_from_axis_angle(np.tile(Z, (len(t), 1)), j["angle_rad"] * on(t) * np.sin(2 * np.pi * j["angle_hz"] * t))
        return quat_multiply(wobble, spin(0.07)(t))

    def force(t: np.ndarray) -> np.ndarray:
        return F0 + np.outer(j["force_N"] * on(t) * np.sin(2 * np.pi * j["force_hz"] * t), [1.0, 0.0, 0.0])

    def plate(t: np.ndarray) -> np.ndarray:
        return P0 + np.outer(j["plate_N"] * on(t) * np.cos(2 * np.pi * j["plate_hz"] * t), Z)

    def build(path: Path) -> None:
        rig = example_rig()
        bias = rb.plate_bias_vector(rig)
        w = manifest(f"conf-{name}", rig, truth=truth, plate_bias=bias, superseded=SUPERSEDED)
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=T,
            position=position,
            quaternion=quaternion,
            force_w=force,
            truth=truth,
            rates=(1000.0, 500.0, 100.0),
            plate_force_w=plate,
            plate_bias=bias,
        )
        w.write(path)

    fx = Fixture(name, build)
    fc = param("signals", "mocap_cutoff_hz")
    gains = {
        k: lowpass_pair_gain(f, rate, cut)
        for k, f, rate, cut in (
            ("mocap", j["position_hz"], 100.0, fc),
            ("force", j["force_hz"], 1000.0, param("signals", "wrench_cutoff_hz")),
            ("plate", j["plate_hz"], 1000.0, param("signals", "wrench_cutoff_hz")),
            ("angle", j["angle_hz"], 100.0, param("signals", "angular_velocity_cutoff_hz")),
        )
    }
    jit = (
        f"marker jitter {j['position_m'] * 1000:g} mm along z and {math.degrees(j['angle_rad']):g}° about the vertical "
        f"at {j['position_hz']:g} Hz (switched on by sin² ramps 1 s from the ends), which the §7.4 low-pass at {fc:g} Hz "
        f"passes with gain {gains['mocap']:.1e}"
    )
    f0 = float(np.linalg.norm(F0))
    felt_note = (
        f"constant force {tuple(F0)} N on the hand plus {j['force_N']} N at {j['force_hz']:g} Hz along x (ramped on "
        f"1 s from the ends); the 20 Hz low-pass at the F/T's 1 kHz leaves {gains['force']:.1e} of it (§7.5: filter at "
        "the native rate, then interpolate; resampled first, 180 Hz aliases to 20 Hz on the 100 Hz grid)"
    )
    desc = "Tricky: vibrations above every cut-off of §7.2 (marker jitter, a motor hum in the force, a ringing plate)."
    fx.cases += [
        case(
            "free_space.speed_mean.jitter",
            "free_space.speed_mean",
            "7.4",
            name,
            0.05,
            "m/s",
            "analytic",
            f"circle r = 0.05 m at 1 rad/s (speed r·ω) with {jit}; velocity is the derivative of the LOW-PASSED position. "
            "Tolerance 0.1 %: the circle passes the low-pass unchanged to 1e-5, the jitter adds its square (1e-11)",
            desc,
        ),
        case(
            "free_space.angular_speed_mean.jitter",
            "free_space.angular_speed_mean",
            "7.4",
            name,
            0.07,
            "rad/s",
            "analytic",
            f"constant rotation at 0.07 rad/s with {jit}; the angular velocity is low-passed at "
            f"{param('signals', 'angular_velocity_cutoff_hz'):g} Hz (§7.4 step 4; gain {gains['angle']:.1e} at {j['angle_hz']:g} Hz). "
            "Tolerance 0.1 %: a rotation about the vertical turns the spin axis without changing |ω| to first order",
            desc,
        ),
        case(
            "free_space.force_mean.jitter",
            "free_space.force_mean",
            "9.2",
            name,
            f0,
            "N",
            "analytic",
            f"|F| of the {felt_note}; the jitter about the vertical leaves the connector's weight in the sensor frame "
            f"unchanged; an earlier handle_gravity record (a {SUPERSEDED.mass * 1000:g} g connector) precedes the one that "
            "applies (§6.4: the last). Tolerance 0.2 % as for the other constant forces",
            desc,
        ),
        case(
            "free_space.force_max.jitter",
            "free_space.force_max",
            "9.2",
            name,
            f0,
            "N",
            "analytic",
            f"max |F| of the {felt_note}",
            desc,
        ),
        case(
            "free_space.force_sd.jitter",
            "free_space.force_sd",
            "9.2",
            name,
            0.0,
            "N",
            "analytic",
            f"SD of |F| of the {felt_note}: 0 (tolerance: the rounding of the calibration under rotation, as for the "
            "other constant force)",
            desc,
        ),
        case(
            "free_space.plate_force_mean.jitter",
            "free_space.plate_force_mean",
            "9.3",
            name,
            0.3,
            "N",
            "analytic",
            f"plate force {tuple(P0)} N plus {j['plate_N']} N at {j['plate_hz']:g} Hz vertical (ramped on 1 s from the ends), "
            f"low-passed at 20 Hz (gain {gains['plate']:.1e}) before resampling (§9.3); removing the mean vertical leaves "
            "|(0.3, 0, 0)|. Tolerance 0.5 % as for the other plate cases",
            desc,
        ),
    ]
    return fx


# --- vibration (spec chapter 10) --------------------------------------------------------------------


def hp_gain(f: float) -> float:
    """Net amplitude gain of the zero-phase high-pass of spec §10.2 at f: 1 / (1 + (fc/f)^(2·order))."""
    fc, order = param("vibration", "highpass_cutoff_hz"), param("vibration", "highpass_order")
    return 1.0 / (1.0 + (fc / f) ** (2 * order))


def tones_rms(tones: list[tuple[float, float]]) -> float:
    return math.sqrt(sum((a * hp_gain(f)) ** 2 / 2 for f, a in tones))


def tones_centroid(tones: list[tuple[float, float]]) -> float:
    p = [(a * hp_gain(f)) ** 2 for f, a in tones]
    return sum(pi * f for pi, (f, _) in zip(p, tones)) / sum(p)


Tones = dict[int, list[tuple[float, float]]]  # axis → [(frequency Hz, amplitude m/s²)]


def write_vibration_session(
    path: Path, session_id: str, fmt: str, rate: float, secs: float, fs_tones: Tones, base_tones: Tones, rig_kind: str
) -> None:
    """A free-space trial whose handle acceleration carries ``fs_tones`` and a baseline trial carrying
    ``base_tones`` (spec §10), both at ``rate`` Hz for ``secs`` s, on the example or the rotated rig; the
    known answers are :func:`tones_rms` and :func:`tones_centroid` of the tones (every tone an integer
    frequency, so it falls on a DFT bin of the trimmed signal)."""
    rig = example_rig() if rig_kind == "example" else rotated_rig_full()

    def extra(tones: Tones) -> Fn:
        def fn(t: np.ndarray) -> np.ndarray:
            a = np.zeros((len(t), 3))
            for axis, ts in tones.items():
                for f, amp in ts:
                    a[:, axis] += amp * np.sin(2 * np.pi * f * t)
            return a

        return fn

    w = manifest(session_id, rig)
    handle_trial(
        w,
        "free_space-1",
        "free_space",
        duration_s=secs - 1 / rate,
        position=circle(0.03, 0.5),
        quaternion=spin(0.05),
        force_w=lambda t: np.tile([0.1, 0.0, -0.2], (len(t), 1)),
        rates=(250.0, rate, 100.0),
        fmt=fmt,
        accel_extra=extra(fs_tones),
    )
    tb = clock(secs, rate)[:-1]
    a_base = rb.HandleTruth().accel_bias + np.array([0.0, 0.0, 9.81]) + extra(base_tones)(tb)
    w.add_trial("baseline-1", "rig.baseline_vibration", powered=False)
    w.add_stream(
        "baseline-1", "handle_accel", {"t": tb, "ax": a_base[:, 0], "ay": a_base[:, 1], "az": a_base[:, 2]}, rate_hz=rate, fmt=fmt
    )
    w.write(path)


def free_space_repetitions(
    w: SessionWriter, gains: tuple[float, ...], truth: rb.HandleTruth, duration_s: float, fmt: str = "parquet"
) -> None:
    """Free-space trials 1, 2, … whose hand force is ``gain ×`` the fs-typical force :func:`felt` of the
    trial's own clock (each trial starts 20 s after the previous one), on the fs-typical circle and spin."""
    for rep, gain in enumerate(gains, start=1):
        t0 = 20.0 * (rep - 1)

        def force_w(t: np.ndarray, g: float = gain, t0: float = t0) -> np.ndarray:
            return g * felt(t - t0)

        handle_trial(
            w,
            f"free_space-{rep}",
            "free_space",
            duration_s=duration_s,
            position=circle(0.05, 1.0),
            quaternion=spin(0.07),
            force_w=force_w,
            truth=truth,
            repetition=rep,
            start_s=t0,
            fmt=fmt,
        )


def uncertainty_fixtures() -> list[Fixture]:
    """Type A uncertainty with a known answer (spec §19.2, §19.4): two free-space repetitions whose forces are
    the fs-typical force and 1.1 × it, so their mean magnitudes are x₁ and 1.1·x₁ (x₁ analytic). CSV streams, so
    that an implementation without a Parquet reader (the JavaScript example) can answer them too."""
    from scipy import stats

    truth = rb.HandleTruth(force_noise=0.0, torque_noise=0.0, accel_noise=0.0, mass=0.06)
    T = 12.0
    x1 = float(np.linalg.norm(felt(grid(T)), axis=1).mean())
    u = 0.05 * x1  # s = 0.1·x₁/√2, u = s/√2
    k = float(stats.t.ppf(0.975, 1))

    def two_reps(path: Path) -> None:
        w = manifest("conf-unc-fs-two-reps", example_rig(), truth=truth)
        free_space_repetitions(w, (1.0, 1.1), truth, T, fmt="csv")
        w.write(path)

    fx = Fixture("unc-fs-two-reps", two_reps)
    why = (
        f"x₁ = {x1:.6f} N, the fs-typical mean |F| (analytic), and x₂ = 1.1·x₁; no rig trial, so no Type B source "
        "is available (sources_missing) and u is Type A only"
    )
    params = {"uncertainty": True}
    m = "free_space.force_mean"
    fx.cases += [
        case(
            f"{m}.uncertainty-u.two-reps",
            m,
            "19.2",
            fx.name,
            u,
            "N",
            "analytic",
            f"u = s/√2 = |x₂ − x₁|/2 = 0.05·x₁; {why}",
            "Type A of two repetitions.",
            parameters=params,
            quantity="u",
        ),
        case(
            f"{m}.uncertainty-k.two-reps",
            m,
            "19.4",
            fx.name,
            k,
            "1",
            "analytic",
            "k = t_0.975(ν_eff) with ν_eff = n − 1 = 1 (one Type A term): 12.706",
            "Coverage factor of two repetitions.",
            parameters=params,
            quantity="k",
        ),
        case(
            f"{m}.uncertainty-expanded.two-reps",
            m,
            "19.4",
            fx.name,
            k * u,
            "N",
            "analytic",
            f"U = k·u = 12.706 × 0.05·x₁; {why}",
            "Expanded uncertainty of two repetitions.",
            parameters=params,
            quantity="U",
        ),
    ]
    return [fx]


def vibration_fixtures() -> list[Fixture]:
    out: list[Fixture] = []
    variants = [
        # name, fmt, accel rate, seconds, free-space tones per axis, baseline tones, rig
        (
            "vib-tones",
            "parquet",
            2000.0,
            6.0,
            {0: [(150.0, 0.05)], 2: [(230.0, 0.02)]},
            {0: [(110.0, 0.03)]},
            "example",
            "Typical: two tones on two axes (DFT321 combines them).",
        ),
        (
            "vib-two-tone",
            "parquet",
            2000.0,
            6.0,
            {1: [(100.0, 0.1), (300.0, 0.2)]},
            {2: [(60.0, 0.04), (180.0, 0.08)]},
            "rotated",
            "Tricky: two tones on one axis; a magnitude-weighted centroid differs from the power-weighted one.",
        ),
        (
            "vib-near-cutoff-csv",
            "csv",
            1500.0,
            4.0,
            {0: [(12.0, 0.2)], 1: [(400.0, 0.02)]},
            {0: [(15.0, 0.1)]},
            "rotated",
            "Edge: a tone just above the 10 Hz cut-off, an unusual 1.5 kHz rate, CSV (a single-pass filter shows here).",
        ),
        (
            "vib-antiphase-csv",
            "csv",
            1500.0,
            4.0,
            {0: [(200.0, 0.05)], 1: [(200.0, -0.05)]},
            {1: [(90.0, 0.03)], 2: [(90.0, 0.03)]},
            "example",
            "Tricky: one tone in antiphase on two axes; DFT321 keeps both axes' power (the sum of the axes cancels "
            "it, the per-sample vector magnitude doubles its frequency).",
        ),
    ]
    note_filter = (
        "zero-phase Butterworth high-pass gain 1/(1+(10/f)^8) per tone (spec §10.2); every tone falls on a DFT "
        "bin of the trimmed signal"
    )
    for name, fmt, rate, secs, fs_tones, base_tones, rig_kind, desc in variants:

        def build(
            path: Path, fmt=fmt, rate=rate, secs=secs, fs_tones=fs_tones, base_tones=base_tones, rig_kind=rig_kind, name=name
        ) -> None:
            write_vibration_session(path, f"conf-{name}", fmt, rate, secs, fs_tones, base_tones, rig_kind)

        fx = Fixture(name, build)
        all_fs = [tone for ts in fs_tones.values() for tone in ts]
        all_base = [tone for ts in base_tones.values() for tone in ts]
        short = name.removeprefix("vib-")
        fmt_tones = lambda ts: ", ".join(f"{a} m/s² at {f:g} Hz" for f, a in ts)  # noqa: E731
        fx.cases += [
            case(
                f"vibration.rms.{short}",
                "vibration.rms",
                "10.4",
                name,
                tones_rms(all_fs),
                "m/s^2",
                "analytic",
                f"√(Σ (A·g(f))²/2) for {fmt_tones(all_fs)} at {rate:g} Hz; {note_filter}; DFT321 preserves energy",
                desc,
            ),
            case(
                f"vibration.spectral_centroid.{short}",
                "vibration.spectral_centroid",
                "10.5",
                name,
                tones_centroid(all_fs),
                "Hz",
                "analytic",
                f"power-weighted mean frequency Σ f·(A g)² / Σ (A g)² of {fmt_tones(all_fs)}",
                desc,
            ),
            case(
                f"vibration.baseline_rms.{short}",
                "vibration.baseline_rms",
                "10.6",
                name,
                tones_rms(all_base),
                "m/s^2",
                "analytic",
                f"baseline trial (no device): {fmt_tones(all_base)} on top of gravity and bias; {note_filter}",
                desc,
            ),
            case(
                f"vibration.baseline_centroid.{short}",
                "vibration.baseline_centroid",
                "10.6",
                name,
                tones_centroid(all_base),
                "Hz",
                "analytic",
                f"power-weighted mean frequency of {fmt_tones(all_base)}",
                desc,
            ),
        ]
        out.append(fx)
    out.append(repetitions_fixture(note_filter))
    out.append(bursts_fixture())
    return out


REPETITION_TONES = [(120.0, 0.05), (150.0, 0.06), (400.0, 0.20)]  # one tone per free-space repetition: the third is the outlier


def repetitions_fixture(note_filter: str) -> Fixture:
    """Three free-space repetitions, one tone each, the third far larger and higher: the reported value is
    the mean of the per-repetition values (spec §15.3), which the median or the first repetition misses by
    far more than the tolerance."""
    name, rate, secs = "vib-three-reps-csv", 1500.0, 4.0

    def build(path: Path) -> None:
        w = manifest(f"conf-{name}", example_rig())
        for k, (f, amp) in enumerate(REPETITION_TONES):

            def tone(t: np.ndarray, f=f, amp=amp) -> np.ndarray:
                a = np.zeros((len(t), 3))
                a[:, k] = amp * np.sin(2 * np.pi * f * t)
                return a

            handle_trial(
                w,
                f"free_space-{k + 1}",
                "free_space",
                duration_s=secs - 1 / rate,
                position=circle(0.03, 0.5),
                quaternion=spin(0.05),
                force_w=lambda t: np.tile([0.1, 0.0, -0.2], (len(t), 1)),
                rates=(250.0, rate, 100.0),
                fmt="csv",
                repetition=k + 1,
                accel_extra=tone,
            )
        w.write(path)

    fx = Fixture(name, build)
    rms = [tones_rms([tone]) for tone in REPETITION_TONES]
    centroids = [tones_centroid([tone]) for tone in REPETITION_TONES]
    tones = "; ".join(f"repetition {k + 1}: {a} m/s² at {f:g} Hz on {'xyz'[k]}" for k, (f, a) in enumerate(REPETITION_TONES))
    desc = "Tricky: three repetitions, one outlying; the value is their mean (spec §15.3), not their median."
    fx.cases += [
        case(
            "vibration.rms.three-reps",
            "vibration.rms",
            "15.3",
            name,
            float(np.mean(rms)),
            "m/s^2",
            "analytic",
            f"mean over repetitions of √((A·g(f))²/2) — {tones}; {note_filter}. The median "
            f"({np.median(rms):.4g}) and the first repetition ({rms[0]:.4g}) lie ≥ 40 % away",
            desc,
        ),
        case(
            "vibration.spectral_centroid.three-reps",
            "vibration.spectral_centroid",
            "15.3",
            name,
            float(np.mean(centroids)),
            "Hz",
            "analytic",
            f"mean over repetitions of each repetition's single tone frequency — {tones}. "
            f"The median ({np.median(centroids):.4g} Hz) lies 33 % away",
            desc,
        ),
    ]
    return fx


def burst(t: np.ndarray, f: float, amp: float, start: float, stop: float) -> np.ndarray:
    """A tone of ``f`` Hz under a sin² (Hann) envelope from ``start`` to ``stop`` s, zero elsewhere: its spectrum stays
    within a few Hz of f, so the 10 Hz high-pass passes it with the gain at f and spreads none of it in time."""
    inside = (t >= start) & (t <= stop)
    return np.where(inside, amp * np.sin(np.pi * (t - start) / (stop - start)) ** 2 * np.sin(2 * np.pi * f * t), 0.0)


def one_sided_power(a: np.ndarray) -> np.ndarray:
    """P_k = w_k |A_k|² of spec §10.5 (rectangular window, DFT length N)."""
    p = np.abs(np.fft.rfft(a)) ** 2
    w = np.full(len(p), 2.0)
    w[0] = 1.0
    if len(a) % 2 == 0:
        w[-1] = 1.0
    return w * p


BURSTS = {
    "tone": (100.0, 0.05),
    "inner": (400.0, 0.08, 0.55, 0.85),
    "start": (250.0, 0.3, 0.05, 0.45),
    "end": (250.0, 0.3, 1.75, 2.15),
}


def bursts_fixture() -> Fixture:
    """One free-space trial at 1.5 kHz, 2.2 s: a steady 100 Hz tone on x, a 400 Hz burst on y early in the analysed
    window, and 250 Hz bursts inside the two trimmed edges (the start one on z, the end one on y). The analysed signal
    (§10.2: 0.5 s cut from each end) is known exactly; a Hann window before the periodogram weighs the early burst
    down (centroid), analysing the edges adds the edge bursts, and DFT321 before trimming mixes the two edge bursts
    (same band, different axes) into the middle."""
    name, rate, secs = "vib-bursts-csv", 1500.0, 2.2
    (f_tone, a_tone), inner, first, last = BURSTS["tone"], BURSTS["inner"], BURSTS["start"], BURSTS["end"]

    def extra(t: np.ndarray) -> np.ndarray:
        return np.column_stack([a_tone * np.sin(2 * np.pi * f_tone * t), burst(t, *inner) + burst(t, *last), burst(t, *first)])

    def build(path: Path) -> None:
        w = manifest(f"conf-{name}", example_rig())
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=secs - 1 / rate,
            position=circle(0.03, 0.5),
            quaternion=fixed(quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), np.array(0.4))),
            force_w=lambda t: np.tile([0.1, 0.0, -0.2], (len(t), 1)),
            rates=(250.0, rate, 100.0),
            fmt="csv",
            accel_extra=extra,
        )
        w.write(path)

    fx = Fixture(name, build)
    t = clock(secs - 1 / rate, rate)
    trim = int(round(param("vibration", "edge_trim_s") * rate))
    window = t[trim : len(t) - trim]
    x = hp_gain(f_tone) * a_tone * np.sin(2 * np.pi * f_tone * window)
    y = hp_gain(inner[0]) * burst(window, *inner)
    power = one_sided_power(x) + one_sided_power(y)  # DFT321 keeps |X|² + |Y|² per bin (§10.3)
    freqs = np.fft.rfftfreq(len(window), 1 / rate)
    how = (
        f"{a_tone} m/s² at {f_tone:g} Hz on x (on a DFT bin), a {inner[1]} m/s² {inner[0]:g} Hz sin²-burst on y over "
        f"[{inner[2]}, {inner[3]}] s, {first[1]} m/s² {first[0]:g} Hz sin²-bursts over [{first[2]}, {first[3]}] s on z and "
        f"[{last[2]}, {last[3]}] s on y; after the high-pass (gain 1/(1+(10/f)^8)) and the {trim}-sample trims "
        f"(§10.2) the analysed {len(window)} samples hold the tone and the inner burst only, exactly"
    )
    why_tol = (
        "tolerance 1e-4: the analysed signal is known to ~1e-6 of its amplitude (the high-pass's start-up "
        "transient, from poles near 10 Hz, has decayed to e^−12 by the end of the trim; the bursts' sin² envelopes "
        "keep their spectra within a few Hz of their tones, where the gain is exact)"
    )
    desc = (
        "Tricky: a burst early in the analysed window (a Hann window weighs it down) and bursts inside the trimmed "
        "edges (analysing them, or combining the axes before trimming, lets them in)."
    )
    fx.cases += [
        case(
            "vibration.rms.bursts",
            "vibration.rms",
            "10.2",
            name,
            float(np.sqrt(np.mean(x**2 + y**2))),
            "m/s^2",
            "analytic",
            f"RMS over the analysed samples of {how} (DFT321 keeps the energy, §10.3); {why_tol}",
            desc,
        ),
        case(
            "vibration.spectral_centroid.bursts",
            "vibration.spectral_centroid",
            "10.5",
            name,
            float(np.sum(freqs * power) / np.sum(power)),
            "Hz",
            "analytic",
            f"Σ f_k P_k / Σ P_k of the one-sided rectangular periodograms of {how}; {why_tol}",
            desc,
        ),
    ]
    return fx


# --- frictionless surface (spec chapter 12) ----------------------------------------------------------


def tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.cross(n, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def surface_fixture(
    name: str,
    fmt: str,
    rig_kind: str,
    normal_raw,
    point,
    contacts,
    secs: float,
    planar: Fn,
    rates,
    desc: str,
    preload: float,
    outside: float | None = 2.0,
) -> Fixture:
    """A frictionless-surface fixture (spec §12.2): a hand circling on the rendered plane (normal ``normal_raw``
    through ``point``) in contact during ``contacts`` (s), feeling ``planar(t)`` N against its motion and 1.5 N
    along the normal; outside contact ``outside`` N planar (None: ``planar``) and ``preload`` N along the normal.
    Its cases are the planar force's mean and SD over the guarded contact rows."""
    guard = param("surface", "contact_guard_s")
    n = np.asarray(normal_raw, float) / np.linalg.norm(normal_raw)
    u, v = tangent_basis(n)
    pp = np.asarray(point, float)

    def contact(t, contacts=contacts):
        return np.any([(t >= on) & (t <= off) for on, off in contacts], axis=0)

    def position(t, u=u, v=v, n=n, pp=pp, contact=contact):
        depth = np.where(contact(t), 0.002, -0.01)
        return pp + 0.03 * (np.cos(2 * t)[:, None] * u + np.sin(2 * t)[:, None] * v) - depth[:, None] * n

    def force(t, u=u, v=v, n=n, contact=contact, planar=planar, outside=outside, preload=preload):
        d = np.sin(2 * t)[:, None] * u - np.cos(2 * t)[:, None] * v
        mag = np.where(contact(t), planar(t), outside if outside is not None else planar(t))
        return mag[:, None] * d + np.where(contact(t), 1.5, preload)[:, None] * n

    def commanded(t, n=n, contact=contact):
        return np.where(contact(t), 1.5, 0.0)[:, None] * n

    rendering = {"surface_point_m": list(point), "surface_normal": [float(c) for c in n], "stiffness_N_per_m": 750.0}

    fx = Fixture(
        name,
        active_session(
            name, rig_kind, "surface-1", "frictionless_surface", secs, 0.05, position, force, commanded, rendering, rates, fmt
        ),
    )
    tg = grid(secs)
    used = np.any([(tg >= on + guard - 1e-9) & (tg <= off - guard + 1e-9) for on, off in contacts], axis=0)
    truth = planar(tg[used])
    if preload:  # the low-passed steps of the planar force still ring a little beyond the guard: superpose them
        fs, step = rates[0], planar(tg[used]) - outside
        truth = outside + step * sum(
            pair_step(tg[used] - on, fs) - pair_step(tg[used] - off - 1 / fs, fs) for on, off in contacts
        )
    short = name.removeprefix("surf-")
    spans = " and ".join(f"from {on} s to {off} s" for on, off in contacts)
    how = (
        f"planar force of the stated magnitude against the motion plus 1.5 N along the normal {normal_raw}, in contact "
        f"{spans} (commanded normal force 1.5 N), statistics over the 100 Hz grid rows inside the "
        f"contact minus the {guard} s guard at both ends (spec §12.2)"
    )
    if preload:
        how += (
            f"; outside contact the hand feels {outside} N planar and {preload} N along the normal while the "
            "commanded force is zero: contact is the COMMANDED force's (§12.2), so those rows never count. The "
            "planar force steps at each transition; the values superpose the zero-phase low-pass's step response "
            "(§7.2, 20 Hz at 1 kHz), whose ringing beyond the 50 ms guard moves them by up to 0.3 %; the hand "
            "direction turns 0.1 rad within the filter's span, a second-order effect"
        )
    fx.cases += [
        case(
            f"surface.planar_force_mean.{short}",
            "surface.planar_force_mean",
            "12.2",
            name,
            truth.mean(),
            "N",
            "analytic",
            how,
            desc,
        ),
        case(
            f"surface.planar_force_sd.{short}",
            "surface.planar_force_sd",
            "12.2",
            name,
            truth.std(ddof=1) if len(truth) > 1 else 0.0,
            "N",
            "analytic",
            how,
            desc,
        ),
    ]
    return fx


def surface_fixtures() -> list[Fixture]:
    # name, format, rig, normal, plane point, contact intervals (s), duration, planar force in contact, rates, description,
    # measured normal force outside contact (N: the device's own weight pushing the hand up)
    variants = [
        (
            "surf-typical",
            "parquet",
            "example",
            [0.0, 0.0, 1.0],
            (0.0, 0.05, 0.10),
            ((1.0, 9.0),),
            10.0,
            lambda t: 0.53 + 0.1 * np.sin(2 * np.pi * 0.5 * t),
            (1000.0, 500.0, 100.0),
            "Typical: a horizontal surface.",
            0.0,
        ),
        (
            "surf-tilted-rotated-csv",
            "csv",
            "rotated",
            [0.0, 0.2, 1.0],
            (0.0, 0.05, 0.12),
            ((1.5, 8.5),),
            10.0,
            lambda t: 0.4 + 0.15 * np.cos(2 * np.pi * 0.25 * t),
            (400.0, 250.0, 150.0),
            "Tricky: a tilted surface normal, rotated sensor frames, CSV, unusual rates.",
            0.0,
        ),
        (
            "surf-constant",
            "parquet",
            "example",
            [0.3, 0.0, 1.0],
            (0.01, 0.0, 0.10),
            ((0.8, 5.2),),
            6.0,
            lambda t: 0.25 + 0 * t,
            (1000.0, 500.0, 100.0),
            "Edge: a constant planar force (SD 0), short trial.",
            0.0,
        ),
        (
            "surf-preload",
            "parquet",
            "example",
            [0.0, 0.0, 1.0],
            (0.0, 0.02, 0.11),
            ((0.8, 1.8), (2.4, 3.4), (4.0, 5.0), (5.6, 6.6)),
            7.4,
            lambda t: 0.3 + 0 * t,
            (1000.0, 500.0, 100.0),
            "Tricky: four short contacts, and outside them the device's uncompensated weight pushes the hand up 0.5 N along "
            "the normal (a measured-force contact rule counts those samples; the guard matters at eight transitions).",
            0.5,
        ),
    ]
    return [surface_fixture(*v, outside=None if v[0] == "surf-constant" else 2.0) for v in variants]


# --- stiffness (spec chapter 13) -------------------------------------------------------------------------

K_CMD = 750.0
HOVER = 0.005  # m above the plane between presses
DEPTH = 0.012  # m, the deepest penetration of every press
PRESS_S, GAP_S, PRESSES = 1.2, 0.5, 5


def duration(press_s: float = PRESS_S) -> float:
    """Length (s) of a stiffness fixture's trial: PRESSES presses of ``press_s`` with their gaps, and 0.5 s after."""
    return GAP_S + PRESSES * (press_s + GAP_S) + 0.5


def press_phase(t: np.ndarray, press_s: float = PRESS_S) -> tuple[np.ndarray, np.ndarray]:
    """(τ, inside): time since the current press began (s) and whether a press is under way."""
    tau = np.mod(t - GAP_S, press_s + GAP_S)
    return tau, (t >= GAP_S) & (tau < press_s) & (t < GAP_S + PRESSES * (press_s + GAP_S))


def press_depth(t: np.ndarray, press_s: float = PRESS_S, scales: tuple[float, ...] = (1.0,) * PRESSES) -> np.ndarray:
    """Penetration (m): from hovering HOVER above the plane, PRESSES presses −HOVER + (s_k·DEPTH + HOVER)·sin²(π τ / press_s),
    τ the time since press k began, s_k = ``scales[k]``, separated by GAP_S. Smooth throughout (at the default 1.2 s the
    hand crosses the plane at about 0.04 m/s, the protocol's pace), so the motion-capture low-pass of §7.4 has no step to
    ring at."""
    tau, inside = press_phase(t, press_s)
    k = np.clip(np.floor((t - GAP_S) / (press_s + GAP_S)).astype(int), 0, PRESSES - 1)
    deepest = DEPTH * np.asarray(scales, dtype=float)[k]
    return np.where(inside, -HOVER + (deepest + HOVER) * np.sin(np.pi * tau / press_s) ** 2, -HOVER)


def press_time(depth: float, press_s: float = PRESS_S) -> float:
    """Time (s) after a press begins at which its loading stroke reaches ``depth`` (m): the inverse of press_depth."""
    return press_s / np.pi * math.asin(math.sqrt((depth + HOVER) / (DEPTH + HOVER)))


def loading_stroke(t: np.ndarray, press_s: float = PRESS_S) -> np.ndarray:
    """True while a press's penetration grows (its first half, up to its deepest instant)."""
    tau, inside = press_phase(t, press_s)
    return inside & (tau <= press_s / 2)


def contact_kick(t: np.ndarray, amplitude: float, length_s: float, press_s: float = PRESS_S) -> np.ndarray:
    """A force kick (N) at every press's contact instant: amplitude·sin²(π (τ − τ_c) / length_s) for
    τ_c ≤ τ < τ_c + length_s, τ_c the instant the press crosses the plane."""
    tau, inside = press_phase(t, press_s)
    tau = tau - press_time(0.0, press_s)
    on = inside & (tau >= 0) & (tau < length_s)
    return np.where(on, amplitude * np.sin(np.pi * np.clip(tau, 0, length_s) / length_s) ** 2, 0.0)


FIT_RULE = (
    "after the contact transient (the first 4 grid samples of a press), from the force there up to 90 % of "
    "the rise to where the force stops rising (spec §13.2)"
)


def spring_fixture(
    name: str, fmt: str, rig_kind: str, normal_raw, point, k: float, peak: float, after: float | None, rates, desc: str
) -> Fixture:
    """A stiffness fixture (spec §13.2–§13.4): five presses into a rendered K_CMD N/m plane (normal ``normal_raw``
    through ``point``) of a device whose force is ``k`` N/m × penetration, saturating at ``peak`` N (``after`` None)
    or giving way to ``after`` N once it reaches ``peak``. Cases: the measured stiffness, the accuracy and, when
    it saturates, the peak force."""
    n = np.asarray(normal_raw, float) / np.linalg.norm(normal_raw)
    pp = np.asarray(point, float)

    def law(t, k=k, peak=peak, after=after):
        d = press_depth(t)
        if after is None:
            return np.clip(k * d, 0.0, peak)
        # gives way: once k·d reaches the peak the force drops to `after` for the rest of that press
        tau, _ = press_phase(t)
        return np.where(d <= 0, 0.0, np.where(tau < press_time(peak / k), k * d, after))

    def position(t, n=n, pp=pp):
        return pp - press_depth(t)[:, None] * n

    def force(t, n=n, law=law):
        side = np.array([0.1, 0.0, 0.0]) - (np.array([0.1, 0.0, 0.0]) @ n) * n  # a small planar force
        return law(t)[:, None] * n + side

    def commanded(t, n=n):
        return (K_CMD * np.maximum(press_depth(t), 0.0))[:, None] * n

    rendering = {"surface_point_m": list(point), "surface_normal": [float(c) for c in n], "stiffness_N_per_m": K_CMD}

    fx = Fixture(
        name,
        active_session(
            name, rig_kind, "stiffness-1", "stiffness", duration(), 0.03, position, force, commanded, rendering, rates, fmt
        ),
    )
    short = name.removeprefix("stiff-")
    how = (
        f"five presses from {HOVER * 1000:g} mm above to {DEPTH * 1000:g} mm into a rendered {K_CMD:g} N/m surface (normal "
        f"{normal_raw}); the device's force is {k:g} N/m × penetration "
        + (f"saturating at {peak} N" if after is None else f"up to {peak} N, then {after} N until the press ends")
        + "; the fit samples, "
        + FIT_RULE
        + ", lie on the linear part"
    )
    fx.cases += [
        case(f"stiffness.measured.{short}", "stiffness.measured", "13.3", name, k, "N/m", "analytic", how, desc),
        case(
            f"stiffness.accuracy.{short}",
            "stiffness.accuracy",
            "13.4",
            name,
            100 * k / K_CMD,
            "%",
            "analytic",
            how + f"; accuracy = 100·{k:g}/{K_CMD:g}",
            desc,
        ),
    ]
    if after is None:
        fx.cases.append(
            case(
                f"stiffness.peak_force.{short}",
                "stiffness.peak_force",
                "13.4",
                name,
                peak,
                "N",
                "analytic",
                how + "; every press reaches the saturation plateau",
                desc,
            )
        )
    return fx


def stiffness_fixtures() -> list[Fixture]:
    variants = [
        (
            "stiff-saturating",
            "parquet",
            "example",
            [0.0, -0.15, 1.0],
            (0.01, 0.04, 0.11),
            360.0,
            2.7,
            None,
            (1000.0, 500.0, 100.0),
            "Typical: a linear spring that saturates (the Touch, paper §VI-F).",
        ),
        (
            "stiff-rotated-csv",
            "csv",
            "rotated",
            [0.2, 0.1, 1.0],
            (0.0, 0.02, 0.09),
            520.0,
            4.0,
            None,
            (400.0, 250.0, 150.0),
            "Tricky: rotated sensor frames, a tilted surface, CSV and unusual rates.",
        ),
        (
            "stiff-giving-way",
            "parquet",
            "example",
            [0.0, 0.0, 1.0],
            (0.0, 0.0, 0.10),
            600.0,
            5.7,
            1.0,
            (1000.0, 500.0, 100.0),
            "Edge: a spring that gives way after its peak (the Touch X, paper §VI-F).",
        ),
    ]
    out: list[Fixture] = [spring_fixture(*v) for v in variants]
    up = np.array([0.0, 0.0, 1.0])

    def linear_presses(name: str, scales: tuple[float, ...]) -> Fixture:
        """A purely linear 300 N/m spring pressed PRESSES times, press k ``scales[k]``·DEPTH deep."""
        depth = lambda t: press_depth(t, scales=scales)  # noqa: E731
        return Fixture(
            name,
            active_session(
                name,
                "example",
                "stiffness-1",
                "stiffness",
                duration(),
                0.03,
                lambda t: np.array([0.0, 0.01, 0.1]) - depth(t)[:, None] * up,
                lambda t: np.clip(300.0 * depth(t), 0.0, None)[:, None] * up,
                lambda t: (K_CMD * np.maximum(depth(t), 0.0))[:, None] * up,
                {"surface_point_m": [0.0, 0.01, 0.1], "surface_normal": [0.0, 0.0, 1.0], "stiffness_N_per_m": K_CMD},
                (500.0, 500.0, 100.0),
                "parquet",
            ),
        )

    # A third peak-force case: a press that never saturates, so its peak is k·depth.
    fx = linear_presses("stiff-linear", (1.0,) * PRESSES)
    fx.cases += [
        case(
            "stiffness.peak_force.linear",
            "stiffness.peak_force",
            "13.4",
            fx.name,
            300.0 * DEPTH,
            "N",
            "analytic",
            "a purely linear 300 N/m spring pressed 12 mm deep: the peak is 3.6 N (the sin² press is smooth at its bottom, "
            "so the 20 Hz low-pass leaves the peak)",
            "Edge: no saturation.",
        ),
        case(
            "stiffness.measured.linear",
            "stiffness.measured",
            "13.3",
            fx.name,
            300.0,
            "N/m",
            "analytic",
            "a purely linear 300 N/m spring pressed five times 12 mm deep: the least-squares slope of force against "
            "penetration over the fit samples is the spring constant (the rise ends at the deepest sample)",
            "Edge: no saturation.",
        ),
    ]
    out.append(fx)
    # Presses of unequal depth: the peak force is the MEAN of the presses' peaks (§13.4), not the largest.
    scales = (0.7, 0.85, 1.0, 1.15, 1.3)
    fx = linear_presses("stiff-linear-uneven", scales)
    peaks = [300.0 * DEPTH * sc for sc in scales]
    fx.cases += [
        case(
            "stiffness.peak_force.linear-uneven",
            "stiffness.peak_force",
            "13.4",
            fx.name,
            float(np.mean(peaks)),
            "N",
            "analytic",
            f"a purely linear 300 N/m spring pressed {', '.join(f'{1000 * DEPTH * sc:g}' for sc in scales)} mm "
            f"deep: the press peaks are {', '.join(f'{pk:.3g}' for pk in peaks)} N and the value is their mean (the largest "
            f"is {max(peaks) / np.mean(peaks) - 1:.0%} higher)",
            "Tricky: presses of unequal depth.",
        ),
        case(
            "stiffness.measured.linear-uneven",
            "stiffness.measured",
            "13.3",
            fx.name,
            300.0,
            "N/m",
            "analytic",
            "a purely linear 300 N/m spring: every press's fit samples lie on one line whatever its depth",
            "Tricky: presses of unequal depth.",
        ),
    ]
    out.append(fx)
    out += [kick_dip_fixture(), falling_release_fixture()]
    return out


KICK_N, KICK_S = 3.0, 0.01  # the contact kick of stiff-kick-dip: 3 N for 10 ms
SLOW_S = 2.4  # stiff-kick-dip's presses last 2.4 s: the plane is crossed at 0.02 m/s


def kick_dip_law(t: np.ndarray) -> np.ndarray:
    """stiff-kick-dip's normal force (N): 400 N/m up to 1.6 N at 4 mm, a sag to 1.0 N and back to 1.6 N at 11 mm,
    then 400 N/m to 2.0 N at the 12 mm bottom; a 3 N, 10 ms kick at every contact."""
    d = press_depth(t, SLOW_S)
    sag = 1.6 - 0.6 * np.sin(np.pi * np.clip((d - 0.004) / 0.007, 0.0, 1.0))
    spring = np.where(d <= 0, 0.0, np.where(d <= 0.004, 400.0 * d, np.where(d <= 0.011, sag, 1.6 + 400.0 * (d - 0.011))))
    return spring + contact_kick(t, KICK_N, KICK_S, SLOW_S)


def kick_dip_fixture() -> Fixture:
    """A rendering that kicks at contact and whose plateau sags and climbs above its first top: the fit must
    leave out the contact transient and end the rise at the first top (spec §13.2). The previous rule (rising
    phase up to the press's largest force, 20–80 % of it) takes in the sag; a fit over the whole rise from the
    first contact sample takes in the kick."""
    up = np.array([0.0, 0.0, 1.0])
    pp = np.array([0.0, 0.02, 0.1])
    fx = Fixture(
        "stiff-kick-dip",
        active_session(
            "stiff-kick-dip",
            "example",
            "stiffness-1",
            "stiffness",
            duration(SLOW_S),
            0.03,
            lambda t: pp - press_depth(t, SLOW_S)[:, None] * up,
            lambda t: kick_dip_law(t)[:, None] * up,
            lambda t: (K_CMD * np.maximum(press_depth(t, SLOW_S), 0.0))[:, None] * up,
            {"surface_point_m": pp.tolist(), "surface_normal": up.tolist(), "stiffness_N_per_m": K_CMD},
            (1000.0, 500.0, 100.0),
            "parquet",
        ),
    )
    how = (
        "five slow presses (2.4 s, crossing the plane at 0.02 m/s) 12 mm deep; force 400 N/m × penetration up to 1.6 N at 4 mm, a sag to 1.0 N and back to 1.6 N at "
        "11 mm, then 400 N/m more to 2.0 N at the bottom; a 3 N, 10 ms sin² kick at each contact. The fit samples, "
        + FIT_RULE
        + ", lie on the first 400 N/m part: the rise ends at the first top (the force stays below 1.6 N for "
        "0.39 s after it), and the kick has decayed through the 20 Hz low-pass before the first settled sample"
    )
    desc = "Edge: a kick at contact and a plateau that sags and climbs again (the fit window of §13.2)."
    fx.cases += [
        case("stiffness.measured.kick-dip", "stiffness.measured", "13.3", fx.name, 400.0, "N/m", "analytic", how, desc),
        case(
            "stiffness.peak_force.kick-dip",
            "stiffness.peak_force",
            "13.4",
            fx.name,
            2.0,
            "N",
            "analytic",
            how + "; the peak is the loading stroke's largest force, 2.0 N at the smooth bottom of the press",
            desc,
        ),
    ]
    return fx


WEIGHT_N = 0.8  # stiff-falling-release: the device's uncompensated weight pulls the hand into the plane


def falling_release_law(t: np.ndarray) -> np.ndarray:
    """stiff-falling-release's normal force (N): 360 N/m up to 2.88 N at 8 mm, 2.88 N for 2 mm, then falling linearly
    with depth to 1.44 N at the 12 mm bottom; on the release stroke 0.15 N more wherever the spring is past its
    knee; the device's weight (−0.8 N) throughout."""
    d = press_depth(t)
    d_sat, top = 0.008, 360.0 * 0.008
    spring = np.where(
        d <= 0,
        0.0,
        np.where(
            d <= d_sat,
            360.0 * d,
            np.where(d <= d_sat + 0.002, top, top - top / 2 * (d - d_sat - 0.002) / (DEPTH - d_sat - 0.002)),
        ),
    )
    return spring + np.where(loading_stroke(t) | (d <= d_sat), 0.0, 0.15) - WEIGHT_N


def falling_release_fixture() -> Fixture:
    """A device whose force saturates, then falls with depth, and pushes harder on the way back up than on the way
    in (the peak and the fit must come from the loading stroke, spec §13.2), with its weight uncompensated (the line's
    intercept is −0.8 N, not 0)."""
    up = np.array([0.0, 0.0, 1.0])
    pp = np.array([0.01, 0.0, 0.12])
    fx = Fixture(
        "stiff-falling-release",
        active_session(
            "stiff-falling-release",
            "example",
            "stiffness-1",
            "stiffness",
            duration(),
            0.03,
            lambda t: pp - press_depth(t)[:, None] * up,
            lambda t: falling_release_law(t)[:, None] * up,
            lambda t: (K_CMD * np.maximum(press_depth(t), 0.0))[:, None] * up,
            {"surface_point_m": pp.tolist(), "surface_normal": up.tolist(), "stiffness_N_per_m": K_CMD},
            (1000.0, 500.0, 100.0),
            "parquet",
        ),
    )
    how = (
        "five presses 12 mm deep; force 360 N/m × penetration up to 2.88 N at 8 mm, flat for 2 mm, then falling with "
        "depth to 1.44 N at the bottom; 0.15 N more on the release stroke past the knee (the whole press's largest force, "
        "3.03 N − the weight, "
        f"lies on the release); the device's weight −{WEIGHT_N:g} N throughout. The fit samples, "
        + FIT_RULE
        + ", lie on the 360 N/m part"
    )
    desc = "Edge: a force that falls with depth and is higher on the release stroke (the loading stroke of §13.2)."
    fx.cases += [
        case("stiffness.measured.falling-release", "stiffness.measured", "13.3", fx.name, 360.0, "N/m", "analytic", how, desc),
        case(
            "stiffness.peak_force.falling-release",
            "stiffness.peak_force",
            "13.4",
            fx.name,
            2.88 - WEIGHT_N,
            "N",
            "analytic",
            how + f"; the peak is the loading stroke's largest force, 2.88 − {WEIGHT_N:g} N on its 2 mm plateau",
            desc,
        ),
    ]
    return fx


# --- rig (spec chapter 14) ---------------------------------------------------------------------------------


def damped_peak(f_n: float, zeta: float) -> float:
    """Frequency of the maximum of |Fourier transform| of e^(−ζωt) sin(ω_d t): ω_n √(1 − 2ζ²) / 2π."""
    return f_n * math.sqrt(1 - 2 * zeta**2)


def calibration_rms(truth: rb.HandleTruth) -> list[float]:
    """The known rig.handle_calibration_rms (spec §14.7) of a calibration trial of ``truth``'s white sensor noise
    (F/T at 1 kHz, accelerometer at 2 kHz) after the 20 Hz zero-phase low-pass: per channel σ·√(variance gain);
    the torque residual τ − (b + c × F) adds the force noise through c × n_F, E|c × n|² = 2|c|²σ_F² (per axis
    ⅔|c|²σ_F²)."""
    ft_var = lowpass_noise_ratio(param("signals", "wrench_cutoff_hz"), 1000.0, param("signals", "filter_order"))
    acc_var = lowpass_noise_ratio(param("signals", "accel_cutoff_hz"), 2000.0, param("signals", "filter_order"))
    torque_sigma = math.sqrt(truth.torque_noise**2 + 2 / 3 * float(truth.com @ truth.com) * truth.force_noise**2)
    return [truth.force_noise * math.sqrt(ft_var), truth.accel_noise * math.sqrt(acc_var), torque_sigma * math.sqrt(ft_var)]


def calibration_offset_u(truth: rb.HandleTruth, rig: dict, duration_s: float) -> float:
    """The known rig.handle_force_offset_u (spec §6.2 step 5, §14.7) of a calibration trial of ``truth``'s white F/T
    noise σ (1 kHz) over ``duration_s`` of :func:`rig_builders.tumbling_orientation`: the low-pass keeps the noise's
    spectral density at 0 Hz, so on the fit grid (rate r) the scores' long-run covariance is σ²·(r/1000)·JᵀJ and
    Cov(c, ρ) = σ²·(r/1000)·(JᵀJ)⁻¹, Jᵢ = −(ĝᵢ, 1) with ĝᵢ the gravity direction in the sensor frame."""
    rate = float(param("calibration", "fit_rate_hz"))
    t = np.arange(int(duration_s * rate)) / rate
    q_ws = quat_multiply(
        rb.tumbling_orientation(t),
        np.broadcast_to(np.asarray(rig["handle"]["ft_sensor"]["pose"]["quaternion"], float), (len(t), 4)),
    )
    g = quat_rotate(quat_conjugate(q_ws), np.broadcast_to(GRAVITY_W, (len(t), 3)))
    jac = np.column_stack([g / np.linalg.norm(g, axis=1, keepdims=True), np.ones(len(t))])
    cov = truth.force_noise**2 * rate / 1000.0 * np.linalg.inv(jac.T @ jac)
    return float(np.sqrt(np.max(np.diag(cov)[:3]) + cov[3, 3]))


def rig_fixtures() -> list[Fixture]:
    out: list[Fixture] = []
    variants = [
        # name, rig, modes, zeta, accel delay, mocap delay, cop offset, truth, seed
        (
            "rig-rotated",
            "rotated",
            (205.0, 206.0, 182.0),
            0.03,
            0.003,
            -0.001,
            0.005,
            rb.HandleTruth(),
            SEED + 10,
            "Typical: the paper's plate modes, rotated handle sensors.",
        ),
        (
            "rig-late-mocap",
            "example",
            (150.0, 163.0, 121.0),
            0.02,
            -0.002,
            0.004,
            0.008,
            rb.HandleTruth(force_noise=0.006),
            SEED + 11,
            "Tricky: late motion capture, an early accelerometer, a weaker plate.",
        ),
        (
            "rig-quiet",
            "rotated-plate",
            (240.0, 230.0, 260.0),
            0.04,
            0.0,
            0.0,
            0.002,
            QUIET,
            SEED + 12,
            "Edge: noise-free handle sensors (residuals vanish), synchronous recorders, yawed corner sensors.",
        ),
    ]
    for name, rig_kind, modes, zeta, acc_d, moc_d, cop_off, truth, seed, desc in variants:

        def build(
            path: Path,
            rig_kind=rig_kind,
            modes=modes,
            zeta=zeta,
            acc_d=acc_d,
            moc_d=moc_d,
            cop_off=cop_off,
            truth=truth,
            seed=seed,
            name=name,
        ) -> None:
            rng = np.random.default_rng(seed)
            rig = {"rotated": rb.rotated_rig, "example": example_rig, "rotated-plate": rotated_rig_full}[rig_kind]()
            rig["motion_capture"]["markers"] = sorted(set(rig["motion_capture"]["markers"]) | {"w1"})
            w = rb.writer(rig=rig, sid=f"conf-{name}")
            rb.add_calibration_trial(w, truth, rng, duration_s=12.0, accel_delay_s=acc_d, mocap_delay_s=moc_d)
            rb.add_plate_bias_trial(w, rng)
            rb.add_impact_trial(w, rng, modes=modes, zeta=zeta)
            pos = np.array([[0.0, 0.0], [0.2, 0.1], [-0.2, -0.2]])
            ang = np.linspace(0, 2 * np.pi, len(pos), endpoint=False)
            rb.add_cop_trial(w, rng, pos, cop_off * np.column_stack([np.cos(ang), np.sin(ang)]))
            w.write(path)

        fx = Fixture(name, build)
        short = name.removeprefix("rig-")
        peaks = [damped_peak(f, zeta) for f in modes]
        expected_rms = calibration_rms(truth)
        rig_desc = {"rotated": rb.rotated_rig, "example": example_rig, "rotated-plate": rotated_rig_full}[rig_kind]()
        quiet = truth.force_noise == 0.0
        fx.cases += [
            case(
                f"rig.plate_natural_frequency.{short}",
                "rig.plate_natural_frequency",
                "14.4",
                name,
                peaks,
                "Hz",
                "analytic",
                f"a ball drop rings each axis as e^(−ζωt) sin(ω_d t) with f_n = {modes} Hz, ζ = {zeta}: the "
                "magnitude spectrum peaks at f_n √(1 − 2ζ²); tolerance = the 0.5 s window's zero-padded bin (0.24 Hz) "
                "refined by a parabola, plus 0.01 N noise",
                desc,
            ),
            case(
                f"rig.cop_error.{short}",
                "rig.cop_error",
                "14.5",
                name,
                cop_off,
                "m",
                "analytic",
                f"three placements of a 1 kg weight whose marker is offset by {cop_off} m from the load point in three "
                "directions; corner readings split the load statically (spec §14.1); noise 5 mN per channel",
                desc,
            ),
            case(
                f"rig.sync_offset.{short}",
                "rig.sync_offset",
                "14.6",
                name,
                max(abs(acc_d), abs(moc_d)),
                "s",
                "analytic",
                f"accelerometer time stamps late by {acc_d} s, motion capture by {moc_d} s against the F/T "
                "recorder; the value is the larger |delay|; tolerance = a third of the 1 ms grid step",
                desc,
            ),
            case(
                f"rig.handle_calibration_rms.{short}",
                "rig.handle_calibration_rms",
                "14.7",
                name,
                expected_rms,
                "[N, m/s^2, N*m]",
                "analytic",
                (
                    "noise-free sensors: the residuals are only the filters' end effects on the tumbling gravity (< 2e-4)"
                    if quiet
                    else f"white noise σ = ({truth.force_noise} N, {truth.accel_noise} m/s², {truth.torque_noise} N·m) per axis, "
                    "low-passed at 20 Hz (zero phase, order 4: variance × (2/fs)∫|H|⁴ df) before the fits: the radial residual "
                    "of an isotropic error has the per-axis σ; the torque residual adds the force noise through the centre of "
                    "mass, √(σ_τ² + ⅔|c|²σ_F²); tolerance 15 % = the sampling spread of an RMS over a few hundred "
                    "independent samples"
                ),
                desc,
            ),
            case(
                f"rig.handle_force_offset_u.{short}",
                "rig.handle_force_offset_u",
                "14.7",
                name,
                calibration_offset_u(truth, rig_desc, 12.0),
                "N",
                "analytic",
                (
                    "noise-free sensors: only the filters' end effects on the tumbling gravity are left to the fit"
                    if quiet
                    else f"white F/T noise σ = {truth.force_noise} N per axis at 1 kHz over 12 s of the tumble: the low-pass keeps its "
                    "density at 0 Hz, so the fitted bias and weight have Cov = σ²·(r/1 kHz)·(JᵀJ)⁻¹ on the 100 Hz fit grid "
                    "(Jᵢ = −(ĝᵢ, 1)); value √(max per-axis variance of the bias + variance of the weight)"
                ),
                desc,
            ),
        ]
        out.append(fx)
    out.append(impact_fixture())
    out.append(early_accel_fixture())
    out.append(cop_spread_fixture())
    return out


def cop_spread_fixture() -> Fixture:
    """A COP trial whose marker offsets differ from placement to placement (0, 5 and 25 mm): their mean, 10 mm, is
    the metric; their root mean square (14.7 mm) or median (5 mm) is not."""
    name, offsets = "rig-cop-spread", np.array([[0.0, 0.0], [0.005, 0.0], [0.0, -0.025]])

    def build(path: Path) -> None:
        rng = np.random.default_rng(SEED + 14)
        rig = example_rig()
        rig["motion_capture"]["markers"] = sorted(set(rig["motion_capture"]["markers"]) | {"w1"})
        w = rb.writer(rig=rig, sid=f"conf-{name}")
        rb.add_plate_bias_trial(w, rng)
        rb.add_cop_trial(w, rng, np.array([[0.05, -0.05], [-0.15, 0.1], [0.2, 0.2]]), offsets)
        w.write(path)

    fx = Fixture(name, build)
    errors = np.linalg.norm(offsets, axis=1)
    fx.cases.append(
        case(
            "rig.cop_error.spread",
            "rig.cop_error",
            "14.5",
            name,
            float(errors.mean()),
            "m",
            "analytic",
            f"three placements of a 1 kg weight whose marker is offset from the load point by {errors.tolist()} m: "
            "the mean distance over the placements; corner readings split the load statically (spec §14.1); "
            "noise 5 mN per channel; tolerance 0.5 mm as for the other COP cases",
            "Tricky: placements of different errors (mean, not RMS or median).",
        )
    )
    return fx


def early_accel_fixture() -> Fixture:
    """A calibration trial whose accelerometer is EARLY by 4 ms and motion capture late by 1.5 ms: the largest |delay|
    is the negative one."""
    name, acc_d, moc_d = "rig-early-accel", -0.004, 0.0015

    def build(path: Path) -> None:
        w = rb.writer(rig=rb.rotated_rig(), sid=f"conf-{name}")
        rb.add_calibration_trial(
            w, rb.HandleTruth(), np.random.default_rng(SEED + 13), duration_s=12.0, accel_delay_s=acc_d, mocap_delay_s=moc_d
        )
        w.write(path)

    fx = Fixture(name, build)
    fx.cases.append(
        case(
            "rig.sync_offset.early-accel",
            "rig.sync_offset",
            "14.6",
            name,
            max(abs(acc_d), abs(moc_d)),
            "s",
            "analytic",
            f"accelerometer time stamps early by {-acc_d} s (delay {acc_d} s), motion "
            f"capture late by {moc_d} s against the F/T recorder; the value is the larger |delay|, that of the "
            "early recorder; tolerance = a third of the 1 ms grid step",
            "Edge: the largest delay is negative.",
        )
    )
    return fx


def impact_peaks(t: np.ndarray, force: np.ndarray, rate: float) -> list[float]:
    """Spec §14.4 steps 2–4 written out for a known total plate force ``force (N, 3)``: the window around the largest
    deviation from the median, per axis the mean removed, zero-padding to a power of two, the largest |FFT| in the band
    and the vertex of the parabola through the log-magnitudes around it (clipped to half a bin)."""
    centre = t[np.argmax(np.linalg.norm(force - np.median(force, axis=0), axis=1))]
    inside = (t >= centre - param("rig", "impact_pre_s")) & (t <= centre + param("rig", "impact_window_s"))
    nfft = 1 << int(math.ceil(math.log2(inside.sum() * param("rig", "zero_pad_factor"))))
    freqs = np.arange(nfft // 2 + 1) * rate / nfft
    band = (freqs >= param("rig", "impact_band_low_hz")) & (freqs <= param("rig", "impact_band_high_fraction") * rate / 2)
    peaks = []
    for axis in range(3):
        x = force[inside, axis]
        mag = np.abs(np.fft.rfft(x - x.mean(), nfft))
        k = int(np.flatnonzero(band)[np.argmax(mag[band])])
        lo, mid, hi = np.log(mag[k - 1 : k + 2])
        shift = 0.5 * (lo - hi) / (lo - 2 * mid + hi) if lo - 2 * mid + hi < 0 else 0.0
        peaks.append(float(freqs[k] + min(max(shift, -0.5), 0.5) * rate / nfft))
    return peaks


def impact_fixture() -> Fixture:
    """Noise-free ball drops: the value is the §14.4 procedure applied to the exactly known ringing, so its discrete
    choices (no taper, zero-padding, the parabola) are pinned to 1e-4 Hz; broad peaks (ζ = 6 %) make them matter."""
    name, zeta, modes = "rig-impact-clean", 0.06, [(187.0, 214.0, 143.0), (191.0, 209.0, 151.0)]

    def build(path: Path) -> None:
        w = rb.writer(rig=rotated_rig_full(), sid=f"conf-{name}")
        for rep, m in enumerate(modes, start=1):
            rb.add_impact_trial(
                w, np.random.default_rng(SEED), modes=m, zeta=zeta, trial_id=f"impact-{rep}", repetition=rep, noise=0.0
            )
        w.write(path)

    fx = Fixture(name, build)
    t = np.arange(3000) / 1000.0
    per_trial = [
        impact_peaks(t, np.column_stack([rb.damped(t, f, zeta, 1.0, a) for f, a in zip(m, (4.0, 3.0, 20.0))]), 1000.0)
        for m in modes
    ]
    analytic = [[round(damped_peak(f, zeta), 3) for f in m] for m in modes]
    fx.cases.append(
        case(
            "rig.plate_natural_frequency.clean",
            "rig.plate_natural_frequency",
            "14.4",
            name,
            np.mean(per_trial, axis=0),
            "Hz",
            "spec",
            f"two noise-free impact trials ringing as e^(−ζωt) sin(ω_d t), ζ = {zeta}, f_n = {modes} Hz (x, y, z), "
            "split over four corner sensors yawed 0/90/180/270°; the value is the per-axis mean of §14.4's procedure applied to "
            "the known ringing (0.5 s window, no taper, zero-padding to 8× the length, parabola on the log-magnitudes), "
            f"close to the continuous peaks f_n √(1 − 2ζ²) = {analytic} Hz; tolerance 1e-4 Hz: the inputs are exact, only "
            "rounding differs",
            "Tricky: broad, noise-free peaks, where a taper or a shorter FFT moves the estimate.",
        )
    )
    return fx


# --- local dynamics (spec chapter 11) --------------------------------------------------------------------

INPUTS = ["qw", "qx", "qy", "qz", "px", "py", "pz", "vx", "vy", "vz", "ax", "ay", "az"]
IN_UNITS = ["1"] * 4 + ["m"] * 3 + ["m/s"] * 3 + ["m/s^2"] * 3
OUTPUTS = ["fx", "fy", "fz", "tx", "ty", "tz"]
OUT_UNITS = ["N"] * 3 + ["N*m"] * 3


def hw_model(variant: str) -> dict:
    """A Hammerstein–Wiener parameter file (spec §11.5) with nonlinear maps on the channels that move."""
    zero = {"b": [0.0, 0.0], "f": [0.0, 0.0], "nk": 0}
    linear = [[dict(zero) for _ in INPUTS] for _ in OUTPUTS]
    in_maps: list[dict] = [{"type": "unit_gain"} for _ in INPUTS]
    out_maps: list[dict] = [{"type": "unit_gain"} for _ in OUTPUTS]
    if variant == "a":
        in_maps[4] = {"type": "piecewise_linear", "breakpoints": [-0.05, 0.0, 0.02, 0.06], "values": [0.5, 0.0, 0.4, -0.2]}
        linear[0][4] = {"b": [1.5, -0.7], "f": [-0.6, 0.08], "nk": 0}
        linear[0][0] = {"b": [0.4, 0.0], "f": [0.0, 0.0], "nk": 0}
        out_maps[0] = {"type": "piecewise_linear", "breakpoints": [-1.0, 0.0, 0.5, 1.5], "values": [-0.5, 0.1, 0.2, 1.4]}
        linear[1][7] = {"b": [2.0, 1.0], "f": [-0.5, 0.0], "nk": 1}
        linear[3][6] = {"b": [0.01, 0.0], "f": [-0.9, 0.0], "nk": 0}
    elif variant == "c":  # every input kind reaches an output: orientation, position, velocity, acceleration
        in_maps[5] = {"type": "piecewise_linear", "breakpoints": [-0.03, 0.0, 0.03], "values": [-0.2, 0.0, 0.5]}
        in_maps[12] = {"type": "piecewise_linear", "breakpoints": [-1.0, 0.0, 1.0], "values": [-0.5, 0.0, 0.2]}
        linear[0][1] = {"b": [0.8, 0.0], "f": [-0.3, 0.0], "nk": 0}
        linear[0][10] = {"b": [0.05, 0.02], "f": [0.0, 0.0], "nk": 0}
        linear[1][5] = {"b": [1.0, -0.4], "f": [-0.5, 0.0], "nk": 0}
        linear[1][11] = {"b": [0.04, 0.0], "f": [0.0, 0.0], "nk": 0}
        linear[2][12] = {"b": [0.3, 0.0], "f": [-0.2, 0.0], "nk": 0}
        linear[2][8] = {"b": [5.0, 0.0], "f": [0.0, 0.0], "nk": 1}
        linear[5][2] = {"b": [0.01, 0.0], "f": [-0.4, 0.0], "nk": 0}
    else:
        in_maps[7] = {"type": "piecewise_linear", "breakpoints": [-0.05, 0.0, 0.05], "values": [0.2, 0.0, 0.3]}
        linear[2][7] = {"b": [0.5, 0.5], "f": [-0.2, 0.0], "nk": 0}
        linear[2][4] = {"b": [3.0, 0.0], "f": [0.0, 0.0], "nk": 0}
        linear[4][0] = {"b": [0.02, 0.0], "f": [-0.5, 0.0], "nk": 0}
    return {
        "format": "haptify-hw-model",
        "spec_version": SPEC_VERSION,
        "sample_rate_hz": 100.0,
        "inputs": [{"name": n, "unit": u} for n, u in zip(INPUTS, IN_UNITS)],
        "outputs": [{"name": n, "unit": u} for n, u in zip(OUTPUTS, OUT_UNITS)],
        "input_maps": in_maps,
        "output_maps": out_maps,
        "linear": linear,
        "quaternion_hemisphere": {"columns": [0, 1, 2, 3], "reference": [1.0, 0.0, 0.0, 0.0]},
    }


def pwl(m: dict, u: np.ndarray) -> np.ndarray:
    """Spec §11.3 step 2, written out: linear between breakpoints, the end segments extended."""
    if m["type"] == "unit_gain":
        return u
    x, v = np.asarray(m["breakpoints"]), np.asarray(m["values"])
    k = np.clip(np.searchsorted(x, u, side="right") - 1, 0, len(x) - 2)
    return v[k] + (u - x[k]) / (x[k + 1] - x[k]) * (v[k + 1] - v[k])


def hw_predict(model: dict, u: np.ndarray) -> np.ndarray:
    """Spec §11.3 applied to inputs u (N, 13): hemisphere rule, input maps, lfilter blocks from rest, output maps."""
    u = u.copy()
    hemi = model.get("quaternion_hemisphere")
    if hemi:
        cols = hemi["columns"]
        flip = u[:, cols] @ np.asarray(hemi["reference"]) < 0
        u[np.ix_(flip, cols)] *= -1
    w = np.column_stack([pwl(m, u[:, i]) for i, m in enumerate(model["input_maps"])])
    y = np.zeros((len(u), len(model["outputs"])))
    for j, row in enumerate(model["linear"]):
        x = np.zeros(len(u))
        for i, tf in enumerate(row):
            x = x + lfilter([0.0] * tf["nk"] + tf["b"], [1.0] + tf["f"], w[:, i])
        y[:, j] = pwl(model["output_maps"][j], x)
    return y


@dataclass
class LineMotion:
    """Straight-line motion at constant velocity with a fixed orientation: the §7.2 filters pass it unchanged
    (chord removal), so the model inputs on the 100 Hz grid are known exactly."""

    p0: np.ndarray
    v: np.ndarray
    q: np.ndarray
    f0: np.ndarray
    f1: np.ndarray

    def position(self, t: np.ndarray) -> np.ndarray:
        return self.p0 + np.outer(t, self.v)

    def force(self, t: np.ndarray) -> np.ndarray:
        """Measured hand force: linear in time (passes the zero-phase low-pass unchanged)."""
        return self.f0 + np.outer(t, self.f1)

    def inputs(self, t: np.ndarray) -> np.ndarray:
        n = len(t)
        return np.column_stack([np.tile(self.q, (n, 1)), self.position(t), np.tile(self.v, (n, 1)), np.zeros((n, 3))])


PREDICT_S = 25.0  # s, each trial of a prediction fixture


@dataclass
class Prediction:
    """A prediction fixture (spec §16.8.2): a training and a test trial on straight lines at constant velocity, and
    given parameter files. The test trial's motion is the training one moved by ``shift`` (m), turned by ``turn``
    = (axis, angle in rad) about a world axis, and its force offset by ``df0`` (N)."""

    name: str
    fmt: str
    rig_kind: str
    train: LineMotion
    shift: np.ndarray
    df0: np.ndarray
    desc: str
    models: tuple[str, ...] = ("a", "b")
    turn: tuple[tuple[float, float, float], float] = ((0.0, 0.0, 1.0), 0.0)
    rates: tuple[float, float, float] = (100.0, 100.0, 100.0)
    start_s: float = 0.0
    clock_offsets: dict[str, float] = field(default_factory=dict)
    how: str = ""
    test_listed_first: bool = False

    @property
    def test(self) -> LineMotion:
        axis, angle = self.turn
        q = quat_multiply(quat_from_axis_angle(np.asarray(axis, float), np.array(angle)), self.train.q) if angle else self.train.q
        return LineMotion(self.train.p0 + self.shift, self.train.v, q, self.train.f0 + self.df0, self.train.f1)


def prediction_expectations(model: dict, pr: Prediction) -> dict:
    """The known answers of a prediction fixture for the parameter file ``model``: spec §11.3 on both trials' inputs
    on the grid of §7.3 (from the streams' common start), §11.6 for the line: every test window's nearest training
    window is its twin, |Δp|/R_p + turn/R_θ away."""
    seg = int(round(param("dynamics", "segment_s") * 100))
    tg = pr.start_s + grid(PREDICT_S)
    train, test = pr.train, pr.test
    y_hat = hw_predict(model, train.inputs(tg))
    meas = np.column_stack([train.force(tg), np.zeros((len(tg), 3))])
    err = meas - y_hat
    rm = np.sqrt(np.mean(err**2, axis=0))
    y_test = hw_predict(model, test.inputs(tg))
    err_test = np.column_stack([test.force(tg), np.zeros((len(tg), 3))]) - y_test

    def seg_errors(e):
        nseg = len(tg) // seg
        return [float(np.mean(np.sqrt(np.mean(e[s * seg : (s + 1) * seg, :3] ** 2, axis=0)))) for s in range(nseg)]

    tr, te = seg_errors(err), seg_errors(err_test)
    d_test = float(np.linalg.norm(pr.shift) / param("dynamics", "R_p") + pr.turn[1] / math.radians(param("dynamics", "R_theta")))
    x = np.array([0.0] * len(tr) + [d_test] * len(te))
    yv = np.array(tr + te)
    slope, intercept = np.polyfit(x, yv, 1)
    return {"force": rm[:3], "torque": rm[3:], "line": [float(slope), float(intercept)], "distance": d_test}


def prediction_fixture(pr: Prediction) -> Fixture:
    """A prediction fixture (spec §16.8.2) with, per given parameter file, the cases of §11.3, §11.6 and §11.7."""
    R_p = param("dynamics", "R_p")
    R_theta = math.radians(param("dynamics", "R_theta"))

    def build(path: Path) -> None:
        rig = example_rig() if pr.rig_kind == "example" else rb.rotated_rig()
        w = manifest(f"conf-{pr.name}", rig, truth=rb.HandleTruth(force_noise=0.0, torque_noise=0.0, accel_noise=0.0))
        trials = (("local_dynamic-1", 1, pr.train), ("local_dynamic-2", 2, pr.test))
        for tid, rep, m in trials[::-1] if pr.test_listed_first else trials:
            handle_trial(
                w,
                tid,
                "local_dynamic",
                duration_s=PREDICT_S,
                position=m.position,
                quaternion=fixed(m.q),
                force_w=m.force,
                truth=rb.HandleTruth(force_noise=0.0, torque_noise=0.0, accel_noise=0.0),
                rates=pr.rates,
                fmt=pr.fmt,
                repetition=rep,
                start_s=pr.start_s,
                clock_offsets=pr.clock_offsets,
            )
        w.write(path)
        for variant in pr.models:
            (path / f"model-{variant}.json").write_text(json.dumps(hw_model(variant), indent=1) + "\n", encoding="utf-8")

    fx = Fixture(pr.name, build)
    short, desc = pr.name.removeprefix("dyn-"), pr.desc
    how = (
        "the handle moves on a straight line at constant velocity with a fixed orientation and the hand force is "
        "linear in time, so the §7.2 filters (chord removed) pass every signal unchanged and the model inputs on "
        "the 100 Hz grid are known exactly; the value is spec §11.3 applied to them (lfilter from rest, maps with "
        "linear extension) against the measured force" + pr.how
    )
    for variant in pr.models:
        e = prediction_expectations(hw_model(variant), pr)
        params = {"model": f"model-{variant}.json"}
        sfx = f"{short}.model-{variant}"
        away = f"{np.linalg.norm(pr.shift) / R_p:g}·R_p away" + (
            f" and turned by {pr.turn[1]} rad = {pr.turn[1] / R_theta:.4g}·R_θ" if pr.turn[1] else ""
        )
        fx.cases += [
            case(
                f"dynamics.force_rmse.{sfx}",
                "dynamics.force_rmse",
                "11.3",
                pr.name,
                e["force"],
                "N",
                "spec",
                how + f"; model file model-{variant}.json given in parameters.model",
                desc,
                parameters=params,
            ),
            case(
                f"dynamics.force_rmse_mean.{sfx}",
                "dynamics.force_rmse_mean",
                "11.7",
                pr.name,
                float(np.mean(e["force"])),
                "N",
                "spec",
                how,
                desc,
                parameters=params,
            ),
            case(
                f"dynamics.torque_rmse.{sfx}",
                "dynamics.torque_rmse",
                "11.3",
                pr.name,
                e["torque"],
                "N*m",
                "spec",
                how + "; the measured torque about the gimbal centre is zero",
                desc,
                parameters=params,
            ),
            case(
                f"dynamics.torque_rmse_mean.{sfx}",
                "dynamics.torque_rmse_mean",
                "11.7",
                pr.name,
                float(np.mean(e["torque"])),
                "N*m",
                "spec",
                how,
                desc,
                parameters=params,
            ),
            case(
                f"dynamics.error_vs_distance.{sfx}",
                "dynamics.error_vs_distance",
                "11.6",
                pr.name,
                e["line"],
                "N",
                "spec",
                how
                + f"; the test trial repeats the motion {away}, perpendicular to its velocity (every window's nearest training "
                f"window is its twin: distance {e['distance']:g}), training segments at distance 0; "
                "the least-squares line through (distance, mean per-axis RMS error) of the 5 s segments",
                desc,
                parameters=params,
            ),
        ]
    return fx


def dynamics_fixtures() -> list[Fixture]:
    R_p = param("dynamics", "R_p")

    q_tilt = quat_from_axis_angle(np.array([0.2, 1.0, 0.1]), np.array(0.6))
    turned_start, turn = 0.0037, 0.75
    variants = [
        Prediction(
            "dyn-predict",
            "parquet",
            "example",
            LineMotion(
                np.array([-0.04, 0.01, 0.15]),
                np.array([0.003, 0.0, 0.0]),
                np.array([1.0, 0.0, 0.0, 0.0]),
                np.array([0.2, -0.1, 0.3]),
                np.array([0.01, 0.004, 0.0]),
            ),
            np.array([0.0, 0.0, R_p]),
            np.array([0.5, 0.2, -0.1]),
            "Typical: a given model, a test trial one R_p away.",
        ),
        Prediction(
            "dyn-predict-hemisphere-csv",
            "csv",
            "rotated",
            LineMotion(
                np.array([0.05, -0.02, 0.12]),
                np.array([-0.002, 0.001, 0.0005]),
                -q_tilt,
                np.array([-0.3, 0.2, 0.1]),
                np.array([0.0, -0.01, 0.006]),
            ),
            0.5 * R_p * np.array([1.0, 2.0, 0.0]) / math.sqrt(5.0),
            np.array([0.1, 0.0, 0.2]),
            "Tricky: the motion-capture quaternion is stored as −q (hemisphere rule), rotated sensor frames, CSV.",
        ),
        Prediction(
            "dyn-predict-clock-csv",
            "csv",
            "rotated",
            LineMotion(
                np.array([0.02, 0.035, 0.13]),
                np.array([0.002, -0.0015, 0.001]),
                q_tilt,
                np.array([0.1, 0.3, -0.2]),
                np.array([0.008, 0.0, -0.005]),
            ),
            0.5 * R_p * np.array([0.6, 0.8, 0.0]),
            np.array([-0.2, 0.1, 0.05]),
            "Tricky: streams at 250, 400 and 120 Hz starting 3.7 ms into the session clock, motion capture and "
            "accelerometer shifted by clock-offset records, a test trial turned by 43°, a model that reads "
            "orientation, position beyond its map, velocity and the gravity-free acceleration.",
            models=("c",),
            turn=((0.3, -0.4, 0.87), turn),
            rates=(250.0, 400.0, 120.0),
            start_s=turned_start,
            clock_offsets={"handle_pose": 0.0213, "handle_accel": -0.0171},
            test_listed_first=True,
            how=(
                f"; the streams start at t = {turned_start} s (the grid of §7.3 starts there, not at a multiple of "
                "10 ms), handle_pose is stored 21.3 ms early and handle_accel 17.1 ms late with clock_offset records "
                "+0.0213 s and −0.0171 s (§2.8: added to t), and at 250/400/120 Hz the 100 Hz grid falls between "
                "samples (linear interpolation is exact on lines); the calibrated acceleration is zero (gravity, "
                "bias and the rotated accelerometer frame removed, §6.6) and model-c maps it; the test trial "
                "(repetition 2) is listed first in the manifest, the training trial is repetition 1 (§11.7)"
            ),
        ),
    ]
    out: list[Fixture] = [prediction_fixture(pr) for pr in variants]

    # Fitting quality (spec §11.4.5): data from a known linear law inside the model class, known noise.
    mass, damping, sigma = 0.15, 0.8, 0.01

    def fitdata(path: Path) -> None:
        rng = np.random.default_rng(SEED + 20)
        w = manifest("conf-dyn-fit", example_rig())
        t = clock(22.0, 1000.0)
        chirp = 2 * np.pi * (0.8 * t + 0.02 * t**2)
        dph = 2 * np.pi * (0.8 + 0.04 * t)
        amp, shift = 0.03 * np.array([1.0, 0.7, 0.5]), np.array([0.0, 1.1, 2.3])
        ph = chirp[:, None] + shift
        centre = np.array([0.0, 0.0, 0.15])
        pos = centre + amp * np.sin(ph)
        vel = amp * np.cos(ph) * dph[:, None]
        acc = -amp * np.sin(ph) * dph[:, None] ** 2 + amp * np.cos(ph) * 2 * np.pi * 0.04
        q = quat_from_axis_angle(np.tile(Z, (len(t), 1)), 0.3 * np.sin(2 * np.pi * 0.05 * t))
        force = -mass * acc - damping * vel + sigma * rng.standard_normal((len(t), 3))
        w.add_trial("local_dynamic-1", "local_dynamic", powered=False, repetition=1)
        wrench, accel = rb.raw_handle(
            QUIET, w.manifest["rig"], t, q, t, q, rng, hand_force_w=force, hand_torque_g_w=np.zeros_like(force), lin_acc_w=acc
        )
        w.add_stream("local_dynamic-1", "handle_wrench", wrench, rate_hz=1000.0)
        w.add_stream("local_dynamic-1", "handle_accel", accel, rate_hz=1000.0)
        k = slice(None, None, 10)
        w.add_stream(
            "local_dynamic-1",
            "handle_pose",
            {
                "t": t[k],
                "px": pos[k, 0],
                "py": pos[k, 1],
                "pz": pos[k, 2],
                "qw": q[k, 0],
                "qx": q[k, 1],
                "qy": q[k, 2],
                "qz": q[k, 3],
            },
            rate_hz=100.0,
        )
        w.write(path)

    fx = Fixture("dyn-fit-linear-law", fitdata)
    sigma_f = sigma * math.sqrt(
        lowpass_noise_ratio(param("signals", "wrench_cutoff_hz"), 1000.0, param("signals", "filter_order"))
    )
    law = (
        f"force on the hand F = −{mass} a − {damping} v + white noise σ = {sigma} N per axis at 1 kHz ({sigma_f:.4f} N "
        "after the 20 Hz zero-phase low-pass); the force amplitude is ~0.1 N. A linear law lies inside the model class, "
        "so a converged fit leaves only the noise and the pipeline's velocity and acceleration estimates: the quality "
        f"bound is the raw noise σ = {sigma} N (an unfitted or diverged model is ~10× above it; spec §11.4.5 judges "
        "quality, not parameters)"
    )
    fx.cases += [
        case(
            "dynamics.force_rmse.fit-quality",
            "dynamics.force_rmse",
            "11.4.5",
            fx.name,
            [0.0] * 3,
            "N",
            "generated",
            law,
            "Typical: H-W fitting on data from a known model with known noise.",
        ),
        case(
            "dynamics.force_rmse_mean.fit-quality",
            "dynamics.force_rmse_mean",
            "11.4.5",
            fx.name,
            0.0,
            "N",
            "generated",
            law,
            "Typical: fit quality.",
        ),
        case(
            "dynamics.torque_rmse.fit-quality",
            "dynamics.torque_rmse",
            "11.4.5",
            fx.name,
            [0.0, 0.0, 0.0],
            "N*m",
            "generated",
            "the law applies no torque about the gimbal centre and the torque channel has no noise: a fitted "
            "model predicts (nearly) zero torque",
            "Edge: a silent output channel.",
            level="SHOULD",
        ),
        case(
            "dynamics.torque_rmse_mean.fit-quality",
            "dynamics.torque_rmse_mean",
            "11.4.5",
            fx.name,
            0.0,
            "N*m",
            "generated",
            "the mean of the three torque RMS errors of dynamics.torque_rmse.fit-quality: no torque about the "
            "gimbal centre, no torque noise, so a fitted model predicts (nearly) zero torque",
            "Edge.",
            level="SHOULD",
        ),
    ]
    out.append(fx)
    return out


# --- validate cases from fixtures/invalid and fixtures/valid --------------------------------------------------


def validate_cases(fixtures_root: Path) -> list[dict]:
    cases = []
    for group in ("valid", "invalid"):
        for sidecar in sorted((fixtures_root / group).glob("*.expected.json")):
            name = sidecar.name.removesuffix(".expected.json")
            meta = json.loads(sidecar.read_text(encoding="utf-8"))
            codes = sorted(meta.get("codes", []))
            accepted = meta.get("exit_code", 1) == 0
            expected: dict[str, Any] = {}
            if codes:
                expected["codes"] = codes
            if accepted:
                expected["valid"] = True
            section = "4" if group == "invalid" else "2"
            cases.append(
                {
                    "id": f"validate.{group}.{name}",
                    "metric": "validate",
                    "spec_section": section,
                    "level": "MUST" if (not accepted or group == "valid") else "SHOULD",
                    "fixture": f"{group}/{name}",
                    "parameters": {},
                    "expected": expected,
                    "tolerance": None,
                    "provenance": {
                        "kind": "spec",
                        "note": f"built by tools/haptify_tools/build_invalid_fixtures.py with "
                        f"one known defect; the codes are the sidecar {group}/{sidecar.name}",
                    },
                    "spec_versions": [SPEC_VERSION],
                    "description": meta.get("description", name),
                }
            )
    return cases


# --- building and checking ------------------------------------------------------------------------------------

FAMILIES: dict[str, Callable[[], list[Fixture]]] = {
    "workspace": workspace_fixtures,
    "free_space": free_space_fixtures,
    "vibration": vibration_fixtures,
    "surface": surface_fixtures,
    "stiffness": stiffness_fixtures,
    "rig": rig_fixtures,
    "dynamics": dynamics_fixtures,
    "uncertainty": uncertainty_fixtures,
}
FAMILY_TEXT = {
    "workspace": "Workspace volumes (spec chapter 8): analytic shapes sampled on their boundary and the DH model's Pappus volume.",
    "free_space": "Free-space forces and speeds (spec chapter 9): constant and analytic forces on the hand, circles and spins.",
    "vibration": "Free-space vibrations (spec chapter 10): tones of known amplitude and frequency through the specified high-pass.",
    "surface": "Frictionless surface (spec chapter 12): planar forces of known magnitude during rendered contact.",
    "stiffness": "Stiffness (spec chapter 13): linear springs with saturation and giving way, pressed five times.",
    "rig": "Rig checks (spec chapter 14): damped plate modes, offset COP markers, known recorder delays and sensor noise.",
    "dynamics": "Local dynamics (spec chapter 11): H-W prediction from a given parameter file, and fitting quality on a known law.",
    "uncertainty": "Measurement uncertainty (spec chapter 19): Type A, coverage factor and expanded uncertainty of repetitions with known values.",
}


def all_fixtures() -> dict[str, list[Fixture]]:
    return {fam: fn() for fam, fn in FAMILIES.items()}


def with_requirements(c: dict) -> dict:
    """The case with the ids of the requirements it tests after its level (spec §16.7)."""
    ids = requirements_for_case(c["metric"], c["expected"].get("codes"), c.get("quantity", "value"))
    out = {}
    for key, value in c.items():
        out[key] = value
        if key == "level":
            out["requirements"] = ids
    return out


def case_documents(fixtures: dict[str, list[Fixture]], fixtures_root: Path) -> dict[str, str]:
    """File name → text of every case file."""
    docs: dict[str, dict[str, Any]] = {}
    for fam, fxs in fixtures.items():
        docs[f"{fam}.json"] = {"description": FAMILY_TEXT[fam], "cases": [c for fx in fxs for c in fx.cases]}
    docs["validate.json"] = {
        "description": "Validation (spec chapters 2–4): every invalid session of fixtures/invalid must be "
        "rejected (or warned about) with its codes; every fixture of fixtures/valid must be accepted.",
        "cases": validate_cases(fixtures_root),
    }
    for doc in docs.values():
        doc["cases"] = [with_requirements(c) for c in doc["cases"]]
        for c in doc["cases"]:
            if c.get("tolerance") is None:
                c.pop("tolerance", None)
    return {name: json.dumps(doc, indent=2, ensure_ascii=False) + "\n" for name, doc in docs.items()}


def write_digests(root: Path, names: list[str]) -> None:
    """``fixtures/conformance/digests.json``: the logical digest of every fixture, for the suite linter (spec §16.7)."""
    digests = {n: snapshot_digest(root / n) for n in sorted(names)}
    (root / DIGESTS).write_text(
        json.dumps(
            {
                "$comment": "written by haptify_tools.build_conformance_fixtures; checked by haptify-conform --lint",
                "digests": digests,
            },
            indent=1,
        )
        + "\n",
        encoding="utf-8",
    )


def build_fixture(fx: Fixture, target: Path) -> None:
    if target.exists():
        shutil.rmtree(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fx.build(target)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fixtures", type=Path, default=REPO / "fixtures", help="fixtures folder (default: the repository's)")
    parser.add_argument("--cases", type=Path, default=CASES_DIR, help="case folder (default: conformance/cases)")
    parser.add_argument("--check", action="store_true", help="only check that the committed fixtures and cases are current")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="rebuild only these fixtures (case files are always written)")
    args = parser.parse_args(argv)
    fixtures = all_fixtures()
    flat = {fx.name: fx for fxs in fixtures.values() for fx in fxs}
    unknown = sorted(set(args.only or ()) - set(flat))
    if unknown:
        parser.error(f"unknown fixture(s) {unknown}; known: {sorted(flat)}")
    docs = case_documents(fixtures, args.fixtures)
    root = args.fixtures / FIXTURE_DIR
    if args.check:
        stale = []
        with tempfile.TemporaryDirectory(prefix="haptify-conformance-") as tmp:
            for name, fx in flat.items():
                fresh = Path(tmp) / name
                build_fixture(fx, fresh)
                if not (root / name).is_dir() or not trees_agree(fresh, root / name):
                    stale.append(f"fixture {FIXTURE_DIR}/{name}")
        extra = sorted(p.name for p in root.iterdir() if p.is_dir() and p.name not in flat) if root.is_dir() else []
        stale += [f"fixture {FIXTURE_DIR}/{n} is not built by this script" for n in extra]
        recorded = json.loads((root / DIGESTS).read_text(encoding="utf-8"))["digests"] if (root / DIGESTS).is_file() else {}
        if recorded != {n: snapshot_digest(root / n) for n in sorted(flat) if (root / n).is_dir()}:
            stale.append(f"{FIXTURE_DIR}/{DIGESTS}")
        for fname, text in docs.items():
            path = args.cases / fname
            if not path.is_file() or not values_agree(json.loads(path.read_text(encoding="utf-8")), json.loads(text)):
                stale.append(f"case file {fname}")
        for line in stale:
            print(f"stale: {line}")
        print(f"conformance fixtures and cases: {'stale' if stale else 'current'} ({len(flat)} fixtures, {len(docs)} case files)")
        return 1 if stale else 0
    for name in args.only or flat:
        build_fixture(flat[name], root / name)
    write_digests(root, [n for n in flat if (root / n).is_dir()])
    args.cases.mkdir(parents=True, exist_ok=True)
    for fname, text in docs.items():
        (args.cases / fname).write_text(text, encoding="utf-8")
    print(f"built {len(args.only or flat)} fixture(s) under {root} and {len(docs)} case files under {args.cases}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
