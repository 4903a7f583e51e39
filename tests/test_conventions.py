"""Quaternion conventions (spec §1.3): Hamilton, scalar first, body → world."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.formats.conventions import (
    matrix_to_quat,
    quat_angle,
    quat_from_axis_angle,
    quat_mean,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_slerp,
    quat_to_matrix,
)

unit_quats = (
    st.lists(st.floats(-1, 1), min_size=4, max_size=4)
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: quat_normalize(np.array(v)))
)


def test_rotation_about_z_by_90_degrees_maps_x_to_y():
    q = quat_from_axis_angle([0, 0, 1], math.pi / 2)
    np.testing.assert_allclose(q, [math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)])
    np.testing.assert_allclose(quat_rotate(q, [1.0, 0, 0]), [0, 1, 0], atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(unit_quats, unit_quats)
def test_product_composes_rotations(a, b):
    v = np.array([0.3, -1.2, 2.0])
    np.testing.assert_allclose(quat_rotate(quat_multiply(a, b), v), quat_rotate(a, quat_rotate(b, v)), atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(unit_quats)
def test_matrix_round_trip_up_to_sign(q):
    back = matrix_to_quat(quat_to_matrix(q))
    assert min(np.abs(back - q).max(), np.abs(back + q).max()) < 1e-9
    assert back[0] >= 0


@settings(max_examples=100, deadline=None)
@given(unit_quats, st.floats(0, 1))
def test_slerp_moves_a_fraction_of_the_angle(q, s):
    r = quat_multiply(q, quat_from_axis_angle([1.0, 2.0, 2.0], 1.2))
    mid = quat_slerp(q, r, s)
    np.testing.assert_allclose(quat_angle(q, mid), 1.2 * s, atol=1e-7)


def test_mean_of_symmetric_rotations_is_the_centre():
    base = quat_from_axis_angle([0, 1, 0], 0.4)
    spread = [quat_multiply(base, quat_from_axis_angle([1, 0, 0], a)) for a in (-0.2, 0.2)]
    spread += [-spread[0]]  # sign ambiguity must not matter
    np.testing.assert_allclose(quat_mean(np.array(spread[:2] + [spread[2]])), base, atol=0.07)
    np.testing.assert_allclose(quat_mean(np.array(spread[:2])), base, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    centres=st.lists(unit_quats, min_size=1, max_size=5),
    angle=st.floats(0.0, 0.5),
    seed=st.integers(0, 2**16),
)
def test_the_mean_of_a_stack_of_windows_is_each_window_s_mean_with_w_non_negative(centres, angle, seed):
    """spec §11.6.1: windows (W, N, 4) averaged at once equal their means one by one, each the centre of
    rotations spread symmetrically about it (sign-flipped samples included), scalar part ≥ 0."""
    rng = np.random.default_rng(seed)
    windows = []
    for centre in centres:
        axes = rng.standard_normal((3, 3))
        spread = [quat_multiply(centre, quat_from_axis_angle(a, s * angle)) for a in axes for s in (-1.0, 1.0)]
        windows.append(np.array([q if k % 3 else -q for k, q in enumerate(spread)]))
    stack = np.array(windows)
    means = quat_mean(stack)
    assert means.shape == (len(centres), 4)
    for k, window in enumerate(stack):
        np.testing.assert_allclose(means[k], quat_mean(window), atol=1e-12)
        expected = centres[k] if centres[k][0] >= 0 else -centres[k]
        assert means[k][0] >= 0 and quat_angle(means[k], expected) < 1e-6
