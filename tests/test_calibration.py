"""Handle gravity calibration (spec chapter 6): fits recover known parameters; compensation inverts the
sensor model exactly; the record/trial precedence rule; coded errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.errors import HaptifyError
from haptify.formats.conventions import STANDARD_GRAVITY, quat_from_axis_angle, quat_multiply, quat_normalize
from haptify.formats.session_format import Pose
from haptify.formats.storage import open_session
from haptify.processing import calibration
from haptify_tools import rig_builders as rb


def _unit_vectors(n: int, rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_sphere_fit_recovers_centre_radius_and_noise():
    rng = np.random.default_rng(0)
    centre, radius, sigma, n = np.array([0.3, -0.2, 0.5]), 0.51, 0.004, 4000
    pts = centre + radius * _unit_vectors(n, rng) + rng.normal(0, sigma, (n, 3))
    fit = calibration.fit_sphere(pts)
    # geometric fit: the centre is known to ~ sigma·sqrt(3/n) per axis, radius to ~ sigma/sqrt(n)
    assert np.allclose(fit.centre, centre, atol=5 * sigma * np.sqrt(3 / n))
    assert fit.radius == pytest.approx(radius, abs=5 * sigma / np.sqrt(n))
    assert fit.rms == pytest.approx(sigma, rel=0.05)  # the radial residual of isotropic noise has sd sigma
    assert fit.coverage == pytest.approx(1 / 3, abs=0.02)


def _tumble_directions(n: int, periods: float) -> np.ndarray:
    """Unit vectors along a slow continuous path that visits the whole sphere (time-ordered samples)."""
    t = np.linspace(0.0, 1.0, n)
    az, pol = 2 * np.pi * 2.3 * periods * t, np.pi * (0.5 + 0.45 * np.sin(2 * np.pi * 1.7 * periods * t))
    return np.column_stack([np.sin(pol) * np.cos(az), np.sin(pol) * np.sin(az), np.cos(pol)])


@pytest.mark.parametrize("phi", [0.0, 0.9])
def test_offset_uncertainty_matches_the_known_long_run_variance(phi):
    """Spec §6.2 step 5: for AR(1) noise e_k = φe_{k−1} + w_k (per axis, sd σ_w), the long-run variance is
    σ_w²/(1 − φ)², so Cov(c, ρ) = σ_w²/(1 − φ)²·(JᵀJ)⁻¹ with Jᵢ = −(uᵢ, 1); the batch-means estimate averaged over
    seeds agrees within its sampling spread, while σ²(JᵀJ)⁻¹ from the per-sample RMS misses by √((1 + φ)/(1 − φ))."""
    from scipy.signal import lfilter

    n, sigma_w, centre, radius = 3000, 0.002, np.array([0.31, -0.12, 0.45]), 0.51
    d = _tumble_directions(n, 1.0)
    jac = np.column_stack([d, np.ones(n)])
    cov = sigma_w**2 / (1 - phi) ** 2 * np.linalg.inv(jac.T @ jac)
    expected = np.sqrt(np.max(np.diag(cov)[:3]) + cov[3, 3])
    got = []
    for seed in range(12):
        noise = lfilter([1.0], [1.0, -phi], np.random.default_rng(seed).normal(0, sigma_w, (n, 3)), axis=0)
        got.append(calibration.fit_sphere(centre + radius * d + noise).offset_u)
    # 20 blocks: each estimate's u has a relative sd of 1/√38 ≈ 16 % (the mean of 12: 5 %), and batch means read
    # low by about the correlation time over the block length (φ = 0.9: 19 of 150 samples, ≈ −10 % on u)
    assert np.mean(got) == pytest.approx(expected, rel=0.2)
    per_sample = calibration.fit_sphere(centre + radius * d).rms  # noise-free: the fit is exact
    assert per_sample < 1e-9


def test_offset_uncertainty_of_a_twin_like_trial_covers_the_actual_bias_error(tmp_path):
    """Spec §14.7: rig.handle_force_offset_u of calibration trials with known white F/T noise is the spread of the
    fitted bias's actual error over independent trials (not the per-sample fit RMS, an order of magnitude larger)."""
    truth = rb.HandleTruth(force_noise=0.006)
    errors, us, rms = [], [], []
    for seed in range(8):
        w = rb.writer(sid=f"cal{seed}")
        rb.add_calibration_trial(w, truth, np.random.default_rng(seed), duration_s=12.0)
        w.write(tmp_path / f"s{seed}")
        cal = calibration.fit_trial(open_session(tmp_path / f"s{seed}"), "cal-1")
        errors.append(cal.force_bias_N - truth.force_bias)
        us.append(cal.force_offset_u_N)
        rms.append(cal.rms_force_N)
    actual = np.sqrt(np.max(np.mean(np.square(errors), axis=0)))
    assert 0.5 < np.mean(us) / actual < 2.0  # 8 trials: the actual spread itself is known to ~25 %
    assert np.mean(rms) > 4 * np.mean(us)  # 12 s of a 20 Hz low-passed noise: the fit RMS is ≈ 6× u_off


def test_sphere_fit_is_exact_without_noise():
    rng = np.random.default_rng(1)
    pts = np.array([1.0, 2.0, -3.0]) + 9.81 * _unit_vectors(200, rng)
    fit = calibration.fit_sphere(pts)
    assert np.allclose(fit.centre, [1.0, 2.0, -3.0], atol=1e-9)
    assert fit.radius == pytest.approx(9.81, abs=1e-9)
    assert fit.rms < 1e-9


def test_sphere_fit_refuses_one_great_circle_and_too_few_points():
    ang = np.linspace(0, 2 * np.pi, 300)
    circle = np.column_stack([np.cos(ang), np.sin(ang), 0 * ang])
    with pytest.raises(HaptifyError) as e:
        calibration.fit_sphere(circle)
    assert e.value.code == "E602"
    with pytest.raises(HaptifyError) as e:
        calibration.fit_sphere(_unit_vectors(10, np.random.default_rng(2)))
    assert e.value.code == "E602"


def test_torque_fit_recovers_bias_and_com_and_resists_outliers():
    rng = np.random.default_rng(3)
    n, mass, com, bias = 3000, 0.05, np.array([0.004, -0.003, 0.02]), np.array([0.01, -0.02, 0.005])
    load = mass * STANDARD_GRAVITY * _unit_vectors(n, rng)
    tau = bias + np.cross(com, load) + rng.normal(0, 1e-4, (n, 3))
    tau[::50] += 0.05  # 2 % gross outliers (e.g. the examiner bumped the handle)
    b, r, rms = calibration.fit_torque(tau, load)
    assert np.allclose(b, bias, atol=5e-5)  # soft-L1 leaves ~ share·f_scale of bias
    assert np.allclose(r, com, atol=5e-5)
    b_ls, r_ls, _ = calibration.fit_torque(tau, load, loss="linear")
    assert np.linalg.norm(b_ls - bias) > 10 * np.linalg.norm(b - bias)  # plain least squares is pulled away
    assert rms > 1e-4  # the RMS reports every residual, outliers included


@pytest.fixture(scope="module")
def calibration_session(tmp_path_factory):
    w = rb.writer()
    rb.add_calibration_trial(w, rb.HandleTruth(), np.random.default_rng(4), duration_s=16.0)
    return open_session(w.write(tmp_path_factory.mktemp("cal") / "s"))


def test_fit_from_a_trial_recovers_the_truth(calibration_session):
    truth = rb.HandleTruth()
    c = calibration.fit_trial(calibration_session, "cal-1")
    assert np.allclose(c.force_bias_N, truth.force_bias, atol=1e-3)
    assert c.connector_mass_kg == pytest.approx(truth.mass, abs=1e-4)
    assert np.allclose(c.connector_com_m, truth.com, atol=1e-4)
    assert np.allclose(c.torque_bias_Nm, truth.torque_bias, atol=2e-5)
    assert np.allclose(c.accel_bias_m_per_s2, truth.accel_bias, atol=0.01)
    assert c.gravity_m_per_s2 == pytest.approx(truth.gravity, abs=0.01)
    # low-passed white noise: the residual is below the raw noise level and above zero
    assert 0 < c.rms_force_N < truth.force_noise
    assert 0 < c.rms_accel_m_per_s2 < truth.accel_noise
    assert 0 < c.rms_torque_Nm < truth.torque_noise
    assert c.diagnostics["orientation_error_deg"] < 1.0  # the rig's sensor pose is right


def test_record_takes_precedence_and_trial_is_the_fallback(calibration_session, tmp_path):
    fitted = calibration.handle_calibration(calibration_session)
    assert fitted.source == "trial:cal-1" and fitted.rms_force_N is not None
    rec = rb.HandleTruth(mass=0.1).record("lab-cal")
    w = rb.writer(calibration=[rec])
    rb.add_calibration_trial(w, rb.HandleTruth(), np.random.default_rng(5), duration_s=4.0)
    c = calibration.handle_calibration(open_session(w.write(tmp_path / "with-record")))
    assert c.source == "record:lab-cal" and c.connector_mass_kg == 0.1
    assert calibration.HandleCalibration.from_record(open_session(tmp_path / "with-record").manifest.calibration[0]).to_record(
        "lab-cal"
    ) == {k: v for k, v in rec.items()}


def test_no_calibration_is_a_coded_error(example_session):
    with pytest.raises(HaptifyError) as e:
        calibration.handle_calibration(open_session(example_session))
    assert e.value.code == "E601"


def _random_quats(n: int, rng: np.random.Generator) -> np.ndarray:
    q = quat_normalize(rng.normal(size=(n, 4)))
    return q * np.where(q[:, :1] < 0, -1.0, 1.0)


def test_compensation_returns_exactly_the_hand_wrench_and_acceleration():
    """Raw readings made from a known hand wrench with rotated sensor frames come back exactly (no noise)."""
    rng = np.random.default_rng(6)
    truth = rb.HandleTruth(force_noise=0.0, torque_noise=0.0, accel_noise=0.0)
    rig = rb.rotated_rig()
    n = 500
    q = _random_quats(n, rng)
    f_hand, t_hand, acc = rng.normal(0, 2, (n, 3)), rng.normal(0, 0.1, (n, 3)), rng.normal(0, 5, (n, 3))
    t = np.arange(n) / 1000.0
    wrench, accel = rb.raw_handle(truth, rig, t, q, t, q, rng, f_hand, t_hand, acc)
    cal = calibration.HandleCalibration(
        force_bias_N=truth.force_bias,
        connector_mass_kg=truth.mass,
        connector_com_m=truth.com,
        torque_bias_Nm=truth.torque_bias,
        accel_bias_m_per_s2=truth.accel_bias,
        gravity_m_per_s2=truth.gravity,
    )
    raw = np.column_stack([wrench[c] for c in ("fx", "fy", "fz", "tx", "ty", "tz")])
    f, tq = calibration.compensate_wrench(raw, q, cal, Pose.model_validate(rig["handle"]["ft_sensor"]["pose"]))
    assert np.allclose(f, f_hand, atol=1e-10) and np.allclose(tq, t_hand, atol=1e-10)
    a = calibration.compensate_accel(
        np.column_stack([accel[c] for c in ("ax", "ay", "az")]),
        q,
        cal,
        Pose.model_validate(rig["handle"]["accelerometer"]["pose"]),
    )
    assert np.allclose(a, acc, atol=1e-10)


@settings(max_examples=25, deadline=None)
@given(yaw=st.floats(-np.pi, np.pi), seed=st.integers(0, 2**16))
def test_rotating_the_world_about_vertical_rotates_outputs_and_keeps_magnitudes(yaw, seed):
    """A world frame turned about z (gravity unchanged) leaves the raw readings unchanged: the reported
    vectors turn with the frame and their magnitudes stay the same."""
    rng = np.random.default_rng(seed)
    cal = calibration.HandleCalibration(
        force_bias_N=rng.normal(0, 0.3, 3),
        connector_mass_kg=0.05,
        connector_com_m=rng.normal(0, 0.01, 3),
        torque_bias_Nm=rng.normal(0, 0.01, 3),
        accel_bias_m_per_s2=rng.normal(0, 0.1, 3),
        gravity_m_per_s2=9.8,
    )
    pose = Pose.model_validate(rb.rotated_rig()["handle"]["ft_sensor"]["pose"])
    q = _random_quats(20, rng)
    raw = rng.normal(0, 1, (20, 6))
    turn = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), np.array(yaw))
    q2 = quat_multiply(np.broadcast_to(turn, q.shape), q)
    f1, t1 = calibration.compensate_wrench(raw, q, cal, pose)
    f2, t2 = calibration.compensate_wrench(raw, q2, cal, pose)
    assert np.allclose(np.linalg.norm(f1, axis=1), np.linalg.norm(f2, axis=1))
    assert np.allclose(np.linalg.norm(t1, axis=1), np.linalg.norm(t2, axis=1))
    c, s = np.cos(yaw), np.sin(yaw)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert np.allclose(f2, f1 @ rz.T) and np.allclose(t2, t1 @ rz.T)
    a1 = calibration.compensate_accel(raw[:, :3], q, cal, pose)
    a2 = calibration.compensate_accel(raw[:, :3], q2, cal, pose)
    assert np.allclose(np.linalg.norm(a1, axis=1), np.linalg.norm(a2, axis=1))


def test_a_wrong_sensor_pose_in_the_rig_shows_as_orientation_error(tmp_path):
    """Data recorded with the true sensor pose, described with one turned 10° about x: a direction at angle θ
    from the x axis is off by ≈ 10°·sin θ, so over directions covering the sphere the RMS is
    10°·sqrt(E[sin²θ]) = 10°·sqrt(2/3) ≈ 8.2° (spec §6.3); the fitted parameters do not depend on the pose."""
    w = rb.writer()
    rb.add_calibration_trial(w, rb.HandleTruth(), np.random.default_rng(12), duration_s=12.0)
    wrong = quat_multiply(
        np.asarray(w.manifest["rig"]["handle"]["ft_sensor"]["pose"]["quaternion"]),
        quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), np.array(np.radians(10.0))),
    )
    w.manifest["rig"]["handle"]["ft_sensor"]["pose"]["quaternion"] = wrong.tolist()
    c = calibration.fit_trial(open_session(w.write(tmp_path / "s")), "cal-1")
    assert c.diagnostics["orientation_error_deg"] == pytest.approx(10.0 * np.sqrt(2 / 3), abs=0.5)
    assert c.connector_mass_kg == pytest.approx(rb.HandleTruth().mass, abs=1e-4)
