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

The rigid-body dynamics and friction laws are in :mod:`haptify_tools.twin.rigid_body`, the drive stepped in
time in :mod:`haptify_tools.twin.drive_steps`, the device's parasitic vibration in
:mod:`haptify_tools.twin.vibration_model`; this module runs them along a hand path.
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import ValidationError

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.session_format import Kinematics, Rendering
from haptify.processing import kinematics as ref
from haptify_tools.twin import drive_loops
from haptify_tools.twin.drive_steps import _passive_drive, _render_loop
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
from haptify_tools.twin.rigid_body import (
    _backward_pass,
    _coupling,
    _cross,
    _diff,
    _forward_pass,
    _gimbal_body_terms,
    _gravity_D,
    _jacobians,
    _unwrap,
    drive_friction,
    reflected_rotor_inertia,
)

# potential_energy is re-exported for benchmarks/bench_stiffness_spread.py
from haptify_tools.twin.rigid_body import potential_energy as potential_energy

DEFAULT_LOOP_HZ = 1000.0  # CHAI3D's haptic loop rate when the rendering does not say (paper §V-D)


def _check_path(t: np.ndarray, position_W: np.ndarray, quaternion_W: np.ndarray, uniform: bool = False):
    """Validate a hand path: E903 naming what is wrong (shapes, finite values, increasing time)."""
    t = np.asarray(t, dtype=float)
    p = np.atleast_2d(np.asarray(position_W, dtype=float))
    q = np.atleast_2d(np.asarray(quaternion_W, dtype=float))
    if t.ndim != 1 or len(t) < 3:
        raise fail(
            Code.USAGE,
            "the time vector must be one-dimensional with at least 3 samples",
            expected="(N,), N >= 3",
            found=list(t.shape),
        )
    if p.shape != (len(t), 3) or q.shape != (len(t), 4):
        raise fail(
            Code.USAGE,
            "hand positions must be (N, 3) and quaternions (N, 4) for N time samples",
            expected=[[len(t), 3], [len(t), 4]],
            found=[list(p.shape), list(q.shape)],
        )
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        raise fail(Code.USAGE, "the hand path holds NaN or infinite values", expected="finite values", found="NaN/inf")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise fail(Code.USAGE, "time must increase strictly", expected="t[i+1] > t[i]", found=int(np.argmin(dt > 0)))
    if uniform and np.max(np.abs(dt - dt[0])) > 1e-6 * dt[0]:
        raise fail(
            Code.USAGE,
            "the active loop needs uniformly sampled time",
            expected=f"steps of {dt[0]:g} s",
            found=[float(dt.min()), float(dt.max())],
        )
    return t, p, q


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


def _world_wrenches(twin, jp: _JointPath, t: np.ndarray, quaternion_W: np.ndarray, tau_joint: np.ndarray):
    """The hand's force and torque and the base's force and moment in W (N, N·m) when the drives apply
    ``tau_joint`` along the joint path, and the joint torques (:func:`_hand_wrench_from_drive`)."""
    fh, th, fp, tp, jt = _hand_wrench_from_drive(twin, _rigid_part_of(twin, jp, t, quaternion_W), tau_joint)
    f_w, m_w = _to_world(twin, fh, th, about_origin_D=False)
    bf_w, bm_w = _to_world(twin, fp, tp)
    return f_w, m_w, bf_w, bm_w, jt


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
    f_w, m_w, bf_w, bm_w, jt = _world_wrenches(twin, jp, t, quaternion_W, tau_joint)
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
                Code.USAGE,
                f"invalid rendering: {err.errors()[0]['msg']}",
                expected="a session-format Rendering",
                found=str(err.errors()[0]["loc"]),
            ) from None
    if rendering.static_friction or rendering.dynamic_friction:
        raise fail(
            Code.USAGE,
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
    f_w, m_w, bf_w, bm_w, _ = _world_wrenches(twin, jp, t, quat_W, tau_joint)
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
