"""Forces outside the effect library, added to measured trials as if the device produced them (the
verdict's known answers in tests and benchmarks; discrepancy README §3, "unexplained").

No simulator effect id models a cogging force periodic in the hand's position or a force that grows with the
square of the speed, so a session cannot be generated with one. Instead the force field is evaluated along the
trial's hand path on the simulation grid (1 kHz cubic spline, like :func:`.data.simulate_trial`), low-passed at
:data:`.data.RESIDUAL_CUTOFF_HZ` like every force the workflow compares, and added to the measured force: what the
handle would have measured had the device carried the field, up to the path's own reconstruction error.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline

from haptify.processing.preprocessing import lowpass
from haptify_tools.discrepancy.data import RESIDUAL_CUTOFF_HZ, SIM_RATE_HZ, MeasuredTrial

#: field(t s, position m (n, 3, W), velocity m/s (n, 3)) → force on the hand, N (n, 3, W)
ForceField = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Cogging:
    """``F = A·sin(2π·p_axis / λ)·u``: a force of amplitude ``A`` (N) along the unit world axis ``direction``,
    periodic in the hand's world coordinate ``axis`` (0 = x) with period ``λ`` (m)."""

    amplitude_N: float
    period_m: float
    axis: int = 0
    direction: int = 0

    def __call__(self, t: np.ndarray, p: np.ndarray, v: np.ndarray) -> np.ndarray:
        f = np.zeros_like(p)
        f[:, self.direction] = self.amplitude_N * np.sin(2 * np.pi * p[:, self.axis] / self.period_m)
        return f


@dataclass(frozen=True)
class SpeedSquared:
    """``F = c·|v|²·u``: a force along the unit world axis ``direction`` growing with the square of the hand's
    speed (``c`` in N·s²/m²) — even in the velocity, so no friction (odd in every joint speed) can represent it."""

    coefficient_Ns2_per_m2: float
    direction: int = 0

    def __call__(self, t: np.ndarray, p: np.ndarray, v: np.ndarray) -> np.ndarray:
        f = np.zeros_like(p)
        f[:, self.direction] = self.coefficient_Ns2_per_m2 * np.sum(v**2, axis=1)
        return f


def field_on_grid(trial: MeasuredTrial, field: ForceField) -> np.ndarray:
    """``field`` along the trial's hand path on the 1 kHz simulation grid, low-passed at the residual cut-off and
    put back on the trial's grid (N, W, ``(n, 3)``)."""
    dt = 1.0 / SIM_RATE_HZ
    fine = np.arange(trial.t[0], trial.t[-1] + 0.5 * dt, dt)
    fine = fine[fine <= trial.t[-1]]
    spline = CubicSpline(trial.t, trial.position, axis=0)
    force = lowpass(field(fine, spline(fine), spline(fine, 1)), SIM_RATE_HZ, RESIDUAL_CUTOFF_HZ)
    return np.stack([np.interp(trial.t, fine, force[:, k]) for k in range(3)], axis=1)


def with_field(trials: list[MeasuredTrial], field: ForceField) -> list[MeasuredTrial]:
    """Copies of ``trials`` whose measured force also holds ``field`` (module docstring)."""
    return [replace(tr, force=tr.force + field_on_grid(tr, field)) for tr in trials]
