"""Physics of the device twin: passive inverse dynamics, the 1 kHz active rendering loop, vibration (TWIN.md, Physics).

The examiner's hand is a kinematic input: it holds the handle rigidly, so the gimbal-centre position
and the handle orientation are given, and the simulator computes what the device does to the hand.

- Passive (power off): joint motion by inverse kinematics, then recursive Newton–Euler inverse dynamics
  of the links (gravity, link inertia), the motor rotors reflected through the capstans, drive friction
  (Coulomb with a smooth zero crossing, viscous, Stribeck) and the gimbal body → the force and torque
  the device applies to the hand at the gimbal centre, and the wrench the device applies to the force
  plate. The rotors hang on the elastic, backlashed cables (the same drive model as the active loop,
  with zero motor torque), so fast reversals make them lag, cross the backlash gap and ring; with
  ``drive.series_elasticity`` off the cables are rigid and the rotors' inertia and friction reach the
  links directly (then everything is vectorised).
- Active: a rendering loop like CHAI3D's plane example. The device's own position comes from the MOTOR
  encoders through the NOMINAL kinematics; penetration δ into the virtual plane gives the commanded
  force ``F = k·δ·n`` (logged); ``τ = Jᵀ F`` per joint, mapped to the drive axes, saturated and cut off,
  drives the motor rotors, which act on the links only through the elastic (and backlashed) cables.
  Drive compliance in series with the commanded stiffness makes the rendered stiffness softer; the
  saturation makes a force plateau; the cut-off makes the sudden drop; friction and inertia make
  planar forces on a frictionless plane. Nothing is painted on.

Frames: W (world) for inputs and outputs, D (device) inside; SI units.
"""

from __future__ import annotations

import hashlib
import json
import math
import threading
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import ValidationError
from scipy import signal

from haptify import kinematics as ref
from haptify.conventions import quat_conjugate, quat_multiply, quat_to_matrix
from haptify.errors import fail
from haptify.session_format import Kinematics, Rendering

from haptify_tools.twin import drive_loops
from haptify_tools.twin.hand_path import band_noise as _band_noise
from haptify_tools.twin.kinematics import (
    gimbal_angles,
    hand_to_joints,
    in_collision,
    link_transforms,
    nominal_kinematics,
    placement_matrix,
    rows_times,
    true_kinematics,
    world_to_device,
)
from haptify_tools.twin.model import TwinFile, twin_to_dict

DEFAULT_LOOP_HZ = 1000.0  # CHAI3D's haptic loop rate when the rendering does not say (paper §V-D)

# --- small helpers ------------------------------------------------------------------------------


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


def _check_path(t: np.ndarray, position_W: np.ndarray, quaternion_W: np.ndarray, uniform: bool = False):
    """Validate a hand path: E903 naming what is wrong (shapes, finite values, increasing time)."""
    t = np.asarray(t, dtype=float)
    p = np.atleast_2d(np.asarray(position_W, dtype=float))
    q = np.atleast_2d(np.asarray(quaternion_W, dtype=float))
    if t.ndim != 1 or len(t) < 3:
        raise fail(
            "E903",
            "the time vector must be one-dimensional with at least 3 samples",
            expected="(N,), N >= 3",
            found=list(t.shape),
        )
    if p.shape != (len(t), 3) or q.shape != (len(t), 4):
        raise fail(
            "E903",
            "hand positions must be (N, 3) and quaternions (N, 4) for N time samples",
            expected=[[len(t), 3], [len(t), 4]],
            found=[list(p.shape), list(q.shape)],
        )
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        raise fail("E903", "the hand path holds NaN or infinite values", expected="finite values", found="NaN/inf")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise fail("E903", "time must increase strictly", expected="t[i+1] > t[i]", found=int(np.argmin(dt > 0)))
    if uniform and np.max(np.abs(dt - dt[0])) > 1e-6 * dt[0]:
        raise fail(
            "E903",
            "the active loop needs uniformly sampled time",
            expected=f"steps of {dt[0]:g} s",
            found=[float(dt.min()), float(dt.max())],
        )
    return t, p, q


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


# --- rigid-body dynamics ------------------------------------------------------------------------


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


# --- passive ------------------------------------------------------------------------------------


@dataclass
class HandPathResult:
    """What the device does along a hand path, passive or active (W frame, SI units).
    The wrench on the hand as spec §1.5 defines it.

    ``force_W``/``torque_W``: force and torque the device applies to the hand at the gimbal centre.
    ``base_force_W``/``base_torque_W``: wrench the whole device (base included, with its full weight)
    applies to the force plate, torque about the W origin. ``q``: true joint angles; ``gimbal``: gimbal
    angles; ``ok``: False where the hand pose is out of the device's reach or puts the end-effector
    into the base (the hard stops are not modelled: values there are extrapolations).
    """

    t: np.ndarray
    q: np.ndarray
    gimbal: np.ndarray
    force_W: np.ndarray
    torque_W: np.ndarray
    base_force_W: np.ndarray
    base_torque_W: np.ndarray
    ok: np.ndarray


@dataclass
class PassiveResult(HandPathResult):
    """What the powered-off device does along a hand path: :class:`HandPathResult` plus the joint
    velocities ``qd`` and accelerations ``qdd`` and ``joint_torque``, the torque the hand's force produces
    at each joint, N·m."""

    qd: np.ndarray
    qdd: np.ndarray
    joint_torque: np.ndarray = field(repr=False)


def _jacobians(frames: list[np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray]:
    """Position and rotation Jacobians ``(N, 3, n)`` in D from already computed DH frames (revolute joints)."""
    tip = frames[-1][:, :3, 3]
    jw = np.stack([frames[i][:, :3, 2] for i in range(n)], axis=2)
    jv = np.stack([_cross(frames[i][:, :3, 2], tip - frames[i][:, :3, 3]) for i in range(n)], axis=2)
    return jv, jw


@dataclass
class _RigidPart:
    """Everything of the hand and plate wrenches that does not depend on the drive torques (device frame D):
    the gimbal body's wrench ``f_g, m_g``, the gimbal friction ``fric``, the Jacobians, ``rhs0 = τ0 + J_ωᵀ fric``
    (the joint torques the links need with no drive), the base's force/moment on link 1 ``f1, n1`` and the
    chain's ends ``o0, tip``."""

    f_g: np.ndarray
    m_g: np.ndarray
    fric: np.ndarray
    jac: np.ndarray
    rhs0: np.ndarray
    f1: np.ndarray
    n1: np.ndarray
    o0: np.ndarray
    tip: np.ndarray


def _rigid_part(twin, kin, t, q, qd, qdd, quat_W, gimbal, frames=None) -> _RigidPart:
    g_D = _gravity_D(twin)
    inert = twin.on("inertia")
    frames = frames if frames is not None else link_transforms(kin, q)
    st = _forward_pass(twin, kin, q, qd if inert else np.zeros_like(qd), qdd if inert else np.zeros_like(qdd), g_D, frames)
    tau0, f1, n1 = _backward_pass(twin, st)
    a_tip = st.acc_origin[-1] + g_D  # true acceleration of the gimbal centre
    f_g, m_g, fric = _gimbal_body_terms(twin, t, frames, gimbal, quat_W, a_tip, g_D)
    jac, jw = _jacobians(frames, len(twin.links))
    # Link n receives at the gimbal centre a force f_e and moment m_e = −fric from the gimbal.
    # τ_drive = τ0 − Jᵀ f_e − J_ωᵀ m_e  →  Jᵀ f_e = τ0 + J_ωᵀ fric − τ_drive
    rhs0 = tau0 + np.einsum("nik,ni->nk", jw, fric)
    return _RigidPart(f_g, m_g, fric, jac, rhs0, f1, n1, frames[0][:, :3, 3].copy(), frames[-1][:, :3, 3].copy())


def _hand_wrench_from_drive(twin, rigid: _RigidPart, tau_drive_joint):
    """Shared core: device→hand wrench (D) and device→plate wrench (D, about the device origin)
    given the torques the drives apply to the joints."""
    r = rigid
    f_e = np.linalg.solve(np.swapaxes(r.jac, 1, 2), (r.rhs0 - tau_drive_joint)[..., None])[..., 0]
    # The gimbal body: f_link_on_gimbal = −f_e; hand force on gimbal = m(a−g) + f_e
    force_hand = -(r.f_g + f_e)  # device → hand
    torque_hand = -(r.m_g - r.fric)  # device → hand about the gimbal centre
    # Base: link 1 gets f1,n1 from the base when no external load; with f_e, m_e on link n:
    f_base_on_link = r.f1 - f_e
    m_base_on_link = r.n1 - _cross(r.tip - r.o0, f_e) + r.fric
    force_plate = -f_base_on_link  # arm → base → plate (base static)
    torque_plate = -m_base_on_link + _cross(r.o0, force_plate)  # about the device origin
    # base weight
    wb = twin.base.mass_kg * _gravity_D(twin)
    force_plate = force_plate + wb
    torque_plate = torque_plate + _cross(np.asarray(twin.base.com_m), wb)
    joint_torque = np.einsum("nik,ni->nk", r.jac, -force_hand)
    return force_hand, torque_hand, force_plate, torque_plate, joint_torque


def _to_world(twin: TwinFile, force_D, torque_D, about_origin_D: bool = True):
    r_wd, t_wd = placement_matrix(twin)
    f = rows_times(force_D, r_wd.T)
    m = rows_times(torque_D, r_wd.T)
    if about_origin_D:
        m = m + _cross(t_wd, f)
    return f, m


#: What the arm's joint path cannot depend on (dynamics, drive): effect-id prefix → its parameters left out of
#: the memo key (None: the whole effect).
_NOT_KINEMATIC = {"gravity": None, "inertia": None, "friction.": None, "drive.": None, "vibration.": None}
#: What acts on the drive torques only, left out of the rigid part's memo key: the drive's effects and the drive
#: side of friction and inertia (the gimbal's friction and the links' inertia stay in).
_DRIVE_ONLY = {
    "friction.stribeck": None,
    "drive.": None,
    "vibration.": None,
    "inertia": ("rotor_inertia_kg_m2",),
    "friction.coulomb": ("torque_Nm", "ripple_fraction", "ripple_cycles_per_rad"),
    "friction.viscous": ("damping_Nms_per_rad",),
}


def _twin_key(twin: TwinFile, leave_out: Mapping[str, tuple[str, ...] | None]) -> str:
    """The twin as canonical JSON without what ``leave_out`` names, the drive's gearing, the rig and the prose."""
    data = twin_to_dict(twin)
    effects = {}
    for name, effect in data["effects"].items():
        drop = next((fields for prefix, fields in leave_out.items() if name.startswith(prefix)), ())
        if drop is not None:
            effects[name] = {k: v for k, v in effect.items() if k not in (*drop, "description", "sources")}
    data["effects"] = effects
    for k in ("drive", "rig", "sources", "description", "name"):
        data.pop(k)
    return json.dumps(data, sort_keys=True)


def _array_key(*arrays: np.ndarray) -> str:
    h = hashlib.blake2b(digest_size=16)
    for x in arrays:
        x = np.ascontiguousarray(x, float)
        h.update(str(x.shape).encode())
        h.update(x.data)
    return h.hexdigest()


class _Memo:
    """A small least-recently-used store of per-path arrays, bounded in bytes (read-only arrays: callers share them).

    The discrepancy workflow re-simulates the same measured paths with twins that differ in one drive or
    friction parameter: the joint path (inverse kinematics, gimbal angles, finite differences) and the
    rigid-body part of the wrench are the same for all of them.
    """

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes, self.size = max_bytes, 0
        self.items: OrderedDict[tuple, tuple[Any, int]] = OrderedDict()  # key → (value, bytes); values of any kind
        self.lock = threading.Lock()  # simulations may run in threads of one process

    def clear(self) -> None:
        with self.lock:
            self.items.clear()
            self.size = 0

    def get(self, key):
        with self.lock:
            value = self.items.get(key)
            if value is not None:
                self.items.move_to_end(key)
            return value

    def put(self, key, value):
        arrays = [v for v in (value.__dict__.values() if hasattr(value, "__dict__") else value) if isinstance(v, np.ndarray)]
        for x in arrays:
            x.flags.writeable = False
        nbytes = sum(x.nbytes for x in arrays)
        if nbytes > self.max_bytes:
            return value
        with self.lock:
            if key not in self.items:
                self.items[key] = (value, nbytes)
                self.size += nbytes
            while self.size > self.max_bytes:
                _, (_, n) = self.items.popitem(last=False)
                self.size -= n
        return value


MEMO_BYTES = 1 << 30  # per process
_MEMO = _Memo(MEMO_BYTES)


@dataclass
class _JointPath:
    """The arm under a hand path: true kinematics, joint angles (IK), reachability (limits and base collision),
    gimbal angles, joint velocity and acceleration (finite differences), drive coupling ``C`` (θ = C·q);
    ``key`` identifies it (kinematic parts of the twin and the path) for :func:`_rigid_part_of`."""

    kin: Kinematics
    q: np.ndarray
    ok: np.ndarray
    gimbal: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    c: np.ndarray
    key: tuple
    frames: list | None = None  # the DH frames when just computed (not kept in the memo)


def _joint_path(twin, t: np.ndarray, position_W: np.ndarray, quaternion_W: np.ndarray) -> _JointPath:
    """The arm's joint path under a hand path (both trial types); remembered per kinematic twin and path (:class:`_Memo`)."""
    kin = true_kinematics(twin)
    key = ("joint path", _twin_key(twin, _NOT_KINEMATIC), _array_key(t, position_W, quaternion_W))
    hit = _MEMO.get(key)
    if hit is not None:
        q, ok, gimbal, qd, qdd = hit[0]
        return _JointPath(kin, q, ok, gimbal, qd, qdd, _coupling(twin), key)
    q, _, ok = hand_to_joints(twin, position_W, None)
    ok = ok & ~in_collision(twin, world_to_device(twin, position_W))
    q = _unwrap(q)
    frames = link_transforms(kin, q)
    gimbal = gimbal_angles(twin, q, quaternion_W, frames)
    qd = _diff(t, q)
    qdd = _diff(t, qd)
    _MEMO.put(key, (q, ok, gimbal, qd, qdd))
    return _JointPath(kin, q, ok, gimbal, qd, qdd, _coupling(twin), key, frames)


def _rigid_part_of(twin, jp: _JointPath, t: np.ndarray, quaternion_W: np.ndarray) -> _RigidPart:
    """:func:`_rigid_part` along a joint path, remembered per twin without its drive-only effects (:class:`_Memo`)."""
    key = ("rigid part", jp.key, _twin_key(twin, _DRIVE_ONLY))
    hit = _MEMO.get(key)
    if hit is not None:
        return hit[0]
    return _MEMO.put(key, _rigid_part(twin, jp.kin, t, jp.q, jp.qd, jp.qdd, quaternion_W, jp.gimbal, jp.frames))


def simulate_passive(twin: TwinFile, t: np.ndarray, position_W: np.ndarray, quaternion_W: np.ndarray) -> PassiveResult:
    """Simulate the powered-off device moved by the examiner's hand (design §4; TWIN.md, Physics).

    ``t (N,)`` s, strictly increasing (E903 otherwise); ``position_W (N, 3)`` gimbal-centre path in W, m;
    ``quaternion_W (N, 4)`` handle orientation (wxyz, handle → W). Velocities and accelerations are
    second-order finite differences, so give a smooth path sampled at ≥ 500 Hz. Drive friction and the
    reflected rotor inertia act on the drive axes ``θ = C·q`` and reach the joints as ``Cᵀ·τ``.
    """
    t, position_W, quaternion_W = _check_path(t, position_W, quaternion_W)
    jp = _joint_path(twin, t, position_W, quaternion_W)
    q, qd, qdd, c = jp.q, jp.qd, jp.qdd, jp.c
    th_d, th_dd = rows_times(qd, c.T), rows_times(qdd, c.T)
    j_refl = reflected_rotor_inertia(twin)
    if twin.on("drive.series_elasticity") and np.all(j_refl > 0) and len(t) > 2:
        tau_axis = _passive_drive(twin, t, rows_times(q, c.T), th_d)
    else:  # rigid cables (or massless rotors): friction and rotor inertia reach the links directly
        tau_axis = drive_friction(twin, th_d, rows_times(q, c.T)) - j_refl * th_dd
    tau_joint = rows_times(tau_axis, c)
    fh, th, fp, tp, jt = _hand_wrench_from_drive(twin, _rigid_part_of(twin, jp, t, quaternion_W), tau_joint)
    f_w, m_w = _to_world(twin, fh, th, about_origin_D=False)
    bf_w, bm_w = _to_world(twin, fp, tp)
    return PassiveResult(
        t=t,
        q=q,
        gimbal=jp.gimbal,
        force_W=f_w,
        torque_W=m_w,
        base_force_W=bf_w,
        base_torque_W=bm_w,
        ok=jp.ok,
        qd=qd,
        qdd=qdd,
        joint_torque=jt,
    )


# --- active -------------------------------------------------------------------------------------


@dataclass
class ActiveResult(HandPathResult):
    """What the powered device does while rendering a virtual plane: :class:`HandPathResult` plus
    ``commanded_W (N, 6)`` the force and torque the rendering loop commanded (the ``commanded_wrench``
    stream); ``encoder_q`` joint angles the device computes from its motor encoders; ``encoder_position_W``
    its own idea of the gimbal-centre position; ``motor_torque`` torque per drive axis after saturation and
    cut-off (capstan output, N·m); ``cable_torque`` torque the cables transmit to the links;
    ``saturated``/``cut_off`` flags per sample.
    """

    commanded_W: np.ndarray
    encoder_q: np.ndarray
    encoder_position_W: np.ndarray
    motor_torque: np.ndarray
    cable_torque: np.ndarray
    saturated: np.ndarray
    cut_off: np.ndarray


def simulate_active(
    twin: TwinFile, t: np.ndarray, hand_position_W: np.ndarray, hand_quaternion_W: np.ndarray, rendering: Rendering | dict
) -> ActiveResult:
    """Simulate the powered device rendering a frictionless virtual plane (TWIN.md, Physics; CHAI3D plane example).

    The loop runs at ``rendering.loop_rate_hz`` (default 1 kHz, CHAI3D's rate) on the samples of ``t``
    (uniform, a multiple of the loop rate, e.g. the examiner's 2 kHz); each iteration:
    motor encoders → nominal kinematics → device position p̂ → penetration ``δ = (p_s − p̂)·n`` →
    commanded ``F = k·max(δ, 0)·n`` (logged) → ``τ = Jᵀ(q̂)·F`` → drive axes → saturation
    (``drive.torque_saturation``) and cut-off (``drive.force_cutoff``) → motor rotors (reflected inertia,
    drive friction) → cables (``drive.series_elasticity``, ``drive.backlash``) → links → the force the hand
    feels (through the same link and gimbal dynamics as :func:`simulate_passive`). Loop outputs
    (command, motor torque, flags) are held between iterations; the cable torque (a period average)
    and the encoder angles are interpolated onto ``t``. With the series elasticity off the cable is
    rigid, the motor follows the link, and the loop is evaluated vectorised.
    """
    if isinstance(rendering, dict):
        try:
            rendering = Rendering.model_validate(rendering)
        except ValidationError as err:
            raise fail(
                "E903",
                f"invalid rendering: {err.errors()[0]['msg']}",
                expected="a session-format Rendering",
                found=str(err.errors()[0]["loc"]),
            ) from None
    if rendering.static_friction or rendering.dynamic_friction:
        raise fail(
            "E903",
            "the twin renders frictionless planes only (CHAI3D plane example with zero friction)",
            expected="static_friction = dynamic_friction = 0",
            found=[rendering.static_friction, rendering.dynamic_friction],
        )
    t, pos_W, quat_W = _check_path(t, hand_position_W, hand_quaternion_W, uniform=True)
    n_s = len(t)
    nom = nominal_kinematics(twin)
    jp = _joint_path(twin, t, pos_W, quat_W)
    q, qd, qdd, c = jp.q, jp.qd, jp.qdd, jp.c
    c_inv = np.linalg.inv(c)
    th_l, thd_l, thdd_l = rows_times(q, c.T), rows_times(qd, c.T), rows_times(qdd, c.T)
    r_wd, t_wd = placement_matrix(twin)
    nrm = np.asarray(rendering.surface_normal, dtype=float)
    nrm = nrm / np.linalg.norm(nrm)
    n_D = r_wd.T @ nrm
    ps_D = r_wd.T @ (np.asarray(rendering.surface_point_m, dtype=float) - t_wd)
    k_r = rendering.stiffness_N_per_m
    e = twin.effects
    n_j = q.shape[1]
    tau_max = np.asarray(e.drive_torque_saturation.max_torque_Nm) if e.drive_torque_saturation.enabled else np.full(n_j, np.inf)
    cut = e.drive_force_cutoff
    j_refl = reflected_rotor_inertia(twin)

    # the rendering loop runs at its own rate (CHAI3D: 1 kHz); the hand path may be sampled faster
    loop_hz = rendering.loop_rate_hz or DEFAULT_LOOP_HZ
    step = max(1, int(round(1.0 / (loop_hz * float(np.median(np.diff(t)))))) if n_s > 1 else 1)
    ticks = np.arange(0, n_s, step)
    hold_idx = np.minimum(np.arange(n_s) // step, len(ticks) - 1)  # zero-order hold of loop outputs
    if not e.drive_series_elasticity.enabled:
        # rigid cable: the encoders see the link-side drive angles
        enc_q = rows_times(th_l, c_inv.T)
        p_enc = ref.forward_positions(nom, enc_q)
        depth = np.maximum(rows_times(ps_D - p_enc[ticks], n_D), 0.0)
        f_tick = k_r * depth[:, None] * n_D
        tau_cmd = rows_times(np.einsum("nik,ni->nk", ref.jacobian(nom, enc_q[ticks]), f_tick), c_inv)
        motor = np.clip(tau_cmd, -tau_max, tau_max)
        sat_tick = np.any(np.abs(tau_cmd) > tau_max, axis=1)
        cut_tick = (
            drive_loops.cutoff_latch(k_r * depth, cut.trip_force_N, cut.rearm_force_N)
            if cut.enabled
            else np.zeros(len(ticks), bool)
        )
        motor[cut_tick] = 0.0
        motor, f_cmd_D, saturated, cut_flags = motor[hold_idx], f_tick[hold_idx], sat_tick[hold_idx], cut_tick[hold_idx]
        cable = motor + drive_friction(twin, thd_l, th_l) - j_refl * thdd_l
    else:
        se = e.drive_series_elasticity
        k = np.asarray(se.stiffness_Nm_per_rad)
        b = np.asarray(se.damping_Nms_per_rad)
        half_gap = 0.5 * np.asarray(e.drive_backlash.width_rad) if e.drive_backlash.enabled else np.zeros(n_j)
        motor_t, cable_t, enc_t, f_t, sat_t, cut_t = _render_loop(
            twin, t[ticks], th_l[ticks], thd_l[ticks], nom, c_inv, ps_D, n_D, k_r, tau_max, cut, j_refl, k, b, half_gap
        )
        motor, f_cmd_D, saturated, cut_flags = motor_t[hold_idx], f_t[hold_idx], sat_t[hold_idx], cut_t[hold_idx]
        if step == 1:
            cable, enc_q = cable_t, enc_t
        else:
            # the cable torque is a period average (centre of the period); encoders are read at the ticks
            t_tick = t[ticks]
            period = np.diff(t_tick, append=t_tick[-1] + step * (t[1] - t[0]))
            cable = np.stack([np.interp(t, t_tick + period / 2, cable_t[:, a]) for a in range(n_j)], axis=1)
            enc_q = np.stack([np.interp(t, t_tick, enc_t[:, a]) for a in range(n_j)], axis=1)
        p_enc = ref.forward_positions(nom, enc_q)

    tau_joint = rows_times(cable, c)
    fh, th, fp, tp, _ = _hand_wrench_from_drive(twin, _rigid_part_of(twin, jp, t, quat_W), tau_joint)
    f_w, m_w = _to_world(twin, fh, th, about_origin_D=False)
    bf_w, bm_w = _to_world(twin, fp, tp)
    commanded = np.concatenate([rows_times(f_cmd_D, r_wd.T), np.zeros((n_s, 3))], axis=1)
    p_enc_W = rows_times(p_enc, r_wd.T) + t_wd
    return ActiveResult(
        t=t,
        q=q,
        gimbal=jp.gimbal,
        force_W=f_w,
        torque_W=m_w,
        base_force_W=bf_w,
        base_torque_W=bm_w,
        ok=jp.ok,
        commanded_W=commanded,
        encoder_q=enc_q,
        encoder_position_W=p_enc_W,
        motor_torque=motor,
        cable_torque=cable,
        saturated=saturated,
        cut_off=cut_flags,
    )


def _exact_step(j: float, b: float, k: float, h: float) -> tuple[float, ...]:
    """Exact discretisation over ``h`` of ``J·z̈ + b·ż + k·z = 0``: (h, Φ00, Φ01, Φ10, Φ11, Ψ00, Ψ01, Ψ10, Ψ11),
    with Φ = exp(A·h) and Ψ = (1/h)∫₀ʰ exp(A·s) ds (the period average)."""
    from scipy.linalg import expm

    a = np.array([[0.0, 1.0], [-k / j, -b / j]])
    m = np.zeros((4, 4))  # Van Loan: expm([[A, I], [0, 0]]·h) holds ∫exp(As)ds
    m[:2, :2] = a * h
    m[:2, 2:] = np.eye(2) * h
    big = expm(m)
    phi = big[:2, :2]
    psi = big[:2, 2:] / h
    return (h, phi[0, 0], phi[0, 1], phi[1, 0], phi[1, 1], psi[0, 0], psi[0, 1], psi[1, 0], psi[1, 1])


def _passive_drive(twin: TwinFile, t: np.ndarray, th_l: np.ndarray, thd_l: np.ndarray) -> np.ndarray:
    """Cable torques ``(N, n)`` on the links of an unpowered drive whose rotors hang on elastic, backlashed
    cables (``drive.series_elasticity``, ``drive.backlash``) while the hand moves the links.

    The rotors are driven by the link motion through the cables and braked by the drive friction
    (evaluated at the link-side speed, as in the active loop); the zero motor torque makes this the
    active loop without its rendering part (:func:`.drive_loops.passive_drive`).
    """
    n_s, n_j = th_l.shape
    se = twin.effects.drive_series_elasticity
    bl = twin.effects.drive_backlash
    k, b = np.asarray(se.stiffness_Nm_per_rad, float), np.asarray(se.damping_Nms_per_rad, float)
    half_gap = 0.5 * np.asarray(bl.width_rad, float) if bl.enabled else np.zeros(n_j)
    j_refl = reflected_rotor_inertia(twin)
    dts = _periods(t)
    uniform = bool(np.allclose(dts, dts[0], rtol=1e-6, atol=1e-12))
    w_per = np.diff(th_l, axis=0) / dts[:-1, None] if n_s > 1 else np.zeros((0, n_j))
    w_per = np.concatenate([w_per, w_per[-1:] if len(w_per) else np.zeros((1, n_j))])
    # the link's velocity step at the end of each period, seen in the rotor's relative coordinate
    jumps = np.concatenate([w_per[:-1] - w_per[1:], np.zeros((1, n_j))])
    exact = _exact_steps(j_refl, b, k, float(dts[0]))
    return drive_loops.passive_drive(
        np.ascontiguousarray(drive_friction(twin, thd_l, th_l)), jumps, dts, k, b, half_gap, j_refl, exact, uniform
    )


def _periods(t: np.ndarray) -> np.ndarray:
    """Length (s) of each loop period starting at ``t``; the last repeats the one before (1 ms for a single sample)."""
    return np.diff(t, append=t[-1] + (t[-1] - t[-2] if len(t) > 1 else 1e-3))


def _exact_steps(j_refl: np.ndarray, b: np.ndarray, k: np.ndarray, h: float) -> np.ndarray:
    """:func:`_exact_step` per drive axis ``(n, 9)``; zeros for a massless rotor (it has no dynamics to step)."""
    return np.array([_exact_step(j, bb, kk, h) if j > 0 else (0.0,) * 9 for j, bb, kk in zip(j_refl, b, k)], float)


def _render_loop(twin, t, th_l, thd_l, nom, c_inv, ps_D, n_D, k_r, tau_max, cut, j_refl, k, b, half_gap):
    """The sequential loop with an elastic cable (:func:`.drive_loops.render_loop`): the nominal chain as DH
    rows, the drive friction at the link-side speed and angle, the exact cable steps over the first period."""
    dh = np.array([(jt.a, math.cos(jt.alpha), math.sin(jt.alpha), jt.d, jt.theta_offset) for jt in nom.joints], float)
    base_r = quat_to_matrix(np.asarray(nom.base.quaternion, float))
    dts = _periods(t)
    trip, rearm = (cut.trip_force_N, cut.rearm_force_N) if cut.enabled else (math.inf, -1.0)
    k, b, half_gap = (np.asarray(x, float) for x in (k, b, half_gap))
    return drive_loops.render_loop(
        np.ascontiguousarray(th_l, float),
        np.ascontiguousarray(thd_l, float),
        np.ascontiguousarray(drive_friction(twin, thd_l, th_l)),
        dts,
        dh,
        base_r,
        np.asarray(nom.base.position, float),
        np.asarray(c_inv, float),
        np.asarray(ps_D, float),
        np.asarray(n_D, float),
        float(k_r),
        np.asarray(tau_max, float),
        float(trip),
        float(rearm),
        k,
        b,
        half_gap,
        j_refl,
        _exact_steps(j_refl, b, k, float(dts[0])),
    )


# --- vibration ----------------------------------------------------------------------------------


def _resonance_noise(rng: np.random.Generator, n: int, fs: float, f0: float, q_factor: float) -> np.ndarray:
    """Unit-RMS noise ``(n, 3)`` through a second-order resonator at ``f0`` Hz with quality ``q_factor``."""
    f0 = min(f0, 0.45 * fs)
    b, a = signal.iirpeak(f0, q_factor, fs=fs)
    y = signal.lfilter(b, a, rng.standard_normal((n + 2000, 3)), axis=0)[2000:]
    rms = np.sqrt(np.mean(y**2, axis=0))
    return y / np.where(rms > 0, rms, 1.0)


def _sample_rate(t: np.ndarray) -> float:
    if len(t) < 2:
        raise ValueError("vibration needs at least two samples")
    return 1.0 / float(np.median(np.diff(t)))


def device_vibration(twin: TwinFile, t: np.ndarray, speed: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Parasitic acceleration ``(N, 3)`` the device adds at the handle, world axes, m/s² (effect ``vibration.device``).

    ``t`` uniform (the accelerometer's 2 kHz clock), ``speed`` the handle speed at ``t`` in m/s. Each
    broadband and resonant source is unit-RMS coloured noise scaled by its RMS at the reference speed,
    its axis weights (normalised so the three-axis RMS equals the configured value) and the speed law
    ``idle + (1 − idle)·(v/v_ref)^p``. Zeros when the effect is off.
    """
    t = np.asarray(t, dtype=float)
    eff = twin.effects.vibration_device
    out = np.zeros((len(t), 3))
    if not eff.enabled or len(t) < 2:
        return out
    fs = _sample_rate(t)
    v = np.maximum(np.asarray(speed, dtype=float), 0.0)
    law = eff.idle_fraction + (1.0 - eff.idle_fraction) * (v / eff.ref_speed_m_per_s) ** eff.speed_exponent
    for src in eff.broadband:
        w = np.asarray(src.axis_weights, dtype=float)
        w = w / np.linalg.norm(w)
        band = _band_noise(rng, len(t), fs, src.band_hz[0], min(src.band_hz[1], fs / 2), dims=3)
        out += src.rms_at_ref_speed_m_per_s2 * w * band * law[:, None]
    for res in eff.resonances:
        w = np.asarray(res.axis_weights, dtype=float)
        w = w / np.linalg.norm(w)
        out += (
            res.rms_at_ref_speed_m_per_s2 * w * _resonance_noise(rng, len(t), fs, res.frequency_hz, res.q_factor) * law[:, None]
        )
    return out
