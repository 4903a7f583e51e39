"""Common resampling and filtering, and motion capture on a grid (spec §7.1–7.4).

Rules (parameters in ``schemas/<v>/metrics/signals.json``):

- Every low-pass is a Butterworth of ``filter_order`` run forward and backward (``scipy.signal.sosfiltfilt``,
  odd padding): zero phase. A cut-off is lowered to ``max_cutoff_fraction`` of the Nyquist frequency of
  the signal and of the target grid when it would exceed it.
- Raw sensor streams (never NaN) are low-passed at their native rate, then linearly interpolated onto the
  grid.
- Motion capture: occlusion gaps up to ``max_gap_s`` are bridged (position linear, orientation slerp);
  longer gaps split the data into segments that are processed separately and never interpolated across;
  segments shorter than ``min_segment_s`` are dropped. Position is low-passed per segment and
  differentiated by central differences; angular velocity comes from central relative rotations and is
  low-passed at its own, lower cut-off; orientation itself is not filtered. Resampling: linear, quaternions by slerp.

The calibrated handle signals built on these (§7.5) are :mod:`haptify.processing.signals`; the handle calibration
(chapter 6) uses these too, so this module depends on neither.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from scipy.signal import butter, sosfiltfilt

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.conventions import quat_conjugate, quat_multiply, quat_normalize, quat_slerp
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters
from haptify.processing.caching import cached, session_of

FAMILY = "signals"
POSE_COLUMNS = ["px", "py", "pz", "qw", "qx", "qy", "qz"]


class SignalsParameters(FamilyParameters):
    """The parameters of ``metrics/signals.json`` (spec chapter 7), in the units its definition file states."""

    rate_hz: float
    filter_order: int
    wrench_cutoff_hz: float
    accel_cutoff_hz: float
    mocap_cutoff_hz: float
    angular_velocity_cutoff_hz: float
    max_cutoff_fraction: float
    max_gap_s: float
    min_segment_s: float


#: The signals family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = load_parameters(FAMILY, SignalsParameters)


# --- primitives (spec §7.2) ----------------------------------------------------------------------


def nominal_rate(t: np.ndarray) -> float:
    """Mean sample rate of a time column, Hz: ``(n − 1) / (t_last − t_first)`` (spec §2.6)."""
    t = np.asarray(t, float)
    return float((len(t) - 1) / (t[-1] - t[0])) if len(t) > 1 and t[-1] > t[0] else float("inf")


def uniform_grid(t0: float, t1: float, rate_hz: float) -> np.ndarray:
    """The grid ``t0 + k / rate_hz`` for k = 0 … ⌊(t1 − t0)·rate_hz⌋ (s; spec §7.3)."""
    if not t1 >= t0:
        return np.empty(0)
    n = int(np.floor((t1 - t0) * rate_hz + 1e-9)) + 1
    return t0 + np.arange(n) / rate_hz


def effective_cutoff(cutoff_hz: float, *rates_hz: float) -> float:
    """``cutoff_hz`` lowered to ``max_cutoff_fraction`` of the lowest Nyquist frequency among ``rates_hz`` (Hz).
    Spec §7.2."""
    frac = PARAMETERS.max_cutoff_fraction
    return float(min([cutoff_hz] + [frac * r / 2.0 for r in rates_hz if np.isfinite(r)]))


def lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float, *, order: int | None = None) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 (spec §7.2).

    ``x (N, ...)`` sampled at ``rate_hz``; ``cutoff_hz`` is the −3 dB frequency of one pass (the
    forward–backward pair is −6 dB there). The cut-off is first limited by :func:`effective_cutoff`.
    The chord from the first to the last sample is subtracted before filtering and added back after,
    so straight lines pass unchanged and the ends start at zero (no edge transient from a slope);
    then odd padding of ``min(3·(2·sections + 1), N − 1)`` samples at each end.

    The work runs with time on the last axis (a view: the columns of a table's ``to_numpy()`` are
    contiguous), where scipy filters each signal in place without transposing copies; the result is
    the same array of numbers, returned as ``(N, ...)``.
    """
    x = np.asarray(x, float)
    if len(x) < 2:  # nothing to filter; also no rate (nominal_rate of one sample is inf)
        return x.copy()
    order = PARAMETERS.filter_order if order is None else order
    sos = butter_lowpass(order, effective_cutoff(cutoff_hz, rate_hz), rate_hz)
    padlen = min(3 * (2 * len(sos) + 1), len(x) - 1)
    xt = np.moveaxis(x, 0, -1)
    chord = xt[..., :1] + np.linspace(0.0, 1.0, len(x)) * (xt[..., -1:] - xt[..., :1])
    out: np.ndarray = sosfiltfilt(sos, xt - chord, axis=-1, padtype="odd", padlen=padlen)
    out += chord
    return np.moveaxis(out, -1, 0)


def butter_lowpass(order: int, cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """Second-order sections (a fresh array) of the Butterworth low-pass of ``order`` with its −3 dB point
    at ``cutoff_hz`` for ``rate_hz`` (Hz; spec §7.2); the design is made once per distinct triple."""
    return _butter_lowpass(order, cutoff_hz, rate_hz).copy()


@lru_cache(maxsize=256)
def _butter_lowpass(order: int, cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """The sections of :func:`butter_lowpass`, shared between calls, so never modified."""
    return butter(order, cutoff_hz, btype="low", fs=rate_hz, output="sos")


def table_columns(frame: Any, names: list[str]) -> np.ndarray:
    """The columns ``names`` of a stream's table as one ``(N, k)`` array, column-major as
    ``frame[names].to_numpy()`` gives them, without pandas' cost of selecting columns (spec §7.2 works on
    these arrays): a view of the table's values when the columns are consecutive in it, else a copy.
    Raises KeyError for a name the table does not have."""
    at = [int(frame.columns.get_loc(name)) for name in names]
    values = frame.to_numpy()
    if at and at == list(range(at[0], at[0] + len(at))):
        out: np.ndarray = values[:, at[0] : at[0] + len(at)]
        return out
    return np.asarray(values.T[at].T)


def interp_columns(t_src: np.ndarray, x_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Linear interpolation of every column of ``x_src (N, k)`` at ``t_dst`` (values at the ends are held).
    Spec §7.2."""
    x_src = np.asarray(x_src, float)
    if x_src.ndim == 1:
        out: np.ndarray = np.interp(t_dst, t_src, x_src)
        return out
    return np.column_stack([np.interp(t_dst, t_src, x_src[:, j]) for j in range(x_src.shape[1])])


def lowpass_resample(t_src: np.ndarray, x_src: np.ndarray, t_dst: np.ndarray, cutoff_hz: float) -> np.ndarray:
    """Low-pass a gap-free stream at its native rate, then interpolate it linearly at ``t_dst`` (spec §7.2).

    The cut-off is limited by the Nyquist frequency of the stream and of the target grid.
    """
    rate_src = nominal_rate(t_src)
    rate_dst = nominal_rate(t_dst) if len(t_dst) > 1 else float("inf")
    fc = effective_cutoff(cutoff_hz, rate_src, rate_dst)
    return interp_columns(t_src, lowpass(x_src, rate_src, fc), t_dst)


def quat_log(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (rad) of unit quaternions ``(..., 4)``: angle·axis, angle in [0, π].
    ``log`` of spec §7.4 step 4."""
    q = quat_normalize(q)
    q = np.where(q[..., :1] < 0, -q, q)
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    scale = np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 2.0 / np.maximum(q[..., :1], 1e-300))
    out: np.ndarray = v * scale
    return out


def angular_velocity(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """World-frame angular velocity (rad/s) of body→world quaternions ``q (N, 4)`` at times ``t`` (spec §7.4).

    Central relative rotation ``log(q_{k+1} ⊗ q_{k−1}*) / (t_{k+1} − t_{k−1})`` inside, one-sided at the
    ends: exact for rotation at a constant angular velocity.
    """
    q = np.asarray(q, float)
    t = np.asarray(t, float)
    n = len(q)
    if n < 2:
        return np.zeros((n, 3))
    conj = quat_conjugate(q)
    lo = np.r_[0, np.arange(n - 2), n - 2]
    hi = np.r_[1, np.arange(2, n), n - 1]
    rel = quat_multiply(q[hi], conj[lo])
    out: np.ndarray = quat_log(rel) / (t[hi] - t[lo])[:, None]
    return out


# --- motion capture (spec §7.4) --------------------------------------------------------------------


@dataclass
class Kinematics:
    """Handle motion in W at times ``t`` (s): position (m), unit quaternion body → world, velocity (m/s),
    angular velocity (rad/s, world frame). NaN rows where the data are not usable (spec §7.4)."""

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray


@dataclass
class MocapTrack(Kinematics):
    """Processed motion capture at its native samples: NaN (and ``segment`` −1) where unusable.
    Spec §7.4 steps 1–4."""

    segment: np.ndarray  # segment index per sample, −1 outside every usable segment

    @property
    def valid(self) -> np.ndarray:
        return self.segment >= 0


def bridge_gaps(
    t: np.ndarray, position: np.ndarray, quaternion: np.ndarray, max_gap_s: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fill occlusion gaps no longer than ``max_gap_s`` (spec §7.4).

    A gap is a run of samples with any NaN between valid samples i and j; it is bridged when
    ``t_j − t_i ≤ max_gap_s + Δ`` (Δ the median sample interval): position linearly, orientation by
    slerp. Returns the filled position, quaternion and the validity mask after bridging.
    """
    max_gap_s = PARAMETERS.max_gap_s if max_gap_s is None else max_gap_s
    t = np.asarray(t, float)
    pos = np.array(position, float)
    quat = np.array(quaternion, float)
    ok = np.all(np.isfinite(pos), axis=1) & np.all(np.isfinite(quat), axis=1)
    idx = np.flatnonzero(ok)
    if len(idx) < 2:
        return pos, quat, ok
    dt = float(np.median(np.diff(t)))
    gaps = np.flatnonzero(np.diff(idx) > 1)  # valid samples idx[g], idx[g + 1] with missing ones between
    for i, j in zip(idx[gaps], idx[gaps + 1]):
        if t[j] - t[i] <= max_gap_s + dt + 1e-12:
            mid = np.arange(i + 1, j)
            s = (t[mid] - t[i]) / (t[j] - t[i])
            pos[mid] = pos[i] + s[:, None] * (pos[j] - pos[i])
            quat[mid] = quat_slerp(np.broadcast_to(quat[i], (len(mid), 4)), np.broadcast_to(quat[j], (len(mid), 4)), s)
            ok[mid] = True
    return pos, quat, ok


def segments_of(t: np.ndarray, ok: np.ndarray, min_segment_s: float | None = None) -> np.ndarray:
    """Segment index per sample: maximal runs of ``ok`` lasting at least ``min_segment_s``, else −1.
    ``min_segment_s`` in s; spec §7.4 step 3."""
    min_segment_s = PARAMETERS.min_segment_s if min_segment_s is None else min_segment_s
    seg = np.full(len(ok), -1)
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(int), 0]))
    k = 0
    for a, b in zip(edges[::2], edges[1::2]):  # run is [a, b)
        if b - a >= 3 and t[b - 1] - t[a] >= min_segment_s - 1e-12:
            seg[a:b] = k
            k += 1
    return seg


def process_mocap(t: np.ndarray, position: np.ndarray, quaternion: np.ndarray) -> MocapTrack:
    """Gap bridging, segmentation, filtering and differentiation of a pose stream (spec §7.4)."""
    t = np.asarray(t, float)
    pos, quat, ok = bridge_gaps(t, position, quaternion)
    seg = segments_of(t, ok)
    n = len(t)
    out_p, out_q = np.full((n, 3), np.nan), np.full((n, 4), np.nan)
    out_v, out_w = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    fc, fc_w = PARAMETERS.mocap_cutoff_hz, PARAMETERS.angular_velocity_cutoff_hz
    for k in range(seg.max() + 1 if n else 0):
        m = np.flatnonzero(seg == k)
        ts = t[m]
        rate = nominal_rate(ts)
        q = quat_normalize(quat[m])
        flips = np.cumsum(np.r_[False, np.sum(q[1:] * q[:-1], axis=1) < 0]) % 2 == 1  # hemisphere continuity
        q[flips] *= -1.0
        p = lowpass(pos[m], rate, fc)
        out_p[m] = p
        out_q[m] = q
        out_v[m] = np.gradient(p, ts, axis=0)
        out_w[m] = lowpass(angular_velocity(ts, q), rate, fc_w)
    return MocapTrack(t=t, position=out_p, quaternion=out_q, velocity=out_v, angular_velocity=out_w, segment=seg)


def segment_interior(track: MocapTrack, margin_s: float) -> np.ndarray:
    """Samples of a segment at least ``margin_s`` (s) from both of its ends: past the edge transients of the
    per-segment low-pass (spec §7.4 step 4, §9.4). False outside every segment."""
    out = np.zeros(len(track.t), bool)
    for k in range(int(track.segment.max()) + 1 if len(track.t) else 0):
        m = np.flatnonzero(track.segment == k)
        ts = track.t[m]
        out[m] = (ts - ts[0] >= margin_s - 1e-9) & (ts[-1] - ts >= margin_s - 1e-9)
    return out


@dataclass
class PoseOnGrid(Kinematics):
    """Motion-capture quantities on a time grid; NaN where ``valid`` is False (spec §7.4 step 5)."""

    valid: np.ndarray


def _brackets(track: MocapTrack, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For each grid time: the bracketing sample indices ``k``, ``k1``, the fraction ``s`` and validity (§7.4 step 5)."""
    t = track.t
    k = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, max(len(t) - 2, 0))
    inside = (grid >= t[0]) & (grid <= t[-1]) if len(t) else np.zeros(len(grid), bool)
    k1 = np.minimum(k + 1, len(t) - 1)
    same = (track.segment[k] >= 0) & (track.segment[k] == track.segment[k1])
    on_sample = (grid == t[k]) & (track.segment[k] >= 0)
    on_last = (grid == t[k1]) & (track.segment[k1] >= 0)
    span = np.where(t[k1] > t[k], t[k1] - t[k], 1.0)
    return k, k1, np.clip((grid - t[k]) / span, 0.0, 1.0), inside & (same | on_sample | on_last)


def _slerp_rows(track: MocapTrack, k: np.ndarray, k1: np.ndarray, s: np.ndarray) -> np.ndarray:
    qa, qb = track.quaternion[k], track.quaternion[k1]
    return quat_slerp(qa, np.where(np.isfinite(qb), qb, qa), s)


def orientation_at(track: MocapTrack, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orientation (slerp, NaN where invalid) and validity at ``times`` — §7.4 step 5 for the quaternion only."""
    times = np.asarray(times, float)
    k, k1, s, valid = _brackets(track, times)
    q = np.full((len(times), 4), np.nan)
    v = np.flatnonzero(valid)
    if len(v):
        q[v] = _slerp_rows(track, k[v], k1[v], s[v])
    return q, valid


def resample_track(track: MocapTrack, grid: np.ndarray) -> PoseOnGrid:
    """Interpolate a processed track at ``grid`` (spec §7.4): linear, quaternions by slerp.

    A grid time is valid only between two samples of the same segment (or exactly on a segment sample).
    """
    grid = np.asarray(grid, float)
    k, k1, s, valid = _brackets(track, grid)
    n = len(grid)
    out = {name: np.full((n, d), np.nan) for name, d in (("p", 3), ("v", 3), ("w", 3), ("q", 4))}
    v = np.flatnonzero(valid)
    if len(v):
        kk, kn, ss = k[v], k1[v], s[v][:, None]
        for name, arr in (("p", track.position), ("v", track.velocity), ("w", track.angular_velocity)):
            a, b = arr[kk], arr[kn]
            out[name][v] = np.where(np.isfinite(b), a + ss * (b - a), a)
        out["q"][v] = _slerp_rows(track, kk, kn, s[v])
    return PoseOnGrid(t=grid, position=out["p"], quaternion=out["q"], velocity=out["v"], angular_velocity=out["w"], valid=valid)


def mocap_track(ctx_or_session: Any, trial_id: str) -> MocapTrack:
    """The processed ``handle_pose`` of a trial at its native samples (spec §7.4); cached on a context."""

    def build() -> MocapTrack:
        session = session_of(ctx_or_session)
        pose = session.read(trial_id, "handle_pose")
        return process_mocap(pose["t"].to_numpy(), table_columns(pose, POSE_COLUMNS[:3]), table_columns(pose, POSE_COLUMNS[3:]))

    return cached(ctx_or_session, ("mocap_track", trial_id), build)


def pose_on_grid(ctx_or_session: Any, trial_id: str, grid: np.ndarray) -> PoseOnGrid:
    """The trial's handle pose, velocity and angular velocity at ``grid`` (E611 when nothing is usable).
    SI units; spec §7.4."""
    track = mocap_track(ctx_or_session, trial_id)
    out = resample_track(track, grid)
    if not out.valid.any():
        session = session_of(ctx_or_session)
        stream = session.stream(trial_id, "handle_pose")
        raise fail(
            Code.MOTION_CAPTURE_UNUSABLE,
            f"trial {trial_id!r}: no usable motion-capture samples in the analysed time span",
            file=stream.file if stream else None,
            expected=f"valid runs of at least {PARAMETERS.min_segment_s} s",
            found="none",
        )
    return out
