"""DH kinematics (spec §8.2): the paper's eq. 4, Jacobian, coupled limits."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.formats.session_format import Device
from haptify.processing.kinematics import configurations_from_unit, forward_positions, jacobian, joint_limits, within_limits
from haptify_tools.example_session import TOUCH_DEVICE

KIN = Device.model_validate(TOUCH_DEVICE).kinematics
angles = st.tuples(st.floats(-1.0, 1.0), st.floats(0.0, 1.7), st.floats(-2.4, 0.0))


@settings(max_examples=200, deadline=None)
@given(angles)
def test_forward_kinematics_is_the_papers_eq_4(q):
    q1, q2, q3 = q
    a2 = a3 = 0.135
    c1, s1, c2, s2, c3, s3 = math.cos(q1), math.sin(q1), math.cos(q2), math.sin(q2), math.cos(q3), math.sin(q3)
    expected = [
        a2 * c1 * c2 + a3 * c1 * c2 * c3 - a3 * c1 * s2 * s3,
        a2 * s1 * c2 + a3 * s1 * c2 * c3 - a3 * s1 * s2 * s3,
        a2 * s2 + a3 * c2 * s3 + a3 * s2 * c3,
    ]
    np.testing.assert_allclose(forward_positions(KIN, np.array([q]))[0], expected, atol=1e-15)


@settings(max_examples=50, deadline=None)
@given(angles)
def test_jacobian_matches_finite_differences(q):
    q = np.array([q])
    jac = jacobian(KIN, q)[0]
    eps = 1e-7
    for i in range(3):
        dq = np.zeros((1, 3))
        dq[0, i] = eps
        fd = (forward_positions(KIN, q + dq) - forward_positions(KIN, q - dq))[0] / (2 * eps)
        np.testing.assert_allclose(jac[:, i], fd, atol=1e-8)


def test_coupled_limit_of_q3_follows_q2():
    q = np.array([[0.0, math.radians(40), -1.0]])
    lower, upper = joint_limits(KIN, q)
    assert math.isclose(upper[0, 2], math.radians(-10) - 0.85 * math.radians(40))
    assert math.isclose(lower[0, 2], math.radians(-140))


def test_unit_samples_map_inside_the_limits():
    s = np.random.default_rng(3).random((5000, 3))
    q = configurations_from_unit(KIN, s)
    ok = ~np.isnan(q).any(axis=1)
    assert ok.mean() > 0.99
    assert within_limits(KIN, q[ok]).all()
