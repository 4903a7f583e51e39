"""The hand path that drives the twin (discrepancy README §1, the hand path).

The twin is driven along the measured path, and its friction turns every error of that path's velocity
into a force error: on simulated Touch sessions the twin that generated the data, driven along the
motion-capture path low-passed at 8 Hz, still left 0.02 N in a figure eight and 0.13 N in the stiffness
presses; along the true path it leaves 0.003 N and 0.012 N. Motion capture is accurate where the hand
moves slowly and noisy where it moves fast (white noise, differentiated); the handle accelerometer is
the other way round (its small errors of orientation and bias grow when integrated twice). The path is
therefore their complementary blend around :data:`PATH_CROSSOVER_HZ`:

    p = x + S(p_mocap − x) + LP(p_mocap − x − S(p_mocap − x)),   x = ∬ a_W dt,

with LP the zero-phase Butterworth of spec §7.2 at the crossover: below it ``p`` follows motion capture, above it
the accelerometer's double integral ``x`` — taken at the sensor's own rate (at the 100 Hz grid the trapezoid
rule's error, (ωh)²/6 of the amplitude, is 1 % at 4 Hz: 0.3 mm of a local-dynamic stroke) — whose drift
(the unknown start position and velocity, the bias the calibration left, integrated orientation errors) is
fitted to motion capture by ``S``, a least-squares cubic spline with a knot every :data:`SLOW_KNOT_S`. The
low-pass then sees no slow difference and runs with mirrored ends (:func:`smooth`): the spec's low-pass holds
its ends at the first and last samples, and their capture noise became a jump of the path's acceleration — a
0.6–0.9 N force spike in the first and last 0.2 s of the simulated figure eight. ``a_W`` is the calibrated
reading (spec §6.6) turned to W with the orientation smoothed the same way at :data:`ORIENTATION_CUTOFF_HZ` —
gravity leaks into ``a_W`` through every orientation error, and the raw mocap orientation is noisy (0.3° on the
simulated rig; a plain low-pass, held at a noisy last sample, turned 1.5° off in the last 0.2 s) — minus the
accelerometer's lever-arm acceleration about the gimbal centre. The accelerometer clips at its range (the
simulated rig's ±40 m/s² in the fastest local-dynamic strokes): its double integral then misses the clipped
acceleration, so the rows within :data:`CLIP_MARGIN_S` of a reading at the declared range are not compared
(the fastest strokes had 2–14 mm/s of velocity error). Over a motion-capture gap the blend bridges the slow
difference ``p_mocap − x`` by its spline, not the capture, which moves fast (a 0.3 s gap in local-dynamic strokes,
bridged linearly, was 26 mm off); the orientation is bridged linearly, so rows within :data:`GAP_MARGIN_S` of a gap
are not compared either (``unreliable``). A trial without a ``handle_accel`` stream,
or with more than :data:`MAX_CLIPPED_SHARE` of its rows near clipped readings, falls back to motion capture alone,
smoothed at :data:`POSE_CUTOFF_HZ`. On the same sessions the blend leaves 0.004 N (figure eight), 0.02–0.04 N
(stiffness), 0.06 N (local dynamic) and 0.008–0.018 N (free space, against 0.017–0.022 N); holding the drives at
rest in the replay (:mod:`.drive_rest`) then brings stiffness to 0.0035–0.019 N and local dynamic to 0.007–0.009 N.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.interpolate import make_lsq_spline
from scipy.signal import butter, sosfiltfilt

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.conventions import quat_normalize, quat_rotate
from haptify.formats.storage import SessionFolder
from haptify.pipeline.compute import ComputeContext
from haptify.processing import calibration as cal_mod
from haptify.processing import preprocessing
from haptify.processing.preprocessing import effective_cutoff, interp_columns, lowpass, nominal_rate
from haptify.processing.signals import ACCEL_COLUMNS, HandleSignals
from haptify_tools.discrepancy.model import PathSource

PATH_CROSSOVER_HZ = 1.5  # motion capture below, the accelerometer above (the true twin's floor is lowest
# for 1–1.5 Hz on figure-eight, free-space, stiffness and local-dynamic trials)
ORIENTATION_CUTOFF_HZ = 1.0  # the hand's orientation wanders slowly (under 16°/s in free space, paper §V-B);
# its noise becomes gimbal-friction noise and, through gravity, acceleration noise
SLOW_KNOT_S = 1.0  # knot spacing of the splines that carry slow motion past the low-passes' edges
RANGE_FRACTION = 0.999  # a reading at 99.9 % of the declared range is at the range (quantised clipping)
CLIP_MARGIN_S = 0.5  # rows this close to a clipped reading are not compared (the clip's missing
# acceleration stays in the integrated velocity until the blend's low-pass catches up)
GAP_MARGIN_S = 0.5  # rows this close to a capture gap are not compared (the orientation bridged across
# the gap turns gravity into the accelerometer's path; the blend spreads it ±0.5 s)
GAP_WEIGHT = 1e-6  # weight of a bridged row in the slow spline (it keeps the fit defined over long gaps)
MAX_CLIPPED_SHARE = 0.5  # a trial with more rows near clipped readings falls back to motion capture
POSE_CUTOFF_HZ = 8.0  # without an accelerometer: above the local-dynamic 4 Hz oscillations (paper §V-C)
#: slower protocols get a lower cut-off: free-space wandering stays under 0.16 m/s (paper §V-B)
POSE_CUTOFF_BY_PROTOCOL_HZ = {"free_space": 4.0}
FROM_BOTH: Final = "motion capture + accelerometer"
FROM_MOCAP: Final = "motion capture"


@dataclass
class HandPath:
    """A trial's hand path on its residual grid: gimbal-centre position (m, W), orientation (wxyz, body →
    world), where the position came from (:data:`FROM_BOTH` or :data:`FROM_MOCAP`) and ``unreliable``, the rows
    whose path is bridged or disturbed nearby: within :data:`CLIP_MARGIN_S` of an accelerometer reading at its
    range, within :data:`GAP_MARGIN_S` of a row without motion capture."""

    position: np.ndarray
    quaternion: np.ndarray
    source: PathSource
    unreliable: np.ndarray


def fill_gaps(t: np.ndarray, x: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """``x (N, k)`` with the rows where ``ok`` is False linearly interpolated in ``t`` from the usable rows."""
    out = np.array(x, dtype=float)
    for k in range(out.shape[1]):
        out[:, k] = np.interp(t, t[ok], out[ok, k])
    return out


def smooth_orientation(t: np.ndarray, quaternion: np.ndarray, ok: np.ndarray, rate_hz: float) -> np.ndarray:
    """Unit quaternions ``(N, 4)``: gaps bridged, one hemisphere, ``S(q) + LP(q − S(q))`` with LP at
    :data:`ORIENTATION_CUTOFF_HZ` (module docstring)."""
    q = fill_gaps(t, quaternion, ok)
    q = q * np.where(np.sum(q * q[:1], axis=1) < 0, -1.0, 1.0)[:, None]
    q = smooth(t, rate_hz, q, ORIENTATION_CUTOFF_HZ)
    return q / np.linalg.norm(q, axis=1)[:, None]


def second_derivative(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Central second differences of ``x (N, k)`` in ``t`` (s), one-sided at the ends."""
    return np.gradient(np.gradient(x, t, axis=0), t, axis=0)


def near(t: np.ndarray, events: np.ndarray, margin_s: float) -> np.ndarray:
    """Rows of ``t`` within ``margin_s`` (s) of any time in the sorted ``events``."""
    if not len(events):
        return np.zeros(len(t), bool)
    k = np.clip(np.searchsorted(events, t), 1, len(events))
    nearest = np.minimum(np.abs(t - events[k - 1]), np.abs(events[np.minimum(k, len(events) - 1)] - t))
    return nearest <= margin_s


def accelerometer_path(
    session: SessionFolder, ctx: ComputeContext, trial_id: str, t: np.ndarray, quaternion: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """The gimbal centre's path ∬ a_W dt ``(N, 3)`` at times ``t`` (m, W; from rest at the origin) from the handle
    accelerometer, integrated at the sensor's own rate, and the rows within :data:`CLIP_MARGIN_S` of a reading at
    the sensor's declared range (module docstring); ``quaternion`` the orientation at ``t``. None without a
    ``handle_accel`` stream.
    """
    if session.stream(trial_id, "handle_accel") is None:
        return None
    stream = session.read(trial_id, "handle_accel")
    reading = stream[ACCEL_COLUMNS].to_numpy()
    ts = stream["t"].to_numpy()
    handle = session.manifest.rig.handle
    if handle is None:
        raise fail(
            Code.RIG_PART_MISSING,
            "a handle_accel stream needs rig.handle (the accelerometer)",
            file="session.json",
            pointer="/rig/handle",
        )
    sensor = handle.accelerometer
    near_clip = np.zeros(len(t), bool)
    if sensor.range is not None and sensor.range.accel_m_per_s2 is not None:
        at_range = np.any(np.abs(reading) >= RANGE_FRACTION * np.asarray(sensor.range.accel_m_per_s2, float), axis=1)
        near_clip = near(t, ts[at_range], CLIP_MARGIN_S)
    rate = nominal_rate(ts)
    inside = (ts >= t[0]) & (ts <= t[-1])
    ts = ts[inside]
    raw = lowpass(reading, rate, preprocessing.PARAMETERS.accel_cutoff_hz)[inside]
    q = quat_normalize(interp_columns(t, quaternion, ts))
    pose = cal_mod.sensor_pose(session, "accelerometer")
    lever = quat_rotate(q, np.broadcast_to(np.asarray(pose.position, float), (len(ts), 3)))
    a_gimbal = cal_mod.compensate_accel(raw, q, cal_mod.handle_calibration(ctx), pose) - second_derivative(lever, ts)
    return interp_columns(ts, double_integral(ts, a_gimbal), t), near_clip


def double_integral(t: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
    """∬ a dt ``(N, 3)`` from zero position and velocity at ``t[0]`` (trapezoid rule), m."""
    return cumulative_trapezoid(cumulative_trapezoid(acceleration, t, axis=0, initial=0), t, axis=0, initial=0)


def slow_part(t: np.ndarray, x: np.ndarray, ok: np.ndarray | None = None) -> np.ndarray:
    """The least-squares cubic spline of ``x (N, k)`` in ``t`` with a knot every :data:`SLOW_KNOT_S` (module docstring);
    rows where ``ok`` is False (bridged gaps) weigh :data:`GAP_WEIGHT` and steer it only where no usable row is near."""
    inner = np.arange(t[0] + SLOW_KNOT_S, t[-1] - 0.5 * SLOW_KNOT_S, SLOW_KNOT_S)
    knots = np.r_[[t[0]] * 4, inner, [t[-1]] * 4]
    w = None if ok is None else np.where(ok, 1.0, GAP_WEIGHT)
    return make_lsq_spline(t, x, knots, k=3, w=w)(t)


def smooth(t: np.ndarray, rate_hz: float, x: np.ndarray, cutoff_hz: float, ok: np.ndarray | None = None) -> np.ndarray:
    """``S(x) + LP(x − S(x))``: the slow part by :func:`slow_part`, the rest low-passed at ``cutoff_hz`` (the zero-phase
    Butterworth of spec §7.2) with mirrored ends — unlike the spec's low-pass, not held at the first and last samples,
    whose noise would otherwise become a jump of the path's acceleration at the trial's ends (module docstring).
    With ``ok``, the rows where it is False are gaps: bridged by the slow part alone."""
    if ok is not None:
        x = fill_gaps(t, x, ok)
    slow = slow_part(t, x, ok)
    rest = x - slow if ok is None else np.where(ok[:, None], x - slow, 0.0)
    sos = butter(preprocessing.PARAMETERS.filter_order, effective_cutoff(cutoff_hz, rate_hz), fs=rate_hz, output="sos")
    return slow + sosfiltfilt(sos, rest, axis=0, padtype="even", padlen=min(len(x) - 1, int(4 * rate_hz / cutoff_hz)))


def blend(t: np.ndarray, rate_hz: float, mocap_position: np.ndarray, accel_path: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Motion capture below :data:`PATH_CROSSOVER_HZ`, the accelerometer's path ``x`` above (m; both at times ``t``
    on one grid at ``rate_hz``; module docstring): ``x + smooth(p_mocap − x)``, the difference — not the capture,
    which moves fast — bridged by its slow part over the rows where ``ok`` is False (motion capture's gaps)."""
    return accel_path + smooth(t, rate_hz, mocap_position - accel_path, PATH_CROSSOVER_HZ, ok)


def hand_path(session: SessionFolder, ctx: ComputeContext, hs: HandleSignals, ok: np.ndarray, protocol: str) -> HandPath:
    """The path that drives the twin for one trial, on the handle signals' grid (module docstring).

    ``hs``: the trial's calibrated handle signals (spec §7.5); ``ok``: their usable rows (at least two).
    """
    quaternion = smooth_orientation(hs.t, hs.quaternion, ok, hs.rate_hz)
    accel = accelerometer_path(session, ctx, hs.trial_id, hs.t, quaternion)
    near_gap = near(hs.t, hs.t[~ok], GAP_MARGIN_S)
    if accel is None or np.mean(accel[1]) > MAX_CLIPPED_SHARE:
        cutoff = POSE_CUTOFF_BY_PROTOCOL_HZ.get(protocol, POSE_CUTOFF_HZ)
        mocap = fill_gaps(hs.t, hs.position, ok)
        return HandPath(smooth(hs.t, hs.rate_hz, mocap, cutoff), quaternion, FROM_MOCAP, near_gap)
    return HandPath(blend(hs.t, hs.rate_hz, hs.position, accel[0], ok), quaternion, FROM_BOTH, accel[1] | near_gap)
