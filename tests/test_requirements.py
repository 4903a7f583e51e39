"""Requirement ids, coverage and tolerance budgets of the conformance suite (spec §0.1, §16.2, §16.7)."""

from __future__ import annotations

import json
import math
import re
import shutil
from fnmatch import fnmatchcase
from pathlib import Path

import pytest

from haptify.metrics.metric_definitions import all_families
from haptify_conform.cases import REPO_ROOT, Case, load_cases
from haptify_conform.coverage import DISTINGUISHING_RATIO, MUTANT_RESULTS, cases_digest, coverage, requirement_problems
from haptify_conform.lint import _budget_problems
from haptify_conform.requirements import all_requirements, by_id, requirements_for_case, verdict_exemptions
from haptify_tools.tolerance_budgets import BUDGETS, budget_for

METRICS = {m.id for f in all_families() for m in f.metrics}
QUANTITIES = {f"{m}:{q}" for m in METRICS for q in ("u", "U", "k")}  # a chapter-19 case's metric and quantity


def test_requirement_ids_are_unique_well_formed_and_decide_known_metrics():
    reqs = all_requirements()
    assert len({r.id for r in reqs}) == len(reqs)
    for r in reqs:
        assert re.fullmatch(r"R\d+(\.\d+)*-(\d+|[EW]\d{3})", r.id), r.id
        assert r.id.startswith(f"R{r.section}-"), r.id
        if r.kind == "value":
            assert r.level == "MUST" and len(r.statement) > 30
            for pattern in r.metrics:  # every pattern names at least one metric (or uncertainty quantity, §19.7)
                assert any(fnmatchcase(m, pattern) for m in METRICS | QUANTITIES), (r.id, pattern)


def test_verdict_requirements_are_the_validation_codes_but_the_exempt():
    ids = by_id()
    assert "R3.1-E117" in ids and ids["R3.1-E117"].code == "E117"
    assert not any(r.code in verdict_exemptions() for r in all_requirements())
    assert requirements_for_case("validate", ["E117", "W999"]) == ["R3.1-E117"]


def test_a_metric_case_lists_the_value_requirements_that_decide_its_metric():
    ids = requirements_for_case("vibration.rms")
    assert "R10.3-1" in ids and "R15.3-1" in ids and "R13.3-1" not in ids
    assert all(by_id()[i].decides("vibration.rms") for i in ids)


def test_a_case_on_an_uncertainty_adds_the_chapter_19_requirements():
    assert requirements_for_case("free_space.force_mean", quantity="u")[-1:] == ["R19.2-1"]
    assert requirements_for_case("free_space.force_mean", quantity="k")[-2:] == ["R19.2-1", "R19.4-1"]
    assert set(requirements_for_case("free_space.force_mean")) == set(
        requirements_for_case("free_space.force_mean", quantity="u")
    ) - {"R19.2-1"}


def _case(**over) -> Case:
    base = {
        "id": "x.case",
        "metric": "vibration.rms",
        "spec_section": "10.4",
        "level": "MUST",
        "requirements": ["R10.3-1"],
        "fixture": "conformance/vib-tones",
        "expected": {"value": 1.0, "unit": "m/s^2"},
        "tolerance": {"abs": 0.0, "rel": 1e-3},
        "provenance": {"kind": "analytic", "note": "n", "budget": [{"source": "a", "rel": 6e-4}, {"source": "b", "rel": 4e-4}]},
        "spec_versions": ["1.0"],
        "description": "d",
    }
    base.update(over)
    return Case.model_validate(base)


@pytest.mark.parametrize(
    "tol, flagged",
    [
        ({"abs": 0.0, "rel": 1e-3}, False),
        ({"abs": 0.0, "rel": 9e-4}, False),
        ({"abs": 0.0, "rel": 1.1e-3}, True),
        ({"abs": 1e-6, "rel": 1e-3}, True),
    ],
)
def test_a_tolerance_looser_than_its_budget_is_flagged(tol, flagged):
    assert bool(_budget_problems(_case(tolerance=tol))) is flagged


def test_a_metric_case_without_budget_is_flagged():
    assert "no tolerance budget" in _budget_problems(_case(provenance={"kind": "analytic", "note": "n"}))[0]


def test_every_committed_metric_case_has_the_budget_its_builder_table_gives():
    for c in load_cases():
        if c.metric == "validate":
            continue
        terms = budget_for(c.id)
        assert [t.source for t in c.provenance.budget] == [t.source for t in terms], c.id
        assert c.tolerance.abs == pytest.approx(math.fsum(t.abs for t in terms), abs=0)
        assert c.tolerance.rel == pytest.approx(math.fsum(t.rel for t in terms), abs=0)
    assert all(terms for _, terms in BUDGETS)


@pytest.mark.parametrize(
    "ratio, distinguished", [(DISTINGUISHING_RATIO, True), (0.99 * DISTINGUISHING_RATIO, False), (None, True), ("inf", True)]
)
def test_a_requirement_is_distinguished_by_a_mutant_moving_a_case_that_lists_it(ratio, distinguished):
    case = _case()
    mutants = {"m": {"requirement": "R10.3-1", "failing_cases": [{"case": case.id, "ratio": ratio}]}}
    row = next(r for r in coverage([case], mutants) if r.requirement.id == "R10.3-1")
    assert row.cases == [case.id] and row.distinguished is distinguished


def test_a_mutant_failing_a_case_that_does_not_list_its_requirement_is_no_evidence():
    case = _case(requirements=["R15.3-1"])
    mutants = {"m": {"requirement": "R10.3-1", "failing_cases": [{"case": case.id, "ratio": 1e6}]}}
    row = next(r for r in coverage([case], mutants) if r.requirement.id == "R10.3-1")
    assert not row.distinguished


def test_mutant_results_count_only_for_the_case_files_they_were_made_from(tmp_path: Path):
    root = tmp_path / "conformance"
    shutil.copytree(REPO_ROOT / "conformance" / "cases", root / "cases")
    (root / MUTANT_RESULTS).parent.mkdir(parents=True)
    (root / MUTANT_RESULTS).write_text(json.dumps({"cases_digest": cases_digest(root), "mutants": {}}))
    cases = load_cases(root)
    assert not any("made from other case files" in p for p in requirement_problems(cases, root))
    # re-tagging requirements does not invalidate the evidence; changing an expected value does
    path = root / "cases" / "vibration.json"
    doc = json.loads(path.read_text())
    doc["cases"][0]["requirements"] = []
    path.write_text(json.dumps(doc))
    assert not any("made from other case files" in p for p in requirement_problems(load_cases(root), root))
    doc["cases"][0]["expected"]["value"] = 123.0
    path.write_text(json.dumps(doc))
    assert any("made from other case files" in p for p in requirement_problems(load_cases(root), root))
