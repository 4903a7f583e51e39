"""The suite linter (spec §16.7): cases validate, ids are unique, every metric has cases, fixtures exist,
every requirement is tested and every value MUST is distinguished (:mod:`haptify_conform.coverage`)."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from pydantic import ValidationError

import haptify_schemas
from haptify_conform.cases import REPO_ROOT, SUITE_ROOT, Case, CaseFile, case_files
from haptify_conform.coverage import requirement_problems
from haptify_conform.fixture_digest import DIGESTS, snapshot_digest

MIN_CASES_PER_METRIC = 3


def defined_metric_ids() -> set[str]:
    """Every metric id the standard's metric definitions name (``schemas/<version>/metrics/``; spec §0.3)."""
    return {m["id"] for name in haptify_schemas.list_dir("metrics") for m in haptify_schemas.load(f"metrics/{name}")["metrics"]}


def lint(root: Path = SUITE_ROOT, repo: Path = REPO_ROOT) -> list[str]:
    """Every problem of the suite as a readable line; empty when the suite is sound.
    The checks of spec §16.7."""
    problems: list[str] = []
    cases = []
    for path in case_files(root):
        try:
            cases += CaseFile.model_validate(json.loads(path.read_text(encoding="utf-8"))).cases
        except (UnicodeDecodeError, json.JSONDecodeError, ValidationError) as exc:  # not UTF-8, not JSON, not a case file
            problems.append(f"{path.name}: invalid case file: {exc}")
    ids = Counter(c.id for c in cases)
    problems += [f"case id {i!r} is used {n} times" for i, n in ids.items() if n > 1]
    metric_ids = defined_metric_ids()
    per_metric = Counter(c.metric for c in cases)
    for m in sorted(metric_ids):
        if per_metric[m] < MIN_CASES_PER_METRIC:
            problems.append(f"metric {m} has {per_metric[m]} case(s); at least {MIN_CASES_PER_METRIC} are required")
    for c in cases:
        if c.metric != "validate" and c.metric not in metric_ids:
            problems.append(f"case {c.id}: unknown metric {c.metric!r}")
        if c.metric != "validate" and (c.tolerance is None or c.expected.value is None or c.expected.unit is None):
            problems.append(f"case {c.id}: a metric case needs expected value, unit and tolerance")
        elif c.metric != "validate":
            problems += _budget_problems(c)
        if c.metric == "validate" and c.expected.codes is None and c.expected.valid is not True:
            problems.append(f"case {c.id}: a validate case needs expected codes or valid: true")
        if not (repo / "fixtures" / c.fixture / "session.json").exists() and not (repo / "fixtures" / c.fixture).is_dir():
            problems.append(f"case {c.id}: fixture {c.fixture} does not exist")
    problems += requirement_problems(cases, root)
    problems += _stale_fixtures(repo / "fixtures" / "conformance", {c.fixture for c in cases})
    invalid_dir = repo / "fixtures" / "invalid"
    if invalid_dir.is_dir():
        covered = {c.fixture for c in cases if c.metric == "validate"}
        for sidecar in sorted(invalid_dir.glob("*.expected.json")):
            name = f"invalid/{sidecar.name.removesuffix('.expected.json')}"
            if name not in covered:
                problems.append(f"invalid fixture {name} has no negative case")
    return problems


#: Rounding slack between a tolerance and the sum of its budget.
BUDGET_SLACK = 1.0 + 1e-9


def _budget_problems(c: Case) -> list[str]:
    """A metric case states the budget of its tolerance, and its tolerance is not looser than the budget (spec §16.7)."""
    tol = c.tolerance
    assert tol is not None  # lint() asks this of metric cases only, after checking they state a tolerance
    if not c.provenance.budget:
        return [f"case {c.id}: no tolerance budget in its provenance (where does ±{tol.abs} + {tol.rel}·|x| come from?)"]
    need_abs = sum(t.abs for t in c.provenance.budget)
    need_rel = sum(t.rel for t in c.provenance.budget)
    if tol.abs > need_abs * BUDGET_SLACK or tol.rel > need_rel * BUDGET_SLACK:
        return [
            f"case {c.id}: tolerance (abs {tol.abs:g}, rel {tol.rel:g}) is looser than its budget "
            f"(abs {need_abs:g}, rel {need_rel:g})"
        ]
    return []


def _stale_fixtures(root: Path, used: set[str]) -> list[str]:
    """Every metric fixture must match the logical digest its builder recorded (``digests.json``): a
    fixture edited by hand, or rebuilt without its record, is reported (spec §16.7)."""
    if not root.is_dir():
        return []
    path = root / DIGESTS
    if not path.is_file():
        return [f"fixtures/{root.name}/{DIGESTS} is missing: run python -m haptify_tools.build_conformance_fixtures"]
    recorded = json.loads(path.read_text(encoding="utf-8")).get("digests", {})
    out = []
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        name = f"{root.name}/{folder.name}"
        if folder.name not in recorded:
            out.append(f"fixture {name} has no recorded digest (not built by the fixture builder)")
        elif snapshot_digest(folder) != recorded[folder.name]:
            out.append(f"fixture {name} differs from what its builder recorded (edited by hand?); rebuild it")
        elif name not in used:
            out.append(f"fixture {name} is used by no case")
    return out
