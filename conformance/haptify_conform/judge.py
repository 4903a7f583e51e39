"""Judging an implementation's answer against a case (spec §16.3)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, TypedDict

from haptify_conform.cases import Case


@dataclass
class Verdict:
    """The outcome of one case: ``passed``/``failed``/``skipped``/``error`` with the evidence.
    Spec §16.3, §16.6."""

    case_id: str
    metric: str
    status: str
    message: str = ""
    actual: Any = None
    max_abs_error: float | None = None
    max_rel_error: float | None = None
    duration_s: float = 0.0
    spec_section: str = ""
    level: str = "MUST"
    extra: dict[str, Any] = field(default_factory=dict)


class CaseFields(TypedDict):
    """What every verdict of a case repeats from the case (spec §16.6)."""

    case_id: str
    metric: str
    spec_section: str
    level: str


def case_fields(case: Case) -> CaseFields:
    """The fields a verdict of ``case`` copies from it, to be spread into :class:`Verdict`."""
    return CaseFields(case_id=case.id, metric=case.metric, spec_section=case.spec_section, level=case.level)


def _components(value: Any) -> list[float] | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return [float(value)]
    if isinstance(value, list) and value and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        return [float(v) for v in value]
    return None


def judge_metric(case: Case, results: dict[str, Any]) -> Verdict:
    """Compare the metric record in ``results`` (a results.json object) with the case's expectation.
    Spec §16.3."""
    base = case_fields(case)
    if case.expected.codes:
        return Verdict(
            status="failed",
            message=f"expected the session to be rejected with {case.expected.codes}, but the implementation returned results",
            **base,
        )
    records = [m for m in results.get("metrics", []) if isinstance(m, dict) and m.get("id") == case.metric]
    if not records:
        why = next((u for u in results.get("unavailable", []) if isinstance(u, dict) and u.get("id") == case.metric), None)
        msg = f"metric {case.metric} missing from the results"
        if why:
            msg += f" (reported unavailable: {why.get('code')} {why.get('reason')})"
        return Verdict(status="failed", message=msg, **base)
    record = records[0]
    if case.quantity != "value":
        return _judge_number(case, _uncertainty_of(record, case.quantity), base, unit=None)
    return _judge_number(case, record.get("value"), base, unit=record.get("unit"))


def _uncertainty_of(record: dict[str, Any], quantity: str) -> Any:
    """``u``, ``U`` or ``k`` of a metric record's uncertainty (spec §19.4); None when it has none."""
    unc = record.get("uncertainty")
    return unc.get(quantity) if isinstance(unc, dict) else None


def _judge_number(case: Case, found: Any, base: CaseFields, unit: str | None) -> Verdict:
    """``found`` against the case's expected value and tolerance; ``unit`` (the record's) must match the
    case's unless None (an uncertainty's unit is its metric's, a coverage factor's is 1). Spec §16.3."""
    what = "value" if case.quantity == "value" else f"uncertainty {case.quantity}"
    if case.quantity != "value" and found is None:
        return Verdict(
            status="failed", message=f"the record of {case.metric} has no uncertainty {case.quantity} (spec §19.4)", **base
        )
    if unit is not None and unit != case.expected.unit:
        return Verdict(
            status="failed", message=f"unit mismatch: expected {case.expected.unit!r}, found {unit!r}", actual=found, **base
        )
    actual = _components(found)
    expected = _components(case.expected.value)
    if actual is None or expected is None or len(actual) != len(expected):
        return Verdict(
            status="failed",
            message=f"{what} has the wrong shape: expected {case.expected.value!r}, found {found!r}",
            actual=found,
            **base,
        )
    if any(math.isnan(a) or math.isinf(a) for a in actual):
        return Verdict(status="failed", message=f"{what} is NaN or infinite", actual=found, **base)
    tol = case.tolerance
    if tol is None:  # the suite's lint rejects such a case (spec §16.2); a run of an unlinted suite says so
        return Verdict(
            status="error", message=f"case {case.id} states no tolerance: a metric case needs one (spec §16.2)", **base
        )
    abs_err = [abs(a - e) for a, e in zip(actual, expected)]
    rel_err = [d / abs(e) if e else (0.0 if d == 0 else math.inf) for d, e in zip(abs_err, expected)]
    ok = all(d <= tol.abs + tol.rel * abs(e) for d, e in zip(abs_err, expected))
    verdict = Verdict(
        status="passed" if ok else "failed", actual=found, max_abs_error=max(abs_err), max_rel_error=max(rel_err), **base
    )
    if not ok:
        verdict.message = (
            f"expected {what} {case.expected.value} ± ({tol.abs} + {tol.rel}·|expected|) {case.expected.unit}, found {found}"
        )
    return verdict


def judge_rejection(case: Case, findings: list[Any]) -> Verdict:
    """The implementation rejected the session with ``findings``: right when the case expects it.
    Spec §16.3."""
    base = case_fields(case)
    codes = sorted({str(f.get("code")) for f in findings if isinstance(f, dict)})
    if not case.expected.codes or case.expected.valid:
        return Verdict(
            status="failed",
            message=f"the session was rejected ({', '.join(codes) or 'no codes'}) but the case expects it to be accepted",
            actual=codes,
            **base,
        )
    missing = sorted(set(case.expected.codes) - set(codes))
    if missing:
        return Verdict(
            status="failed",
            message=f"expected codes {case.expected.codes}, found {codes} (missing {missing})",
            actual=codes,
            **base,
        )
    return Verdict(status="passed", actual=codes, **base)


def judge_acceptance(case: Case, report: dict[str, Any]) -> Verdict:
    """A 'validate' case on a valid session: the implementation must accept it (no error findings).
    Spec §16.3.

    With ``valid: true`` and ``codes`` (a session that is valid but deserves warnings) the accepted
    document's findings (or results warnings) must hold at least those codes.
    """
    base = case_fields(case)
    if case.expected.codes and not case.expected.valid:
        return Verdict(
            status="failed", message=f"expected rejection with {case.expected.codes}, but the session was accepted", **base
        )
    if case.expected.codes:
        notes = [*(report.get("findings") or []), *(report.get("warnings") or [])]
        codes = sorted({str(f.get("code")) for f in notes if isinstance(f, dict)})
        missing = sorted(set(case.expected.codes) - set(codes))
        if missing:
            return Verdict(
                status="failed",
                message=f"accepted, but expected warnings {case.expected.codes}, found {codes} (missing {missing})",
                actual=codes,
                **base,
            )
        return Verdict(status="passed", actual=codes, **base)
    return Verdict(status="passed", **base)
