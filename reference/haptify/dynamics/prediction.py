"""Prediction with a Hammerstein–Wiener model (spec §11.3): the piecewise-linear static maps, the quaternion
hemisphere rule, the linear output-error block simulated from rest, and the RMS error of a prediction (§11.7).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from haptify.codes import Code
from haptify.dynamics.parameter_file import HWModelFile, PiecewiseLinearMap, QuaternionHemisphere, UnitGainMap
from haptify.errors import fail

#: The segment index k and local coordinate s of every sample on a piecewise-linear map (:func:`_segments`).
Segments = tuple[np.ndarray, np.ndarray]


def _segments(breakpoints: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment index k (0 … K−2) and local coordinate s of every u (spec §11.3 step 2).

    k is the last breakpoint ≤ u, clipped to the first and last segment, so values beyond the ends
    extend the end segments linearly (s < 0 or s > 1).
    """
    k = np.clip(np.searchsorted(breakpoints, u, side="right") - 1, 0, len(breakpoints) - 2)
    s = (u - breakpoints[k]) / (breakpoints[k + 1] - breakpoints[k])
    return k, s


def pwl_eval(breakpoints: np.ndarray, values: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Evaluate a piecewise-linear map with linear extension at ``u`` (spec §11.3)."""
    bp = np.asarray(breakpoints, dtype=float)
    v = np.asarray(values, dtype=float)
    k, s = _segments(bp, np.asarray(u, dtype=float))
    out: np.ndarray = v[k] + s * (v[k + 1] - v[k])
    return out


def pwl_basis(breakpoints: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The ``(N, K)`` matrix Φ with ``pwl_eval(bp, v, u) == Φ @ v`` (hat functions, extended at the ends).
    Φ of spec §11.4.3."""
    bp = np.asarray(breakpoints, dtype=float)
    k, s = _segments(bp, np.asarray(u, dtype=float))
    return _hat_columns(np.empty((len(k), len(bp))), k, s)


def _hat_columns(out: np.ndarray, k: np.ndarray, s: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """``scale`` times the hat functions of the segments (k, s) of :func:`_segments` written into ``out``
    (N, K), which may be a view (e.g. some columns of a Jacobian): row t is zero but for
    scale·(1 − s_t) in column k_t and scale·s_t in column k_t + 1."""
    out[:] = 0.0
    rows = np.arange(len(k))
    out[rows, k] = scale * (1.0 - s)
    out[rows, k + 1] = scale * s
    return out


def pwl_slope(breakpoints: np.ndarray, values: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Slope of the map at ``u`` (output units per input unit): that of the segment step 2 of spec §11.3 picks."""
    bp = np.asarray(breakpoints, dtype=float)
    v = np.asarray(values, dtype=float)
    k, _ = _segments(bp, np.asarray(u, dtype=float))
    out: np.ndarray = (v[k + 1] - v[k]) / (bp[k + 1] - bp[k])
    return out


def apply_map(m: PiecewiseLinearMap | UnitGainMap, u: np.ndarray) -> np.ndarray:
    """A channel's static map applied to a signal (spec §11.3)."""
    if isinstance(m, UnitGainMap):
        return np.asarray(u, dtype=float)
    return pwl_eval(np.asarray(m.breakpoints), np.asarray(m.values), u)


def _delayed(signal: np.ndarray, d: int) -> np.ndarray:
    """``signal`` delayed by ``d`` samples along axis 0, zeros before t = 0."""
    if d == 0:
        return signal
    out = np.zeros_like(signal)
    if d < len(signal):
        out[d:] = signal[: len(signal) - d]
    return out


def hemisphere_align(u: np.ndarray, hemi: QuaternionHemisphere | None) -> np.ndarray:
    """Flip each quaternion input sample to the hemisphere of the model's reference (spec §11.3 step 1)."""
    if hemi is None:
        return u
    u = np.array(u, dtype=float, copy=True)
    cols = list(hemi.columns)
    sign = np.where(u[:, cols] @ np.asarray(hemi.reference, dtype=float) < 0.0, -1.0, 1.0)
    u[:, cols] *= sign[:, None]
    return u


def _check_inputs(model: HWModelFile, u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    if u.ndim != 2 or u.shape[1] != model.nu:
        raise fail(
            Code.HW_MODEL_DATA_MISMATCH,
            f"the model has {model.nu} inputs but the data have shape {u.shape}",
            expected=f"(N, {model.nu})",
            found=list(u.shape),
        )
    if not np.all(np.isfinite(u)):
        bad = int(np.argmax(~np.all(np.isfinite(u), axis=1)))
        raise fail(
            Code.HW_MODEL_DATA_MISMATCH,
            f"model inputs hold a non-finite value (first at sample {bad})",
            expected="finite inputs",
            found="NaN or inf",
        )
    return u


def predict(model: HWModelFile, u: np.ndarray) -> np.ndarray:
    """Simulate the model on inputs ``u (N, nu)`` from zero initial conditions; returns ``y (N, ny)``.

    Spec §11.3: hemisphere alignment, input maps, the linear output-error block by the difference
    equation z(t) = Σ_k b_k w(t − nk − k + 1) − Σ_l f_l z(t − l) with w, z = 0 before t = 0, summation
    over inputs, output maps. Deterministic (double precision, no randomness).
    """
    u = hemisphere_align(_check_inputs(model, u), model.quaternion_hemisphere)
    w = np.column_stack([apply_map(model.input_maps[i], u[:, i]) for i in range(model.nu)])
    y = np.empty((len(u), model.ny))
    for j in range(model.ny):
        x = np.zeros(len(u))
        for i, tf in enumerate(model.linear[j]):
            num = np.concatenate([np.zeros(tf.nk), tf.b])
            x += lfilter(num, np.concatenate([[1.0], tf.f]), w[:, i])
        y[:, j] = apply_map(model.output_maps[j], x)
    return y


def rmse(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """Per-column RMS error of ``yhat`` against ``y`` (same units; spec §11.7)."""
    d = np.asarray(y, dtype=float) - np.asarray(yhat, dtype=float)
    out: np.ndarray = np.sqrt(np.mean(d * d, axis=0))
    return out
