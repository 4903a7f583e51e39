"""Rigid-body dynamics of the twin's arm and gimbal (TWIN.md, Physics): recursive Newton–Euler inverse
dynamics of the links (forward pass of kinematics, backward pass of forces), the joint-space mass matrix and
the potential energy, the motor rotors reflected through the capstans, the drive and gimbal friction laws
(Coulomb with a smooth zero crossing, viscous, Stribeck), the gimbal body's inertial-plus-weight wrench and
the Jacobians. Frames: D (device) inside, W (world) for the handle's rates; SI units."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptify.formats.conventions import quat_conjugate, quat_multiply, quat_to_matrix
from haptify.formats.session_format import Kinematics
from haptify_tools.twin.kinematics import (
    link_transforms,
    placement_matrix,
    rows_times,
    true_kinematics,
)
from haptify_tools.twin.model import TwinFile


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of ``(N, 3)`` arrays (or one of them ``(3,)``); faster than ``np.cross`` here."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _diff(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Time derivative along axis 0 (second-order central differences)."""
    if len(t) < 3:
        return np.zeros_like(x)
    return np.gradient(x, t, axis=0, edge_order=2)


def _unwrap(q: np.ndarray) -> np.ndarray:
    return np.unwrap(q, axis=0)


def _inertia_matrix(vals: list[float]) -> np.ndarray:
    ixx, iyy, izz, ixy, ixz, iyz = vals
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def _gravity_D(twin: TwinFile) -> np.ndarray:
    """Gravitational acceleration in the device frame (zero when ``gravity`` is off), m/s²."""
    if not twin.on("gravity"):
        return np.zeros(3)
    r_wd, _ = placement_matrix(twin)
    return r_wd.T @ np.array([0.0, 0.0, -twin.effects.gravity.g_m_per_s2])


def _coupling(twin: TwinFile) -> np.ndarray:
    return np.asarray(twin.drive.coupling, dtype=float)


def reflected_rotor_inertia(twin: TwinFile) -> np.ndarray:
    """Rotor inertia per drive axis seen at the capstan output, ``n²·J_rotor`` in kg·m² (0 when ``inertia`` is off)."""
    if not twin.on("inertia"):
        return np.zeros(len(twin.links))
    n = np.asarray(twin.drive.capstan_ratio)
    return n * n * np.asarray(twin.effects.inertia.rotor_inertia_kg_m2)


def drive_friction(twin: TwinFile, omega: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
    """Friction torque ``(N, n)`` on the drive axes at drive speeds ``omega`` (rad/s), N·m; opposes motion.

    Sum of the enabled components ``friction.coulomb`` (τ_c·(1 + r·sin(2π·c·θ))·tanh(ω/ω_s); the ripple
    needs the drive angles ``theta``, rad), ``friction.viscous`` (b·ω) and ``friction.stribeck``
    (Δτ·exp(−(ω/ω_st)²)·tanh(ω/ω_s)), with a minus sign.
    """
    omega = np.atleast_2d(omega)
    tau = np.zeros_like(omega)
    e = twin.effects
    if e.friction_coulomb.enabled:
        c = e.friction_coulomb
        level = np.asarray(c.torque_Nm)
        if c.ripple_fraction > 0 and theta is not None:
            level = level * (1.0 + c.ripple_fraction * np.sin(2 * np.pi * c.ripple_cycles_per_rad * np.atleast_2d(theta)))
        tau -= level * np.tanh(omega / c.zero_crossing_velocity_rad_per_s)
    if e.friction_viscous.enabled:
        tau -= np.asarray(e.friction_viscous.damping_Nms_per_rad) * omega
    if e.friction_stribeck.enabled:
        s = e.friction_stribeck
        tau -= (
            np.asarray(s.excess_torque_Nm)
            * np.exp(-((omega / s.stribeck_velocity_rad_per_s) ** 2))
            * np.tanh(omega / s.zero_crossing_velocity_rad_per_s)
        )
    return tau


def gimbal_friction(twin: TwinFile, rate: np.ndarray) -> np.ndarray:
    """Friction torques ``(N, 3)`` of the gimbal joints at joint rates ``rate`` (rad/s), N·m; opposes motion."""
    tau = np.zeros_like(rate)
    e = twin.effects
    if e.friction_coulomb.enabled:
        tau -= np.asarray(e.friction_coulomb.gimbal_torque_Nm) * np.tanh(
            rate / e.friction_coulomb.zero_crossing_velocity_rad_per_s
        )
    if e.friction_viscous.enabled:
        tau -= np.asarray(e.friction_viscous.gimbal_damping_Nms_per_rad) * rate
    return tau


@dataclass
class LinkState:
    """Per-sample kinematics of the arm links in the device frame (from the forward pass)."""

    frames: list[np.ndarray]  # T_0..T_n, (N, 4, 4)
    omega: list[np.ndarray]  # ω_i (N, 3), i = 1..n
    alpha: list[np.ndarray]  # ω̇_i
    acc_origin: list[np.ndarray]  # a_{o_i}, with −g folded in
    com: list[np.ndarray]  # c_i positions (N, 3)
    acc_com: list[np.ndarray]  # a_{c_i} − g


def _forward_pass(twin: TwinFile, kin: Kinematics, q, qd, qdd, g_D, frames=None) -> LinkState:
    frames = frames if frames is not None else link_transforms(kin, q)
    n_s = q.shape[0]
    w = np.zeros((n_s, 3))
    dw = np.zeros((n_s, 3))
    a = np.broadcast_to(-g_D, (n_s, 3)).copy()
    st = LinkState(frames, [], [], [], [], [])
    for i, link in enumerate(twin.links):
        z = frames[i][:, :3, 2]
        o_prev, o = frames[i][:, :3, 3], frames[i + 1][:, :3, 3]
        w_new = w + z * qd[:, i : i + 1]
        dw = dw + z * qdd[:, i : i + 1] + _cross(w, z * qd[:, i : i + 1])
        w = w_new
        r = o - o_prev
        a = a + _cross(dw, r) + _cross(w, _cross(w, r))
        rc = np.einsum("nij,j->ni", frames[i + 1][:, :3, :3], np.asarray(link.com_m))
        ac = a + _cross(dw, rc) + _cross(w, _cross(w, rc))
        st.omega.append(w)
        st.alpha.append(dw)
        st.acc_origin.append(a)
        st.com.append(o + rc)
        st.acc_com.append(ac)
    return st


def _backward_pass(twin: TwinFile, st: LinkState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint torques ``(N, n)`` and the force/moment ``f_1, n_1`` the base applies to link 1 (about o_0)."""
    n_links = len(twin.links)
    n_s = st.frames[0].shape[0]
    f_next = np.zeros((n_s, 3))
    m_next = np.zeros((n_s, 3))
    tau = np.zeros((n_s, n_links))
    for i in reversed(range(n_links)):
        link = twin.links[i]
        rot = st.frames[i + 1][:, :3, :3]
        inertia = rot @ _inertia_matrix(link.inertia_kg_m2) @ np.swapaxes(rot, 1, 2)
        w, dw = st.omega[i], st.alpha[i]
        big_f = link.mass_kg * st.acc_com[i]
        big_n = np.einsum("nij,nj->ni", inertia, dw) + _cross(w, np.einsum("nij,nj->ni", inertia, w))
        o_prev, o = st.frames[i][:, :3, 3], st.frames[i + 1][:, :3, 3]
        f = big_f + f_next
        m = big_n + m_next + _cross(st.com[i] - o_prev, big_f) + _cross(o - o_prev, f_next)
        tau[:, i] = np.einsum("ni,ni->n", st.frames[i][:, :3, 2], m)
        f_next, m_next = f, m
    return tau, f_next, m_next


def inverse_dynamics(twin: TwinFile, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, kin: Kinematics | None = None) -> np.ndarray:
    """Joint torques ``(N, n)`` in N·m that move the bare links (no rotors, no friction, no gimbal body)
    along ``q, q̇, q̈`` with the twin's gravity — recursive Newton–Euler (Luh, Walker & Paul 1980).

    ``inertia`` off drops the velocity and acceleration terms; ``gravity`` off drops the weights.
    """
    kin = kin or true_kinematics(twin)
    q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
    if not twin.on("inertia"):
        qd, qdd = np.zeros_like(qd), np.zeros_like(qdd)
    st = _forward_pass(twin, kin, q, qd, qdd, _gravity_D(twin))
    return _backward_pass(twin, st)[0]


def mass_matrix(twin: TwinFile, q: np.ndarray, with_rotors: bool = True) -> np.ndarray:
    """Joint-space mass matrix ``(N, n, n)`` of the links (plus reflected rotors through the coupling), kg·m²."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    kin = true_kinematics(twin)
    n = q.shape[1]
    cols = []
    zero = np.zeros_like(q)
    for j in range(n):
        e = np.zeros_like(q)
        e[:, j] = 1.0
        st = _forward_pass(twin, kin, q, zero, e, np.zeros(3))
        cols.append(_backward_pass(twin, st)[0])
    m = np.stack(cols, axis=2)
    if with_rotors:
        c = _coupling(twin)
        m = m + c.T @ np.diag(reflected_rotor_inertia(twin) if twin.on("inertia") else np.zeros(n)) @ c
    return m


def potential_energy(twin: TwinFile, q: np.ndarray, quaternion_W: np.ndarray | None = None) -> np.ndarray:
    """Gravitational potential energy ``(N,)`` of links and gimbal body relative to the device origin, J."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    kin = true_kinematics(twin)
    frames = link_transforms(kin, q)
    g = _gravity_D(twin)
    e = np.zeros(q.shape[0])
    for i, link in enumerate(twin.links):
        c = frames[i + 1][:, :3, 3] + np.einsum("nij,j->ni", frames[i + 1][:, :3, :3], np.asarray(link.com_m))
        e -= link.mass_kg * rows_times(c, g)
    gb = twin.gimbal_body
    if gb.mass_kg > 0:
        tip = frames[-1][:, :3, 3]
        offset = 0.0 if quaternion_W is None else _gimbal_com_offset_D(twin, quaternion_W)
        e -= gb.mass_kg * rows_times(tip + offset, g)
    return e


def _gimbal_com_offset_D(twin: TwinFile, quaternion_W: np.ndarray) -> np.ndarray:
    r_wd, _ = placement_matrix(twin)
    r_h = quat_to_matrix(np.atleast_2d(quaternion_W))
    return np.einsum("ij,njk,k->ni", r_wd.T, r_h, np.asarray(twin.gimbal_body.com_m))


def _handle_rates(t: np.ndarray, quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Angular velocity and acceleration ``(N, 3)`` of the handle in W from its quaternions (rad/s, rad/s²)."""
    quat = np.atleast_2d(quat).copy()
    flip = np.sum(quat[1:] * quat[:-1], axis=1) < 0  # keep one hemisphere for differencing
    sign = np.cumprod(np.concatenate([[1.0], np.where(flip, -1.0, 1.0)]))
    quat *= sign[:, None]
    dq = _diff(t, quat)
    w = 2.0 * quat_multiply(dq, quat_conjugate(quat))[:, 1:]
    return w, _diff(t, w)


@dataclass
class _GimbalLoad:
    force_link: np.ndarray  # force the gimbal body applies to the last link at the gimbal centre (D)
    moment_link: np.ndarray  # moment it applies (gimbal friction), D
    force_hand: np.ndarray  # force the device applies to the hand (D), before adding the link's share
    torque_hand: np.ndarray  # torque the device applies to the hand about the gimbal centre (D)


def _gimbal_body_terms(twin: TwinFile, t, frames, angles, quat_W, a_tip_D, g_D) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inertial-plus-weight wrench of the gimbal body ``m(a_c − g)`` and its moment about the gimbal centre,
    and the gimbal friction moment (what the gimbal applies to the hand-side body from the link), all in D."""
    gb = twin.gimbal_body
    r_wd, _ = placement_matrix(twin)
    n_s = len(t)
    w_W, dw_W = _handle_rates(t, quat_W)
    if not twin.on("inertia"):
        w_W, dw_W, a_tip_D = np.zeros_like(w_W), np.zeros_like(dw_W), np.zeros_like(a_tip_D)
    w, dw = rows_times(w_W, r_wd), rows_times(dw_W, r_wd)
    rc = _gimbal_com_offset_D(twin, quat_W) if gb.mass_kg > 0 else np.zeros((n_s, 3))
    a_c = a_tip_D + _cross(dw, rc) + _cross(w, _cross(w, rc))
    f_g = gb.mass_kg * (a_c - g_D)
    r_h = r_wd.T @ quat_to_matrix(np.atleast_2d(quat_W))
    inertia = r_h @ np.diag(gb.inertia_kg_m2) @ np.swapaxes(r_h, 1, 2)
    m_g = np.einsum("nij,nj->ni", inertia, dw) + _cross(w, np.einsum("nij,nj->ni", inertia, w)) + _cross(rc, f_g)
    # gimbal joint friction, each joint's torque along its own axis
    rates = _diff(t, _unwrap(angles))
    tau_j = gimbal_friction(twin, rates)
    if not np.any(tau_j):
        return f_g, m_g, np.zeros((n_s, 3))
    axes = _gimbal_axes_D(twin, frames, angles)
    fric = np.einsum("nk,nki->ni", tau_j, axes)
    return f_g, m_g, fric


def _elementary(axis: str, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(N, 3, 3)`` about one coordinate axis."""
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    i = "xyz".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    m[:, i, i] = 1.0
    m[:, j, j], m[:, j, k], m[:, k, j], m[:, k, k] = c, -s, s, c
    return m


def _gimbal_axes_D(twin: TwinFile, frames: list[np.ndarray], angles: np.ndarray) -> np.ndarray:
    """Unit axes ``(N, 3, 3)`` (joint k in row k) of the three gimbal joints in D."""
    r = frames[-1][:, :3, :3] @ quat_to_matrix(np.asarray(twin.gimbal_body.alignment))
    axes = []
    for k, ch in enumerate(twin.gimbal_body.axes):
        axes.append(r[:, :, "xyz".index(ch)])
        r = r @ _elementary(ch, angles[:, k])
    return np.stack(axes, axis=1)


def _jacobians(frames: list[np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray]:
    """Position and rotation Jacobians ``(N, 3, n)`` in D from already computed DH frames (revolute joints)."""
    tip = frames[-1][:, :3, 3]
    jw = np.stack([frames[i][:, :3, 2] for i in range(n)], axis=2)
    jv = np.stack([_cross(frames[i][:, :3, 2], tip - frames[i][:, :3, 3]) for i in range(n)], axis=2)
    return jv, jw
