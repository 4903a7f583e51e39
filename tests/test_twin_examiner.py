"""The virtual examiner (design §4): protocol limits, coverage and determinism, known by construction."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.formats.conventions import STANDARD_GRAVITY, quat_conjugate, quat_rotate
from haptify.processing.kinematics import joint_limits
from haptify_tools.twin import examiner as ex
from haptify_tools.twin import hand_path, plate_loads
from haptify_tools.twin.kinematics import inverse_kinematics, true_kinematics, world_to_device
from haptify_tools.twin.model import preset
from haptify_tools.twin.reach import reach_from_twin

DEG = math.pi / 180
RATE = 500.0  # a slower examiner clock keeps the tests fast; every generator takes rate_hz


@pytest.fixture(scope="module")
def twin():
    return preset("touch")


@pytest.fixture(scope="module")
def reach(twin):
    return reach_from_twin(twin)


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 2**31))
def test_free_space_respects_paper_limits(reach, seed):
    rng = np.random.default_rng(seed)
    tr = ex.free_space_wander(rng, reach, 25.0, rate_hz=RATE)
    speed, ang = tr.speed(), tr.angular_speed()
    assert speed.max() < ex.FREE_SPACE_MAX_SPEED  # paper §V-B: < 0.16 m/s
    assert 0.03 < speed.mean() < 0.07  # paper §VI-B: ≈ 0.05 m/s
    assert ang.max() < ex.FREE_SPACE_MAX_ANGULAR  # < 16 °/s
    assert 2 * DEG < ang.mean() < 6 * DEG  # ≈ 4 °/s
    # never touches the base (kept 1 cm away, less the tremor's micrometres)
    assert reach.clearance(tr.position_W).min() > 0.009
    assert reach.reachable(tr.position_W).all()
    # it wanders over a real part of the workspace, not a spot
    assert np.ptp(tr.position_W, axis=0).max() > 0.05


def test_local_oscillations_band_directions_and_centre(reach):
    rng = np.random.default_rng(5)
    tr = ex.local_oscillations(rng, reach, 40.0, rate_hz=RATE)
    centre = reach.centre()
    assert np.linalg.norm(tr.position_W[0] - centre) < 1e-4 and np.linalg.norm(tr.position_W[-1] - centre) < 1e-4
    assert set(tr.meta["directions"]) == set(ex.OSCILLATION_DIRECTIONS)
    assert tr.meta["band_hz"] == [0.5, 4.0]
    # the displacement's spectrum lies in the 0.5–4 Hz band (tremor aside), slow first and fast last
    disp = tr.position_W - centre
    mag = np.abs(np.fft.rfft(disp, axis=0)) ** 2
    f = np.fft.rfftfreq(len(disp), 1 / RATE)
    share = mag[(f > 0.35) & (f < 4.5)].sum() / mag[f > 0].sum()
    assert share > 0.95
    first, last = disp[: int(8 * RATE)], disp[-int(8 * RATE) :]
    assert _dominant_hz(first, RATE) < 1.0 and _dominant_hz(last, RATE) > 2.5
    assert reach.reachable(tr.position_W).all()


def test_local_oscillations_reach_the_papers_speeds_and_accelerations(reach):
    """Paper §VI-D: its examiner's windows differ by up to R_v = 1.6 m/s and R_a = 38 m/s² — the fastest
    oscillations come near both and never exceed the acceleration."""
    from haptify.processing.preprocessing import lowpass

    tr = ex.local_oscillations(np.random.default_rng(5), reach, 40.0, rate_hz=RATE)
    p = lowpass(tr.position_W, RATE, 10.0)
    v = np.gradient(p, 1 / RATE, axis=0)
    a = np.linalg.norm(np.gradient(v, 1 / RATE, axis=0), axis=1)
    assert 30.0 < a.max() < 38.0 * 1.05
    assert 1.0 < np.linalg.norm(v, axis=1).max() < 1.6


def _dominant_hz(x: np.ndarray, rate: float) -> float:
    spec = np.sum(np.abs(np.fft.rfft(x - x.mean(axis=0), n=8 * len(x), axis=0)) ** 2, axis=1)
    f = np.fft.rfftfreq(8 * len(x), 1 / rate)
    return float(f[np.argmax(spec[1:]) + 1])


def test_local_dynamic_default_is_about_140_s():
    import inspect

    assert inspect.signature(ex.local_oscillations).parameters["duration_s"].default == pytest.approx(140.0)


def test_boundary_sweep_stays_on_the_joint_box_or_the_base(twin, reach):
    tr = ex.boundary_sweep(np.random.default_rng(2), reach, 60.0, rate_hz=RATE)
    pts = tr.position_W[int(0.6 * RATE) : -int(0.6 * RATE)]
    kin = true_kinematics(twin)
    q, _ = inverse_kinematics(kin, world_to_device(twin, pts))
    lo, hi = joint_limits(kin, q)
    at_limit = np.any((np.abs(q - lo) < 2e-3) | (np.abs(q - hi) < 2e-3), axis=1)
    on_base = reach.clearance(pts) < 2e-3
    assert np.mean(at_limit | on_base) > 0.85  # the rest: strokes lifted over the base
    assert reach.clearance(pts).min() > -2e-4  # never inside the base (tremor aside)
    assert np.all((q >= lo - 2e-3) & (q <= hi + 2e-3))  # never beyond a joint limit
    # the raster spacing is what the volume operator needs
    assert tr.meta["line_spacing_m"] <= 0.03 and tr.speed().max() < 1.0


def test_surface_trials_press_into_the_plane(reach):
    z = float(reach.centre()[2])
    circ = ex.surface_circles(np.random.default_rng(3), reach, z, 12.0, rate_hz=RATE)
    mid = circ.position_W[int(3 * RATE) : -int(3 * RATE)]
    assert np.all(mid[:, 2] < z) and np.all(mid[:, 2] > z - 0.006)  # lightly pressed, ≈ 2.5 mm
    assert circ.position_W[0, 2] > z + 0.009  # starts above the surface
    press = ex.surface_presses(np.random.default_rng(3), reach, z, 20.0, rate_hz=RATE)
    assert press.meta["press_count"] >= 3
    deepest = z - press.position_W[:, 2].min()
    edge = press.meta["edge_distance_m"]  # measured from 1 cm above the plane
    assert deepest > 0.85 * (edge - 0.002) - 0.01 - 1e-4  # down to the workspace edge
    assert reach.reachable(press.position_W).all()


def test_figure_eight_is_protocol_other(reach):
    tr = ex.figure_eight(np.random.default_rng(1), reach, 10.0, rate_hz=RATE)
    assert (tr.protocol, tr.label) == ("other", "figure_eight")
    assert np.linalg.norm(tr.position_W[0] - reach.centre()) < 1e-4


def test_generators_are_deterministic_for_a_seed(reach):
    a = ex.free_space_wander(np.random.default_rng(7), reach, 5.0, rate_hz=RATE)
    b = ex.free_space_wander(np.random.default_rng(7), reach, 5.0, rate_hz=RATE)
    c = ex.free_space_wander(np.random.default_rng(8), reach, 5.0, rate_hz=RATE)
    assert np.array_equal(a.position_W, b.position_W) and np.array_equal(a.quaternion_W, b.quaternion_W)
    assert not np.allclose(a.position_W, c.position_W)


@settings(max_examples=12, deadline=None)
@given(accel=st.floats(0.002, 0.2), seed=st.integers(0, 2**31))
def test_tremor_has_configured_level_and_band(accel, seed):
    rate = 1000.0
    disp, rot = hand_path.tremor(np.random.default_rng(seed), 8000, rate, accel_rms=accel, angle_rms=1e-4)
    acc = hand_path.derivative(disp, rate, 2)
    assert np.sqrt(np.mean(acc**2, axis=0)) == pytest.approx(accel, rel=0.02)
    spec = np.abs(np.fft.rfft(disp, axis=0)) ** 2
    f = np.fft.rfftfreq(len(disp), 1 / rate)
    inside = spec[(f >= 8.0) & (f <= 12.0)].sum() / spec.sum()
    assert inside > 0.999
    assert np.sqrt(np.mean(rot**2, axis=0)) == pytest.approx(1e-4, rel=1e-9)


def test_handle_rotation_shows_gravity_from_every_direction():
    tr = ex.handle_rotation(np.random.default_rng(0), 20.0, rate_hz=RATE)
    g_body = quat_rotate(quat_conjugate(tr.quaternion_W), np.broadcast_to([0, 0, -1.0], (len(tr.t), 3)))
    coverage = np.linalg.eigvalsh(g_body.T @ g_body / len(g_body))[0]
    assert coverage > 0.1  # 1/3 would be a perfectly even sphere
    assert tr.speed().max() < 0.1  # held in place, only drifting


def test_ball_impact_carries_the_momentum():
    load = plate_loads.ball_impact(
        np.random.default_rng(4), 3.0, rate_hz=1000.0, mass_kg=0.05, drop_height_m=0.2, restitution=0.5
    )
    impulse = -np.sum(load.force_W[:, 2]) / 1000.0
    v, total = math.sqrt(2 * STANDARD_GRAVITY * 0.2), 0.0
    for ev in load.meta["impacts"]:
        total += ev["impulse_N_s"]
    assert impulse == pytest.approx(total, rel=1e-9)
    assert load.meta["impacts"][0]["impulse_N_s"] == pytest.approx(0.05 * 1.5 * v)


def test_weight_placements_visit_30_positions_with_markers():
    load = plate_loads.weight_placements(np.random.default_rng(9), rate_hz=1000.0, mass_kg=2.0)
    pos = np.array(load.meta["positions_m"])
    assert pos.shape == (30, 2)
    full = np.isclose(load.force_W[:, 2], -2.0 * STANDARD_GRAVITY)
    assert full.any()
    # while fully loaded, the load point and the marker centroid sit over one of the 30 positions
    pts = load.point_W[full, :2]
    centroid = np.mean([m for m in load.markers_W.values()], axis=0)[full]
    assert np.allclose(pts, centroid[:, :2] - plate_loads.COP_MARKER_OFFSETS.mean(axis=0)[:2], atol=1e-12)
    d = np.min(np.linalg.norm(pts[:, None, :] - pos[None, :, :], axis=2), axis=1)
    assert d.max() < 1e-12
