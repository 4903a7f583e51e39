"""Mutants of the local dynamics (spec chapter 11): the Hammerstein–Wiener model's evaluation (§11.3), the
pose distance (§11.6.2), the segment errors and the trend line (§11.6.4, §11.6.5) and the RMSE (§11.7)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable

import numpy as np

from haptify.dynamics import distance as ld_distance
from haptify.dynamics import fitting as ld_fitting
from haptify.dynamics import metrics as ld_metrics
from haptify.dynamics import prediction as ld_prediction
from haptify.dynamics import trials as ld_trials
from haptify_mutants.catalogue.model import Make, Mutant, Patch, _post, _replace


def _rmse_of_magnitude(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """Per column block of three (force, torque) the RMS of the error vector's magnitude, for each of its axes."""
    d = np.asarray(y, dtype=float) - np.asarray(yhat, dtype=float)
    out = np.sqrt(np.mean(d * d, axis=0))
    for start in range(0, d.shape[1] - 2, 3):
        out[start : start + 3] = np.sqrt(np.mean(np.sum(d[:, start : start + 3] ** 2, axis=1)))
    return out


def _scales(theta: Callable[[float], float]) -> Make:
    """``DistanceScales.from_definition`` with R_θ replaced by ``theta(R_θ in rad)``."""
    return lambda real: staticmethod(lambda: dataclasses.replace(real(), theta=theta(real().theta)))


def _angle_not_doubled(real: Callable) -> Callable:
    """θ_ab = arccos|q̄_a·q̄_b| (the half angle) instead of 2 arccos|q̄_a·q̄_b|."""

    def pair_distance(a: Any, b: Any, scales: Any) -> np.ndarray:
        half = np.arccos(np.clip(np.abs(a.orientation @ b.orientation.T), 0.0, 1.0))
        return real(a, b, scales) - half / scales.theta

    return pair_distance


def _euclidean_terms(real: Callable) -> Callable:
    """Δ as the Euclidean norm of the four normalised differences instead of their sum."""

    def pair_distance(a: Any, b: Any, scales: Any) -> np.ndarray:
        inf = math.inf
        alone = [
            dataclasses.replace(scales, **{k: inf for k in ("p", "v", "a", "theta") if k != keep})
            for keep in ("p", "v", "a", "theta")
        ]
        return np.sqrt(sum(real(a, b, s) ** 2 for s in alone))

    return pair_distance


def _mean_to_training(test: Any, train: Any, scales: Any, chunk: int = 512) -> np.ndarray:
    """A test window's distance to the training set as the mean over training windows, not the minimum."""
    return ld_distance.pair_distance(test, train, scales).mean(axis=1)


def _vector_rms_errors(force: np.ndarray, predicted: np.ndarray, segment_samples: int) -> np.ndarray:
    """A segment's force error as the RMS of the error vector's norm, not the mean of per-axis RMS errors."""
    n_seg = len(force) // segment_samples
    d = (np.asarray(force, dtype=float) - np.asarray(predicted, dtype=float))[: n_seg * segment_samples]
    return np.sqrt(np.mean(np.sum(d.reshape(n_seg, segment_samples, -1) ** 2, axis=2), axis=1))


def _clamped_map(breakpoints: np.ndarray, values: np.ndarray, u: np.ndarray) -> np.ndarray:
    """A piecewise-linear map held constant beyond its end breakpoints (``numpy.interp``)."""
    return np.interp(u, breakpoints, values)


def _denominator_sign(real: Callable) -> Callable:
    """F(q) = 1 − f_1 q⁻¹ − … (the autoregressive sign convention) instead of 1 + f_1 q⁻¹ + …."""

    def lfilter(b: Any, a: Any, x: Any, *args: Any, **kw: Any) -> Any:
        a = np.asarray(a, dtype=float)
        return real(b, np.concatenate([a[:1], -a[1:]]), x, *args, **kw)

    return lfilter


def _delays_ignored(real: Callable) -> Callable:
    """Every block's input delay nk taken as 0."""

    def predict(model: Any, u: np.ndarray) -> np.ndarray:
        rows = [[tf.model_copy(update={"nk": 0}) for tf in row] for row in model.linear]
        return real(model.model_copy(update={"linear": rows}), u)

    return predict


def _test_segments_only(rows: list, *_: Any) -> list:
    """The error-vs-distance line fitted through the test segments only."""
    return [r for r in rows if r["set"] != "training"]


MUTANTS: tuple[Mutant, ...] = (
    # local dynamics
    Mutant(
        "training_trial_first_listed",
        "11.7",
        "R11.7-2",
        "the training trial is the local_dynamic trial with the LOWEST repetition",
        "the first local_dynamic trial in manifest order",
        (
            Patch(
                ld_metrics,
                "training_trial",
                _replace(lambda session: next(t for t in session.trials if t.protocol == "local_dynamic")),
            ),
        ),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "hemisphere_ignored",
        "11.3",
        "R11.3-1",
        "quaternions are flipped to the hemisphere of the file's reference",
        "the hemisphere rule is left out",
        (Patch(ld_prediction, "hemisphere_align", _replace(lambda u, hemi: np.array(u, dtype=float)), everywhere=True),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "pwl_clamped_ends",
        "11.3",
        "R11.3-1",
        "piecewise-linear maps extend their end segments linearly",
        "values beyond the end breakpoints are clamped (numpy.interp)",
        (Patch(ld_prediction, "pwl_eval", _replace(_clamped_map)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "denominator_sign_flipped",
        "11.3",
        "R11.3-1",
        "F(q) = 1 + f_1 q⁻¹ + … + f_nf q^−nf",
        "1 − f_1 q⁻¹ − … (autoregressive sign)",
        (Patch(ld_prediction, "lfilter", _denominator_sign), Patch(ld_fitting, "lfilter", _denominator_sign)),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "input_delay_ignored",
        "11.3",
        "R11.3-1",
        "each block delays its input by nk samples",
        "nk is ignored",
        (Patch(ld_trials, "predict", _delays_ignored),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "orientation_rad_over_86",
        "11.6.2",
        "R11.6-1",
        "R_θ = 86° is converted to radians; θ is in radians",
        "θ in radians divided by 86",
        (Patch(ld_distance.DistanceScales, "from_definition", _scales(lambda th: 86.0)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "orientation_degrees_over_rad",
        "11.6.2",
        "R11.6-1",
        "R_θ = 86° is converted to radians; θ is in radians",
        "θ in degrees divided by R_θ in radians",
        (Patch(ld_distance.DistanceScales, "from_definition", _scales(lambda th: th * math.pi / 180.0)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "orientation_angle_not_doubled",
        "11.6.2",
        "R11.6-1",
        "θ_ab = 2 arccos|q̄_a·q̄_b|",
        "arccos|q̄_a·q̄_b| (the half angle)",
        (Patch(ld_distance, "pair_distance", _angle_not_doubled),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "distance_euclidean",
        "11.6.2",
        "R11.6-1",
        "Δ is the SUM of the four normalised differences",
        "their Euclidean norm",
        (Patch(ld_distance, "pair_distance", _euclidean_terms),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "distance_mean_over_training",
        "11.6.2",
        "R11.6-1",
        "a window's distance to the training set is the minimum over training windows",
        "the mean over training windows",
        (Patch(ld_trials, "nearest_distances", _replace(_mean_to_training)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "segment_error_vector_rms",
        "11.6.4",
        "R11.6-2",
        "a segment's force error is the mean over x, y, z of per-axis RMS errors",
        "the RMS of the error vector's norm",
        (Patch(ld_trials, "segment_force_errors", _replace(_vector_rms_errors)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "line_through_test_segments_only",
        "11.6.5",
        "R11.6-2",
        "the line is fitted through the training AND test segments",
        "through the test segments only",
        (Patch(ld_metrics, "segment_table", _post(_test_segments_only)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "rmse_of_error_magnitude",
        "11.7",
        "R11.7-1",
        "force (torque) RMSE is the per-axis RMS of the prediction error",
        "the RMS of the error vector's magnitude for every axis",
        (Patch(ld_prediction, "rmse", _replace(_rmse_of_magnitude), everywhere=True),),
        ("dynamics.force_rmse", "dynamics.force_rmse_mean"),
    ),
)
