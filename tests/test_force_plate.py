"""Force plate (spec §14.1–14.5): a point load at a known position gives the known wrench and COP;
damped sinusoids give their frequency; placements give the COP error they were built with."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.errors import HaptifyError
from haptify.formats.conventions import quat_from_axis_angle, quat_to_matrix
from haptify.formats.session_format import Rig
from haptify.formats.storage import open_session
from haptify.processing import force_plate
from haptify_tools import rig_builders as rb


def turned_corner_rig() -> dict:
    """The example rig with each corner sensor turned about z (45°, 135°, …), as a lab might mount them."""
    rig = rb.example_rig()
    for i, c in enumerate(rig["force_plate"]["corners"]):
        c["pose"]["quaternion"] = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), np.array(np.pi / 4 + i * np.pi / 2)).tolist()
    return rig


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(-0.29, 0.29),
    y=st.floats(-0.29, 0.29),
    fx=st.floats(-20, 20),
    fy=st.floats(-20, 20),
    fz=st.floats(-200, -5),
    turned=st.booleans(),
)
def test_point_load_gives_its_wrench_and_position(x, y, fx, fy, fz, turned):
    rig_dict = turned_corner_rig() if turned else rb.example_rig()
    pos, rot = force_plate.corner_geometry(Rig.model_validate(rig_dict))
    load = np.array([[fx, fy, fz]])
    point = np.array([[x, y, 0.0]])
    bias = rb.plate_bias_vector(rig_dict)
    raw = rb.corner_readings(rig_dict, load, point, bias)
    f, m = force_plate.total_wrench(raw, pos, rot, bias)
    assert np.allclose(f, load, atol=1e-9)
    assert np.allclose(m, np.cross(point, load), atol=1e-9)
    cop, ok = force_plate.center_of_pressure(f, m)
    assert ok.all() and np.allclose(cop, [[x, y]], atol=1e-9)  # horizontal force does not move the COP


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40))
def test_total_wrench_is_the_sum_of_the_rotated_corner_readings(seed, n):
    """Any corner poses and readings: F = Σ R_i (f_i − b_f,i) and M = Σ [R_i (τ_i − b_τ,i) + p_i × R_i (f_i − b_f,i)],
    the spec §14.1 sums written out sample by sample and corner by corner."""
    rng = np.random.default_rng(seed)
    rotations = quat_to_matrix(rng.normal(size=(4, 4)))
    positions = rng.uniform(-0.4, 0.4, size=(4, 3))
    raw = rng.normal(size=(n, 24)) * 50.0
    bias = rng.normal(size=24)
    force, moment = force_plate.total_wrench(raw, positions, rotations, bias)
    assert force.shape == moment.shape == (n, 3)
    for k in range(n):
        f_sum, m_sum = np.zeros(3), np.zeros(3)
        for c in range(4):
            f = rotations[c] @ (raw[k, 6 * c : 6 * c + 3] - bias[6 * c : 6 * c + 3])
            tau = rotations[c] @ (raw[k, 6 * c + 3 : 6 * c + 6] - bias[6 * c + 3 : 6 * c + 6])
            f_sum += f
            m_sum += tau + np.cross(positions[c], f)
        assert np.allclose(force[k], f_sum, rtol=1e-12, atol=1e-11)
        assert np.allclose(moment[k], m_sum, rtol=1e-12, atol=1e-11)


def test_paper_appendix_formula_for_vertical_loads():
    """With identity corner frames and pure vertical corner forces, M_x = L/2 (F1z + F2z − F3z − F4z) and
    M_y = L/2 (−F1z + F2z + F3z − F4z) (paper Appendix, L = 0.6 m); X = −M_y/F_z and Y = +M_x/F_z."""
    rig_dict = rb.example_rig()
    pos, rot = force_plate.corner_geometry(Rig.model_validate(rig_dict))
    fz = np.array([-3.0, -5.0, -11.0, -7.0])
    raw = np.zeros((1, 24))
    raw[0, 2::6] = fz
    f, m = force_plate.total_wrench(raw, pos, rot)
    half = 0.3
    assert m[0, 0] == pytest.approx(half * (fz[0] + fz[1] - fz[2] - fz[3]))
    assert m[0, 1] == pytest.approx(half * (-fz[0] + fz[1] + fz[2] - fz[3]))
    cop, _ = force_plate.center_of_pressure(f, m)
    assert cop[0, 0] == pytest.approx(-m[0, 1] / f[0, 2]) and cop[0, 1] == pytest.approx(m[0, 0] / f[0, 2])
    # more load on c3/c4 (y < 0) and on c2/c3 (x < 0): the COP lies in the −x, −y quadrant
    assert cop[0, 0] < 0 and cop[0, 1] < 0


def test_cop_is_undefined_below_the_force_threshold():
    f = np.array([[0.0, 0.0, -0.5], [0.0, 0.0, -50.0]])
    m = np.array([[0.1, 0.1, 0.0], [-5.0, 2.5, 0.0]])
    cop, ok = force_plate.center_of_pressure(f, m)
    assert ok.tolist() == [False, True] and np.isnan(cop[0]).all() and np.allclose(cop[1], [0.05, 0.1])


@pytest.mark.parametrize("f_hz", [35.0, 182.0, 205.0, 206.0, 300.0])
def test_damped_sinusoid_gives_its_frequency(f_hz):
    t = np.arange(3000) / 1000.0
    x = rb.damped(t, f_hz, 0.02, 1.0, 5.0)
    idx = force_plate.impact_window(t, np.column_stack([x, x, x]))
    # the magnitude spectrum of a lightly damped sinusoid peaks at its damped frequency (within ~0.1 %)
    assert force_plate.dominant_frequency(x[idx], 1000.0) == pytest.approx(f_hz, abs=0.2)


def test_three_axes_get_their_own_frequencies():
    t = np.arange(3000) / 1000.0
    force = np.column_stack(
        [rb.damped(t, 205.0, 0.03, 1.0, 4.0), rb.damped(t, 206.0, 0.03, 1.0, 3.0), rb.damped(t, 182.0, 0.03, 1.0, 20.0)]
    )
    assert np.allclose(force_plate.natural_frequencies(t, force, 1000.0), [205.0, 206.0, 182.0], atol=0.3)


def test_flat_signal_has_no_peak():
    with pytest.raises(HaptifyError) as e:
        force_plate.dominant_frequency(np.ones(500), 1000.0)
    assert e.value.code == "E622"


def test_placements_and_cop_error_by_construction(tmp_path):
    rig = rb.rotated_rig()
    rig["motion_capture"]["markers"] = ["h1", "h2", "h3", "w1"]
    w = rb.writer(rig=rig)
    rng = np.random.default_rng(8)
    bias = rb.add_plate_bias_trial(w, rng)
    pos = np.array([[0.0, 0.0], [0.2, -0.1], [-0.25, 0.25]])
    off = np.array([[0.003, 0.004], [-0.006, 0.008], [0.0, -0.002]])
    rb.add_cop_trial(w, rng, pos, off)
    s = open_session(w.write(tmp_path / "s"))
    b, source = force_plate.plate_bias(s)
    assert source == "trial:plate-bias-1" and np.allclose(b, bias, atol=0.002)
    found = force_plate.cop_trial_placements(s, "cop-1")
    assert len(found) == 3
    # sensor noise (0.005 per channel; 1 mm per-sample COP noise) and the bias estimate leave < 0.5 mm
    assert np.allclose([p.error for p in found], np.linalg.norm(off, axis=1), atol=5e-4)
    assert np.allclose([p.cop for p in found], pos, atol=5e-4)
    assert np.allclose([p.mocap for p in found], pos + off, atol=1e-12)


def test_bias_record_takes_precedence_and_missing_bias_is_coded(tmp_path):
    rec = {"kind": "plate_bias", "id": "pb", "bias": list(range(24))}
    w = rb.writer(calibration=[rec])
    rb.add_plate_bias_trial(w, np.random.default_rng(9))
    b, source = force_plate.plate_bias(open_session(w.write(tmp_path / "a")))
    assert source == "record:pb" and b.tolist() == list(range(24))
    w = rb.writer()
    rb.add_impact_trial(w, np.random.default_rng(9))
    with pytest.raises(HaptifyError) as e:
        force_plate.plate_bias(open_session(w.write(tmp_path / "b")))
    assert e.value.code == "E621"


def test_rig_without_plate_is_coded():
    rig = rb.example_rig()
    del rig["force_plate"]
    with pytest.raises(HaptifyError) as e:
        force_plate.corner_geometry(Rig.model_validate(rig))
    assert e.value.code == "E603"


@settings(max_examples=30, deadline=None)
@given(scale=st.floats(0.01, 100.0), seed=st.integers(0, 2**16))
def test_unit_scaled_readings_scale_the_wrench_and_keep_the_cop(scale, seed):
    """Readings (and bias) multiplied by s give s·F and s·M; the COP, a ratio, does not change."""
    rng = np.random.default_rng(seed)
    rig_dict = turned_corner_rig()
    pos, rot = force_plate.corner_geometry(Rig.model_validate(rig_dict))
    raw = rng.normal(0, 1, (5, 24))
    raw[:, 2::6] -= 10.0  # a vertical load on every corner so the COP is defined
    bias = rng.normal(0, 0.1, 24)
    f1, m1 = force_plate.total_wrench(raw, pos, rot, bias)
    f2, m2 = force_plate.total_wrench(scale * raw, pos, rot, scale * bias)
    assert np.allclose(f2, scale * f1) and np.allclose(m2, scale * m1)
    c1, ok1 = force_plate.center_of_pressure(f1, m1, min_force_N=0.0)
    c2, ok2 = force_plate.center_of_pressure(f2, m2, min_force_N=0.0)
    assert np.allclose(c1, c2)


@settings(max_examples=30, deadline=None)
@given(yaw=st.floats(-np.pi, np.pi), seed=st.integers(0, 2**16))
def test_rotating_the_world_about_vertical_rotates_wrench_and_cop(yaw, seed):
    """The same raw readings with the world frame (corner poses) turned about z: F, M and the COP turn
    with it and their magnitudes stay the same."""
    rng = np.random.default_rng(seed)
    rig_dict = turned_corner_rig()
    pos, rot = force_plate.corner_geometry(Rig.model_validate(rig_dict))
    c, s = np.cos(yaw), np.sin(yaw)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    raw = rng.normal(0, 1, (6, 24))
    raw[:, 2::6] -= 10.0
    f1, m1 = force_plate.total_wrench(raw, pos, rot)
    f2, m2 = force_plate.total_wrench(raw, pos @ rz.T, np.einsum("ij,cjk->cik", rz, rot))
    assert np.allclose(f2, f1 @ rz.T) and np.allclose(m2, m1 @ rz.T)
    assert np.allclose(np.linalg.norm(f2, axis=1), np.linalg.norm(f1, axis=1))
    c1, _ = force_plate.center_of_pressure(f1, m1, min_force_N=0.0)
    c2, _ = force_plate.center_of_pressure(f2, m2, min_force_N=0.0)
    assert np.allclose(c2, c1 @ rz[:2, :2].T)
