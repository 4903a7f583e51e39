"""Mutants of the vibration chapter (spec chapter 10): axis combination (§10.3), the high-pass filter and its
edge trim (§10.2, §7.2) and the spectral weighting of the centroid (§10.5)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable

import numpy as np
from scipy.signal import cheby1, sosfilt

from haptify.metrics import vibration
from haptify.processing import preprocessing
from haptify_mutants.catalogue.model import Mutant, Patch, _parameters, _replace


def _summed_axes(x: np.ndarray) -> np.ndarray:
    """x + y + z sample by sample."""
    return np.asarray(x, dtype=float).sum(axis=1)


def _vector_magnitude(x: np.ndarray) -> np.ndarray:
    """√(x² + y² + z²) sample by sample."""
    return np.linalg.norm(np.asarray(x, dtype=float), axis=1)


def _z_axis(x: np.ndarray) -> np.ndarray:
    """The accelerometer's z axis alone."""
    return np.asarray(x, dtype=float)[:, 2]


def _loudest_axis(x: np.ndarray) -> np.ndarray:
    """The axis with the largest RMS alone."""
    x = np.asarray(x, dtype=float)
    return x[:, int(np.argmax(np.mean(x * x, axis=0)))]


def _one_pass(sos: np.ndarray, x: np.ndarray, axis: int = -1, **_: Any) -> np.ndarray:
    """A causal single pass where the spec runs the filter forward and backward."""
    return sosfilt(sos, x, axis=axis)


def _butter_order_halved(real: Callable) -> Callable:
    """Butterworth of half the order, so that the forward-backward pair has the stated order."""
    return lambda order, wn, *a, **k: real(max(1, order // 2), wn, *a, **k)


def _butter_rad_per_s(real: Callable) -> Callable:
    """The cut-off taken for an angular frequency (rad/s) and divided by 2π."""
    return lambda order, wn, *a, **k: real(order, wn / (2.0 * math.pi), *a, **k)


def _chebyshev(real: Callable) -> Callable:
    """A Chebyshev type I design (0.5 dB ripple) of the same order and cut-off."""
    return lambda order, wn, *a, **k: cheby1(order, 0.5, wn, *a, **k)


def _hann_spectrum(real: Callable) -> Callable:
    """A Hann window applied before the periodogram (as Welch-type estimators do)."""

    def power_spectrum(a: np.ndarray, rate_hz: float) -> Any:
        a = np.asarray(a, dtype=float)
        return real(a * np.hanning(len(a)), rate_hz)

    return power_spectrum


def _magnitude_spectrum(real: Callable) -> Callable:
    """|A_k| instead of |A_k|² as the centroid's weight (librosa's convention)."""

    def power_spectrum(a: np.ndarray, rate_hz: float) -> Any:
        f, p = real(a, rate_hz)
        return f, np.sqrt(p)

    return power_spectrum


def _combine_then_trim(real: Callable) -> Callable:
    """DFT321 over the whole filtered signal; the edges are cut from the combined signal afterwards."""

    def combine(t: np.ndarray, accel: np.ndarray, trial_id: str = "") -> Any:
        out = real(t, accel, trial_id)
        whole = vibration.dft321(vibration.highpass(accel, preprocessing.nominal_rate(np.asarray(t, dtype=float))))
        trim = (len(t) - len(out.t)) // 2
        return dataclasses.replace(out, signal=whole[trim : trim + len(out.t)])

    return combine


def _trim_start_only(real: Callable) -> Callable:
    """edge_trim_s cut from the start only (the filter's start-up), the end kept."""

    def combine(t: np.ndarray, accel: np.ndarray, trial_id: str = "") -> Any:
        out = real(t, accel, trial_id)
        trim = (len(t) - len(out.t)) // 2
        kept = slice(trim, len(t))
        filtered = vibration.highpass(accel, preprocessing.nominal_rate(np.asarray(t, dtype=float)))
        return dataclasses.replace(out, t=np.asarray(t, dtype=float)[kept], signal=vibration.dft321(filtered[kept]))

    return combine


MUTANTS: tuple[Mutant, ...] = (
    # vibration: axis combination
    Mutant(
        "axes_summed",
        "10.3",
        "R10.3-1",
        "the three axes are combined by DFT321",
        "the axes added sample by sample",
        (Patch(vibration, "dft321", _replace(_summed_axes)),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "vector_magnitude",
        "10.3",
        "R10.3-1",
        "the three axes are combined by DFT321",
        "the per-sample vector magnitude √(x² + y² + z²)",
        (Patch(vibration, "dft321", _replace(_vector_magnitude)),),
        ("vibration.spectral_centroid",),
        cheap=True,
    ),
    Mutant(
        "single_axis_z",
        "10.3",
        "R10.3-1",
        "the three axes are combined by DFT321",
        "only the accelerometer's z axis is analysed",
        (Patch(vibration, "dft321", _replace(_z_axis)),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "loudest_axis",
        "10.3",
        "R10.3-1",
        "the three axes are combined by DFT321",
        "only the axis with the largest RMS is analysed",
        (Patch(vibration, "dft321", _replace(_loudest_axis)),),
        ("vibration.rms",),
        cheap=True,
    ),
    # vibration: filter
    Mutant(
        "single_pass_filter",
        "7.2",
        "R7.2-1",
        "every filter runs forward and backward (zero phase)",
        "a causal single pass (sosfilt)",
        (Patch(vibration, "sosfiltfilt", _replace(_one_pass)), Patch(preprocessing, "sosfiltfilt", _replace(_one_pass))),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "highpass_order_halved",
        "10.2",
        "R10.2-1",
        "a Butterworth of highpass_order = 4, run forward and backward",
        "order 2, so that the forward-backward pair has order 4",
        (Patch(vibration, "butter", _butter_order_halved),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "highpass_cutoff_rad_per_s",
        "10.2",
        "R10.2-1",
        "the high-pass cut-off is 10 Hz",
        "10 read as rad/s: a 1.6 Hz cut-off",
        (Patch(vibration, "butter", _butter_rad_per_s),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "chebyshev_highpass",
        "10.2",
        "R10.2-1",
        "the high-pass is a Butterworth design",
        "a Chebyshev type I design (0.5 dB ripple) of the same order",
        (Patch(vibration, "butter", _chebyshev),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "edge_trim_off",
        "10.2",
        "R10.2-2",
        "edge_trim_s = 0.5 s is cut from each end after filtering",
        "the whole filtered signal is analysed",
        (Patch(vibration, "PARAMETERS", _parameters(edge_trim_s=0.0)),),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    Mutant(
        "edge_trim_start_only",
        "10.2",
        "R10.2-2",
        "edge_trim_s is cut from EACH end",
        "only from the start (the filter's start-up)",
        (Patch(vibration, "combine", _trim_start_only),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "dft321_before_trim",
        "10.2",
        "R10.2-2",
        "the filtered axes are trimmed, then combined by DFT321",
        "DFT321 over the whole filtered signal, trimmed afterwards",
        (Patch(vibration, "combine", _combine_then_trim),),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    # vibration: spectral weighting
    Mutant(
        "magnitude_centroid",
        "10.5",
        "R10.5-1",
        "the centroid weights frequencies by power |A_k|²",
        "by magnitude |A_k| (librosa)",
        (Patch(vibration, "power_spectrum", _magnitude_spectrum),),
        ("vibration.spectral_centroid",),
        cheap=True,
    ),
    Mutant(
        "hann_window_centroid",
        "10.5",
        "R10.5-1",
        "the periodogram uses a rectangular window",
        "a Hann window before the DFT",
        (Patch(vibration, "power_spectrum", _hann_spectrum),),
        ("vibration.spectral_centroid",),
        cheap=True,
    ),
)
