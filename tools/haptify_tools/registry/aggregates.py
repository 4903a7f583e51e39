"""Aggregates of a metric over labs and repetitions (spec §17.5): mean and spread, the sd a results file
carries (spec §15.2), the uncertainty and interlab precision of a scalar metric (spec §17.5.3), and the
entries of a submission that does not count."""

from __future__ import annotations

import json
import statistics
from typing import Any

from haptify_tools.registry import db, interlab


def not_counted(summary: dict, sub: db.Submission) -> list[dict]:
    """The metrics of a submission that does not count (not verified), one entry each: submission, lab,
    state, metric, submitted value and unit, and — from its verification record — the recomputed value,
    the tolerance and why it does not agree (spec §17.3.1)."""
    checks = {c["metric"]: c for c in json.loads(sub.verification_json).get("checks", [])}
    out = []
    for m in sub.metrics:
        check = checks.get(m.metric_id, {})
        out.append(
            {
                "submission": sub.id,
                "lab": sub.lab_id,
                "verification": sub.verification,
                "metric": m.metric_id,
                "submitted": json.loads(m.value_json),
                "unit": m.unit,
                "recomputed": check.get("recomputed"),
                "check": check.get("status"),
                "tolerance": check.get("tolerance"),
                "why": check.get("message") or json.loads(sub.verification_json).get("note", ""),
                "implementation": summary["implementation"],
            }
        )
    return out


def defined_sd(sd: float | list[float | None] | None) -> float | list[float] | None:
    """An aggregate's sd as a results file carries it (spec §15.2): a vector metric's sd is given for
    every component or not at all (with one repetition no component has one)."""
    if not isinstance(sd, list):
        return sd
    components = [v for v in sd if v is not None]
    return components if len(components) == len(sd) else None


def _components(value: Any) -> list[float]:
    return [float(v) for v in value] if isinstance(value, list) else [float(value)]


def aggregate(metric: str, items: list[tuple[dict, db.MetricValue]]) -> dict:
    """Mean and spread of one metric over labs and repetitions (spec §17.5).

    Repetitions: every per-repetition value of every current submission (the submitted value when a
    submission lists none); ``mean``, ``sd`` (ddof = 1), ``min``, ``max`` over them. Labs: each lab's
    mean of its repetitions; ``between_lab_sd`` is the sd of those means (ddof = 1, with ≥ 2 labs).
    Vector metrics are aggregated per component. A scalar metric also has ``uncertainty``, the pooled
    uncertainty of the mean from the submissions' records (None when one lacks it), and ``interlab``, the
    ISO 5725-2 table of its labs (None with fewer than two labs of ≥ 2 repetitions; spec §17.5.3).
    """
    reps: list[list[float]] = []
    per_lab: dict[str, list[list[float]]] = {}
    for summary, m in items:
        values = json.loads(m.per_repetition_json) or [json.loads(m.value_json)]
        for v in values:
            comp = _components(v)
            reps.append(comp)
            per_lab.setdefault(summary["lab"], []).append(comp)
    width = len(reps[0])
    reps = [r for r in reps if len(r) == width]

    def stat(fn, rows: list[list[float]]) -> list[float | None]:
        return [fn([r[i] for r in rows]) if rows else None for i in range(width)]

    def sd(xs: list[float]) -> float | None:
        return statistics.stdev(xs) if len(xs) >= 2 else None

    lab_means = [[statistics.fmean([r[i] for r in rows]) for i in range(width)] for rows in per_lab.values()]
    unwrap = (lambda v: v[0]) if width == 1 else (lambda v: v)
    first = items[0][1]
    return {
        "metric": metric,
        "unit": first.unit,
        "definition_version": first.definition_version,
        "mean": unwrap(stat(statistics.fmean, reps)),
        "sd": unwrap(stat(sd, reps)),
        "min": unwrap(stat(min, reps)),
        "max": unwrap(stat(max, reps)),
        "repetitions": len(reps),
        "submissions": len(items),
        "labs": len(per_lab),
        "lab_means": {lab: unwrap(mean) for lab, mean in zip(per_lab, lab_means)},
        "between_lab_sd": unwrap(stat(sd, lab_means)),
        **scalar_precision(metric, items, per_lab, width),
    }


def scalar_precision(
    metric: str, items: list[tuple[dict, db.MetricValue]], per_lab: dict[str, list[list[float]]], width: int
) -> dict:
    """``uncertainty`` and ``interlab`` of a scalar metric's aggregate (spec §17.5.3); both None for a vector."""
    if width != 1:
        return {"uncertainty": None, "interlab": None}
    records = [(m.n, summary.get("uncertainties", {}).get(metric)) for summary, m in items]
    return {
        "uncertainty": interlab.pooled_uncertainty(records),
        "interlab": interlab.table({lab: [r[0] for r in rows] for lab, rows in per_lab.items()}),
    }
