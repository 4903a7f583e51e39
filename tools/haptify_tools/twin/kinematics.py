"""Twin-side kinematics: inverse kinematics, joint-limit and base-collision checks, gimbal angles (paper eq. 4; TWIN.md, Physics).

Forward kinematics and the Jacobian are the reference's (:mod:`haptify.processing.kinematics`, spec §8.2); this
module adds what only the simulator needs. Positions are in the device frame D unless a name ends in
``_W`` (world frame); angles in rad; arrays are vectorised over a leading sample axis ``N``.
"""

from __future__ import annotations

import math
import warnings
from typing import Literal, overload

import numpy as np
from scipy.spatial.transform import Rotation

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.conventions import quat_to_matrix
from haptify.formats.session_format import Kinematics
from haptify.processing import kinematics as ref
from haptify_tools.twin.model import Box, Cylinder, HalfSpace, Sphere, TwinFile

# --- which kinematics ---------------------------------------------------------------------------


def nominal_kinematics(twin: TwinFile) -> Kinematics:
    """The nominal DH chain of the twin (what the device's software and the standard description use).
    ``device.kinematics``, spec §2.3; E802 when a twin built in code (not read from a file, whose validation
    requires it) has none."""
    kin = twin.device.kinematics
    if kin is None:
        raise fail(
            Code.TWIN_FILE_INVALID,
            "the twin's device has no kinematics",
            pointer="/device/kinematics",
            expected="a DH chain (TWIN.md)",
        )
    return kin


def true_kinematics(twin: TwinFile) -> Kinematics:
    """The chain the simulated device really has: nominal plus ``kinematics.link_length`` deltas when enabled."""
    kin = nominal_kinematics(twin)
    eff = twin.effects.kinematics_link_length
    if not eff.enabled or (not any(eff.delta_a_m) and not any(eff.delta_d_m)):
        return kin
    joints = [j.model_copy(update={"a": j.a + da, "d": j.d + dd}) for j, da, dd in zip(kin.joints, eff.delta_a_m, eff.delta_d_m)]
    return kin.model_copy(update={"joints": joints})


def rows_times(x: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``x @ m`` for a tall ``x (N, k)`` and a small ``m (k, j)`` or ``(k,)`` without BLAS.

    NumPy hands 2-D products to BLAS, whose threads make this tall-and-thin case several times slower
    on a loaded machine (or in worker processes) than a plain ``einsum``.
    """
    m = np.asarray(m, dtype=float)
    return np.einsum("...k,k->...", x, m) if m.ndim == 1 else np.einsum("...k,kj->...j", x, m)


# --- frames -------------------------------------------------------------------------------------


def placement_matrix(twin: TwinFile) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``R_WD (3, 3)`` and translation ``t_WD (3,)`` of the device frame in W.
    ``t_WD`` in m; ``device_placement``, spec §1.2, §2.1."""
    return quat_to_matrix(np.asarray(twin.placement.quaternion)), np.asarray(twin.placement.position, dtype=float)


def world_to_device(twin: TwinFile, p_W: np.ndarray) -> np.ndarray:
    """Points ``(N, 3)`` from W to the device frame D (m; frames of spec §1.2)."""
    r, t = placement_matrix(twin)
    return rows_times(np.atleast_2d(p_W) - t, r)


def device_to_world(twin: TwinFile, p_D: np.ndarray) -> np.ndarray:
    """Points ``(N, 3)`` from the device frame D to W (m; frames of spec §1.2)."""
    r, t = placement_matrix(twin)
    return rows_times(np.atleast_2d(p_D), r.T) + t


def link_transforms(kin: Kinematics, q: np.ndarray) -> list[np.ndarray]:
    """Homogeneous transforms ``(N, 4, 4)`` of DH frames 0..n in the device frame (frame 0 = the DH base).
    ``T_{i−1,i}`` of spec §2.3, translations in m."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    base = np.eye(4)
    base[:3, :3] = quat_to_matrix(np.asarray(kin.base.quaternion))
    base[:3, 3] = kin.base.position
    frames = [np.broadcast_to(base, (q.shape[0], 4, 4)).copy()]
    frames += [base @ t for t in ref._dh_transforms(kin, q)]
    return frames


# --- inverse kinematics -------------------------------------------------------------------------


def _analytic_ok(kin: Kinematics) -> bool:
    """True when the chain is the planar-elbow structure of paper eq. 4 (α1 = ±90°, α2 = α3 = 0, d2 = d3 = 0)."""
    j = kin.joints
    return (
        len(j) == 3
        and abs(abs(j[0].alpha) - math.pi / 2) < 1e-12
        and abs(j[1].alpha) < 1e-12
        and abs(j[2].alpha) < 1e-12
        and j[1].d == 0.0
        and j[2].d == 0.0
        and j[1].a > 0
        and j[2].a > 0
    )


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _candidates(kin: Kinematics, p_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All four analytic solutions ``(4, N, 3)`` (shoulder ± × elbow ±) and their reachability ``(4, N)``."""
    j1, j2, j3 = kin.joints
    a1, d1, a2, a3 = j1.a, j1.d, j2.a, j3.a
    s_alpha = math.sin(j1.alpha)
    x, y, z = p_B[:, 0], p_B[:, 1], p_B[:, 2]
    rho = np.hypot(x, y)
    w = (z - d1) / s_alpha
    sols, oks = [], []
    for shoulder in (1.0, -1.0):
        th1 = np.arctan2(shoulder * y, shoulder * x)
        u = shoulder * rho - a1
        c3 = (u * u + w * w - a2 * a2 - a3 * a3) / (2 * a2 * a3)
        ok = np.abs(c3) <= 1.0 + 1e-12
        c3 = np.clip(c3, -1.0, 1.0)
        for elbow in (1.0, -1.0):
            th3 = elbow * np.arccos(c3)
            th2 = np.arctan2(w, u) - np.arctan2(a3 * np.sin(th3), a2 + a3 * np.cos(th3))
            q = np.stack([th1 - j1.theta_offset, th2 - j2.theta_offset, th3 - j3.theta_offset], axis=1)
            sols.append(_wrap(q))
            oks.append(ok)
    return np.stack(sols), np.stack(oks)


def limit_violation(kin: Kinematics, q: np.ndarray) -> np.ndarray:
    """Sum over joints of how far ``q (N, n)`` lies outside its coupled limits, rad (0 inside).
    The coupled limits of spec §2.3."""
    lower, upper = ref.joint_limits(kin, q)
    q = np.atleast_2d(q)
    return np.sum(np.maximum(lower - q, 0.0) + np.maximum(q - upper, 0.0), axis=1)


def _numeric_ik(kin: Kinematics, p_D: np.ndarray, q0: np.ndarray, iterations: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Damped least squares from ``q0``: returns ``q`` and the residual distance, m."""
    q = np.array(q0, dtype=float)
    lam = 1e-4
    for _ in range(iterations):
        err = p_D - ref.forward_positions(kin, q)
        if np.max(np.linalg.norm(err, axis=1)) < 1e-12:
            break
        jac = ref.jacobian(kin, q)
        jt = np.swapaxes(jac, 1, 2)
        a = jt @ jac + lam * np.eye(jac.shape[2])
        q = q + np.linalg.solve(a, np.einsum("nij,nj->ni", jt, err)[..., None])[..., 0]
    return q, np.linalg.norm(p_D - ref.forward_positions(kin, q), axis=1)


def _limit_centre(kin: Kinematics) -> np.ndarray:
    s = np.full((1, len(kin.joints)), 0.5)
    return ref.configurations_from_unit(kin, s)[0]


def inverse_kinematics(
    kin: Kinematics, p_D: np.ndarray, q_hint: np.ndarray | None = None, tol_m: float = 1e-9
) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles ``q (N, n)`` placing the gimbal centre at ``p_D (N, 3)`` (device frame), and ``ok (N,)``.

    Analytic for the structure of paper eq. 4 (four candidates: shoulder and elbow up/down); among the
    candidates the one inside the coupled joint limits (spec §8.2) is chosen — nearest to ``q_hint`` when
    several are — else the one violating the limits least. Other DH chains use damped least squares
    from ``q_hint`` (or the centre of the limit box). ``ok`` is False where the point is out of reach or
    no solution respects the joint limits.
    """
    p_D = np.atleast_2d(np.asarray(p_D, dtype=float))
    n = p_D.shape[0]
    if _analytic_ok(kin):
        r = quat_to_matrix(np.asarray(kin.base.quaternion))
        p_B = rows_times(p_D - np.asarray(kin.base.position), r)
        sols, reach = _candidates(kin, p_B)
        viol = np.stack([limit_violation(kin, s) for s in sols])
        viol = np.where(reach, viol, np.inf)
        score = viol.copy()
        if q_hint is not None:
            hint = np.broadcast_to(np.atleast_2d(q_hint), (n, len(kin.joints)))
            dist = np.stack([np.linalg.norm(_wrap(s - hint), axis=1) for s in sols])
            score = np.where(viol < 1e-12, dist * 1e-6, viol + 1.0 + dist * 1e-6)
        best = np.argmin(score, axis=0)
        q = sols[best, np.arange(n)]
        ok = reach[best, np.arange(n)] & (viol[best, np.arange(n)] < 1e-9)
        return q, ok
    q0 = np.broadcast_to(np.atleast_2d(q_hint) if q_hint is not None else _limit_centre(kin)[None], (n, len(kin.joints)))
    q, resid = _numeric_ik(kin, p_D, q0)
    return q, (resid < max(tol_m, 1e-7)) & (limit_violation(kin, q) < 1e-9)


# --- collisions ---------------------------------------------------------------------------------


def _primitive_distance(prim, p: np.ndarray) -> np.ndarray:
    """Signed distance ``(N,)`` from points to a primitive's surface (negative inside), m."""
    if isinstance(prim, Sphere):
        return np.linalg.norm(p - np.asarray(prim.center_m), axis=1) - prim.radius_m
    if isinstance(prim, HalfSpace):
        nrm = np.asarray(prim.normal, dtype=float)
        nrm = nrm / np.linalg.norm(nrm)
        return -rows_times(p - np.asarray(prim.point_m), nrm)
    if isinstance(prim, Cylinder):
        d = p - np.asarray(prim.center_m)
        dr = np.hypot(d[:, 0], d[:, 1]) - prim.radius_m
        dz = np.abs(d[:, 2]) - prim.half_height_m
        outside = np.hypot(np.maximum(dr, 0), np.maximum(dz, 0))
        return outside + np.minimum(np.maximum(dr, dz), 0.0)
    if isinstance(prim, Box):
        r = quat_to_matrix(np.asarray(prim.quaternion))
        d = np.abs(rows_times(p - np.asarray(prim.center_m), r)) - np.asarray(prim.half_extents_m)
        outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
        return outside + np.minimum(np.max(d, axis=1), 0.0)
    raise TypeError(f"unknown primitive {prim!r}")


def collision_clearance(twin: TwinFile, p_D: np.ndarray) -> np.ndarray:
    """Smallest distance ``(N,)`` between the end-effector sphere and the base primitives, m (< 0: collision).

    ``+inf`` when ``kinematics.base_collision`` is disabled or has no primitives.
    """
    p = np.atleast_2d(np.asarray(p_D, dtype=float))
    eff = twin.effects.kinematics_base_collision
    if not eff.enabled or not eff.primitives:
        return np.full(p.shape[0], np.inf)
    d = np.min(np.stack([_primitive_distance(pr, p) for pr in eff.primitives]), axis=0)
    return d - eff.clearance_m


def in_collision(twin: TwinFile, p_D: np.ndarray) -> np.ndarray:
    """True where the end-effector at gimbal-centre positions ``p_D (N, 3)`` would intersect the base or table.
    ``p_D`` in m."""
    return collision_clearance(twin, p_D) < 0.0


def reachable(twin: TwinFile, p_W: np.ndarray) -> np.ndarray:
    """True where the true device can put its gimbal centre at ``p_W (N, 3)``: IK solution within the
    coupled joint limits and no base collision; ``p_W`` in m."""
    p_D = world_to_device(twin, p_W)
    _, ok = inverse_kinematics(true_kinematics(twin), p_D)
    return ok & ~in_collision(twin, p_D)


def random_reachable_points(twin: TwinFile, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` gimbal-centre points ``(n, 3)`` in W, uniform in joint space within the limits, collision-free.
    Positions in m."""
    kin = true_kinematics(twin)
    out: list[np.ndarray] = []
    while sum(len(o) for o in out) < n:
        q = ref.configurations_from_unit(kin, rng.random((2 * n, len(kin.joints))))
        q = q[~np.isnan(q).any(axis=1)]
        p = ref.forward_positions(kin, q)
        out.append(p[~in_collision(twin, p)])
    return device_to_world(twin, np.concatenate(out)[:n])


# --- gimbal -------------------------------------------------------------------------------------


def _arm_end_rotation_W(twin: TwinFile, kin: Kinematics, q: np.ndarray, frames: list[np.ndarray] | None = None) -> np.ndarray:
    """Rotation ``(N, 3, 3)`` of the gimbal's reference frame (last DH frame ∘ alignment) in W."""
    r_wd, _ = placement_matrix(twin)
    r_end = (frames if frames is not None else link_transforms(kin, q))[-1][:, :3, :3]
    r_align = quat_to_matrix(np.asarray(twin.gimbal_body.alignment))
    return r_wd @ r_end @ r_align


# scipy's upper-case sequences are intrinsic rotations (gimbal_body.axes, TWIN.md)
_INTRINSIC: dict[str, Literal["ZXZ", "ZYX", "ZXY", "XYZ", "YZX"]] = {
    "zxz": "ZXZ",
    "zyx": "ZYX",
    "zxy": "ZXY",
    "xyz": "XYZ",
    "yzx": "YZX",
}


def gimbal_angles(twin: TwinFile, q: np.ndarray, quaternion_W: np.ndarray, frames: list[np.ndarray] | None = None) -> np.ndarray:
    """The three passive gimbal angles ``(N, 3)`` in rad that give the handle orientation ``quaternion_W``
    (wxyz, handle → W) with the arm at ``q``; sequence ``gimbal_body.axes`` (intrinsic). ``frames``
    (from :func:`link_transforms` of the true kinematics at ``q``) saves recomputing them.
    Quaternion convention of spec §1.3."""
    r_ref = _arm_end_rotation_W(twin, true_kinematics(twin), q, frames)
    r_h = quat_to_matrix(np.atleast_2d(quaternion_W))
    rel = np.swapaxes(r_ref, 1, 2) @ r_h
    with warnings.catch_warnings():  # gimbal lock: scipy picks the third angle 0, which is a valid answer
        warnings.simplefilter("ignore", UserWarning)
        return Rotation.from_matrix(rel).as_euler(_INTRINSIC[twin.gimbal_body.axes])


def handle_quaternion(twin: TwinFile, q: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Handle orientation ``(N, 4)`` wxyz in W from arm angles ``q`` and gimbal angles (inverse of :func:`gimbal_angles`).
    Spec §1.3."""
    r_ref = _arm_end_rotation_W(twin, true_kinematics(twin), q)
    rel = Rotation.from_euler(_INTRINSIC[twin.gimbal_body.axes], np.atleast_2d(angles)).as_matrix()
    xyzw = Rotation.from_matrix(r_ref @ rel).as_quat()
    return np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)


@overload
def hand_to_joints(
    twin: TwinFile, position_W: np.ndarray, quaternion_W: np.ndarray, strict: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


@overload
def hand_to_joints(
    twin: TwinFile, position_W: np.ndarray, quaternion_W: None = None, strict: bool = False
) -> tuple[np.ndarray, None, np.ndarray]: ...


def hand_to_joints(
    twin: TwinFile, position_W: np.ndarray, quaternion_W: np.ndarray | None = None, strict: bool = False
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Arm angles ``(N, n)``, gimbal angles ``(N, 3)`` (None without orientation) and ``ok (N,)`` for a hand path.

    Uses the TRUE kinematics and the IK solution inside the joint limits (unique for the structure of
    paper eq. 4, whose limits keep the elbow down and the shoulder forward). With ``strict`` an
    unreachable sample raises E803 naming the first bad sample.
    """
    kin = true_kinematics(twin)
    p_D = world_to_device(twin, position_W)
    q, ok = inverse_kinematics(kin, p_D)
    if strict and not ok.all():
        i = int(np.argmin(ok))
        raise fail(
            Code.TWIN_POSE_UNREACHABLE,
            f"hand position {p_D[i].round(4).tolist()} m (device frame, sample {i}) is out of reach",
            expected="a point inside the joint limits",
            found=p_D[i].tolist(),
        )
    g = None if quaternion_W is None else gimbal_angles(twin, q, quaternion_W)
    return q, g, ok
