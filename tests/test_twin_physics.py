"""Known-answer physics of the device twin (TWIN.md, Physics): gravity, Coulomb friction, series stiffness,
saturation, cut-off, energy balance, base reaction, vibration."""

from __future__ import annotations

import numpy as np
import pytest

from haptify.formats.conventions import quat_from_axis_angle, quat_to_matrix
from haptify.processing import kinematics as ref
from haptify_tools.twin import kinematics as tk
from haptify_tools.twin import physics as ph
from haptify_tools.twin import rigid_body, vibration_model
from haptify_tools.twin.model import EFFECT_IDS, RIG_EFFECT_IDS, disable, preset, set_param

G = 9.80665


def only(twin, *keep):
    """The twin with every device effect switched off except ``keep``."""
    for eid in EFFECT_IDS:
        if eid not in keep and eid not in RIG_EFFECT_IDS:
            twin = disable(twin, eid)
    return twin


def massless(twin):
    """No link, gimbal or base mass."""
    for i in range(3):
        twin = set_param(twin, f"links.{i}.mass_kg", 0.0)
    twin = set_param(twin, "gimbal_body.mass_kg", 0.0)
    return set_param(twin, "base.mass_kg", 0.0)


def centre_q(twin):
    kin = tk.true_kinematics(twin)
    return ref.configurations_from_unit(kin, np.array([[0.5, 0.5, 0.5]]))[0]


def hold(twin, q, n=200, rate=1000.0):
    """A hand holding still at configuration ``q`` with the handle level."""
    kin = tk.true_kinematics(twin)
    p = tk.device_to_world(twin, ref.forward_positions(kin, q[None]))[0]
    t = np.arange(n) / rate
    return t, np.tile(p, (n, 1)), np.tile([1.0, 0, 0, 0], (n, 1))


# --- gravity ------------------------------------------------------------------------------------


@pytest.mark.parametrize("q2", [0.1, 0.6, 1.2])
def test_one_link_under_gravity_gives_the_analytic_torque(q2):
    tw = massless(only(preset("touch"), "gravity"))
    m, cx = 0.05, -0.04
    tw = set_param(tw, "links.1.mass_kg", m)
    tw = set_param(tw, "links.1.com_m", [cx, 0.0, 0.0])
    a2 = tw.device.kinematics.joints[1].a
    q = np.array([0.3, q2, -1.0])
    # inverse dynamics of the bare links
    tau = rigid_body.inverse_dynamics(tw, q[None], np.zeros((1, 3)), np.zeros((1, 3)))[0]
    expected = m * G * (a2 + cx) * np.cos(q2)
    assert tau == pytest.approx([0.0, expected, 0.0], abs=1e-12)
    # the hand holding the arm still supplies exactly that torque, and the device pulls it down
    t, p, quat = hold(tw, q)
    res = ph.simulate_passive(tw, t, p, quat)
    assert res.joint_torque[100] == pytest.approx([0.0, expected, 0.0], abs=1e-9)
    jac = ref.jacobian(tk.true_kinematics(tw), q[None])[0]
    assert jac.T @ (-res.force_W[100]) == pytest.approx([0.0, expected, 0.0], abs=1e-9)


def test_static_balance_of_the_whole_device_on_the_plate():
    """Weight = plate reaction + hand support, and the moments balance (the base's reaction)."""
    tw = only(preset("touch"), "gravity")
    q = np.array([0.4, 0.7, -1.4])
    t, p, quat = hold(tw, q)
    res = ph.simulate_passive(tw, t, p, quat)
    m_total = tw.base.mass_kg + sum(link.mass_kg for link in tw.links) + tw.gimbal_body.mass_kg
    weight = np.array([0.0, 0.0, -m_total * G])
    # forces on the device: weight, plate (−base_force), hand (−force_W) sum to zero
    assert res.base_force_W[100] == pytest.approx(weight - res.force_W[100], abs=1e-9)
    # moments about the W origin: the plate takes the weights' moment minus the hand's support
    kin = tk.true_kinematics(tw)
    frames = tk.link_transforms(kin, q[None])
    moment = np.cross(tk.device_to_world(tw, np.asarray(tw.base.com_m)[None])[0], [0, 0, -tw.base.mass_kg * G])
    for i, link in enumerate(tw.links):
        c = frames[i + 1][0, :3, :3] @ link.com_m + frames[i + 1][0, :3, 3]
        moment += np.cross(tk.device_to_world(tw, c[None])[0], [0, 0, -link.mass_kg * G])
    gc = p[100] + np.asarray(tw.gimbal_body.com_m)  # handle level: handle frame parallel to W
    moment += np.cross(gc, [0, 0, -tw.gimbal_body.mass_kg * G])
    moment -= np.cross(p[100], res.force_W[100]) + res.torque_W[100]
    assert res.base_torque_W[100] == pytest.approx(moment, abs=1e-9)


# --- friction -----------------------------------------------------------------------------------


@pytest.mark.parametrize("ripple", [0.0, 0.5])
def test_pure_coulomb_friction_opposes_the_motion_with_known_magnitude(ripple):
    tw = massless(only(preset("touch"), "friction.coulomb"))
    tw = set_param(tw, "friction.coulomb.ripple_fraction", ripple)
    tw = set_param(tw, "friction.coulomb.gimbal_torque_Nm", [0.0, 0.0, 0.0])
    tau_c = 0.02
    tw = set_param(tw, "friction.coulomb.torque_Nm", tau_c)
    kin = tk.true_kinematics(tw)
    t = np.arange(0, 1.0, 1e-3)
    w1 = 0.5  # rad/s about the vertical joint-1 axis: only drive axis 1 moves
    q = np.stack([-0.25 + w1 * t, 0.8 + 0 * t, -1.5 + 0 * t], axis=1)
    p = tk.device_to_world(tw, ref.forward_positions(kin, q))
    quat = np.tile([1.0, 0, 0, 0], (len(t), 1))
    res = ph.simulate_passive(tw, t, p, quat)
    v = np.gradient(p, t, axis=0)
    base = tk.device_to_world(tw, np.asarray(kin.base.position)[None])[0]
    rho = np.hypot(p[:, 0] - base[0], p[:, 1] - base[1])
    mid = slice(100, 900)
    mag = np.linalg.norm(res.force_W[mid], axis=1)
    ripple = 1.0 + tw.effects.friction_coulomb.ripple_fraction * np.sin(
        2 * np.pi * tw.effects.friction_coulomb.ripple_cycles_per_rad * q[mid, 0]
    )
    assert mag == pytest.approx(tau_c * ripple / rho[mid], rel=1e-6)
    cosang = np.sum(res.force_W[mid] * v[mid], axis=1) / (mag * np.linalg.norm(v[mid], axis=1))
    assert cosang == pytest.approx(-1.0, abs=1e-6)


def test_friction_only_dissipates():
    """Over any path the hand does positive work against friction and the torque never aids motion."""
    tw = massless(only(preset("touch"), "friction.coulomb", "friction.viscous", "friction.stribeck"))
    rng = np.random.default_rng(3)
    kin = tk.true_kinematics(tw)
    t = np.arange(0, 3.0, 1e-3)
    qc = centre_q(tw)
    q = qc + 0.2 * np.sin(2 * np.pi * np.outer(t, rng.uniform(0.3, 1.0, 3)) + rng.uniform(0, 6, 3))
    p = tk.device_to_world(tw, ref.forward_positions(kin, q))
    res = ph.simulate_passive(tw, t, p, np.tile([1.0, 0, 0, 0], (len(t), 1)))
    power_hand = np.sum(-res.force_W * np.gradient(p, t, axis=0), axis=1)
    assert np.all(power_hand[5:-5] >= -1e-9)


def test_passive_elastic_drive_tends_to_the_rigid_one():
    """Rotors on very stiff cables without backlash act like rigidly coupled rotors (same friction and inertia)."""
    base = massless(only(preset("touch"), "inertia", "friction.coulomb", "friction.viscous", "drive.series_elasticity"))
    base = set_param(base, "friction.coulomb.ripple_fraction", 0.0)
    kin = tk.true_kinematics(base)
    t = np.arange(0, 2.0, 1e-3)
    qc = centre_q(base)
    q = qc + 0.15 * np.stack([np.sin(2 * np.pi * 1.0 * t), np.sin(2 * np.pi * 0.7 * t), np.sin(2 * np.pi * 1.3 * t)], axis=1)
    p = tk.device_to_world(base, ref.forward_positions(kin, q))
    quat = np.tile([1.0, 0, 0, 0], (len(t), 1))
    stiff = set_param(
        set_param(base, "drive.series_elasticity.stiffness_Nm_per_rad", 2000.0),
        "drive.series_elasticity.damping_Nms_per_rad",
        1.0,
    )
    elastic = ph.simulate_passive(stiff, t, p, quat)
    rigid = ph.simulate_passive(disable(base, "drive.series_elasticity"), t, p, quat)
    sl = slice(200, -200)
    scale = np.max(np.abs(rigid.force_W[sl]))
    assert np.max(np.abs(elastic.force_W[sl] - rigid.force_W[sl])) < 0.05 * scale
    # a compliant, backlashed drive differs (the rotors lag and ring)
    soft = set_param(base, "drive.series_elasticity.stiffness_Nm_per_rad", 2.0)
    assert np.max(np.abs(ph.simulate_passive(soft, t, p, quat).force_W[sl] - rigid.force_W[sl])) > 0.1 * scale


def test_rendering_loop_runs_at_its_own_rate_on_a_faster_hand_clock():
    """A 2 kHz hand path with a 1 kHz loop: the command changes only every second sample, and the
    rendered stiffness is still the series value."""
    tw = massless(only(preset("touch"), "drive.series_elasticity", "inertia"))
    q = centre_q(tw)
    rate = 2000.0
    t, p, quat = hold(tw, q, n=int(4.0 * rate), rate=rate)
    surface = p[0].copy()
    s = t / t[-1]
    p = p.copy()
    p[:, 2] = surface[2] + 0.002 - 0.005 * 0.5 * (1 - np.cos(np.pi * s))
    rend = {
        "surface_point_m": surface.tolist(),
        "surface_normal": [0.0, 0.0, 1.0],
        "stiffness_N_per_m": 750.0,
        "loop_rate_hz": 1000.0,
    }
    res = ph.simulate_active(tw, t, p, quat, rend)
    fz = res.commanded_W[:, 2]
    assert np.all(fz[0::2] == fz[1::2])
    depth = surface[2] - p[:, 2]
    i, j = np.argmax(depth > 0.0005), len(t) - 1
    slope = (res.force_W[j, 2] - res.force_W[i, 2]) / (depth[j] - depth[i])
    assert slope == pytest.approx(series_value(tw, q), rel=0.02)


# --- energy -------------------------------------------------------------------------------------


def test_passive_arm_energy_balance():
    """Work done by the hand = change of kinetic plus potential energy (no friction)."""
    tw = only(preset("touch"), "gravity", "inertia")
    tw = set_param(tw, "gimbal_body.com_m", [0.0, 0.0, 0.0])
    kin = tk.true_kinematics(tw)
    rate = 4000.0
    t = np.arange(0, 1.5, 1 / rate)
    qc = centre_q(tw)
    q = qc + np.stack(
        [0.3 * np.sin(2 * np.pi * 1.1 * t), 0.25 * np.sin(2 * np.pi * 0.7 * t + 0.4), 0.3 * np.sin(2 * np.pi * 1.7 * t + 1.0)],
        axis=1,
    )
    p = tk.device_to_world(tw, ref.forward_positions(kin, q))
    ang = 0.3 * np.sin(2 * np.pi * 0.9 * t)
    quat = quat_from_axis_angle(np.array([0.3, 0.5, 0.8]), ang)
    res = ph.simulate_passive(tw, t, p, quat)
    v = np.gradient(p, t, axis=0)
    w = np.outer(np.gradient(ang, t), np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8]))
    power = np.sum(-res.force_W * v, axis=1) + np.sum(-res.torque_W * w, axis=1)
    m = rigid_body.mass_matrix(tw, res.q)
    ke_arm = 0.5 * np.einsum("ni,nij,nj->n", res.qd, m, res.qd)
    gb = tw.gimbal_body
    # gimbal body (COM at the gimbal centre here): translational plus rotational energy in body axes
    r = quat_to_matrix(quat)
    wb = np.einsum("nji,nj->ni", r, w)
    ke_g = 0.5 * gb.mass_kg * np.sum(v * v, axis=1) + 0.5 * np.einsum("ni,i,ni->n", wb, gb.inertia_kg_m2, wb)
    energy = ke_arm + ke_g + rigid_body.potential_energy(tw, res.q)
    sl = slice(20, -20)
    work = np.concatenate([[0.0], np.cumsum(0.5 * (power[sl][1:] + power[sl][:-1]) / rate)])
    change = energy[sl] - energy[sl][0]
    scale = np.max(np.abs(change))
    assert scale > 1e-3
    assert np.max(np.abs(work - change)) < 2e-3 * scale


# --- active rendering ---------------------------------------------------------------------------


def press(tw, depth_max, duration=4.0, rate=1000.0, stiffness=750.0):
    """A slow press straight down at the joint-box centre; returns result, true depth, rendering."""
    q = centre_q(tw)
    t, p, quat = hold(tw, q, n=int(duration * rate), rate=rate)
    surface = p[0].copy()
    s = np.clip(t / duration, 0, 1)
    p = p.copy()
    p[:, 2] = surface[2] + 0.002 - (depth_max + 0.002) * 0.5 * (1 - np.cos(np.pi * s))
    rend = {"surface_point_m": surface.tolist(), "surface_normal": [0.0, 0.0, 1.0], "stiffness_N_per_m": stiffness}
    res = ph.simulate_active(tw, t, p, quat, rend)
    return res, surface[2] - p[:, 2], q


def series_value(tw, q, k_r=750.0):
    """1 / (1/k_r + nᵀ J C⁻¹ K⁻¹ C⁻ᵀ Jᵀ n) at configuration q, n = z (known answer)."""
    kin = tk.true_kinematics(tw)
    jac = ref.jacobian(kin, q[None])[0]
    c_inv = np.linalg.inv(np.asarray(tw.drive.coupling))
    k = np.diag(tw.effects.drive_series_elasticity.stiffness_Nm_per_rad)
    compliance = jac @ c_inv @ np.linalg.inv(k) @ c_inv.T @ jac.T
    return 1.0 / (1.0 / k_r + compliance[2, 2])


@pytest.mark.parametrize("rotors", [False, True])
def test_commanded_stiffness_in_series_with_the_drive_gives_the_series_value(rotors):
    keep = ("drive.series_elasticity",) + (("inertia",) if rotors else ())
    tw = massless(only(preset("touch"), *keep))
    res, depth, q = press(tw, 0.003)
    expected = series_value(tw, q)
    i = np.argmax(depth > 0.0005)
    j = len(depth) - 1
    slope = (res.force_W[j, 2] - res.force_W[i, 2]) / (depth[j] - depth[i])
    assert slope == pytest.approx(expected, rel=0.02)
    assert expected < 0.9 * 750.0  # the drive really softens the rendering
    # the commanded force is along the plane's normal only
    assert np.all(res.commanded_W[:, :2] == 0.0) and np.all(res.commanded_W[:, 3:] == 0.0)
    assert np.all(res.commanded_W[:, 2] >= 0.0)


def test_commanded_force_is_stiffness_times_encoder_penetration():
    tw = massless(only(preset("touch-x"), "drive.series_elasticity", "inertia"))
    res, depth, q = press(tw, 0.004)
    kin = tk.true_kinematics(tw)
    surface_z = tk.device_to_world(tw, ref.forward_positions(kin, q[None]))[0, 2]
    expected = 750.0 * np.maximum(surface_z - res.encoder_position_W[:, 2], 0.0)
    assert res.commanded_W[:, 2] == pytest.approx(expected, abs=1e-9)
    # with the drive compliant the encoder sees less penetration than the true one
    assert np.all(surface_z - res.encoder_position_W[-1, 2] < depth[-1])


def test_saturation_makes_a_plateau_at_the_torque_limit():
    tw = massless(only(preset("touch"), "drive.series_elasticity", "drive.torque_saturation", "inertia"))
    tau_max = 0.2
    tw = set_param(tw, "drive.torque_saturation.max_torque_Nm", tau_max)
    res, depth, q = press(tw, 0.02, duration=6.0)
    kin = tk.true_kinematics(tw)
    jac = ref.jacobian(kin, q[None])[0]
    c_inv = np.linalg.inv(np.asarray(tw.drive.coupling))
    a = c_inv.T @ jac.T @ np.array([0, 0, 1.0])
    plateau = tau_max / np.max(np.abs(a))
    deep = depth > 0.015
    assert res.saturated[deep].all()
    # the felt force stays near the plateau although the commanded one keeps rising
    assert np.max(res.force_W[deep, 2]) < plateau * 1.1
    assert np.min(res.force_W[deep, 2]) > plateau * 0.85
    assert res.commanded_W[deep, 2][-1] > 2 * plateau


def test_force_cutoff_drops_the_force_suddenly():
    tw = massless(only(preset("touch-x"), "drive.series_elasticity", "drive.force_cutoff", "inertia"))
    tw = set_param(tw, "drive.force_cutoff.trip_force_N", 4.0)
    res, depth, q = press(tw, 0.015, duration=6.0)
    i = int(np.argmax(res.cut_off))
    assert res.cut_off[i:].all() and not res.cut_off[:i].any()
    assert res.commanded_W[i, 2] > 4.0 and res.commanded_W[i - 1, 2] <= 4.0
    before = res.force_W[i - 5, 2]
    assert before > 3.0
    assert np.max(np.abs(res.force_W[i + 20 :, 2])) < 0.6 * before  # a sudden drop (the drive mode rings out)
    assert np.all(np.abs(res.force_W[i + 400 :, 2]) < 0.1)  # and the drive has let go
    assert np.all(res.motor_torque[i:] == 0.0)


def test_frictionless_surface_planar_forces_come_from_friction_and_inertia():
    """Circles on a frictionless plane: zero commanded planar force, nonzero felt planar force,
    which vanishes when friction and inertia are switched off (the mechanism emerges from the model)."""
    base = preset("touch")
    q = centre_q(base)
    t, p, quat = hold(base, q, n=3000)
    surface = p[0].copy()
    p = p.copy()
    p[:, 0] += 0.03 * np.cos(2 * np.pi * 1.0 * t) - 0.03
    p[:, 1] += 0.03 * np.sin(2 * np.pi * 1.0 * t)
    p[:, 2] -= 0.001
    rend = {"surface_point_m": surface.tolist(), "surface_normal": [0.0, 0.0, 1.0], "stiffness_N_per_m": 750.0}
    full = ph.simulate_active(only(massless(base), "drive.series_elasticity", "friction.coulomb", "inertia"), t, p, quat, rend)
    bare = ph.simulate_active(only(massless(base), "drive.series_elasticity"), t, p, quat, rend)
    sl = slice(500, 2500)
    assert np.all(np.abs(full.commanded_W[:, :2]) < 1e-12)
    planar_full = np.mean(np.hypot(full.force_W[sl, 0], full.force_W[sl, 1]))
    planar_bare = np.mean(np.hypot(bare.force_W[sl, 0], bare.force_W[sl, 1]))
    assert planar_full > 0.05
    assert planar_bare < 0.1 * planar_full


# --- vibration ----------------------------------------------------------------------------------


def test_device_vibration_rms_and_speed_law():
    tw = preset("touch")
    eff = tw.effects.vibration_device
    fs = 2000.0
    t = np.arange(0, 20.0, 1 / fs)
    rng = np.random.default_rng(7)
    v_ref = eff.ref_speed_m_per_s
    a = vibration_model.device_vibration(tw, t, np.full(len(t), v_ref), rng)
    expected = np.sqrt(sum(s.rms_at_ref_speed_m_per_s2**2 for s in eff.broadband + eff.resonances))
    rms = np.sqrt(np.mean(np.sum(a**2, axis=1)))
    assert rms == pytest.approx(expected, rel=0.05)
    a2 = vibration_model.device_vibration(tw, t, np.full(len(t), 2 * v_ref), np.random.default_rng(7))
    rms2 = np.sqrt(np.mean(np.sum(a2**2, axis=1)))
    law = eff.idle_fraction + (1 - eff.idle_fraction) * 2**eff.speed_exponent
    assert rms2 == pytest.approx(expected * law, rel=0.05)
    assert not np.any(vibration_model.device_vibration(disable(tw, "vibration.device"), t, np.full(len(t), v_ref), rng))
    # deterministic for a seed
    again = vibration_model.device_vibration(tw, t, np.full(len(t), v_ref), np.random.default_rng(7))
    assert np.array_equal(a, again)


def test_resonant_vibration_peaks_at_its_frequency():
    tw = preset("touch-x")
    tw = set_param(tw, "vibration.device.broadband", [])
    f0 = tw.effects.vibration_device.resonances[0].frequency_hz
    fs = 2000.0
    t = np.arange(0, 10.0, 1 / fs)
    a = vibration_model.device_vibration(tw, t, np.full(len(t), 0.05), np.random.default_rng(1))
    spec = np.sum(np.abs(np.fft.rfft(a, axis=0)) ** 2, axis=1)
    f = np.fft.rfftfreq(len(t), 1 / fs)
    kernel = np.ones(41) / 41
    peak = f[np.argmax(np.convolve(spec, kernel, mode="same"))]
    assert peak == pytest.approx(f0, rel=0.05)


# --- bad input ----------------------------------------------------------------------------------


@pytest.mark.parametrize("case", ["short", "shape", "nan", "backwards", "friction"])
def test_bad_hand_paths_are_e903(case):
    from haptify.errors import HaptifyError

    tw = preset("touch")
    t, p, quat = hold(tw, centre_q(tw), n=50)
    rend = {"surface_point_m": p[0].tolist(), "surface_normal": [0.0, 0.0, 1.0], "stiffness_N_per_m": 750.0}
    if case == "short":
        t, p, quat = t[:2], p[:2], quat[:2]
    elif case == "shape":
        p = p[:, :2]
    elif case == "nan":
        p = p.copy()
        p[7, 1] = np.nan
    elif case == "backwards":
        t = t.copy()
        t[10] = t[9]
    elif case == "friction":
        rend["dynamic_friction"] = 0.3
    with pytest.raises(HaptifyError) as err:
        ph.simulate_active(tw, t, p, quat, rend)
    assert err.value.findings[0].code == "E903"
    if case != "friction":
        with pytest.raises(HaptifyError):
            ph.simulate_passive(tw, t, p, quat)


def test_backlash_delays_the_force_but_keeps_the_series_slope():
    """With play in the drive the force starts later, then rises with the series stiffness; massless
    (quasi-static Newton) and massive (dynamic) rotors agree on a slow press."""
    results = []
    for keep in [("drive.series_elasticity", "drive.backlash"), ("drive.series_elasticity", "drive.backlash", "inertia")]:
        tw = set_param(massless(only(preset("touch"), *keep)), "drive.backlash.width_rad", 0.01)
        res, depth, q = press(tw, 0.006)
        results.append(res.force_W[:, 2])
        touching = depth > 0.0002
        assert np.all(np.abs(res.force_W[touching & (depth < 0.0005), 2]) < 1e-3)  # lost motion first
        i, j = np.argmax(depth > 0.003), len(depth) - 1
        slope = (res.force_W[j, 2] - res.force_W[i, 2]) / (depth[j] - depth[i])
        assert slope == pytest.approx(series_value(tw, q), rel=0.03)
    assert results[0] == pytest.approx(results[1], abs=0.02)


def test_a_twin_without_effects_does_nothing_to_the_hand():
    """Every device effect off: the hand feels nothing along any path, the plate only the base's weight
    (and nothing once gravity is off too)."""
    tw = only(preset("touch-x"), "gravity")
    tw = set_param(massless(tw), "base.mass_kg", 1.5)
    for i in range(3):
        tw = set_param(tw, f"links.{i}.inertia_kg_m2", [0.0] * 6)
    kin = tk.true_kinematics(tw)
    rng = np.random.default_rng(9)
    t = np.arange(0, 1.0, 1e-3)
    q = centre_q(tw) + 0.2 * np.sin(2 * np.pi * np.outer(t, rng.uniform(0.5, 3.0, 3)) + rng.uniform(0, 6, 3))
    p = tk.device_to_world(tw, ref.forward_positions(kin, q))
    quat = quat_from_axis_angle(np.array([0.2, 1.0, 0.3]), 0.4 * np.sin(2 * np.pi * t))
    res = ph.simulate_passive(tw, t, p, quat)
    assert np.max(np.abs(res.force_W)) < 1e-12 and np.max(np.abs(res.torque_W)) < 1e-12
    assert res.base_force_W == pytest.approx(np.tile([0.0, 0.0, -1.5 * G], (len(t), 1)), abs=1e-12)
    res = ph.simulate_passive(disable(tw, "gravity"), t, p, quat)
    assert np.max(np.abs(res.base_force_W)) < 1e-12


# --- remembered paths ---------------------------------------------------------------------------


def _variants(base):
    """The preset with each effect switched the other way, with longer links and with a stronger gravity."""
    out = {}
    for effect in EFFECT_IDS:
        on = base.on(effect)
        out[f"{effect} {'off' if not on else 'on'}→{'on' if not on else 'off'}"] = set_param(base, f"{effect}.enabled", not on)
    links = set_param(base, "kinematics.link_length.delta_a_m", [0.004, 0.004, 0.004])
    out["link length +4 mm"] = set_param(links, "kinematics.link_length.enabled", True)
    out["gravity 10.5"] = set_param(base, "gravity.g_m_per_s2", 10.5)
    for key, value in (
        ("friction.coulomb.gimbal_torque_Nm", [0.004, 0.004, 0.004]),
        ("friction.coulomb.torque_Nm", [0.05] * 3),
        ("friction.coulomb.zero_crossing_velocity_rad_per_s", 0.01),
        ("friction.viscous.gimbal_damping_Nms_per_rad", [2e-4, 2e-4, 2e-4]),
        ("friction.viscous.damping_Nms_per_rad", [2e-3] * 3),
        ("inertia.rotor_inertia_kg_m2", [3e-6] * 3),
    ):
        out[f"{key} changed"] = set_param(base, key, value)
    return out


@pytest.mark.parametrize("kind", ["passive", "active"])
def test_remembered_joint_paths_and_rigid_parts_never_change_a_result(kind):
    """The in-process memo (TWIN.md: joint path and rigid-body part per path and twin) must be invisible: a twin
    simulated right after the preset on the same path gives exactly what it gives from scratch."""
    base = preset("touch")
    q = centre_q(base)
    t, p, quat = hold(base, q, n=3000)
    p = p + 0.02 * np.sin(2 * np.pi * 0.7 * t)[:, None] * np.array([1.0, 0.5, -0.8])  # reversals, some contact
    surface = p[0] - np.array([0.0, 0.0, 0.01])
    rend = {"surface_point_m": surface.tolist(), "surface_normal": [0.0, 0.0, 1.0], "stiffness_N_per_m": 750.0}

    def run(tw):
        r = ph.simulate_passive(tw, t, p, quat) if kind == "passive" else ph.simulate_active(tw, t, p, quat, rend)
        return np.concatenate([r.force_W, r.torque_W, r.base_force_W, r.base_torque_W], axis=1)

    for name, tw in _variants(base).items():
        ph._MEMO.clear()
        fresh = run(tw)
        ph._MEMO.clear()
        run(base)
        assert np.array_equal(run(tw), fresh, equal_nan=True), name
        if name.startswith(("gravity", "inertia", "friction.", "link length")):  # they act on any moving hand
            assert not np.array_equal(fresh, run(base), equal_nan=True), name
