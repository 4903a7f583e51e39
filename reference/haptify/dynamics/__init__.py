"""The local dynamic model (spec chapter 11; paper §IV-D, §VI-D, eq. 9, Figs. 8–9).

A MIMO Hammerstein–Wiener model with exactly the structure of MATLAB's ``nlhw``:

    w_i(t) = f_i(u_i(t))                                        one static map per input  (§11.2)
    x_j(t) = Σ_i B_ji(q)/F_ji(q) · w_i(t − nk_ji)               ny × nu output-error block
    y_j(t) = h_j(x_j(t))                                        one static map per output

with piecewise-linear maps (linear extension beyond the end breakpoints) or unit-gain maps. The package holds,
stage by stage: the parameter file (:mod:`.parameter_file`, §11.5), deterministic prediction
(:mod:`.prediction`, §11.3), fitting by Levenberg–Marquardt on the simulation error (:mod:`.fitting`, §11.4)
with its analytic Jacobian (:mod:`.jacobian`, §11.4.3), the kinematic distance of paper eq. 9 and the segment
errors (:mod:`.distance`, §11.6), the model on a session's trials (:mod:`.trials`, §11.1, §11.7), the family's
``compute(ctx)`` (:mod:`.metrics`, §11.7); its report figure is :mod:`haptify.report.figures.dynamics`. Every parameter comes from
``schemas/<v>/metrics/dynamics.json``. This module re-exports the public names; the entry point of the family
``dynamics`` (pyproject.toml) names it.
"""

from __future__ import annotations

from haptify.dynamics.distance import (
    DistanceScales,
    WindowFeatures,
    line_fit,
    nearest_distances,
    pair_distance,
    segment_distances,
    segment_force_errors,
    window_features,
)
from haptify.dynamics.fitting import FitOptions, FitReport, fit, place_breakpoints
from haptify.dynamics.metrics import compute
from haptify.dynamics.parameter_file import (
    FAMILY,
    INPUT_NAMES,
    INPUT_UNITS,
    MODEL_FORMAT,
    OUTPUT_NAMES,
    OUTPUT_UNITS,
    Channel,
    FitSummary,
    HWModelFile,
    PiecewiseLinearMap,
    QuaternionHemisphere,
    StaticMap,
    TransferFunction,
    UnitGainMap,
    export_mat,
    load_model,
    model_to_mat_dict,
    save_model,
)
from haptify.dynamics.prediction import apply_map, hemisphere_align, predict, pwl_basis, pwl_eval, pwl_slope, rmse
from haptify.dynamics.trials import (
    REQUIRED_STREAMS,
    TEST_PROTOCOLS,
    TrialData,
    fit_trial,
    given_model_trial,
    held_out_trials,
    predict_trial,
    segment_table,
    training_trial,
    trial_data,
    trial_features,
    valid_runs,
)

__all__ = [
    "FAMILY",
    "INPUT_NAMES",
    "INPUT_UNITS",
    "MODEL_FORMAT",
    "OUTPUT_NAMES",
    "OUTPUT_UNITS",
    "REQUIRED_STREAMS",
    "TEST_PROTOCOLS",
    "Channel",
    "DistanceScales",
    "FitOptions",
    "FitReport",
    "FitSummary",
    "HWModelFile",
    "PiecewiseLinearMap",
    "QuaternionHemisphere",
    "StaticMap",
    "TransferFunction",
    "TrialData",
    "UnitGainMap",
    "WindowFeatures",
    "apply_map",
    "compute",
    "export_mat",
    "fit",
    "fit_trial",
    "given_model_trial",
    "held_out_trials",
    "hemisphere_align",
    "line_fit",
    "load_model",
    "model_to_mat_dict",
    "nearest_distances",
    "pair_distance",
    "place_breakpoints",
    "predict",
    "predict_trial",
    "pwl_basis",
    "pwl_eval",
    "pwl_slope",
    "rmse",
    "save_model",
    "segment_distances",
    "segment_force_errors",
    "segment_table",
    "training_trial",
    "trial_data",
    "trial_features",
    "valid_runs",
    "window_features",
]
