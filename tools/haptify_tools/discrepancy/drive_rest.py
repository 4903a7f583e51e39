"""Drives at rest stay at rest in the replay (discrepancy README §1, drives at rest).

The twin's drive friction is ``τ_c·tanh(ω/ω_s)`` with ``ω_s`` a few mrad/s (the Touch preset: 5 mrad/s), so its
sign follows the drive's speed wherever that speed is above a few mrad/s. The measured hand path resolves a drive's
speed only to 1–3 mrad/s (the blend of motion capture and accelerometer, ``hand_path.py``, on the simulated rig).
While the hand moves, no drive stays that slow for long; but protocols hold some drives still for seconds — the
local-dynamic strokes in a vertical plane through the base axis leave the base drive at rest, a stiffness press
leaves it still too — and along the measured path such a drive jitters around zero, its friction flipping
between ±τ_c. On simulated Touch sessions that jitter was nearly all of the floor (the true twin's own held-out
gap): 0.06 N in the local-dynamic trial (0.007–0.009 N with the resting drives held; 0.008 N along the true path)
and 0.035 N in a stiffness trial (0.010 N).

A drive axis (``θ = C·q``, the twin's coupling) is at rest in every window of :data:`REST_WINDOW_S` in which it
turns less than :data:`REST_RANGE_RAD`; over each run of such windows it is held at its mean
angle, eased in and out over :data:`REST_EASE_S` at each end, and the hand path is moved accordingly (forward
kinematics of the twin's true chain). Everywhere else the path is untouched.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_dilation, maximum_filter1d, minimum_filter1d

from haptify_tools.twin.kinematics import device_to_world, hand_to_joints, link_transforms, rows_times, true_kinematics
from haptify_tools.twin.model import TwinFile

REST_WINDOW_S = 1.0  # shortest rest: long against a drive's speed reversal (tens of ms), short against a hold
REST_RANGE_RAD = 0.002  # a drive turning less than this in REST_WINDOW_S moves under 2 mrad/s — below what the path
# resolves (0.4 mm at the Touch's 0.2 m reach; the path's angle noise spans ≈ 0.5 mrad a second)
REST_EASE_S = 0.2  # the hold is eased in and out over this time at each end of a run


def resting_runs(angle: np.ndarray, rate_hz: float) -> list[tuple[int, int]]:
    """Half-open row ranges ``[a, b)`` where ``angle (N,)`` (rad, sampled at ``rate_hz``) rests (module docstring)."""
    n = max(int(round(REST_WINDOW_S * rate_hz)) | 1, 3)
    if len(angle) < n:
        return []
    span = maximum_filter1d(angle, n) - minimum_filter1d(angle, n)  # over the window centred on each row
    span[: n // 2] = span[len(angle) - n // 2 :] = np.inf  # only whole windows count
    rest = binary_dilation(span < REST_RANGE_RAD, np.ones(n, bool))  # every row of every such window
    edges = np.diff(np.r_[0, rest.astype(np.int8), 0])
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))


def hold_at_rest(angle: np.ndarray, t: np.ndarray, runs: list[tuple[int, int]]) -> np.ndarray:
    """``angle`` with each run held at its mean, eased in and out over :data:`REST_EASE_S` (raised cosine)."""
    out = np.array(angle, dtype=float)
    for a, b in runs:
        tt = t[a:b]
        w = np.clip(np.minimum(tt - tt[0], tt[-1] - tt) / REST_EASE_S, 0.0, 1.0)
        w = 0.5 - 0.5 * np.cos(np.pi * w)
        out[a:b] += w * (out[a:b].mean() - out[a:b])
    return out


def hold_resting_drives(twin: TwinFile, t: np.ndarray, position: np.ndarray) -> np.ndarray:
    """The hand path ``(N, 3)`` (m, W; at times ``t``, s, uniform) with the twin's resting drive axes held
    (module docstring). Rows the twin cannot reach are never part of a run."""
    q, _, ok = hand_to_joints(twin, position, None)
    if not ok.any():
        return position
    c = np.asarray(twin.drive.coupling, dtype=float)
    theta = rows_times(np.where(ok[:, None], q, 0.0), c.T)
    rate = (len(t) - 1) / (t[-1] - t[0])
    held = theta.copy()
    for k in range(theta.shape[1]):
        runs = [(a, b) for a, b in resting_runs(theta[:, k], rate) if ok[a:b].all()]
        held[:, k] = hold_at_rest(theta[:, k], t, runs)
    moved = np.any(held != theta, axis=1)
    if not moved.any():
        return position
    q_held = rows_times(held[moved], np.linalg.inv(c).T)
    out = np.array(position, dtype=float)
    out[moved] += gimbal_centre(twin, q_held) - gimbal_centre(twin, q[moved])
    return out


def gimbal_centre(twin: TwinFile, q: np.ndarray) -> np.ndarray:
    """Forward kinematics of the twin's true chain: the gimbal centre ``(N, 3)`` (m, W) at arm angles ``q`` (rad)."""
    return device_to_world(twin, link_transforms(true_kinematics(twin), q)[-1][:, :3, 3])
