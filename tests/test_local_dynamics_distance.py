"""Known answers for the kinematic distance of paper eq. 9 and the error-vs-distance line (spec §11.6)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.dynamics import (
    DistanceScales,
    WindowFeatures,
    line_fit,
    nearest_distances,
    pair_distance,
    parameter_file,
    segment_distances,
    segment_force_errors,
    window_features,
)
from haptify.errors import HaptifyError
from haptify.formats.conventions import quat_from_axis_angle

R = DistanceScales.from_definition()
WIN = 20  # 0.2 s at 100 Hz


def test_scales_are_the_papers():
    assert (R.p, R.v, R.a) == (0.12, 1.6, 38.0)
    assert R.theta == pytest.approx(math.radians(86.0))
    assert round(parameter_file.PARAMETERS.window_s * 100) == WIN and parameter_file.PARAMETERS.segment_s == 5.0


def motion(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """Random smooth-ish signals for position, velocity, acceleration and orientation."""
    axis = rng.standard_normal(3)
    ang = 0.3 * np.sin(np.arange(n) / 40.0)
    return {
        "position": 0.05 * rng.standard_normal((n, 3)).cumsum(axis=0) / 10,
        "velocity": 0.2 * rng.standard_normal((n, 3)),
        "acceleration": 5.0 * rng.standard_normal((n, 3)),
        "quaternion": quat_from_axis_angle(np.tile(axis, (n, 1)), ang),
    }


def features(sig: dict[str, np.ndarray]) -> WindowFeatures:
    return window_features(sig["position"], sig["velocity"], sig["acceleration"], sig["quaternion"], WIN)


def test_windows_are_means_and_the_tail_is_dropped():
    n = 3 * WIN + 7
    p = np.repeat(np.arange(4.0), WIN)[:n, None] * np.ones((1, 3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    f = window_features(p, p, p, q, WIN)
    assert len(f) == 3
    assert np.allclose(f.position[:, 0], [0.0, 1.0, 2.0])
    assert np.allclose(f.orientation, [1.0, 0.0, 0.0, 0.0])


def test_identical_windows_are_at_distance_zero():
    sig = motion(np.random.default_rng(1), 50 * WIN)
    f = features(sig)
    assert np.allclose(nearest_distances(f, f, R), 0.0, atol=1e-6)


@pytest.mark.parametrize("term", ["position", "velocity", "acceleration"])
def test_an_offset_of_one_representative_distance_gives_one(term):
    sig = motion(np.random.default_rng(2), 40 * WIN)
    scale = {"position": R.p, "velocity": R.v, "acceleration": R.a}[term]
    shifted = dict(sig)
    direction = np.array([2.0, -1.0, 2.0]) / 3.0
    shifted[term] = sig[term] + scale * direction
    a, b = features(shifted), features(sig)
    # pair each window with its own original (the nearest window could be another one)
    assert np.allclose(np.diag(pair_distance(a, b, R)), 1.0, atol=1e-9)


def test_an_orientation_offset_of_86_degrees_gives_one():
    n = 30 * WIN
    rng = np.random.default_rng(3)
    sig = motion(rng, n)
    turned = dict(sig)
    extra = quat_from_axis_angle(np.array([[0.0, 0.0, 1.0]]), np.array([math.radians(86.0)]))[0]
    from haptify.formats.conventions import quat_multiply

    turned["quaternion"] = quat_multiply(np.tile(extra, (n, 1)), sig["quaternion"])  # rotated in the world frame
    d = np.diag(pair_distance(features(turned), features(sig), R))
    assert np.allclose(d, 1.0, atol=1e-9)


def test_the_segment_distance_is_the_mean_of_its_window_minima():
    """Training: a still pose. Test windows offset by 0, 1, 2, … R_p: each minimum is its offset."""
    train = WindowFeatures(np.zeros((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)), np.tile([1.0, 0, 0, 0], (5, 1)))
    k = np.arange(50.0)
    test = WindowFeatures(
        np.column_stack([k * R.p, 0 * k, 0 * k]), np.zeros((50, 3)), np.zeros((50, 3)), np.tile([1.0, 0, 0, 0], (50, 1))
    )
    minima = nearest_distances(test, train, R, chunk=7)
    assert np.allclose(minima, k)
    assert np.allclose(segment_distances(minima, 25), [k[:25].mean(), k[25:].mean()])


def test_nearest_distances_agree_with_a_plain_double_loop():
    rng = np.random.default_rng(4)
    a, b = features(motion(rng, 30 * WIN)), features(motion(rng, 17 * WIN))
    loop = np.array(
        [
            min(
                pair_distance(
                    WindowFeatures(
                        a.position[i : i + 1], a.velocity[i : i + 1], a.acceleration[i : i + 1], a.orientation[i : i + 1]
                    ),
                    b,
                    R,
                )[0]
            )
            for i in range(len(a))
        ]
    )
    assert np.allclose(nearest_distances(a, b, R, chunk=4), loop)


unit_quats = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1)
vec3 = st.lists(st.floats(-2, 2), min_size=3, max_size=3)
window = st.tuples(vec3, vec3, vec3, unit_quats)


def _one(w) -> WindowFeatures:
    q = np.array(w[3]) / np.linalg.norm(w[3])
    return WindowFeatures(np.array([w[0]]), np.array([w[1]]), np.array([w[2]]), q[None, :])


@settings(max_examples=60, deadline=None)
@given(window, window, window)
def test_delta_is_a_metric(x, y, z):
    a, b, c = _one(x), _one(y), _one(z)
    ab, ba = pair_distance(a, b, R)[0, 0], pair_distance(b, a, R)[0, 0]
    assert ab >= 0 and abs(ab - ba) < 1e-9
    assert pair_distance(a, c, R)[0, 0] <= ab + pair_distance(b, c, R)[0, 0] + 1e-6
    assert pair_distance(a, a, R)[0, 0] < 1e-6


def test_segment_force_error_is_the_mean_of_axis_rms():
    seg = 500
    force = np.zeros((2 * seg + 30, 3))
    predicted = force.copy()
    predicted[:seg] += [0.1, 0.2, 0.3]  # constant errors: RMS = |offset|
    predicted[seg:, 0] += 0.4 * np.where(np.arange(len(force) - seg) % 2, 1.0, -1.0)
    assert np.allclose(segment_force_errors(force, predicted, seg), [0.2, 0.4 / 3])


def test_line_fit_recovers_a_known_line_and_needs_two_distances():
    x = np.array([0.0, 0.5, 1.0, 2.0])
    assert np.allclose(line_fit(x, 0.3 * x + 0.1), (0.3, 0.1))
    with pytest.raises(HaptifyError) as err:
        line_fit(np.array([0.0, 0.0]), np.array([1.0, 2.0]))
    assert err.value.code == "E701"
