"""The twin's elastic, backlashed drive stepped in time (TWIN.md, Physics): the exact discretisation of a
rotor on its cable per loop period, the unpowered drive dragged by the hand (passive trials) and the 1 kHz
rendering loop with an elastic cable (active trials), both run by :mod:`haptify_tools.twin.drive_loops`."""

from __future__ import annotations

import math

import numpy as np

from haptify.formats.conventions import quat_to_matrix
from haptify_tools.twin import drive_loops
from haptify_tools.twin.model import TwinFile
from haptify_tools.twin.rigid_body import drive_friction, reflected_rotor_inertia


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
