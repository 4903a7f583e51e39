"""Mutants of the low-pass filtering and resampling of spec chapter 7 (§7.2, §7.3, §7.5) and of the
recorders' clock offsets (§2.8)."""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.signal import butter, sosfiltfilt

from haptify.formats import storage
from haptify.processing import preprocessing
from haptify_mutants.catalogue.model import Mutant, Patch, _replace


def _lowpass_rad_per_s(real: Callable) -> Callable:
    """Every low-pass cut-off taken for rad/s and divided by 2π."""
    return lambda x, rate_hz, cutoff_hz, *, order=None: real(x, rate_hz, cutoff_hz / (2.0 * math.pi), order=order)


def _lowpass_ends_untreated(real: Callable) -> Callable:
    """Forward-backward Butterworth without §7.2's chord removal and odd padding (filter started at the
    first sample's value)."""

    def lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float, *, order: int | None = None) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if len(x) < 2:
            return x.copy()
        order = preprocessing.PARAMETERS.filter_order if order is None else order
        sos = butter(order, preprocessing.effective_cutoff(cutoff_hz, rate_hz), fs=rate_hz, output="sos")
        return sosfiltfilt(sos, x, axis=0, padtype=None)

    return lowpass


def _resample_then_lowpass(real: Callable) -> Callable:
    """Interpolate the raw stream onto the grid first, then low-pass it there."""

    def lowpass_resample(t_src: np.ndarray, x_src: np.ndarray, t_dst: np.ndarray, cutoff_hz: float) -> np.ndarray:
        on_grid = preprocessing.interp_columns(t_src, x_src, t_dst)
        return preprocessing.lowpass(on_grid, preprocessing.nominal_rate(t_dst), cutoff_hz)

    return lowpass_resample


def _nearest_columns(t_src: np.ndarray, x_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Nearest-neighbour resampling (the sample nearest each grid time) instead of linear interpolation."""
    t_src = np.asarray(t_src, dtype=float)
    t_dst = np.asarray(t_dst, dtype=float)
    k = np.clip(np.searchsorted(t_src, t_dst), 1, len(t_src) - 1)
    k = k - ((t_dst - t_src[k - 1]) <= (t_src[k] - t_dst))
    return np.asarray(x_src, dtype=float)[k]


def _grid_on_clock_multiples(real: Callable) -> Callable:
    """The grid anchored at multiples of 1/rate on the session clock (pandas-style resampling)."""
    return lambda t0, t1, rate_hz: real(math.ceil(t0 * rate_hz - 1e-9) / rate_hz, t1, rate_hz)


MUTANTS: tuple[Mutant, ...] = (
    # low-pass filtering and resampling
    Mutant(
        "lowpass_cutoff_rad_per_s",
        "7.2",
        "R7.2-1",
        "low-pass cut-offs are in Hz (wrench 20 Hz, mocap 10 Hz)",
        "read as rad/s and divided by 2π",
        (Patch(preprocessing, "lowpass", _lowpass_rad_per_s, everywhere=True),),
        ("surface.planar_force_sd", "free_space.speed_mean"),
        cheap=True,
    ),
    Mutant(
        "filter_ends_untreated",
        "7.2",
        "R7.2-1",
        "the chord is removed and the ends odd-padded before filtering",
        "sosfiltfilt without padding, started from the first sample",
        (Patch(preprocessing, "lowpass", _lowpass_ends_untreated, everywhere=True),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "sensor_streams_unfiltered",
        "7.5",
        "R7.5-1",
        "raw F/T and accelerometer streams are low-passed before resampling",
        "they are interpolated onto the grid as recorded",
        (
            Patch(
                preprocessing,
                "lowpass_resample",
                _replace(lambda t_src, x_src, t_dst, cutoff_hz: preprocessing.interp_columns(t_src, x_src, t_dst)),
                everywhere=True,
            ),
        ),
        ("free_space.force_max",),
        cheap=True,
    ),
    Mutant(
        "lowpass_after_resampling",
        "7.5",
        "R7.5-1",
        "raw streams are low-passed at their native rate, then interpolated",
        "interpolated onto the grid first, then low-passed at the grid rate",
        (Patch(preprocessing, "lowpass_resample", _resample_then_lowpass, everywhere=True),),
        ("free_space.force_max",),
        cheap=True,
    ),
    Mutant(
        "nearest_resampling",
        "7.2",
        "R7.2-2",
        "values between samples are interpolated linearly",
        "the nearest sample is taken",
        (Patch(preprocessing, "interp_columns", _replace(_nearest_columns), everywhere=True),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "grid_on_clock_multiples",
        "7.3",
        "R7.3-1",
        "the grid starts at the latest first sample of the trial's streams",
        "the grid is anchored at multiples of 1/rate on the session clock",
        (Patch(preprocessing, "uniform_grid", _grid_on_clock_multiples, everywhere=True),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "clock_offset_opposite_sign",
        "2.8",
        "R1.4-1",
        "a clock_offset record's offset_s is ADDED to the stream's t",
        "subtracted from the stream's t",
        (Patch(storage.SessionFolder, "clock_offset", lambda real: lambda self, s: -real(self, s)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "clock_offset_ignored",
        "2.8",
        "R1.4-1",
        "clock_offset records put streams on the session clock",
        "the records are ignored",
        (Patch(storage.SessionFolder, "clock_offset", _replace(lambda self, s: 0.0)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
)
