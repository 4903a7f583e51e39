"""The kinematic distance of paper eq. 9 and the segment errors (spec §11.6): window features, the distance
of each test window to the training set, segment means, segment force errors and the error-vs-distance line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptify.codes import Code
from haptify.dynamics import parameter_file
from haptify.dynamics.fitting import one_blas_thread
from haptify.errors import fail
from haptify.formats.conventions import quat_mean


@dataclass(frozen=True)
class DistanceScales:
    """R_p (m), R_v (m/s), R_a (m/s²), R_θ (rad) of paper eq. 9."""

    p: float
    v: float
    a: float
    theta: float

    @classmethod
    def from_definition(cls) -> "DistanceScales":
        """R_p, R_v, R_a, R_θ from the definition file (R_θ converted from degrees; spec §11.6.2)."""
        return cls(
            p=parameter_file.PARAMETERS.R_p,
            v=parameter_file.PARAMETERS.R_v,
            a=parameter_file.PARAMETERS.R_a,
            theta=math.radians(parameter_file.PARAMETERS.R_theta),
        )


@dataclass(frozen=True)
class WindowFeatures:
    """Per-window means (spec §11.6.1): position, velocity, acceleration (W, 3), orientation (W, 4)."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    orientation: np.ndarray

    def __len__(self) -> int:
        return len(self.position)


def window_features(
    position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, quaternion: np.ndarray, window_samples: int
) -> WindowFeatures:
    """Split signals (N, 3)/(N, 4) into consecutive windows of ``window_samples`` samples, dropping the
    incomplete tail, and average each (spec §11.6.1): arithmetic means of position, velocity and
    acceleration; the Markley mean of the quaternions (:func:`haptify.formats.conventions.quat_mean`)."""
    n_win = len(position) // window_samples
    m = n_win * window_samples

    def means(x: np.ndarray, width: int) -> np.ndarray:
        out: np.ndarray = np.asarray(x, dtype=float)[:m].reshape(n_win, window_samples, width).mean(axis=1)
        return out

    q = np.asarray(quaternion, dtype=float)[:m].reshape(n_win, window_samples, 4)
    orient = quat_mean(q) if n_win else np.zeros((0, 4))
    return WindowFeatures(means(position, 3), means(velocity, 3), means(acceleration, 3), orient)


def pair_distance(a: WindowFeatures, b: WindowFeatures, scales: DistanceScales) -> np.ndarray:
    """Δ (dimensionless) of paper eq. 9 between every window of ``a`` and every window of ``b``:
    an array (len(a), len(b)) (spec §11.6.2)."""
    from scipy.spatial.distance import cdist

    dot = np.abs(a.orientation @ b.orientation.T)
    out = (2.0 / scales.theta) * np.arccos(np.clip(dot, 0.0, 1.0))
    out += cdist(a.position, b.position) / scales.p
    out += cdist(a.velocity, b.velocity) / scales.v
    out += cdist(a.acceleration, b.acceleration) / scales.a
    result: np.ndarray = out
    return result


def nearest_distances(test: WindowFeatures, train: WindowFeatures, scales: DistanceScales, chunk: int = 512) -> np.ndarray:
    """For each test window, the minimum over training windows of Δ (paper eq. 9; spec §11.6.2).

    Exact brute force, vectorised in chunks of ``chunk`` test windows (memory ≈ chunk × training
    windows × 8 bytes × a few arrays).
    """
    if len(train) == 0:
        raise fail(
            Code.DYNAMICS_DATA_INSUFFICIENT, "the training set has no complete distance window", expected="≥ 1 window", found=0
        )
    out = np.empty(len(test))
    with one_blas_thread():
        for start in range(0, len(test), chunk):
            stop = min(start + chunk, len(test))
            part = WindowFeatures(
                test.position[start:stop], test.velocity[start:stop], test.acceleration[start:stop], test.orientation[start:stop]
            )
            out[start:stop] = pair_distance(part, train, scales).min(axis=1)
    return out


def segment_distances(window_distances: np.ndarray, windows_per_segment: int) -> np.ndarray:
    """Mean of the window minima over each complete segment (spec §11.6.3); incomplete tail dropped."""
    n_seg = len(window_distances) // windows_per_segment
    out: np.ndarray = window_distances[: n_seg * windows_per_segment].reshape(n_seg, windows_per_segment).mean(axis=1)
    return out


def segment_force_errors(force: np.ndarray, predicted: np.ndarray, segment_samples: int) -> np.ndarray:
    """Each complete segment's force error (spec §11.6.4): the mean over x, y, z of the per-axis RMS error."""
    n_seg = len(force) // segment_samples
    m = n_seg * segment_samples
    d = (np.asarray(force, dtype=float)[:m] - np.asarray(predicted, dtype=float)[:m]).reshape(n_seg, segment_samples, -1)
    out: np.ndarray = np.sqrt(np.mean(d * d, axis=1)).mean(axis=1)
    return out


def line_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Ordinary least-squares line ``y = slope·x + intercept`` (spec §11.6.5).

    E701 unless the distances span more than 1e-6 (distances are dimensionless, O(1)).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if len(x) < 2 or np.ptp(x) <= 1e-6:
        raise fail(
            Code.DYNAMICS_DATA_INSUFFICIENT,
            "a line needs at least two segments at different distances",
            expected="≥ 2 distinct distances",
            found=len(np.unique(x)),
        )
    xm, ym = x.mean(), y.mean()
    slope = float(np.sum((x - xm) * (y - ym)) / np.sum((x - xm) ** 2))
    return slope, float(ym - slope * xm)
