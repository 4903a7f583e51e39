"""The hand path that drives the twin (discrepancy README §1, ``hand_path.py``): motion capture below the
crossover, the accelerometer above — checked on analytic paths with known noise, and on a simulated
session against the simulator's true path."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from haptify.formats.conventions import quat_normalize, quat_to_matrix
from haptify.formats.session_format import SensorRange
from haptify.formats.storage import open_session
from haptify.pipeline.compute import ComputeContext
from haptify.processing.signals import handle_signals
from haptify_tools.discrepancy import hand_path as hp
from haptify_tools.discrepancy.data import EDGE_S, load_measured
from haptify_tools.twin.dossier_plan import SimulationOptions
from haptify_tools.twin.model import preset
from haptify_tools.twin.simulate import simulate_dossier

RATE = 100.0
T = np.arange(0.0, 20.0, 1 / RATE)
ALL = np.ones(len(T), bool)


def _path(t):
    """A hand-like path (m): slow wandering plus 3 Hz and 6 Hz motion, its exact acceleration (m/s²)."""
    comps = [(0.03, 0.2, 0.0), (0.004, 3.0, 0.7), (0.001, 6.0, 1.9)]
    p = np.zeros((len(t), 3))
    a = np.zeros((len(t), 3))
    for k in range(3):
        for amp, f, ph in comps:
            w = 2 * np.pi * f
            p[:, k] += amp * np.sin(w * t + ph + k)
            a[:, k] -= amp * w * w * np.sin(w * t + ph + k)
    return p, a


def _accel_path(shift=(0.0, 0.0, 0.0)):
    """The accelerometer's path on the grid from the exact acceleration sampled at 2 kHz (plus a constant ``shift``, m/s²)."""
    fine = np.arange(0.0, T[-1] + 1e-9, 1 / 2000)
    _, a = _path(fine)
    x = hp.double_integral(fine, a + np.asarray(shift))
    return np.stack([np.interp(T, fine, x[:, k]) for k in range(3)], axis=1)


def _interior(x):
    return x[200:-200]  # 2 s from each end: the zero-phase filters' edges


def test_exact_measurements_give_the_path_back():
    p, _ = _path(T)
    out = hp.blend(T, RATE, p, _accel_path(), ALL)
    assert np.max(np.abs(_interior(out - p))) < 2e-6


def test_a_constant_accelerometer_bias_is_taken_out_with_the_drift():
    p, _ = _path(T)
    out = hp.blend(T, RATE, p, _accel_path((0.05, -0.03, 0.2)), ALL)
    assert np.max(np.abs(_interior(out - p))) < 2e-6


def test_a_capture_gap_in_fast_motion_is_bridged_by_the_accelerometer():
    """Motion capture lost for 0.3 s (NaN rows) while the hand moves at 3 Hz: the blend bridges the slow
    difference capture − accelerometer, not the capture itself, so the path stays exact through the gap and
    on both sides of it (bridging the capture linearly put it 4 mm off the stroke, spread over ±2.5 s)."""
    p, _ = _path(T)
    ok = ALL.copy()
    ok[1000:1030] = False
    mocap = np.where(ok[:, None], p, np.nan)
    out = hp.blend(T, RATE, mocap, _accel_path((0.05, -0.03, 0.2)), ok)
    assert np.all(np.isfinite(out))
    assert np.max(np.abs(_interior(out - p))) < 2e-6


def test_capture_noise_above_the_crossover_is_removed():
    """White capture noise σ: the blend keeps only its part under the crossover's zero-phase order-4 low-pass
    (power response 1/(1 + (f/fc)⁸)²), variance σ²·fc/(fs/2)·(π/8)(7/8)/sin(π/8); its velocity error is far
    below that of motion capture alone smoothed at 8 Hz (the fallback)."""
    p, _ = _path(T)
    sigma = 1e-4
    noisy = p + np.random.default_rng(3).normal(0.0, sigma, p.shape)
    err = _interior(hp.blend(T, RATE, noisy, _accel_path(), ALL) - p)
    expected = sigma * np.sqrt(hp.PATH_CROSSOVER_HZ / (RATE / 2) * (np.pi / 8) * (7 / 8) / np.sin(np.pi / 8))
    assert np.sqrt(np.mean(err**2)) == pytest.approx(expected, rel=0.15)
    only_mocap = _interior(hp.smooth(T, RATE, noisy, hp.POSE_CUTOFF_HZ) - p)  # the fallback without an accelerometer
    v_err = np.gradient(err, axis=0) * RATE
    v_mocap = np.gradient(only_mocap, axis=0) * RATE
    assert np.sqrt(np.mean(v_err**2)) < 0.2 * np.sqrt(np.mean(v_mocap**2))


ACCEL_PATH = _accel_path()


@settings(max_examples=25, deadline=None)
@given(
    q=hst.lists(hst.floats(-1, 1), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1), scale=hst.floats(1e-3, 1e3)
)
def test_the_blend_turns_with_the_frame_and_scales_with_the_unit(q, scale):
    p, _ = _path(T)
    noisy = p + np.random.default_rng(5).normal(0.0, 1e-4, p.shape)
    x = ACCEL_PATH
    r = quat_to_matrix(quat_normalize(np.asarray(q, float)))
    base = hp.blend(T, RATE, noisy, x, ALL)
    np.testing.assert_allclose(hp.blend(T, RATE, noisy @ r.T, x @ r.T, ALL), base @ r.T, atol=1e-12)
    np.testing.assert_allclose(hp.blend(T, RATE, noisy * scale, x * scale, ALL), base * scale, rtol=1e-9, atol=1e-15 * scale)


@pytest.fixture(scope="module")
def figure_eight(tmp_path_factory):
    opt = SimulationOptions(
        protocols=("figure_eight", "rig.handle_calibration"),
        reps=1,
        seed=4,
        durations={"figure_eight": 16.0, "rig.handle_calibration": 12.0},
        rig_trials=False,
        workers=1,
    )
    return simulate_dossier(preset("touch"), tmp_path_factory.mktemp("hand-path") / "s", opt)


def _true_path(dossier, trial):
    z = np.load(dossier.truth_npz)
    t, p = z[f"{trial.trial_id}/t"], z[f"{trial.trial_id}/position_W"]
    return np.stack([np.interp(trial.t, t, p[:, k]) for k in range(3)], axis=1)


def test_on_a_simulated_session_the_blend_follows_the_true_path(figure_eight):
    """The simulator's own true path: the blended velocity is ≥ 2× closer to it than motion capture alone (the fallback)."""
    session = open_session(figure_eight.session)
    trial = next(tr for tr in load_measured(session) if tr.protocol == "other")
    assert trial.path_source == hp.FROM_BOTH
    truth = _true_path(figure_eight, trial)
    ok = trial.valid
    v_true = np.gradient(truth, trial.t, axis=0)
    v_err = (np.gradient(trial.position, trial.t, axis=0) - v_true)[ok]
    hs = handle_signals(ComputeContext(session=session), trial.trial_id)
    mocap = hp.smooth(hs.t, hs.rate_hz, hp.fill_gaps(hs.t, hs.position, hs.valid), hp.POSE_CUTOFF_HZ)  # the fallback
    v_mocap = (np.gradient(mocap, trial.t, axis=0) - v_true)[ok]
    assert np.sqrt(np.mean(v_err**2)) < 0.5 * np.sqrt(np.mean(v_mocap**2))
    assert np.sqrt(np.mean((trial.position - truth)[ok] ** 2)) < 1e-4


def _eight(session):
    return next(tr for tr in load_measured(session) if tr.protocol == "other")


def test_rows_near_a_reading_at_the_accelerometers_range_are_not_compared(figure_eight, monkeypatch):
    """The declared range set so that only the trial's largest reading is at it: exactly the rows within
    CLIP_MARGIN_S of that reading's time leave the comparison; the path still uses the accelerometer."""
    session = open_session(figure_eight.session)
    free = _eight(session)
    eight = free.trial_id
    reading = session.read(eight, "handle_accel")
    values = np.abs(reading[["ax", "ay", "az"]].to_numpy())
    peak_row = int(np.argmax(values.max(axis=1)))
    peak, t_peak = float(values.max()), float(reading["t"].iloc[peak_row])
    monkeypatch.setattr(
        session.manifest.rig.handle.accelerometer, "range", SensorRange(accel_m_per_s2=[peak / hp.RANGE_FRACTION] * 3)
    )
    clipped = _eight(session)
    assert clipped.path_source == hp.FROM_BOTH
    near = np.abs(clipped.t - t_peak) <= hp.CLIP_MARGIN_S
    assert near.any()
    np.testing.assert_array_equal(clipped.valid, free.valid & ~near)
    monkeypatch.setattr(
        session.manifest.rig.handle.accelerometer, "range", SensorRange(accel_m_per_s2=[1.01 * peak / hp.RANGE_FRACTION] * 3)
    )
    np.testing.assert_array_equal(_eight(session).valid, free.valid)


def test_rows_near_a_capture_gap_are_not_compared(figure_eight, monkeypatch):
    """Motion capture lost for 0.3 s: exactly the usable rows farther than GAP_MARGIN_S from every row without it,
    and EDGE_S from the trial's ends, are compared (no reading is at the accelerometer's range in this trial)."""
    session = open_session(figure_eight.session)
    eight = _eight(session).trial_id
    read = session.read

    def read_with_gap(trial_id, kind):
        df = read(trial_id, kind)
        if (trial_id, kind) == (eight, "handle_pose"):
            df = df.copy()
            df.loc[
                (df["t"] >= df["t"].iloc[0] + 8.0) & (df["t"] < df["t"].iloc[0] + 8.3), ["px", "py", "pz", "qw", "qx", "qy", "qz"]
            ] = np.nan
        return df

    monkeypatch.setattr(session, "read", read_with_gap)
    trial = _eight(session)
    hs = handle_signals(ComputeContext(session=session), trial.trial_id)
    ok = hs.valid & np.all(np.isfinite(hs.force), axis=1)
    assert 25 <= (~ok).sum() <= 40
    gap_t = hs.t[~ok]
    distance = np.min(np.abs(hs.t[:, None] - gap_t[None, :]), axis=1)
    inner = (hs.t >= hs.t[0] + EDGE_S) & (hs.t <= hs.t[-1] - EDGE_S)
    np.testing.assert_array_equal(trial.valid, ok & (distance > hp.GAP_MARGIN_S) & inner)


def test_near_marks_the_rows_within_the_margin_of_an_event():
    t = np.arange(0.0, 10.0, 0.5)
    np.testing.assert_array_equal(hp.near(t, np.array([2.0, 7.2]), 0.5), (np.abs(t - 2.0) <= 0.5) | (np.abs(t - 7.2) <= 0.5))
    assert not hp.near(t, np.array([]), 0.5).any()


def test_without_an_accelerometer_or_when_it_is_mostly_at_its_range_the_path_is_motion_capture_alone(figure_eight, monkeypatch):
    session = open_session(figure_eight.session)
    assert _eight(session).path_source == hp.FROM_BOTH
    monkeypatch.setattr(session.manifest.rig.handle.accelerometer, "range", SensorRange(accel_m_per_s2=[1.0, 1.0, 1.0]))
    trial = _eight(session)  # gravity alone is past 1 m/s² on some axis all the time
    assert trial.path_source == hp.FROM_MOCAP and trial.valid.sum() > 0.8 * len(trial.t)
    monkeypatch.setattr(session.manifest.rig.handle.accelerometer, "range", None)
    stream = type(session).stream
    eight = trial.trial_id
    monkeypatch.setattr(
        type(session),
        "stream",
        lambda self, trial_id, kind: None if (trial_id, kind) == (eight, "handle_accel") else stream(self, trial_id, kind),
    )
    assert _eight(session).path_source == hp.FROM_MOCAP
