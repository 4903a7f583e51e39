"""Shared truth of the conformance fixtures (spec chapter 16): the seed, the quiet handle, the rotated rig, the
session manifest, analytic motions (clocks, fixed poses, spins, circles), the handle trial and active-session
writers, and the closed-form gains of the zero-phase low-pass of §7.2 on the 100 Hz grid."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.signal import butter, sosfiltfilt

from haptify.formats.conventions import quat_from_axis_angle, quat_multiply
from haptify.formats.storage import SessionWriter
from haptify.processing import preprocessing
from haptify_tools import rig_builders as rb
from haptify_tools.example_session import IDENTITY, TOUCH_DEVICE, example_rig

SEED = 20261122
Z = np.array([0.0, 0.0, 1.0])
Fn = Callable[[np.ndarray], np.ndarray]


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
    fc = min(fc, preprocessing.PARAMETERS.max_cutoff_fraction * fs / 2.0)
    omega = math.tan(math.pi * f / fs) / math.tan(math.pi * fc / fs)
    return 1.0 / (1.0 + omega ** (2 * preprocessing.PARAMETERS.filter_order))


def pair_step(t: np.ndarray, fs: float, fc: float | None = None) -> np.ndarray:
    """Response at times ``t`` (s) of the zero-phase Butterworth low-pass of spec §7.2 (order ``filter_order``, cut-off
    ``fc``, default ``wrench_cutoff_hz``, at rate ``fs``) to a unit step whose first sample of 1 is at t = 0: it rises
    0 → 1 symmetrically about the step, ringing on both sides. scipy's butter + sosfiltfilt, as §7.2 names them."""
    fc = float(preprocessing.PARAMETERS.wrench_cutoff_hz if fc is None else fc)
    k = np.arange(-4 * int(fs), 4 * int(fs) + 1)
    y = sosfiltfilt(butter(preprocessing.PARAMETERS.filter_order, fc, fs=fs, output="sos"), (k >= 0).astype(float))
    return np.interp(np.asarray(t, float) * fs, k, y)


def lowpass_noise_ratio(fc: float, fs: float, order: int) -> float:
    """Variance gain of white noise through the zero-phase Butterworth low-pass of spec §7.2:
    (2/fs)·∫₀^{fs/2} |H(f)|⁴ df with |H|² = 1 / (1 + Ω^(2N)), Ω = tan(πf/fs) / tan(πfc/fs) (midpoint rule)."""
    f = (np.arange(200_000) + 0.5) / 200_000 * fs / 2
    omega = np.tan(np.pi * f / fs) / np.tan(np.pi * fc / fs)
    return float(np.mean((1.0 / (1.0 + omega ** (2 * order))) ** 2))
