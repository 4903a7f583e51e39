"""Mutants of the motion-capture processing (spec §7.4): gaps bridged or not, and velocities differentiated
without the low-pass."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable

import numpy as np

from haptify.processing import preprocessing
from haptify_mutants.catalogue.model import Make, Mutant, Patch


def _raw_derivative(which: str) -> Make:
    """``process_mocap`` whose velocity (or angular velocity) is differentiated without the §7.4 low-pass."""

    def make(real: Callable) -> Callable:
        def process_mocap(t: np.ndarray, position: np.ndarray, quaternion: np.ndarray) -> Any:
            track = real(t, position, quaternion)
            t = np.asarray(t, dtype=float)
            raw, _, _ = preprocessing.bridge_gaps(t, position, quaternion)
            out = np.array(getattr(track, which), copy=True)
            for k in range(int(track.segment.max()) + 1 if len(t) else 0):
                m = np.flatnonzero(track.segment == k)
                out[m] = (
                    np.gradient(raw[m], t[m], axis=0)
                    if which == "velocity"
                    else preprocessing.angular_velocity(t[m], track.quaternion[m])
                )
            return dataclasses.replace(track, **{which: out})

        return process_mocap

    return make


def _gap_limit_strict(real: Callable) -> Callable:
    """Gaps bridged only when t_j − t_i ≤ max_gap_s (the sample interval Δ of §7.4 left out)."""

    def bridge_gaps(t: np.ndarray, position: np.ndarray, quaternion: np.ndarray, max_gap_s: float | None = None) -> Any:
        limit = float(preprocessing.PARAMETERS.max_gap_s if max_gap_s is None else max_gap_s)
        return real(t, position, quaternion, max_gap_s=limit - float(np.median(np.diff(np.asarray(t, dtype=float)))))

    return bridge_gaps


MUTANTS: tuple[Mutant, ...] = (
    # motion capture
    Mutant(
        "gaps_interpolated",
        "7.4",
        "R7.4-1",
        "occlusion gaps longer than max_gap_s are never interpolated across",
        "every gap is bridged",
        (Patch(preprocessing, "bridge_gaps", lambda real: lambda t, p, q, max_gap_s=None: real(t, p, q, max_gap_s=math.inf)),),
        ("free_space.speed_mean",),
        cheap=True,
    ),
    Mutant(
        "gap_limit_without_sample_interval",
        "7.4",
        "R7.4-1",
        "a gap is bridged when t_j − t_i ≤ max_gap_s + Δ",
        "when t_j − t_i ≤ max_gap_s",
        (Patch(preprocessing, "bridge_gaps", _gap_limit_strict),),
        ("free_space.force_max",),
        cheap=True,
    ),
    Mutant(
        "speed_from_raw_positions",
        "7.4",
        "R7.4-2",
        "velocity is the derivative of the low-passed position",
        "of the raw positions",
        (Patch(preprocessing, "process_mocap", _raw_derivative("velocity")),),
        ("free_space.speed_mean",),
        cheap=True,
    ),
    Mutant(
        "angular_velocity_unfiltered",
        "7.4",
        "R7.4-2",
        "the angular velocity is low-passed at angular_velocity_cutoff_hz",
        "it is used as differentiated",
        (Patch(preprocessing, "process_mocap", _raw_derivative("angular_velocity")),),
        ("free_space.angular_speed_mean",),
        cheap=True,
    ),
)
