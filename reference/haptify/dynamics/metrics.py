"""The dynamics family's metrics for a session (spec §11.7): the training fit's RMS errors and the slope and
intercept of the force error against the kinematic distance to the training set.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from haptify.codes import Code
from haptify.dynamics.distance import line_fit
from haptify.dynamics.parameter_file import FAMILY
from haptify.dynamics.prediction import rmse
from haptify.dynamics.trials import (
    REQUIRED_STREAMS,
    fit_trial,
    given_model_trial,
    held_out_trials,
    predict_trial,
    segment_table,
    training_trial,
    trial_data,
)
from haptify.errors import HaptifyError, fail
from haptify.metrics.metric_definitions import family

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.pipeline.results import MetricResult, Unavailable


def _unavailable_all(code: str, reason: str, ids: list[str]) -> list[MetricResult | Unavailable]:
    from haptify.pipeline.results import Unavailable

    return [Unavailable(id=i, code=code, reason=reason) for i in ids]


def compute(ctx: ComputeContext) -> list[MetricResult | Unavailable]:
    """The dynamics family's metrics for a session (spec §11.7): training-fit RMS errors and error vs distance."""
    from haptify.pipeline.results import MetricResult

    fam = family(FAMILY)
    ids = [m.id for m in fam.metrics]
    session = ctx.session
    try:
        train = training_trial(session)
        missing = [k for k in REQUIRED_STREAMS if session.stream(train.id, k) is None]
        if missing:
            raise fail(
                Code.REQUIRED_STREAM_MISSING,
                f"training trial {train.id!r} lacks {missing}",
                expected=list(REQUIRED_STREAMS),
                found=missing,
            )
        given = (getattr(ctx, "parameters", None) or {}).get("model")
        if given:
            model, data = ctx.cached(("dynamics_given_model", train.id, given), lambda: given_model_trial(ctx, train.id, given))
        else:
            model, data = ctx.cached(("dynamics_model", train.id), lambda: fit_trial(ctx, train.id))
    except HaptifyError as err:
        return _unavailable_all(err.code, err.findings[0].message, ids)

    unit = {m.id: m.unit for m in fam.metrics}
    out: list[MetricResult | Unavailable] = []
    predicted = predict_trial(model, data)
    ok = data.valid & np.all(np.isfinite(predicted), axis=1)  # runs of one row have no prediction
    n = int(ok.sum())
    if n == 0:  # e.g. a given parameter file whose rate leaves single-row runs: no RMS, not NaN (spec §15.2)
        return _unavailable_all(
            Code.DYNAMICS_DATA_INSUFFICIENT,
            f"training trial {train.id!r} has no valid run of at least 2 samples at {model.sample_rate_hz:g} Hz to predict",
            ids,
        )
    err_rmse = rmse(data.y[ok], predicted[ok])
    summary = (
        {
            "iterations": model.fit.iterations,
            "stop_reason": model.fit.stop_reason,
            "fit_percent": model.fit.fit_percent,
            "samples": n,
        }
        if model.fit
        else {"model": given, "samples": n}
    )
    for name, cols in (("force", slice(0, 3)), ("torque", slice(3, 6))):
        vec = [float(v) for v in err_rmse[cols]]
        mid = f"dynamics.{name}_rmse"
        out.append(
            MetricResult(
                id=mid,
                value=vec,
                unit=unit[mid],
                per_repetition=[vec],
                trials=[train.id],
                n=n,
                diagnostics=summary,
                definition_version=fam.version,
            )
        )
        out.append(
            MetricResult(
                id=mid + "_mean",
                value=float(np.mean(vec)),
                unit=unit[mid + "_mean"],
                per_repetition=[float(np.mean(vec))],
                trials=[train.id],
                n=n,
                definition_version=fam.version,
            )
        )

    eid = "dynamics.error_vs_distance"
    if not ctx.wants(eid):
        return out
    tests = held_out_trials(session, train.id)
    if not tests:
        return out + _unavailable_all(
            Code.DYNAMICS_DATA_INSUFFICIENT,
            "no test trial (another local_dynamic repetition, free_space or an unpowered "
            "'other' trial) with handle pose, wrench and acceleration",
            [eid],
        )
    try:
        labels = {train.id: "training"}
        datasets = []
        for t in tests:
            labels[t.id] = f"{t.protocol}:{t.label}" if t.label else t.protocol
            datasets.append(trial_data(ctx, t.id, model.sample_rate_hz))
        rows = segment_table(model, data, datasets, labels)
        slope, intercept = line_fit(np.array([r["distance"] for r in rows]), np.array([r["force_error"] for r in rows]))
    except HaptifyError as err:
        return out + _unavailable_all(err.code, err.findings[0].message, [eid])
    used = [train.id] + [t.id for t in tests if any(r["trial"] == t.id for r in rows)]
    out.append(
        MetricResult(
            id=eid,
            value=[slope, intercept],
            unit=unit[eid],
            trials=used,
            n=len(rows),
            diagnostics={"order": ["slope", "intercept"], "segments": rows},
            definition_version=fam.version,
        )
    )
    return out
