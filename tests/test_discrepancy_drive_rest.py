"""Drives at rest stay at rest in the replay (discrepancy README §1, ``drive_rest.py``): analytic angle signals
and arm paths whose resting drive is known by construction."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as hst

from haptify_tools.discrepancy import drive_rest as dr
from haptify_tools.twin.kinematics import hand_to_joints, rows_times
from haptify_tools.twin.model import preset

RATE = 100.0
T = np.arange(0.0, 12.0, 1 / RATE)
TWIN = preset("touch")


def _rest_between(t0, t1, noise_rad=1e-4, seed=0):
    """An angle (rad) moving at 2 Hz, still (plus white noise) from t0 to t1 s."""
    moving = 0.05 * np.sin(2 * np.pi * 2.0 * T)
    still = (T >= t0) & (T < t1)
    angle = np.where(still, 0.05 * np.sin(2 * np.pi * 2.0 * t0), moving)
    return angle + np.random.default_rng(seed).normal(0.0, noise_rad, len(T)) * still, still


def test_a_still_drive_is_found_and_a_moving_one_is_not():
    angle, still = _rest_between(4.0, 7.0)
    runs = dr.resting_runs(angle, RATE)
    assert len(runs) == 1
    a, b = runs[0]
    assert abs(T[a] - 4.0) <= 0.02 and abs(T[b - 1] - 7.0) <= 0.02
    creeping = 0.003 * T  # 3 mrad/s: more than REST_RANGE_RAD in every window
    assert dr.resting_runs(creeping, RATE) == []
    assert dr.resting_runs(0.05 * np.sin(2 * np.pi * 0.5 * T), RATE) == []


def test_a_stillness_shorter_than_the_window_is_not_a_rest():
    angle, _ = _rest_between(4.0, 4.0 + 0.6 * dr.REST_WINDOW_S)
    assert dr.resting_runs(angle, RATE) == []


def test_a_run_is_held_at_its_mean_and_eased_in_and_out():
    angle, _ = _rest_between(4.0, 7.0)
    runs = dr.resting_runs(angle, RATE)
    held = dr.hold_at_rest(angle, T, runs)
    a, b = runs[0]
    core = slice(a + int(dr.REST_EASE_S * RATE) + 1, b - int(dr.REST_EASE_S * RATE) - 1)
    np.testing.assert_allclose(held[core], angle[a:b].mean(), atol=1e-15)
    outside = np.ones(len(T), bool)
    outside[a:b] = False
    np.testing.assert_array_equal(held[outside], angle[outside])
    assert held[a] == angle[a] and held[b - 1] == angle[b - 1]  # no jump where the hold begins or ends


def _arm_path(seed=0):
    """A hand path whose base drive rests from 3 to 9 s (capture-like noise of 0.1 mrad on it) while the elbow
    and shoulder drives stroke at 3 Hz; its arm angles (rad)."""
    rng = np.random.default_rng(seed)
    q = np.zeros((len(T), 3))
    still = (T >= 3.0) & (T < 9.0)
    turning = 0.2 * np.sin(0.5 * (T - np.where(T < 3.0, 3.0, 9.0)))  # slow turns into and out of the rest
    q[:, 0] = np.where(still, 0.1, 0.1 + turning)
    q[:, 0] += still * rng.normal(0.0, 1e-4, len(T))
    q[:, 1] = 0.8 + 0.15 * np.sin(2 * np.pi * 3.0 * T)
    q[:, 2] = -1.6 + 0.15 * np.cos(2 * np.pi * 3.0 * T)
    return dr.gimbal_centre(TWIN, q), q, still


def test_the_resting_base_drive_is_held_and_the_other_drives_are_untouched():
    position, q, still = _arm_path()
    out = dr.hold_resting_drives(TWIN, T, position)
    q_out, _, ok = hand_to_joints(TWIN, out, None)
    assert ok.all()
    c = np.asarray(TWIN.drive.coupling)
    theta, theta_out = rows_times(q, c.T), rows_times(q_out, c.T)
    np.testing.assert_allclose(theta_out[:, 1:], theta[:, 1:], atol=1e-9)
    core = (T >= 3.0 + dr.REST_WINDOW_S) & (T < 9.0 - dr.REST_WINDOW_S)
    np.testing.assert_allclose(theta_out[core, 0], theta[still, 0].mean(), atol=2e-5)
    moving = ~still
    np.testing.assert_array_equal(
        out[moving & (np.abs(T - 3.0) > 0.6) & (np.abs(T - 9.0) > 0.6)],
        position[moving & (np.abs(T - 3.0) > 0.6) & (np.abs(T - 9.0) > 0.6)],
    )


@settings(max_examples=10, deadline=None)
@given(amplitude=hst.floats(0.02, 0.3), frequency=hst.floats(0.3, 4.0))
def test_a_path_whose_drives_all_move_is_returned_unchanged(amplitude, frequency):
    q = np.stack(
        [
            0.1 + amplitude * np.sin(2 * np.pi * frequency * T),
            0.8 + amplitude * np.cos(2 * np.pi * frequency * T),
            -1.6 + 0.5 * amplitude * np.sin(2 * np.pi * frequency * T + 1.0),
        ],
        axis=1,
    )
    position = dr.gimbal_centre(TWIN, q)
    np.testing.assert_array_equal(dr.hold_resting_drives(TWIN, T, position), position)
