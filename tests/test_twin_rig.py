"""The virtual rig's sensor models (design §4): noise levels and biases come out as configured, and the raw
streams follow the reference's sign conventions (haptify.processing.calibration, spec §6.1)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.formats.conventions import STANDARD_GRAVITY, quat_conjugate, quat_normalize, quat_rotate
from haptify.formats.session_format import Pose, Rig
from haptify.processing.calibration import HandleCalibration, compensate_accel, compensate_wrench
from haptify_tools.twin import rig as rg
from haptify_tools.twin.model import NoiseFloor

N = 4000
RATE = 2000.0
quiet = dataclasses.replace(
    rg.RigConfig(),
    ft_force_noise_N=0.0,
    ft_torque_noise_Nm=0.0,
    accel_lsb_m_per_s2=0.0,
    plate_force_noise_N=0.0,
    plate_torque_noise_Nm=0.0,
)


def _random_quats(rng, n):
    return quat_normalize(rng.normal(size=(n, 4)))


def _static(q, n=N):
    return np.zeros((n, 3)) + [0.1, 0.05, 0.2], np.broadcast_to(q, (n, 4)).copy()


def _sensor_pose(cfg):
    return Pose(position=list(cfg.ft_pose_position_m), quaternion=rg.yaw_quat(cfg.ft_pose_yaw_rad).tolist())


@settings(max_examples=10, deadline=None)
@given(bias=st.lists(st.floats(-2, 2), min_size=3, max_size=3), mass=st.floats(0.0, 0.2), seed=st.integers(0, 2**31))
def test_handle_wrench_noise_bias_and_connector_weight(bias, mass, seed):
    rng = np.random.default_rng(seed)
    cfg = rg.RigConfig()
    q = _random_quats(rng, 1)[0]
    pos, quat = _static(q)
    com = np.array([0.0, 0.01, 0.02])
    cols = rg.handle_wrench(
        rng,
        cfg,
        position_W=pos,
        quaternion_W=quat,
        rate_hz=RATE,
        loads=None,
        bias_force=np.array(bias),
        bias_torque=np.zeros(3),
        connector_mass=mass,
        connector_com_S=com,
    )
    f = np.stack([cols["fx"], cols["fy"], cols["fz"]], axis=1)
    assert len(f) == N // 2  # 1 kHz from a 2 kHz path
    # paper eq. 1: F = b + m g_S, with g_S gravity (down) in the sensor frame
    q_ws = rg.quat_multiply(q, rg.yaw_quat(cfg.ft_pose_yaw_rad))
    g_s = quat_rotate(quat_conjugate(q_ws), np.array([0, 0, -STANDARD_GRAVITY]))
    assert np.allclose(f.mean(axis=0), np.array(bias) + mass * g_s, atol=4 * cfg.ft_force_noise_N / math.sqrt(len(f)))
    assert np.std(f, axis=0) == pytest.approx(np.full(3, cfg.ft_force_noise_N), rel=0.1)
    t = np.stack([cols["tx"], cols["ty"], cols["tz"]], axis=1)
    assert np.allclose(t.mean(axis=0), np.cross(com, mass * g_s), atol=4 * cfg.ft_torque_noise_Nm / math.sqrt(len(t)))  # eq. 3
    assert np.std(t, axis=0) == pytest.approx(np.full(3, cfg.ft_torque_noise_Nm), rel=0.1)


def test_reference_compensation_recovers_the_device_wrench():
    """Raw → haptify.processing.calibration.compensate_wrench gives back the device's force and torque at the gimbal."""
    rng = np.random.default_rng(1)
    n = 400
    quat = _random_quats(rng, 1).repeat(n, axis=0)  # one fixed pose per call (no connector inertia)
    pos = np.zeros((n, 3)) + [0.2, 0.0, 0.1]
    f_dev, t_dev = rng.normal(size=(n // 2, 3)), 0.05 * rng.normal(size=(n // 2, 3))
    bias_f, bias_t, m, com = np.array([0.3, -0.2, 1.0]), np.array([0.01, 0.0, -0.02]), 0.05, np.array([0.0, 0.0, 0.025])
    cols = rg.handle_wrench(
        rng,
        quiet,
        position_W=pos,
        quaternion_W=quat,
        rate_hz=RATE,
        loads=rg.HandleLoads(f_dev, t_dev),
        bias_force=bias_f,
        bias_torque=bias_t,
        connector_mass=m,
        connector_com_S=com,
    )
    raw = np.stack([cols[c] for c in ("fx", "fy", "fz", "tx", "ty", "tz")], axis=1)
    cal = HandleCalibration(
        force_bias_N=bias_f,
        connector_mass_kg=m,
        connector_com_m=com,
        torque_bias_Nm=bias_t,
        accel_bias_m_per_s2=np.zeros(3),
        gravity_m_per_s2=STANDARD_GRAVITY,
    )
    f, t = compensate_wrench(raw, quat[::2], cal, _sensor_pose(quiet))
    assert np.allclose(f, f_dev, atol=1e-9) and np.allclose(t, t_dev, atol=1e-9)


def test_accelerometer_reads_plus_g_up_at_rest_with_bias_and_quantisation():
    rng = np.random.default_rng(2)
    cfg = rg.RigConfig()
    q = _random_quats(rng, 1)[0]
    pos, quat = _static(q)
    bias = np.array([0.15, -0.1, 0.2])
    true_a = rg.specific_force(cfg, position_W=pos, quaternion_W=quat, rate_hz=RATE, vibration_W=None, floor_W=None)
    cols = rg.handle_accel(rng, cfg, specific_force_A=true_a, bias=bias)
    a = np.stack([cols["ax"], cols["ay"], cols["az"]], axis=1)
    q_wa = rg.quat_multiply(q, rg.yaw_quat(cfg.accel_pose_yaw_rad))
    up = quat_rotate(quat_conjugate(q_wa), np.array([0, 0, STANDARD_GRAVITY]))
    assert np.allclose(true_a, up, atol=1e-9)  # the perfect reading (truth.npz)
    assert np.allclose(a, up + bias, atol=cfg.accel_lsb_m_per_s2 / 2 + 1e-12)  # paper eq. 2, +g up
    assert np.allclose(a / cfg.accel_lsb_m_per_s2, np.round(a / cfg.accel_lsb_m_per_s2), atol=1e-6)
    # the reference removes it again
    cal = HandleCalibration(
        force_bias_N=np.zeros(3),
        connector_mass_kg=0.0,
        connector_com_m=np.zeros(3),
        torque_bias_Nm=np.zeros(3),
        accel_bias_m_per_s2=bias,
        gravity_m_per_s2=STANDARD_GRAVITY,
    )
    pose = Pose(position=list(cfg.accel_pose_position_m), quaternion=rg.yaw_quat(cfg.accel_pose_yaw_rad).tolist())
    assert np.abs(compensate_accel(a, quat, cal, pose)).max() < cfg.accel_lsb_m_per_s2


def test_accelerometer_clips_at_its_range():
    cfg = rg.RigConfig()
    t = np.arange(N) / RATE
    pos = np.zeros((N, 3))
    pos[:, 0] = 0.05 * np.sin(2 * np.pi * 8 * t)  # 126 m/s² peak
    quat = np.tile([1.0, 0, 0, 0], (N, 1))
    true_a = rg.specific_force(cfg, position_W=pos, quaternion_W=quat, rate_hz=RATE, vibration_W=None, floor_W=None)
    cols = rg.handle_accel(np.random.default_rng(0), cfg, specific_force_A=true_a, bias=np.zeros(3))
    a = np.stack([cols["ax"], cols["ay"]], axis=1)
    lim = cfg.accel_range_m_per_s2
    assert np.abs(a).max() <= lim + cfg.accel_lsb_m_per_s2 and np.isclose(np.abs(a).max(), lim, atol=cfg.accel_lsb_m_per_s2)


@given(radius=st.floats(0.01, 0.1), hz=st.floats(0.5, 3.0))
@settings(max_examples=10, deadline=None)
def test_connector_acceleration_on_a_circle_is_centripetal(radius, hz):
    # a handle translating (no rotation) on a horizontal circle: the connector's centre accelerates by r ω²
    # towards the centre, whatever its offset from the handle (truth.npz's connector_inertia_W = m a_c)
    cfg = rg.RigConfig()
    t = np.arange(N) / RATE
    w = 2 * np.pi * hz
    pos = np.stack([radius * np.cos(w * t), radius * np.sin(w * t), np.zeros(N)], axis=1)
    quat = np.tile([1.0, 0, 0, 0], (N, 1))
    *_, a_c = rg.connector_motion(
        cfg, position_W=pos, quaternion_W=quat, rate_hz=RATE, connector_com_S=np.array([0.0, 0.01, 0.02])
    )
    inner = slice(10, -10)  # the finite differences' ends
    expected = -radius * w**2 * pos[::2][inner] / radius
    assert np.allclose(a_c[inner], expected, atol=1e-3 * radius * w**2 + 1e-9)


def test_noise_floor_levels_per_axis():
    floor = NoiseFloor(low_rms_m_per_s2=0.02, low_band_hz=[10.0, 100.0], high_rms_m_per_s2=0.03, high_band_hz=[100.0, 200.0])
    x = rg.noise_floor(np.random.default_rng(3), 40000, 2000.0, floor)
    assert np.sqrt(np.mean(x**2, axis=0)) == pytest.approx(np.full(3, math.hypot(0.02, 0.03)), rel=0.03)
    f = np.fft.rfftfreq(len(x), 1 / 2000.0)
    p = np.abs(np.fft.rfft(x, axis=0)) ** 2
    assert p[(f < 10) | (f > 200)].sum() / p.sum() < 1e-9


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-50, 50), min_size=6, max_size=6), st.lists(st.floats(-0.004, 0.004), min_size=8, max_size=8))
def test_corner_loads_reproduce_the_wrench(w, jitter):
    cfg = rg.RigConfig()
    pos = rg.corner_positions(cfg)
    pos[:, :2] += np.array(jitter).reshape(4, 2)
    force, moment = np.array([w[:3]]), np.array([w[3:]])
    c = rg.corner_loads(pos, force, moment)
    assert np.allclose(c.sum(axis=1), force, atol=1e-9)
    assert np.allclose(np.sum(np.cross(pos[None], c), axis=1), moment, atol=1e-9)


def test_plate_static_weight_bias_noise_and_cop():
    rng = np.random.default_rng(4)
    cfg = rg.RigConfig()
    n, weight, x, y = 3000, 19.6, 0.12, -0.08
    force = np.tile([0.0, 0.0, -weight], (n, 1))
    moment = np.cross(np.tile([x, y, 0.0], (n, 1)), force)
    bias = np.array([0.3, -0.2, 1.0])
    cols = rg.plate_wrench(rng, cfg, force_W=force, moment_W=moment, bias_force=bias)
    fz = []
    for c, q in enumerate(rg.corner_quaternions(cfg)):
        f_s = np.stack([cols[f"c{c + 1}_f{a}"] for a in "xyz"], axis=1) - bias
        fz.append(quat_rotate(np.broadcast_to(q, (n, 4)), f_s)[:, 2])
        assert np.std(cols[f"c{c + 1}_fz"]) == pytest.approx(cfg.plate_force_noise_N, rel=0.1)
        assert np.std(cols[f"c{c + 1}_tx"]) == pytest.approx(cfg.plate_torque_noise_Nm, rel=0.1)
        assert np.mean(cols[f"c{c + 1}_fz"]) - bias[2] == pytest.approx(np.mean(fz[-1]), abs=0.01)  # z axes aligned
    fz = np.mean(fz, axis=1)
    assert fz.sum() == pytest.approx(-(weight + cfg.plate_weight_N), abs=0.005)
    # centre of pressure from the corner readings (moment balance about the plate centre), plate weight removed
    load = fz + cfg.plate_weight_N / 4
    corners = rg.corner_positions(cfg)
    cop = (corners[:, :2] * load[:, None]).sum(axis=0) / load.sum()
    assert cop == pytest.approx([x, y], abs=5e-4)


def test_plate_mode_resonates_at_the_configured_frequency():
    from scipy import signal

    for f0 in (182.0, 205.0):
        b, a = rg.plate_mode_filter(f0, 0.03, 1000.0)
        w, h = signal.freqz(b, a, worN=20000, fs=1000.0)
        assert w[np.argmax(np.abs(h))] == pytest.approx(f0, abs=1.0)
        assert abs(h[0]) == pytest.approx(1.0)


def test_mocap_noise_and_occlusion():
    rng = np.random.default_rng(5)
    cfg = dataclasses.replace(rg.RigConfig(), occlusion_rate_per_s=0.5, occlusion_mean_s=0.1)
    n = 60000
    truth = {"m1": np.zeros((n, 3)) + [0.1, 0.2, 0.3]}
    cols, masks = rg.mocap_markers(rng, cfg, truth)
    x = np.stack([cols["m1_x"], cols["m1_y"], cols["m1_z"]], axis=1)
    nan = np.isnan(x)
    assert np.array_equal(nan[:, 0], nan[:, 2]) and np.array_equal(nan[:, 0], masks["m1"])  # all axes together
    ok = x[~nan[:, 0]] - truth["m1"][0]
    assert np.std(ok, axis=0) == pytest.approx(np.full(3, cfg.mocap_noise_m), rel=0.05)
    expected = 1 - math.exp(-cfg.occlusion_rate_per_s * cfg.occlusion_mean_s)  # Poisson gaps of exponential length
    assert nan[:, 0].mean() == pytest.approx(expected, rel=0.35)


def test_rig_description_is_a_valid_standard_rig():
    layout = rg.marker_layout(["link1", "link2", "link3"], [0.0, 0.135, 0.135])
    rig = Rig.model_validate(rg.rig_description(rg.RigConfig(), layout, extra_markers=("w1",)))
    names = [b.name for b in rig.motion_capture.rigid_bodies]
    assert names == ["base", "link1", "link2", "link3", "handle"]
    assert len(rig.motion_capture.markers) == 3 * 5 + 1


def test_sync_pulse():
    cfg = rg.RigConfig()
    t = 10.0 + np.arange(2000) / 1000.0
    trig = rg.sync_trigger(cfg, t, 10.0)["trigger"]
    assert trig.sum() == pytest.approx(cfg.sync_pulse_length_s * 1000, abs=1)
    assert t[np.argmax(trig)] == pytest.approx(10.0 + cfg.sync_pulse_start_s)
