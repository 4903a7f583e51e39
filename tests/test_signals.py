"""Common signal processing (spec chapter 7): filter properties, gap rules, differentiation, the
calibrated handle signals on a session built from known hand forces, and invariances."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.errors import HaptifyError
from haptify.formats.conventions import quat_from_axis_angle
from haptify.formats.storage import open_session
from haptify.pipeline.compute import ComputeContext
from haptify.processing import preprocessing, signals
from haptify_tools import rig_builders as rb


def _gain(rate: float, f: float, cutoff: float) -> float:
    t = np.arange(int(20 * rate)) / rate
    x = np.sin(2 * np.pi * f * t)
    y = preprocessing.lowpass(x, rate, cutoff)
    mid = slice(len(t) // 4, 3 * len(t) // 4)
    return float(np.sqrt(np.mean(y[mid] ** 2) / np.mean(x[mid] ** 2)))


def test_lowpass_is_zero_phase_with_the_butterworth_magnitude():
    rate, fc = 1000.0, 20.0
    t = np.arange(20000) / rate
    x = np.sin(2 * np.pi * 2.0 * t)
    y = preprocessing.lowpass(x, rate, fc)
    mid = slice(5000, 15000)
    assert np.max(np.abs(y[mid] - x[mid])) < 1e-4  # no delay and unity gain well inside the pass band
    order = preprocessing.PARAMETERS.filter_order
    for f in (10.0, 20.0, 40.0):
        # forward-backward gives |H|² of one digital (bilinear, pre-warped) Butterworth pass: 1 / (1 + Ω^(2n))
        omega = np.tan(np.pi * f / rate) / np.tan(np.pi * fc / rate)
        assert _gain(rate, f, fc) == pytest.approx(1.0 / (1.0 + omega ** (2 * order)), rel=0.01)


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(2, 400),
    k=st.integers(1, 5),
    seed=st.integers(0, 2**32 - 1),
    column_major=st.booleans(),
)
def test_lowpass_filters_each_signal_on_its_own_whatever_the_layout(n, k, seed, column_major):
    """A block of signals gives, signal by signal, exactly the low-pass of that signal alone (spec §7.2 filters
    each signal independently), whether its columns or its rows are contiguous and for (N, a, b) blocks."""
    rng = np.random.default_rng(seed)
    block = rng.normal(size=(n, k)) * 10.0 + rng.normal(size=k)
    block = np.asfortranarray(block) if column_major else np.ascontiguousarray(block)
    out = preprocessing.lowpass(block, 100.0, 7.0)
    assert out.shape == (n, k)
    for j in range(k):
        assert np.array_equal(out[:, j], preprocessing.lowpass(np.ascontiguousarray(block[:, j]), 100.0, 7.0))
    cube = preprocessing.lowpass(np.stack([block, -block], axis=2), 100.0, 7.0)
    assert cube.shape == (n, k, 2)
    assert np.array_equal(cube[:, :, 0], out) and np.array_equal(cube[:, :, 1], preprocessing.lowpass(-block, 100.0, 7.0))


def test_cutoff_is_limited_by_nyquist():
    frac = preprocessing.PARAMETERS.max_cutoff_fraction
    assert preprocessing.effective_cutoff(20.0, 1000.0) == 20.0
    assert preprocessing.effective_cutoff(20.0, 1000.0, 30.0) == pytest.approx(frac * 15.0)


def test_uniform_grid_and_resampling_of_a_line_are_exact():
    g = preprocessing.uniform_grid(0.25, 1.25, 100.0)
    assert len(g) == 101 and g[0] == 0.25 and g[-1] == pytest.approx(1.25)
    t = np.arange(2000) / 1000.0
    x = np.column_stack([3.0 * t + 1.0, -t])
    # a straight line passes the zero-phase low-pass (odd padding) and linear interpolation unchanged
    y = preprocessing.lowpass_resample(t, x, g[g <= t[-1]], 20.0)
    gg = g[g <= t[-1]]
    assert np.allclose(y, np.column_stack([3.0 * gg + 1.0, -gg]), atol=1e-9)


def test_angular_velocity_is_exact_for_constant_rotation():
    t = np.arange(300) / 100.0
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    q = quat_from_axis_angle(np.broadcast_to(axis, (300, 3)), 1.3 * t)
    w = preprocessing.angular_velocity(t, q)
    assert np.allclose(w, 1.3 * axis, atol=1e-9)


def _pose_columns(t, pos, q):
    return {"t": t, "px": pos[:, 0], "py": pos[:, 1], "pz": pos[:, 2], "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]}


def test_short_gaps_are_bridged_and_long_gaps_never_interpolated():
    t = np.arange(400) / 100.0
    pos = np.column_stack([0.1 * t, 0 * t, 0 * t])
    q = np.tile([1.0, 0, 0, 0], (400, 1))
    max_gap = preprocessing.PARAMETERS.max_gap_s
    short = slice(100, 100 + int(round(max_gap * 100)))  # exactly the longest gap that is bridged
    long = slice(250, 250 + int(round(max_gap * 100)) + 1)
    pos[short] = np.nan
    q[short] = np.nan
    pos[long] = np.nan
    q[long] = np.nan
    track = preprocessing.process_mocap(t, pos, q)
    assert track.valid[short].all() and not track.valid[long].any()
    assert np.allclose(track.position[short, 0], 0.1 * t[short], atol=1e-9)
    assert np.allclose(track.velocity[track.valid, 0], 0.1, atol=1e-9)
    grid = np.arange(0, 3.99, 0.001)
    on = preprocessing.resample_track(track, grid)
    inside_long = (grid > t[249]) & (grid < t[long.stop])
    assert not on.valid[inside_long].any() and on.valid[~inside_long].all()
    assert np.isnan(on.position[inside_long]).all()


@settings(max_examples=40, deadline=None)
@given(gaps=st.lists(st.tuples(st.integers(5, 380), st.integers(1, 30)), min_size=1, max_size=8))
def test_every_gap_is_bridged_exactly_when_it_is_short(gaps):
    """On a straight-line motion, each run of missing samples is filled on the line when the valid samples
    around it are at most ``max_gap_s`` + one interval apart, and stays missing otherwise (spec §7.4)."""
    t = np.arange(400) / 100.0
    pos = np.column_stack([0.1 * t, -0.2 * t, 0.05 + 0 * t])
    q = np.tile([1.0, 0, 0, 0], (400, 1))
    missing = np.zeros(400, bool)
    for start, length in gaps:
        missing[start : start + length] = True
    pos[missing] = np.nan
    q[missing, 2] = np.nan  # one missing component makes the whole sample missing
    filled, quat, ok = preprocessing.bridge_gaps(t, pos, q)
    expected = ~missing
    edges = np.flatnonzero(np.diff(np.r_[0, missing.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2]):  # missing run [a, b) between valid samples a − 1 and b
        if 0 < a and b < 400 and t[b] - t[a - 1] <= preprocessing.PARAMETERS.max_gap_s + 0.01 + 1e-12:
            expected[a:b] = True
    assert np.array_equal(ok, expected)
    assert np.allclose(filled[ok], np.column_stack([0.1 * t, -0.2 * t, 0.05 + 0 * t])[ok], atol=1e-12)
    assert np.allclose(quat[ok], [1.0, 0, 0, 0], atol=1e-12) and np.isnan(filled[~ok]).all()


def test_short_segments_are_dropped():
    t = np.arange(200) / 100.0
    pos = np.zeros((200, 3))
    q = np.tile([1.0, 0, 0, 0], (200, 1))
    pos[:90] = np.nan
    pos[100:] = np.nan  # leaves a 0.1 s island, shorter than min_segment_s
    track = preprocessing.process_mocap(t, pos, q)
    assert not track.valid.any()


def test_velocity_of_a_sinusoid():
    t = np.arange(1000) / 100.0
    pos = np.column_stack([0.05 * np.sin(2 * np.pi * 1.0 * t), 0 * t, 0 * t])
    track = preprocessing.process_mocap(t, pos, np.tile([1.0, 0, 0, 0], (1000, 1)))
    v_true = 0.05 * 2 * np.pi * np.cos(2 * np.pi * t)
    mid = slice(100, 900)
    assert np.max(np.abs(track.velocity[mid, 0] - v_true[mid])) < 0.01 * 0.05 * 2 * np.pi


# --- handle_signals on a session with a known hand wrench -----------------------------------------

HAND_F = np.array([0.4, -0.3, 1.2])
HAND_T = np.array([0.01, 0.02, -0.005])


def _handle_session(tmp, shift: float = 0.0, gap: bool = False):
    truth = rb.HandleTruth()
    w = rb.writer(calibration=[truth.record()])
    rng = np.random.default_rng(7)
    dur = 6.0
    t_ft, t_acc, t_m = np.arange(int(dur * 1000)) / 1000.0, np.arange(int(dur * 2000)) / 2000.0, np.arange(int(dur * 100)) / 100.0
    q = rb.tumbling_orientation
    wrench, accel = rb.raw_handle(
        truth,
        w.manifest["rig"],
        t_ft,
        q(t_ft),
        t_acc,
        q(t_acc),
        rng,
        np.tile(HAND_F, (len(t_ft), 1)),
        np.tile(HAND_T, (len(t_ft), 1)),
        np.zeros((len(t_acc), 3)),
    )
    pos = np.column_stack([0.02 * t_m, 0.01 * np.ones_like(t_m), 0.15 + 0 * t_m])
    qm = q(t_m)
    if gap:
        pos[300:320] = np.nan
        qm[300:320] = np.nan
    wrench["t"] = wrench["t"] + shift
    accel["t"] = accel["t"] + shift
    w.add_trial("fs-1", "free_space", powered=False)
    w.add_stream("fs-1", "handle_wrench", wrench, rate_hz=1000)
    w.add_stream("fs-1", "handle_accel", accel, rate_hz=2000)
    w.add_stream("fs-1", "handle_pose", _pose_columns(t_m + shift, pos, qm), rate_hz=100)
    return open_session(w.write(tmp / f"h{shift}{gap}"))


@pytest.fixture(scope="module")
def handle_session(tmp_path_factory):
    return _handle_session(tmp_path_factory.mktemp("hs"))


def test_handle_signals_report_the_hand_wrench_in_world(handle_session):
    hs = signals.handle_signals(handle_session, "fs-1")
    assert hs.rate_hz == preprocessing.PARAMETERS.rate_hz
    assert np.allclose(np.diff(hs.t), 1 / hs.rate_hz)
    v = hs.valid
    assert v.all()
    inner = slice(20, -20)  # the filter edges
    assert np.allclose(hs.force[inner], HAND_F, atol=0.01)
    assert np.allclose(hs.torque[inner], HAND_T, atol=0.002)
    assert np.allclose(hs.acceleration[inner], 0.0, atol=0.05)
    assert np.allclose(hs.velocity[inner], [0.02, 0.0, 0.0], atol=1e-6)
    assert np.allclose(hs.angular_speed[inner] > 0.5, True)  # the tumble turns at ≥ 0.5 rad/s


def test_handle_signals_are_cached_on_the_context(handle_session):
    ctx = ComputeContext(session=handle_session)
    a = signals.handle_signals(ctx, "fs-1")
    assert signals.handle_signals(ctx, "fs-1") is a
    assert signals.handle_signals(ctx, "fs-1", rate_hz=200.0) is not a


def test_long_occlusion_is_invalid_not_interpolated(tmp_path):
    hs = signals.handle_signals(_handle_session(tmp_path, gap=True), "fs-1")
    in_gap = (hs.t > 2.995) & (hs.t < 3.2)
    assert not hs.valid[in_gap].any() and np.isnan(hs.force[in_gap]).all()
    assert hs.valid[(hs.t < 2.9) | (hs.t > 3.3)].all()


def test_native_acceleration_for_vibration(handle_session):
    na = signals.handle_accel_native(handle_session, "fs-1")
    assert na.rate_hz == pytest.approx(2000.0)
    assert np.allclose(np.nanmean(na.acceleration[na.valid], axis=0), 0.0, atol=0.01)
    assert np.allclose(np.linalg.norm(na.sensor, axis=1).mean(), rb.HandleTruth().gravity, atol=0.01)


@settings(max_examples=4, deadline=None)
@given(shift=st.floats(-50.0, 50.0).filter(lambda s: abs(s) > 1e-3))
def test_shifting_time_changes_nothing(tmp_path_factory, shift):
    base = signals.handle_signals(_handle_session(tmp_path_factory.mktemp("a")), "fs-1")
    moved = signals.handle_signals(_handle_session(tmp_path_factory.mktemp("b"), shift=shift), "fs-1")
    assert len(moved.t) == len(base.t)
    assert np.allclose(moved.t - shift, base.t, atol=1e-9)
    for name in ("position", "velocity", "angular_velocity", "force", "torque", "acceleration"):
        assert np.allclose(getattr(moved, name), getattr(base, name), atol=1e-6), name


def test_trial_without_usable_mocap_is_a_coded_error(tmp_path):
    w = rb.writer(calibration=[rb.HandleTruth().record()])
    t = np.arange(300) / 100.0
    w.add_trial("ws-1", "workspace", powered=False)
    w.add_stream("ws-1", "handle_pose", _pose_columns(t, np.full((300, 3), np.nan), np.full((300, 4), np.nan)), rate_hz=100)
    with pytest.raises(HaptifyError) as e:
        signals.handle_signals(open_session(w.write(tmp_path / "s")), "ws-1")
    assert e.value.code == "E611"


def test_lowpass_resample_of_one_sample_holds_it():
    # one sample has no rate (nominal_rate is inf): the low-pass passes it through, interpolation holds it (spec §7.2)
    x = np.array([[1.0, -2.0, 3.0]])
    out = preprocessing.lowpass_resample(np.array([0.5]), x, np.array([0.0, 0.5, 1.0]), 20.0)
    assert np.array_equal(out, np.repeat(x, 3, axis=0))


@settings(max_examples=30, deadline=None)
@given(names=st.lists(st.sampled_from(["fx", "fy", "fz", "tx", "ty", "tz"]), min_size=1, max_size=6, unique=True))
def test_table_columns_are_the_named_columns(names):
    """Any selection of a table's columns, consecutive or not and in any order, gives those columns' values
    column by column, as ``frame[names]`` holds them."""
    import pandas as pd

    rng = np.random.default_rng(3)
    frame = pd.DataFrame({c: rng.normal(size=50) for c in ["t", "fx", "fy", "fz", "tx", "ty", "tz"]})
    out = preprocessing.table_columns(frame, names)
    assert out.shape == (50, len(names))
    for j, name in enumerate(names):
        assert np.array_equal(out[:, j], frame[name].to_numpy())
    with pytest.raises(KeyError):
        preprocessing.table_columns(frame, ["fx", "nope"])
