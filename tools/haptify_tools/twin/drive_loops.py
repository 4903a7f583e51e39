"""The twin's sequential drive loops, compiled with numba (TWIN.md, Physics).

The elastic cable (``drive.series_elasticity``, ``drive.backlash``) makes the drive a state machine that
must be stepped sample by sample: the powered rendering loop (:func:`render_loop`, used by
:func:`haptify_tools.twin.physics.simulate_active`) and the unpowered drive dragged by the hand
(:func:`passive_drive`, used by :func:`haptify_tools.twin.physics.simulate_passive`); the cut-off latch
(:func:`cutoff_latch`) is the rigid drive's only sequential part. Everything here works on plain arrays
in drive-axis units (rad, rad/s, N·m) and the device frame D; :mod:`.drive_steps` prepares the inputs. The
functions are compiled on first use and cached on disk (numba ``cache=True``): the discrepancy workflow
re-simulates every active trial dozens of times, which plain-Python loops make slow (figures in
benchmarks/RESULTS.md).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Euler sub-steps per loop period near or inside the backlash gap (and without an exact step).
SUBSTEPS = 8


@njit(cache=True)
def axis_period(d, dd, u, k, b, g, j, exact, use_exact, margin, dt):
    """Advance one drive axis over a period ``dt`` (s) with a constant input torque ``u`` (N·m) on the rotor.

    State: cable deflection ``d = θ_motor − θ_link`` (rad) and its rate ``ḋ`` (rad/s); the link-side angle
    moves linearly within the period. Engaged on one side of the backlash gap (``|d| > g + margin``) and
    with ``use_exact``, the exact solution of ``J·d̈ + b·ḋ + k·(d ∓ g) = u`` is used (``exact`` from
    :func:`haptify_tools.twin.drive_steps._exact_step`); near or inside the gap, :data:`SUBSTEPS` semi-implicit
    Euler steps. Returns ``(d, ḋ, period-average cable torque)``.
    """
    if use_exact and abs(d) > g + margin:
        side = g if d > 0 else -g
        off = side + u / k
        z0 = d - off
        d_avg = off + exact[5] * z0 + exact[6] * dd
        dd_avg = exact[7] * z0 + exact[8] * dd
        return off + exact[1] * z0 + exact[2] * dd, exact[3] * z0 + exact[4] * dd, k * (d_avg - side) + b * dd_avg
    h = dt / SUBSTEPS
    acc = 0.0
    for _ in range(SUBSTEPS):
        if d > g:
            spring = k * (d - g) + b * dd
        elif d < -g:
            spring = k * (d + g) + b * dd
        else:
            spring = 0.0
        dd += h * (u - spring) / j
        d += h * dd
        acc += spring
    return d, dd, acc / SUBSTEPS


@njit(cache=True)
def dead_zone(d, g):
    """The cable's stretch beyond the backlash half-gap ``g`` (rad)."""
    if d > g:
        return d - g
    if d < -g:
        return d + g
    return 0.0


@njit(cache=True)
def passive_drive(friction, jumps, dts, stiffness, damping, half_gap, rotor_inertia, exact, use_exact):
    """Cable torques ``(N, n)`` on the links of an unpowered elastic drive (N·m).

    ``friction (N, n)``: drive friction at the link-side speed (N·m), the rotor's only input;
    ``jumps (N, n)``: the link's velocity step at the end of each period (rad/s); ``dts (N,)`` periods (s);
    per axis ``stiffness`` (N·m/rad), ``damping`` (N·m·s/rad), ``half_gap`` (rad), ``rotor_inertia``
    (kg·m²), ``exact (n, 9)`` the exact step over ``dts[0]`` and ``use_exact`` whether the periods are
    uniform. Each axis starts at rest relative to its link with the cable carrying the friction.
    """
    n_s, n_j = friction.shape
    out = np.zeros((n_s, n_j))
    for a in range(n_j):
        k, b, g, j = stiffness[a], damping[a], half_gap[a], rotor_inertia[a]
        f0 = friction[0, a]
        d = f0 / k + (g if f0 > 0 else (-g if f0 < 0 else 0.0))
        dd = 0.0
        for i in range(n_s):
            d, dd, out[i, a] = axis_period(d, dd, friction[i, a], k, b, g, j, exact[a], use_exact, 0.25 * g, dts[i])
            dd += jumps[i, a]
    return out


@njit(cache=True)
def cutoff_latch(force, trip, rearm):
    """Latched cut-off flags ``(N,)``: on when the commanded force (N) exceeds ``trip``, off below ``rearm``."""
    out = np.zeros(force.shape[0], np.bool_)
    on = False
    for i in range(force.shape[0]):
        if on and force[i] < rearm:
            on = False
        elif not on and force[i] > trip:
            on = True
        out[i] = on
    return out


@njit(cache=True)
def _command(th_m, dh, base_r, base_p, c_inv, surface_point, normal, k_r, tau_max, ta, qe, a_vec, f_vec, origins, axes):
    """One evaluation of the rendering software at motor angles ``θ_m`` (drive axes, rad): encoder joint
    angles ``qe`` → nominal DH chain (rows ``a, cos α, sin α, d, θ_offset``; base pose ``base_r``,
    ``base_p``) → penetration of the plane → commanded force ``f_vec`` (N, D) → drive torques ``ta``
    after saturation (N·m). ``a_vec = C⁻ᵀ Jᵀ n`` (zero out of contact). Returns (force magnitude, saturated?)."""
    n_j = th_m.shape[0]
    for r in range(n_j):
        s = 0.0
        for cc in range(n_j):
            s += c_inv[r, cc] * th_m[cc]
        qe[r] = s
    r00, r01, r02 = base_r[0, 0], base_r[0, 1], base_r[0, 2]
    r10, r11, r12 = base_r[1, 0], base_r[1, 1], base_r[1, 2]
    r20, r21, r22 = base_r[2, 0], base_r[2, 1], base_r[2, 2]
    px, py, pz = base_p[0], base_p[1], base_p[2]
    for i in range(n_j):
        origins[i, 0], origins[i, 1], origins[i, 2] = px, py, pz
        axes[i, 0], axes[i, 1], axes[i, 2] = r02, r12, r22
        a, ca, sa, d, off = dh[i, 0], dh[i, 1], dh[i, 2], dh[i, 3], dh[i, 4]
        th = qe[i] + off
        ct, st = np.cos(th), np.sin(th)
        tx, ty = a * ct, a * st
        px, py, pz = (px + r00 * tx + r01 * ty + r02 * d, py + r10 * tx + r11 * ty + r12 * d, pz + r20 * tx + r21 * ty + r22 * d)
        yx, yy = -st * ca, ct * ca
        zx, zy = st * sa, -ct * sa
        r00, r01, r02 = r00 * ct + r01 * st, r00 * yx + r01 * yy + r02 * sa, r00 * zx + r01 * zy + r02 * ca
        r10, r11, r12 = r10 * ct + r11 * st, r10 * yx + r11 * yy + r12 * sa, r10 * zx + r11 * zy + r12 * ca
        r20, r21, r22 = r20 * ct + r21 * st, r20 * yx + r21 * yy + r22 * sa, r20 * zx + r21 * zy + r22 * ca
    nx, ny, nz = normal[0], normal[1], normal[2]
    depth = (surface_point[0] - px) * nx + (surface_point[1] - py) * ny + (surface_point[2] - pz) * nz
    fmag = k_r * depth if depth > 0.0 else 0.0
    for cc in range(n_j):
        a_vec[cc] = 0.0
    for r in range(n_j):
        dx, dy, dz = px - origins[r, 0], py - origins[r, 1], pz - origins[r, 2]
        zx, zy, zz = axes[r, 0], axes[r, 1], axes[r, 2]
        jn = (zy * dz - zz * dy) * nx + (zz * dx - zx * dz) * ny + (zx * dy - zy * dx) * nz  # Jᵀ n, joint r
        for cc in range(n_j):
            a_vec[cc] += c_inv[r, cc] * jn
    sat = False
    for cc in range(n_j):
        ta[cc] = fmag * a_vec[cc]
        if ta[cc] > tau_max[cc]:
            ta[cc], sat = tau_max[cc], True
        elif ta[cc] < -tau_max[cc]:
            ta[cc], sat = -tau_max[cc], True
    if depth <= 0.0:
        for cc in range(n_j):
            a_vec[cc] = 0.0
    f_vec[0], f_vec[1], f_vec[2] = fmag * nx, fmag * ny, fmag * nz
    return fmag, sat


@njit(cache=True)
def _any_massless(rotor_inertia):
    """Whether any drive axis has a massless rotor (``rotor_inertia`` ≤ 0, kg·m²): :func:`render_loop`
    then balances the motors quasi-statically instead of integrating them."""
    for a in range(rotor_inertia.shape[0]):
        if rotor_inertia[a] <= 0.0:
            return True
    return False


@njit(cache=True)
def _render(th_m, scene, ws):
    """:func:`_command` at motor angles ``th_m`` (rad) for the rendering software's ``scene`` ``(dh, base_r,
    base_p, c_inv, surface_point, normal, k_r, tau_max)`` into the work arrays ``ws`` ``(ta, qe, a_vec, res,
    f_vec, origins, axes)`` of :func:`render_loop`. Returns (force magnitude, saturated?)."""
    dh, base_r, base_p, c_inv, surface_point, normal, k_r, tau_max = scene
    ta, qe, a_vec, _, f_vec, origins, axes = ws
    return _command(th_m, dh, base_r, base_p, c_inv, surface_point, normal, k_r, tau_max, ta, qe, a_vec, f_vec, origins, axes)


@njit(cache=True)
def _balance_motors(i, th_m, th_l, friction, stiffness, half_gap, latched, trip, scene, ws):
    """Massless rotors: solve the quasi-static balance ``k·dz(θ_m − θ_l) = τ(θ_m) + friction`` of period
    ``i`` for the motor angles ``th_m`` (rad, updated in place) by at most 6 Newton steps with the Jacobian
    ``K + k_r·A·Aᵀ`` (Sherman–Morrison), the command cut while ``latched`` or above ``trip`` (N); ``scene``
    and ``ws`` as in :func:`_render`."""
    k_r = scene[6]
    ta, a_vec, res = ws[0], ws[2], ws[3]
    n_j = th_m.shape[0]
    for _ in range(6):
        fmag, s_flag = _render(th_m, scene, ws)
        if latched or fmag > trip:
            ta[:] = 0.0
            a_vec[:] = 0.0
        for a in range(n_j):
            res[a] = stiffness[a] * dead_zone(th_m[a] - th_l[i, a], half_gap[a]) - ta[a] - friction[i, a]
        if s_flag:
            a_vec[:] = 0.0
        s_aa, s_ar = 0.0, 0.0
        for a in range(n_j):
            s_aa += a_vec[a] * (a_vec[a] / stiffness[a])
            s_ar += a_vec[a] * (res[a] / stiffness[a])
        proj = k_r * s_ar / (1.0 + k_r * s_aa)
        biggest = 0.0
        for a in range(n_j):
            step = res[a] / stiffness[a] - a_vec[a] / stiffness[a] * proj
            th_m[a] -= step
            biggest = max(biggest, abs(step))
        if biggest < 1e-12:
            break


@njit(cache=True)
def _latch(latched, fmag, trip, rearm):
    """The cut-off latch after a command of ``fmag`` (N): on above ``trip``, off below ``rearm``."""
    if latched and fmag < rearm:
        return False
    if not latched and fmag > trip:
        return True
    return latched


@njit(cache=True)
def _massless_cable(i, latched, th_m, th_l, friction, stiffness, half_gap, tau_c):
    """Massless rotors: the cable torques ``tau_c`` (N·m) of period ``i``; while cut off (``latched``) the
    motor relaxes onto the link within the period (``th_m`` updated in place)."""
    for a in range(th_m.shape[0]):
        if latched:
            th_m[a] = th_l[i, a] + friction[i, a] / stiffness[a]
            tau_c[a] = friction[i, a]
        else:
            tau_c[a] = stiffness[a] * dead_zone(th_m[a] - th_l[i, a], half_gap[a])


@njit(cache=True)
def _advance_rotors(
    i, th_m, w_m, th_l, thd_l, ta, friction, dts, stiffness, damping, half_gap, rotor_inertia, exact, margin, tau_c
):
    """Rotors with inertia: advance every axis over period ``i`` by :func:`axis_period` with the command
    ``ta`` (N·m) held, the link moving linearly to its next sample; updates the motor angles ``th_m`` (rad)
    and rates ``w_m`` (rad/s) and writes the period-average cable torques ``tau_c`` (N·m)."""
    n_s = th_l.shape[0]
    nxt = i + 1 if i + 1 < n_s else i
    dt = dts[i]
    for a in range(th_m.shape[0]):
        w_l = (th_l[nxt, a] - th_l[i, a]) / dt if dt > 0 else thd_l[i, a]
        use_exact = abs(dt - exact[a, 0]) < 1e-12
        d_new, dd_new, tau_c[a] = axis_period(
            th_m[a] - th_l[i, a],
            w_m[a] - w_l,
            ta[a] + friction[i, a],
            stiffness[a],
            damping[a],
            half_gap[a],
            rotor_inertia[a],
            exact[a],
            use_exact,
            margin[a],
            dt,
        )
        th_m[a] = th_l[nxt, a] + d_new
        w_m[a] = w_l + dd_new


@njit(cache=True)
def render_loop(
    th_l,
    thd_l,
    friction,
    dts,
    dh,
    base_r,
    base_p,
    c_inv,
    surface_point,
    normal,
    k_r,
    tau_max,
    trip,
    rearm,
    stiffness,
    damping,
    half_gap,
    rotor_inertia,
    exact,
):
    """The rendering loop with an elastic cable, one iteration per row of ``th_l (N, n)`` (link-side drive
    angles, rad; ``thd_l`` their rates, rad/s; ``friction (N, n)`` drive friction at them, N·m; ``dts`` the
    periods, s). Plane: ``surface_point``, unit ``normal`` (D), stiffness ``k_r`` (N/m); ``tau_max`` the
    torque limits (N·m, inf: none); cut-off ``trip``/``rearm`` (N; inf/−1: none); cable per axis as in
    :func:`passive_drive` (``exact`` rows valid where the rotor has inertia).

    Rotors with inertia: the command is held over the period and each axis is advanced by
    :func:`axis_period` (:func:`_advance_rotors`). Massless rotors (any ``rotor_inertia`` ≤ 0): the motor is
    in quasi-static balance with the cable (:func:`_balance_motors`, :func:`_massless_cable`). Returns motor
    torque, period-average cable torque, encoder joint angles (each ``(N, n)``), commanded force ``(N, 3)``
    (D), saturated and cut-off flags.
    """
    n_s, n_j = th_l.shape
    motor = np.zeros((n_s, n_j))
    cable = np.zeros((n_s, n_j))
    enc = np.zeros((n_s, n_j))
    fcmd = np.zeros((n_s, 3))
    sat = np.zeros(n_s, np.bool_)
    cutf = np.zeros(n_s, np.bool_)
    massless = _any_massless(rotor_inertia)
    th_m = th_l[0].copy()  # the motors start at rest on the links (cables relaxed)
    w_m = thd_l[0].copy()
    ta, qe, a_vec, res, tau_c = np.zeros(n_j), np.zeros(n_j), np.zeros(n_j), np.zeros(n_j), np.zeros(n_j)
    f_vec = np.zeros(3)
    origins, axes = np.zeros((n_j, 3)), np.zeros((n_j, 3))
    ws = (ta, qe, a_vec, res, f_vec, origins, axes)
    scene = (dh, base_r, base_p, c_inv, surface_point, normal, k_r, tau_max)
    margin = 0.25 * half_gap  # stay sub-stepped within a quarter gap of the gap's edge
    latched = False
    for i in range(n_s):
        if massless:
            _balance_motors(i, th_m, th_l, friction, stiffness, half_gap, latched, trip, scene, ws)
        fmag, s_flag = _render(th_m, scene, ws)
        latched = _latch(latched, fmag, trip, rearm)
        if latched:
            ta[:] = 0.0
        if massless:
            _massless_cable(i, latched, th_m, th_l, friction, stiffness, half_gap, tau_c)
        else:
            _advance_rotors(
                i, th_m, w_m, th_l, thd_l, ta, friction, dts, stiffness, damping, half_gap, rotor_inertia, exact, margin, tau_c
            )
        motor[i] = ta
        cable[i] = tau_c
        enc[i] = qe
        fcmd[i] = f_vec
        sat[i] = s_flag
        cutf[i] = latched
    return motor, cable, enc, fcmd, sat, cutf
