"""Device kinematics: standard DH chains with linearly coupled joint limits (spec chapter 8, §8.2).

Joint ``j``'s limits are ``constant + Σ_k c_k q_k`` and may depend only on joints before it, so a
configuration can be sampled joint by joint. Positions are of the last DH frame's origin (the gimbal
centre), in the device frame unless a function says otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptify.formats.conventions import pose_apply
from haptify.formats.session_format import Kinematics, LinearLimit


def _dh_transforms(kin: Kinematics, q: np.ndarray) -> list[np.ndarray]:
    """Cumulative transforms ``T_0i (N, 4, 4)`` from the DH base frame for i = 1..n."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = q.shape[0]
    out = []
    t = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    for i, j in enumerate(kin.joints):
        th = q[:, i] + j.theta_offset
        ct, st = np.cos(th), np.sin(th)
        ca, sa = np.cos(j.alpha), np.sin(j.alpha)
        a = np.zeros((n, 4, 4))
        a[:, 0, 0], a[:, 0, 1], a[:, 0, 2], a[:, 0, 3] = ct, -st * ca, st * sa, j.a * ct
        a[:, 1, 0], a[:, 1, 1], a[:, 1, 2], a[:, 1, 3] = st, ct * ca, -ct * sa, j.a * st
        a[:, 2, 1], a[:, 2, 2], a[:, 2, 3] = sa, ca, j.d
        a[:, 3, 3] = 1.0
        t = t @ a
        out.append(t)
    return out


def forward_positions(kin: Kinematics, q: np.ndarray) -> np.ndarray:
    """Gimbal-centre positions ``(N, 3)`` in the device frame for joint angles ``q (N, n)`` in rad.
    Positions in m; the DH chain of spec §2.3, §8.2."""
    tip = _dh_transforms(kin, q)[-1][:, :3, 3]
    return pose_apply(kin.base.position, kin.base.quaternion, tip)


def jacobian(kin: Kinematics, q: np.ndarray) -> np.ndarray:
    """Geometric position Jacobians ``∂p/∂q (N, 3, n)`` in the device frame (revolute joints).
    Units m/rad; the DH chain of spec §2.3."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    ts = _dh_transforms(kin, q)
    n = q.shape[0]
    p_end = ts[-1][:, :3, 3]
    origins = [np.zeros((n, 3))] + [t[:, :3, 3] for t in ts[:-1]]
    axes = [np.broadcast_to([0.0, 0.0, 1.0], (n, 3))] + [t[:, :3, 2] for t in ts[:-1]]
    cols = [np.cross(z, p_end - o) for z, o in zip(axes, origins)]
    from haptify.formats.conventions import quat_to_matrix

    r_base = quat_to_matrix(np.asarray(kin.base.quaternion))
    out: np.ndarray = np.einsum("ij,njk->nik", r_base, np.stack(cols, axis=-1))
    return out


def _limit_value(limit: LinearLimit, q: np.ndarray, names: list[str]) -> np.ndarray:
    value = np.full(q.shape[0], limit.constant)
    for joint_name, coeff in limit.coefficients.items():
        value = value + coeff * q[:, names.index(joint_name)]
    return value


def joint_limits(kin: Kinematics, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper limits ``(N, n)`` in rad at configurations ``q`` (coupled limits evaluated).
    Spec §2.3, §8.2."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    names = [j.name for j in kin.joints]
    lower = np.stack([_limit_value(j.lower, q, names) for j in kin.joints], axis=1)
    upper = np.stack([_limit_value(j.upper, q, names) for j in kin.joints], axis=1)
    return lower, upper


def within_limits(kin: Kinematics, q: np.ndarray, tol: float = 1e-12) -> np.ndarray:
    """True where every joint lies within its (coupled) limits (``tol`` in rad; spec §8.2)."""
    lower, upper = joint_limits(kin, q)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    out: np.ndarray = np.all((q >= lower - tol) & (q <= upper + tol), axis=1)
    return out


#: samples per joint of the unit lattice on which joint ranges are judged (spec §8.3 step 1; E115, E311)
RANGE_LATTICE_POINTS = 5


def limit_order_violations(kin: Kinematics) -> list[tuple[int, str, str]]:
    """Every limit that names a joint that is not an earlier one: ``(joint index, "lower"|"upper", named joint)``
    (spec §2.3, §8.2)."""
    names = [j.name for j in kin.joints]
    return [
        (i, side, other)
        for i, j in enumerate(kin.joints)
        for side in ("lower", "upper")
        for other in getattr(j, side).coefficients
        if other not in names[:i]
    ]


def check_limit_order(kin: Kinematics) -> None:
    """Raise ValueError unless every limit depends only on earlier joints (spec §8.2)."""
    for i, side, other in limit_order_violations(kin)[:1]:
        raise ValueError(f"{side} limit of {kin.joints[i].name} depends on {other}, which is not an earlier joint")


def unit_lattice(counts: list[int]) -> np.ndarray:
    """The unit cube's lattice with ``counts[j]`` evenly spaced samples of joint j in [0, 1], one row a point
    (spec §8.3 step 1)."""
    axes = [np.linspace(0.0, 1.0, c) for c in counts]
    return np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)


@dataclass(frozen=True)
class EmptyRange:
    """The first joint whose coupled range is empty at every sample: its index and the largest
    ``upper − lower`` (rad, negative) over the samples that reached it."""

    joint: int
    widest_rad: float


def _fill_configurations(kin: Kinematics, s: np.ndarray) -> tuple[np.ndarray, EmptyRange | None]:
    check_limit_order(kin)
    s = np.atleast_2d(np.asarray(s, dtype=float))
    names = [j.name for j in kin.joints]
    q = np.zeros_like(s)
    empty = None
    for i, j in enumerate(kin.joints):
        alive = ~np.isnan(q[:, 0]) if i else np.ones(len(q), bool)
        lo = _limit_value(j.lower, q, names)
        hi = _limit_value(j.upper, q, names)
        q[:, i] = lo + s[:, i] * (hi - lo)
        q[hi < lo, :] = np.nan
        if empty is None and alive.any() and np.isnan(q[alive, 0]).all():
            empty = EmptyRange(i, float(np.max((hi - lo)[alive])))
    return q, empty


def configurations_from_unit(kin: Kinematics, s: np.ndarray) -> np.ndarray:
    """Map unit-cube samples ``s (N, n)`` in [0, 1] to configurations within the coupled limits.
    Spec §8.3 step 3.

    Joint by joint: ``q_j = lower_j(q_<j) + s_j · (upper_j(q_<j) − lower_j(q_<j))``; where the coupled
    range is empty the configuration is infeasible and returned as NaN.
    """
    return _fill_configurations(kin, s)[0]


def empty_joint_range(kin: Kinematics, points: int = RANGE_LATTICE_POINTS) -> EmptyRange | None:
    """The joint at which every configuration of the ``points``-per-joint unit lattice has an empty coupled
    range (spec §2.3, §8.3 step 1), or None when some configuration is feasible. Limits must name earlier
    joints only (:func:`limit_order_violations`)."""
    return _fill_configurations(kin, unit_lattice([points] * len(kin.joints)))[1]
