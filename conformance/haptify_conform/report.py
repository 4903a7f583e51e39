"""Conformance reports: a readable table, JSON (``conform-report.schema.json``) and JUnit XML (spec §16.6)."""

from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET
from collections import Counter
from dataclasses import asdict
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from haptify_schemas import SPEC_VERSION
from haptify_conform import PROTOCOL_VERSION, SUITE_VERSION
from haptify_conform.judge import Verdict


class ReportHeader(BaseModel):
    """Header of a JSON conformance report: suite, spec and protocol versions, adapter, implementation, start time (spec §16.6)."""

    model_config = ConfigDict(extra="forbid")
    suite_version: str
    spec_version: str
    protocol_version: int
    adapter: str
    implementation: dict[str, Any]
    started: str


class CaseRecord(BaseModel):
    """One case's outcome in the JSON report: status, level, spec section, message, maximum errors, duration in s (spec §16.6)."""

    model_config = ConfigDict(extra="forbid")
    case_id: str
    metric: str
    status: str
    level: str
    spec_section: str
    message: str
    actual: object = None
    max_abs_error: float | None = None
    max_rel_error: float | None = None
    duration_s: float


class Summary(BaseModel):
    """Case counts of a run and the verdict (spec §16, §16.6): the implementation conforms when no case
    failed or errored and no MUST case it had to answer was skipped — a negative (``validate``) case, or a
    case of a metric it reports (one with a passed case)."""

    model_config = ConfigDict(extra="forbid")
    total: int
    passed: int
    failed: int
    error: int
    skipped: int
    must_skipped: list[str] = Field(
        default_factory=list, description="MUST cases skipped that a conforming implementation answers."
    )
    conforms: bool


class ConformReport(BaseModel):
    """The JSON report of one run: header, one record per case, summary (spec §16.6; its schema is generated from this model)."""

    model_config = ConfigDict(extra="forbid")
    header: ReportHeader
    cases: list[CaseRecord]
    summary: Summary


def build_report(header: ReportHeader, verdicts: list[Verdict]) -> ConformReport:
    """The JSON report (spec §16.6): header, one record per case, counts; it conforms when none failed or errored."""
    counts = Counter(v.status for v in verdicts)
    records = [CaseRecord(**{k: v for k, v in asdict(verdict).items() if k != "extra"}) for verdict in verdicts]
    must_skipped = skipped_must_cases(verdicts)
    summary = Summary(
        total=len(verdicts),
        passed=counts["passed"],
        failed=counts["failed"],
        error=counts["error"],
        skipped=counts["skipped"],
        must_skipped=must_skipped,
        conforms=bool(verdicts) and counts["failed"] == 0 and counts["error"] == 0 and not must_skipped,
    )
    return ConformReport(header=header, cases=records, summary=summary)


def skipped_must_cases(verdicts: list[Verdict]) -> list[str]:
    """The skipped MUST cases that forbid conformance (spec §16): every negative case, and the cases of
    every metric the implementation reports (it passed a case of it). Skipping all cases of a metric
    leaves that metric out of the claim instead."""
    reported = {v.metric for v in verdicts if v.status == "passed"}
    return [
        v.case_id
        for v in verdicts
        if v.status == "skipped" and v.level == "MUST" and (v.metric == "validate" or v.metric in reported)
    ]


def _err(value: float | None) -> str:
    return "—" if value is None else f"{value:.3g}"


def to_table(report: ConformReport) -> str:
    """One line per case: status, id, metric, max abs/rel error; failures name the spec section."""
    lines = [f"{'status':8} {'case':44} {'metric':32} {'max abs err':>12} {'max rel err':>12}"]
    for c in report.cases:
        lines.append(f"{c.status.upper():8} {c.case_id:44} {c.metric:32} {_err(c.max_abs_error):>12} {_err(c.max_rel_error):>12}")
        if c.status in ("failed", "error") or (c.status == "skipped" and c.message):
            lines.append(f"         {c.message} (spec §{c.spec_section})")
    s = report.summary
    if s.must_skipped:
        lines.append(
            f"\n{len(s.must_skipped)} MUST case(s) skipped that a conforming implementation answers "
            f"(every negative case, every case of a metric it reports): {', '.join(s.must_skipped[:8])}"
            + (" …" if len(s.must_skipped) > 8 else "")
        )
    lines.append(
        f"\n{s.passed} passed, {s.failed} failed, {s.error} errors, {s.skipped} skipped of {s.total} cases — "
        + ("CONFORMS" if s.conforms else "DOES NOT CONFORM")
        + f" to Haptify {report.header.spec_version}"
    )
    return "\n".join(lines) + "\n"


def to_junit(report: ConformReport) -> str:
    """The report as JUnit XML, one ``testcase`` per case (``--junit``; spec §16.6)."""
    s = report.summary
    suite = ET.Element(
        "testsuite",
        name=f"haptify-conform {report.header.suite_version}",
        tests=str(s.total),
        failures=str(s.failed),
        errors=str(s.error),
        skipped=str(s.skipped),
        time=f"{sum(c.duration_s for c in report.cases):.3f}",
    )
    for c in report.cases:
        case = ET.SubElement(suite, "testcase", classname=c.metric, name=c.case_id, time=f"{c.duration_s:.3f}")
        if c.status == "failed":
            ET.SubElement(case, "failure", message=c.message).text = f"spec §{c.spec_section}"
        elif c.status == "error":
            ET.SubElement(case, "error", message=c.message).text = f"spec §{c.spec_section}"
        elif c.status == "skipped":
            ET.SubElement(case, "skipped", message=c.message)
    return ET.tostring(suite, encoding="unicode", xml_declaration=True) + "\n"


def header(adapter: str, implementation: dict[str, Any], started: str) -> ReportHeader:
    """The report header: suite, spec and protocol versions, adapter, implementation, start time (spec §16.6)."""
    return ReportHeader(
        suite_version=SUITE_VERSION,
        spec_version=SPEC_VERSION,
        protocol_version=PROTOCOL_VERSION,
        adapter=adapter,
        implementation=implementation,
        started=started,
    )


def write_report(path: Path, text: str) -> None:
    """Write a report file whole or not at all (spec §16.6): a temporary file beside it, synced, renamed over it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile("w", encoding="utf-8", dir=path.parent, prefix=f".{path.name}.", delete=False) as fh:
        try:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        except BaseException:
            os.unlink(fh.name)
            raise
    os.replace(fh.name, path)
