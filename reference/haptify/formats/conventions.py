"""Units, frames, quaternions and time (spec chapter 1).

Quaternions are unit, Hamilton, scalar first ``[w, x, y, z]`` and rotate body → parent (world).
All functions are vectorised over a leading axis: a quaternion array has shape ``(..., 4)``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

STANDARD_GRAVITY = 9.80665  # m/s², the default g (spec §1.2)
GRAVITY_W = np.array([0.0, 0.0, -STANDARD_GRAVITY])  # gravitational acceleration in W (z up)
QUATERNION_NORM_TOLERANCE = 1e-3  # |‖q‖ − 1| allowed in stored quaternions (spec §1.3)


def quat_normalize(q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Quaternions ``(..., 4)`` [w, x, y, z] scaled to unit norm (spec §1.3: readers normalise before use)."""
    q = np.asarray(q, dtype=float)
    out: npt.NDArray[np.float64] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return out


def quat_conjugate(q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Conjugates ``(..., 4)`` [w, −x, −y, −z]: for unit quaternions the inverse rotation, world→body (spec §1.3)."""
    q = np.asarray(q, dtype=float)
    out: npt.NDArray[np.float64] = q * np.array([1.0, -1.0, -1.0, -1.0])
    return out


def quat_multiply(a: npt.ArrayLike, b: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Hamilton product ``a ⊗ b`` (apply b first, then a; quaternions [w, x, y, z], spec §1.3)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_to_matrix(q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)`` (spec §1.3)."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def matrix_to_quat(m: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Unit quaternions (w ≥ 0) of rotation matrices ``(..., 3, 3)`` (Shepperd's method; spec §1.3)."""
    m = np.asarray(m, dtype=float)
    flat = m.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    tr = np.trace(flat, axis1=1, axis2=2)
    for i, r in enumerate(flat):
        if tr[i] > 0:
            s = 2.0 * np.sqrt(tr[i] + 1.0)
            out[i] = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
        else:
            k = int(np.argmax(np.diag(r)))
            j, n = (k + 1) % 3, (k + 2) % 3
            s = 2.0 * np.sqrt(1.0 + r[k, k] - r[j, j] - r[n, n])
            v = np.empty(4)
            v[0] = (r[n, j] - r[j, n]) / s
            v[1 + k] = 0.25 * s
            v[1 + j] = (r[j, k] + r[k, j]) / s
            v[1 + n] = (r[n, k] + r[k, n]) / s
            out[i] = v
    out *= np.where(out[:, :1] < 0, -1.0, 1.0)
    return out.reshape(m.shape[:-2] + (4,))


def quat_rotate(q: npt.ArrayLike, v: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Rotate vectors ``v (..., 3)`` from body to parent by quaternions ``q (..., 4)``.
    ``v_parent = q ⊗ v ⊗ q*``, spec §1.3."""
    out: npt.NDArray[np.float64] = np.einsum("...ij,...j->...i", quat_to_matrix(q), np.asarray(v, dtype=float))
    return out


def quat_from_axis_angle(axis: npt.ArrayLike, angle: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Quaternions of rotations by ``angle`` (rad) about unit ``axis`` (spec §1.3)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = np.asarray(angle, dtype=float)[..., None] / 2.0
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def quat_angle(a: npt.ArrayLike, b: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Angle (rad, in [0, π]) of the rotation that takes orientation ``a`` to ``b`` (θ_ab of spec §11.6.2)."""
    dot = np.abs(np.sum(quat_normalize(a) * quat_normalize(b), axis=-1))
    out: npt.NDArray[np.float64] = 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))
    return out


def quat_slerp(a: npt.ArrayLike, b: npt.ArrayLike, s: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Spherical linear interpolation from ``a`` (s=0) to ``b`` (s=1) along the shorter arc (spec §7.2)."""
    a = quat_normalize(a)
    b = quat_normalize(b)
    s = np.asarray(s, dtype=float)[..., None]
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    small = theta < 1e-8
    sin_t = np.where(small, 1.0, np.sin(theta))
    wa = np.where(small, 1.0 - s, np.sin((1.0 - s) * theta) / sin_t)
    wb = np.where(small, s, np.sin(s * theta) / sin_t)
    return quat_normalize(wa * a + wb * b)


def quat_mean(q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The average orientation of quaternions ``(..., N, 4)`` (Markley et al. 2007: principal eigenvector of
    Σ q qᵀ), with w ≥ 0: ``(..., 4)``, one mean per stack of N (e.g. per window, spec §11.6.1)."""
    q = quat_normalize(np.asarray(q, dtype=float))
    _, vecs = np.linalg.eigh(np.swapaxes(q, -1, -2) @ q)
    mean: npt.NDArray[np.float64] = vecs[..., :, -1]
    return np.where(mean[..., :1] >= 0, mean, -mean)


def pose_apply(position: npt.ArrayLike, quaternion: npt.ArrayLike, points: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Map ``points (..., 3)`` from a child frame to its parent, given the child's pose in the parent.
    Positions in m; spec §1.3."""
    out: npt.NDArray[np.float64] = quat_rotate(quaternion, points) + np.asarray(position, dtype=float)
    return out
