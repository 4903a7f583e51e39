"""Requirement coverage (spec §16.7): which cases test each requirement, and which distinguish it.

A case *tests* a requirement when it lists its id. It *distinguishes* a value requirement when a mutant of
that requirement — the reference with the requirement read the most plausible wrong way (``make mutants``,
spec §16.8.3) — moves the case's value by at least ``DISTINGUISHING_RATIO`` times the case's tolerance (or
makes it unavailable). The mutants' results are read from ``conformance/mutants/results.json``; they count
only while they were produced from the case files as they are now (``cases_digest``).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from haptify_conform.cases import Case, case_files, load_cases
from haptify_conform.requirements import Requirement, all_requirements

#: How far (in tolerances) a plausible wrong reading must move a case for the case to distinguish it (spec §16.8.3).
DISTINGUISHING_RATIO = 5.0
MUTANT_RESULTS = Path("mutants") / "results.json"


def cases_digest(cases_root: Path) -> str:
    """sha256 over the case files' names and content, each case without its ``requirements`` (which a mutant's
    verdict does not depend on): what mutant results are valid for."""
    h = hashlib.sha256()
    for path in case_files(cases_root):
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
            cases = [{k: v for k, v in c.items() if k != "requirements"} for c in doc.get("cases", [])]
            content = json.dumps({**doc, "cases": cases}, sort_keys=True).encode()
        except (UnicodeDecodeError, json.JSONDecodeError, AttributeError, TypeError):  # the lint reports the file
            content = path.read_bytes()
        h.update(path.name.encode() + b"\0" + content + b"\0")
    return h.hexdigest()


@dataclass
class Coverage:
    """One requirement's cases and its strongest distinguishing evidence (mutant, case, deviation/tolerance)."""

    requirement: Requirement
    cases: list[str] = field(default_factory=list)
    evidence: list[tuple[str, str, float]] = field(default_factory=list)

    @property
    def best(self) -> tuple[str, str, float] | None:
        return max(self.evidence, key=lambda e: e[2], default=None)

    @property
    def distinguished(self) -> bool:
        best = self.best
        return best is not None and best[2] >= DISTINGUISHING_RATIO


def load_mutant_results(cases_root: Path) -> tuple[dict[str, dict[str, Any]], str | None]:
    """The mutants of ``results.json`` (name → record) and a problem line when the file is missing or stale."""
    path = cases_root / MUTANT_RESULTS
    where = f"{cases_root.name}/{MUTANT_RESULTS.as_posix()}"
    if not path.is_file():
        return {}, f"{where} is missing: run make mutants"
    data = json.loads(path.read_text(encoding="utf-8"))
    if data.get("cases_digest") != cases_digest(cases_root):
        return data.get("mutants", {}), f"{where} was made from other case files: run make mutants"
    return data.get("mutants", {}), None


def coverage(cases: list[Case], mutants: dict[str, dict[str, Any]]) -> list[Coverage]:
    """Every requirement with the cases listing it and its mutants' failures on those cases. A failure
    without a comparable value (the metric missing or unavailable, the session rejected) counts as infinitely
    far: the mistake cannot pass unnoticed."""
    rows = {r.id: Coverage(r) for r in all_requirements()}
    for c in cases:
        for rid in c.requirements:
            if rid in rows:
                rows[rid].cases.append(c.id)
    for name, m in mutants.items():
        row = rows.get(m.get("requirement", ""))
        if row is None:
            continue
        listed = set(row.cases)
        for failure in m.get("failing_cases", []):
            if failure["case"] in listed:
                ratio = failure.get("ratio")
                row.evidence.append((name, failure["case"], math.inf if ratio in (None, "inf") else float(ratio)))
    return list(rows.values())


def suite_coverage(cases_root: Path) -> list[Coverage]:
    """The coverage of the suite under ``cases_root`` (raises ValueError on an invalid case file)."""
    return coverage(load_cases(cases_root), load_mutant_results(cases_root)[0])


def requirement_problems(cases: list[Case], cases_root: Path) -> list[str]:
    """Unknown requirement ids on cases; requirements no case tests; value MUSTs no case distinguishes."""
    known = {r.id for r in all_requirements()}
    problems = [f"case {c.id}: unknown requirement {rid!r}" for c in cases for rid in c.requirements if rid not in known]
    mutants, stale = load_mutant_results(cases_root)
    if stale:
        problems.append(stale)
    for row in coverage(cases, mutants):
        r = row.requirement
        if not row.cases:
            problems.append(f"requirement {r.id} (§{r.section}) is tested by no case")
        elif r.kind == "value" and r.level.startswith("MUST") and not row.distinguished:
            best = row.best
            found = (
                f"best: mutant {best[0]} moves case {best[1]} by {best[2]:.2g}× its tolerance"
                if best
                else "no mutant of it fails a case listing it"
            )
            problems.append(
                f"requirement {r.id} (§{r.section}) is not distinguished (needs ≥ {DISTINGUISHING_RATIO:g}× a case's "
                f"tolerance; {found})"
            )
    return problems


def coverage_table(rows: list[Coverage]) -> str:
    """Markdown: requirement → cases and distinguishing evidence (the spec's coverage appendix, ``--lint``)."""
    lines = [
        "| requirement | § | level | cases | distinguished by (mutant → case, deviation / tolerance) |",
        "|---|---|---|---|---|",
    ]
    for row in rows:
        r = row.requirement
        best = row.best
        if r.kind == "verdict":
            how = f"expects {r.code}"
        elif best is None:
            how = "—"
        else:
            ratio = "unavailable" if math.isinf(best[2]) else f"{best[2]:.3g}×"
            how = f"`{best[0]}` → `{best[1]}` ({ratio})"
        lines.append(f"| {r.id} | {r.section} | {r.level} | {len(row.cases)} | {how} |")
    return "\n".join(lines) + "\n"
