"""Per-repetition metric values → one metric record (spec §15.2–15.3).

The benchmark families (workspace, free space, vibration, surface, stiffness) compute a value per trial
of their protocol; this module turns those values into a :class:`MetricResult` — mean over repetitions,
sample standard deviation (ddof = 1) when there are at least two — or into an :class:`Unavailable` that
carries the code of the problem that stopped the metric. Unit and definition version come from the
family's definition file, so no family repeats them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.metrics.metric_definitions import MetricDefinition, family
from haptify.pipeline.results import MetricResult, Unavailable
from haptify.processing.caching import session_of

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext


@dataclass
class TrialValue:
    """One repetition's value of one metric, with the trial it came from and that trial's warning codes.
    Spec §15.3."""

    trial: str
    value: float
    warnings: list[str] = field(default_factory=list)


def definition_of(family_name: str, metric_id: str) -> MetricDefinition:
    """The metric's definition record in ``metrics/<family_name>.json`` (KeyError when absent).
    Spec §15.2."""
    for m in family(family_name).metrics:
        if m.id == metric_id:
            return m
    raise KeyError(f"{metric_id} is not defined in metrics/{family_name}.json")


def aggregate(
    family_name: str,
    metric_id: str,
    values: Sequence[TrialValue],
    *,
    diagnostics: dict[str, Any] | None = None,
    warnings: Sequence[str] = (),
) -> MetricResult:
    """Mean of the per-repetition values, sd with ddof = 1 when n ≥ 2 (spec §15.3).

    Per-trial values must be finite (spec §15.2): a family turns degenerate data into a coded error
    before it gets here, so a non-finite value is a programming error (ValueError).
    """
    definition_of(family_name, metric_id)
    if not values:
        raise ValueError("aggregate needs at least one repetition")
    vals = np.array([v.value for v in values], dtype=float)
    if not np.all(np.isfinite(vals)):
        bad = [v.trial for v in values if not math.isfinite(v.value)]
        raise ValueError(f"{metric_id}: non-finite per-trial values from {bad}")
    codes = sorted({c for v in values for c in v.warnings} | set(warnings))
    return MetricResult(
        id=metric_id,
        value=float(vals.mean()),
        unit=definition_of(family_name, metric_id).unit,
        per_repetition=[float(x) for x in vals],
        trials=[v.trial for v in values],
        n=len(vals),
        sd=float(vals.std(ddof=1)) if len(vals) >= 2 else None,
        diagnostics=dict(diagnostics or {}),
        definition_version=family(family_name).version,
        warnings=codes,
    )


def single(
    family_name: str,
    metric_id: str,
    value: float,
    *,
    n: int = 1,
    trials: Sequence[str] = (),
    diagnostics: dict[str, Any] | None = None,
    warnings: Sequence[str] = (),
) -> MetricResult:
    """A metric with one value that is not a mean over repetitions (e.g. the modeled workspace volume).
    Its definition's ``aggregation``, spec §15.3."""
    return MetricResult(
        id=metric_id,
        value=float(value),
        unit=definition_of(family_name, metric_id).unit,
        per_repetition=[],
        trials=list(trials),
        n=n,
        sd=None,
        diagnostics=dict(diagnostics or {}),
        definition_version=family(family_name).version,
        warnings=sorted(set(warnings)),
    )


def unavailable(metric_id: str, error: HaptifyError) -> Unavailable:
    """The record of a metric stopped by a coded error (its first finding's code and message; spec §15.2)."""
    finding = error.findings[0]
    return Unavailable(id=metric_id, code=finding.code, reason=finding.message)


def no_trials(protocol: str) -> HaptifyError:
    """The E310 error of a metric whose protocol has no trial in the session (spec §15.2)."""
    return fail(
        Code.PROTOCOL_TRIALS_MISSING,
        f"the session has no {protocol} trial",
        expected=f"a trial of protocol {protocol!r}",
        found=None,
    )


def per_trial(
    ctx: ComputeContext, trial_ids: Sequence[str], compute_one: Callable[[str], Any], what: str
) -> tuple[dict[str, Any], HaptifyError | None]:
    """Run ``compute_one`` on every trial; return the results of those that worked and the first coded error.

    A metric rests on the trials that worked, and each trial that failed is then reported on ``ctx`` as
    W413 naming its own error. When none worked, nothing is warned: the first error makes the metric
    unavailable (spec §15.2).
    """
    out: dict[str, Any] = {}
    failed: dict[str, HaptifyError] = {}
    for tid in trial_ids:
        try:
            out[tid] = compute_one(tid)
        except HaptifyError as exc:
            failed[tid] = exc
    if out:
        for tid, err in failed.items():
            ctx.warn(
                Code.TRIAL_SKIPPED,
                f"{what}: trial {tid!r} skipped ({err.findings[0].code}: {err.findings[0].message})",
                trial=tid,
            )
    return out, next(iter(failed.values()), None)


def protocol_trials(
    ctx: ComputeContext, protocol: str, metric_ids: Sequence[str], compute_one: Callable[[str], Any], what: str
) -> tuple[dict[str, Any], list[Unavailable]]:
    """:func:`per_trial` over every trial of ``protocol`` (spec §15.2).

    Returns the per-trial results and an empty list, or — when the session has no trial of the protocol
    (E310) or none of its trials worked (the first trial's error) — no results and one
    :class:`Unavailable` per id of ``metric_ids``.
    """
    trials = [t.id for t in session_of(ctx).trials_of(protocol)]
    if not trials:
        err = no_trials(protocol)
        return {}, [unavailable(m, err) for m in metric_ids]
    done, first = per_trial(ctx, trials, compute_one, what)
    if not done:
        assert first is not None  # per_trial: a trial that gave no result raised the error it returns
        return {}, [unavailable(m, first) for m in metric_ids]
    return done, []
