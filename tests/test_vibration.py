"""Free-space vibrations (spec chapter 10): DFT321, RMS and centroid against answers known by construction."""

from __future__ import annotations

import math

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.errors import HaptifyError
from haptify.formats.conventions import quat_from_axis_angle, quat_to_matrix
from haptify.formats.storage import SessionWriter, open_session
from haptify.metrics import vibration
from haptify.metrics.vibration import (
    combine,
    compute,
    dft321,
    highpass,
    power_spectrum,
    rms,
    spectral_centroid,
)
from haptify.pipeline.compute import ComputeContext
from haptify.pipeline.results import MetricResult, Unavailable
from haptify.report.figures.vibration import report_audio, report_figures
from haptify_tools.example_session import IDENTITY, TOUCH_DEVICE, example_rig

RATE = 2000.0
TRIM = vibration.PARAMETERS.edge_trim_s


def gain(f: float) -> float:
    """Net amplitude gain of the zero-phase high-pass at f (Hz): |H|² of the Butterworth design."""
    fc, order = vibration.PARAMETERS.highpass_cutoff_hz, vibration.PARAMETERS.highpass_order
    return 1.0 / (1.0 + (fc / f) ** (2 * order))


def kept_seconds(total_s: float) -> float:
    return total_s - 2 * TRIM


def times(total_s: float, t0: float = 0.0) -> np.ndarray:
    return t0 + np.arange(int(round(total_s * RATE))) / RATE


def band_noise(n: int, f_lo: float, f_hi: float, rms_value: float, rng) -> np.ndarray:
    """Noise with a flat magnitude spectrum on the DFT bins in [f_lo, f_hi] and random phases; exact RMS."""
    f = np.fft.rfftfreq(n, 1 / RATE)
    band = (f >= f_lo) & (f <= f_hi)
    spec = np.zeros(len(f), complex)
    spec[band] = np.exp(1j * rng.uniform(0, 2 * np.pi, band.sum()))
    x = np.fft.irfft(spec, n=n)
    return x * rms_value / rms(x)


# --- DFT321 (spec §10.3) ------------------------------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(st.integers(8, 600), st.integers(0, 2**32 - 1))
def test_dft321_preserves_energy_exactly(n, seed):
    x = np.random.default_rng(seed).normal(size=(n, 3)) * [1.0, 0.3, 2.0]
    a = dft321(x)
    assert a.shape == (n,)
    assert np.sum(a**2) == pytest.approx(np.sum(x**2), rel=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.integers(8, 600), st.integers(0, 2**32 - 1), st.integers(0, 2))
def test_dft321_of_a_single_axis_is_that_axis(n, seed, axis):
    x = np.zeros((n, 3))
    x[:, axis] = np.random.default_rng(seed).normal(size=n)
    np.testing.assert_allclose(dft321(x), x[:, axis], atol=1e-12)


def test_dft321_of_three_equal_axes_is_root_three_times_one():
    x = np.sin(2 * np.pi * 37 * times(1.0)) + 0.2
    np.testing.assert_allclose(dft321(np.column_stack([x, x, x])), math.sqrt(3) * x, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(0, math.pi), st.integers(0, 2**32 - 1))
def test_rotating_the_sensor_frame_changes_neither_rms_nor_centroid(ax, ay, az, angle, seed):
    if ax * ax + ay * ay + az * az < 1e-3:
        ax = 1.0
    x = np.random.default_rng(seed).normal(size=(1000, 3)) * [1.0, 0.5, 0.1]
    r = quat_to_matrix(quat_from_axis_angle(np.array([ax, ay, az]), np.array(angle)))
    a, b = dft321(x), dft321(x @ r.T)
    assert rms(b) == pytest.approx(rms(a), rel=1e-10)
    assert spectral_centroid(b, RATE) == pytest.approx(spectral_centroid(a, RATE), rel=1e-10)


# --- RMS and centroid of known signals (spec §10.4–10.5) -----------------------------------------


def test_centroid_and_rms_of_a_pure_tone():
    t = times(2.0)
    a = 0.3 * np.sin(2 * np.pi * 150.0 * t)
    assert rms(a) == pytest.approx(0.3 / math.sqrt(2), rel=1e-12)
    assert spectral_centroid(a, RATE) == pytest.approx(150.0, rel=1e-12)


def test_centroid_is_power_weighted():
    t = times(2.0)
    a = 1.0 * np.sin(2 * np.pi * 100 * t) + 2.0 * np.sin(2 * np.pi * 300 * t)
    # power weights 1² and 2² (a magnitude-weighted centroid would give (100 + 2·300)/3 = 233.3 Hz)
    assert spectral_centroid(a, RATE) == pytest.approx((1 * 100 + 4 * 300) / 5, rel=1e-12)


def test_band_limited_noise_has_its_constructed_rms_and_centroid():
    rng = np.random.default_rng(7)
    n = 4000
    a = band_noise(n, 50.0, 400.0, 0.05, rng)
    f = np.fft.rfftfreq(n, 1 / RATE)
    band = f[(f >= 50) & (f <= 400)]
    assert rms(a) == pytest.approx(0.05, rel=1e-12)
    assert spectral_centroid(a, RATE) == pytest.approx(band.mean(), rel=1e-12)


def test_periodogram_weights_dc_and_nyquist_once():
    f, p = power_spectrum(np.array([1.0, -1.0, 1.0, -1.0]), 4.0)
    np.testing.assert_allclose(f, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(p, [0.0, 0.0, 16.0])


# --- the pipeline on raw accelerometer data (spec §10.2, §10.6) ---------------------------------


def raw_accel(t: np.ndarray, rng=None, noise=0.0) -> np.ndarray:
    """Gravity slowly rotating through the sensor (0.1 Hz), a bias, hand motion at 1.5 Hz and a 150 Hz tone
    of amplitude 0.05 m/s² on x and 0.02 m/s² at 230 Hz on z."""
    g = 9.81
    th = 0.5 * np.sin(2 * np.pi * 0.1 * t)
    x = g * np.sin(th) + 0.12 + 0.8 * np.sin(2 * np.pi * 1.5 * t) + 0.05 * np.sin(2 * np.pi * 150 * t)
    y = -0.05 + 0.5 * np.cos(2 * np.pi * 1.5 * t)
    z = g * np.cos(th) + 0.3 + 0.02 * np.sin(2 * np.pi * 230 * t)
    out = np.column_stack([x, y, z])
    if noise:
        out += rng.normal(scale=noise, size=out.shape)
    return out


def test_pipeline_removes_gravity_bias_and_hand_motion():
    t = times(11.0)  # 10 s remain after trimming: 150 Hz and 230 Hz fall on DFT bins
    v = combine(t, raw_accel(t))
    expected_power = (0.05 * gain(150)) ** 2 / 2 + (0.02 * gain(230)) ** 2 / 2
    assert v.rms == pytest.approx(math.sqrt(expected_power), rel=2e-3)
    expected_centroid = (150 * 0.05**2 + 230 * 0.02**2) / (0.05**2 + 0.02**2)
    assert v.centroid == pytest.approx(expected_centroid, rel=2e-3)
    assert len(v.signal) == len(t) - 2 * int(TRIM * RATE)


def test_time_shift_changes_nothing_and_scaling_scales_rms_only():
    t = times(6.0)
    a = raw_accel(t, np.random.default_rng(1), noise=0.01)
    base = combine(t, a)
    shifted = combine(t + 123.456, a)
    assert shifted.rms == pytest.approx(base.rms, rel=1e-9)
    assert shifted.centroid == pytest.approx(base.centroid, rel=1e-9)
    scaled = combine(t, 3.0 * a)
    assert scaled.rms == pytest.approx(3.0 * base.rms, rel=1e-9)
    assert scaled.centroid == pytest.approx(base.centroid, rel=1e-9)


def test_highpass_response_is_the_squared_butterworth():
    t = times(20.0)
    for f in (10.0, 20.0, 40.0):
        y = highpass(np.sin(2 * np.pi * f * t), RATE)
        mid = slice(len(t) // 4, 3 * len(t) // 4)
        assert np.max(np.abs(y[mid])) == pytest.approx(gain(f), rel=2e-3)


def test_too_short_and_too_slow_signals_are_coded_errors():
    t = times(1.5)
    with pytest.raises(HaptifyError) as short:
        combine(t, raw_accel(t))
    assert short.value.code == "E316"
    with pytest.raises(HaptifyError) as slow:
        highpass(np.zeros((100, 3)), 15.0)
    assert slow.value.code == "E316"


@pytest.mark.parametrize("n", [1, 2, 5, 15])
def test_a_few_samples_are_e316_not_a_filter_padding_error(n):
    # sosfiltfilt needs more samples than its padding (15 for order 4): the length is checked first (spec §10.2)
    t = np.arange(n) / RATE
    with pytest.raises(HaptifyError) as err:
        combine(t, np.ones((n, 3)), "short")
    assert err.value.code == "E316"


# --- session level (spec §10.6) -----------------------------------------------------------------


def vibration_session(tmp_path, *, with_baseline: bool):
    w = SessionWriter(
        manifest={
            "session_id": "vib",
            "date": "2026-11-22",
            "lab": {"id": "lab"},
            "examiner": {"id": "ex"},
            "device": TOUCH_DEVICE,
            "device_placement": IDENTITY,
            "rig": example_rig(),
        }
    )
    rng = np.random.default_rng(3)
    t = times(6.0)
    amplitudes = [0.04, 0.05, 0.06]
    for i, amp in enumerate(amplitudes, start=1):
        a = raw_accel(t)
        a[:, 0] += (amp - 0.05) * np.sin(2 * np.pi * 150 * t)
        w.add_trial(f"fs-{i}", "free_space", powered=False, repetition=i)
        w.add_stream(f"fs-{i}", "handle_accel", {"t": t, "ax": a[:, 0], "ay": a[:, 1], "az": a[:, 2]}, rate_hz=RATE)
    if with_baseline:
        w.add_trial("base-1", "rig.baseline_vibration", powered=False)
        n = band_noise(len(t), 80.0, 140.0, 0.03, rng)
        g = np.full(len(t), 9.81)
        w.add_stream("base-1", "handle_accel", {"t": t, "ax": n, "ay": 0 * n, "az": g}, rate_hz=RATE)
    return open_session(w.write(tmp_path / "s")), amplitudes


def test_session_metrics_aggregate_repetitions(tmp_path):
    session, amplitudes = vibration_session(tmp_path, with_baseline=True)
    res = {m.id: m for m in compute(ComputeContext(session=session))}
    assert all(isinstance(m, MetricResult) for m in res.values())
    per = res["vibration.rms"].per_repetition
    for value, amp in zip(per, amplitudes):
        assert value == pytest.approx(math.sqrt((amp * gain(150)) ** 2 / 2 + (0.02 * gain(230)) ** 2 / 2), rel=5e-3)
    assert res["vibration.rms"].value == pytest.approx(np.mean(per))
    assert res["vibration.rms"].sd == pytest.approx(np.std(per, ddof=1))
    assert res["vibration.rms"].n == 3 and res["vibration.rms"].unit == "m/s^2"
    assert res["vibration.baseline_rms"].value == pytest.approx(0.03, rel=0.02)
    assert res["vibration.baseline_centroid"].value == pytest.approx(110.0, rel=0.02)
    assert res["vibration.spectral_centroid"].unit == "Hz"
    ctx = ComputeContext(session=session)
    audio = report_audio(ctx)
    assert [a.name for a in audio] == ["vibration_fs-1", "vibration_fs-2", "vibration_fs-3", "vibration_base-1"]
    assert audio[0].rate_hz == pytest.approx(RATE) and len(audio[0].samples) == len(times(6.0)) - 2 * int(TRIM * RATE)
    assert len(report_figures(ctx, None)) == 4
    plt.close("all")


def test_missing_baseline_is_unavailable_with_a_code(tmp_path):
    session, _ = vibration_session(tmp_path, with_baseline=False)
    res = {m.id: m for m in compute(ComputeContext(session=session))}
    assert isinstance(res["vibration.baseline_rms"], Unavailable) and res["vibration.baseline_rms"].code == "E310"
    assert isinstance(res["vibration.rms"], MetricResult)
