"""The conformance suite's content (spec chapter 16, §16.8.3): the reference passes every case, every
cheap mutant of ``haptify_mutants.catalogue`` fails a case of a metric it breaks, the mutant set is well formed
and its recorded result current, the suite lints clean, the committed fixtures and case files are what the
builder makes, and a JavaScript implementation passes its cases."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from haptify_conform.adapters import JsonlAdapter, PythonAdapter
from haptify_conform.cases import REPO_ROOT, load_cases, select
from haptify_conform.lint import lint
from haptify_conform.report import build_report, header
from haptify_conform.runner import load_skips, run_cases
from haptify_mutants import catalogue
from haptify_mutants.run import RESULTS
from haptify_tools import build_conformance_fixtures as builder

JS_DIR = REPO_ROOT / "conformance" / "examples" / "js"


def test_the_reference_passes_every_case_over_json_lines(tmp_path):
    """One run of the whole suite through the JSON-lines protocol (also the speed check's workload)."""
    report = tmp_path / "report.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "haptify_conform.cli",
            "--jsonl",
            f"{sys.executable} -m haptify.conform_adapter",
            "--json-report",
            str(report),
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    data = json.loads(report.read_text())
    bad = [(c["case_id"], c["status"], c["message"]) for c in data["cases"] if c["status"] != "passed"]
    assert not bad, bad
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert data["summary"]["total"] == len(load_cases()) and data["summary"]["conforms"]


@pytest.mark.parametrize("name", [m.name for m in catalogue.cheap_mutants()])
def test_each_cheap_mutant_fails_a_case_of_a_metric_it_breaks(name):
    mutant = catalogue.BY_NAME[name]
    cases = select(load_cases(), metrics=set(mutant.metrics))
    assert len(cases) >= 3
    verdicts = run_cases(cases, PythonAdapter(f"haptify_mutants.catalogue:{name}"))
    failed = [v for v in verdicts if v.status == "failed"]
    assert failed, f"{name}: no case of {mutant.metrics} caught it: {[(v.case_id, v.status) for v in verdicts]}"
    assert all(v.spec_section for v in failed)


def test_the_mutant_set_is_well_formed_and_its_recorded_result_current():
    """At least 40 mutants with unique names, spec sections that exist, known metrics and patch targets that
    exist, each naming a value requirement; conformance/mutants/results.json (written by `make
    mutants`) covers exactly this set and records every mutant caught."""
    import re

    from haptify.metrics.metric_definitions import all_families
    from haptify_conform.requirements import by_id

    requirement_ids = set(by_id())
    mutants = catalogue.MUTANTS
    assert len(mutants) >= 40 and len({m.name for m in mutants}) == len(mutants)
    headings = set(
        re.findall(r"^#+ (\d+(?:\.\d+)*)\.? ", "\n".join(p.read_text() for p in (REPO_ROOT / "spec").glob("*.md")), flags=re.M)
    )
    known = {m.id for f in all_families() for m in f.metrics}
    for m in mutants:
        assert m.section in headings, (m.name, m.section)
        assert m.metrics and set(m.metrics) <= known, (m.name, m.metrics)
        assert m.requirement in requirement_ids and by_id()[m.requirement].kind == "value", (m.name, m.requirement)
        assert len(m.rule) > 10 and len(m.wrong) > 10 and m.patches, m.name
        assert all((p.name in p.owner) if isinstance(p.owner, dict) else hasattr(p.owner, p.name) for p in m.patches), m.name
    recorded = json.loads(RESULTS.read_text(encoding="utf-8"))
    assert set(recorded["mutants"]) == {m.name for m in mutants}, "run `make mutants` after changing the catalogue"
    for m in mutants:  # a caught mutant fails a case of a metric it names
        failing = {f["metric"] for f in recorded["mutants"][m.name]["failing_cases"]}
        assert not failing or failing & set(m.metrics), (m.name, m.metrics, sorted(failing))
    assert recorded["total"] == len(mutants) and recorded["caught"] == len(mutants) - len(recorded["escaped"])
    assert recorded["escaped"] == []


def test_the_suite_lints_clean_and_covers_every_metric_three_times():
    assert lint() == []


def test_every_invalid_and_valid_fixture_is_a_validate_case():
    by_fixture = {c.fixture: c for c in load_cases() if c.metric == "validate"}
    for group in ("invalid", "valid"):
        for sidecar in (REPO_ROOT / "fixtures" / group).glob("*.expected.json"):
            meta = json.loads(sidecar.read_text())
            c = by_fixture[f"{group}/{sidecar.name.removesuffix('.expected.json')}"]
            assert sorted(c.expected.codes or []) == sorted(meta["codes"])
            assert bool(c.expected.valid) == (meta["exit_code"] == 0)


def test_metric_cases_state_both_tolerance_parts_and_how_the_value_is_known():
    for c in load_cases():
        if c.metric == "validate":
            continue
        assert c.tolerance is not None and (c.tolerance.abs > 0 or c.tolerance.rel > 0), c.id
        assert c.provenance.kind in ("analytic", "generated", "paper", "spec") and len(c.provenance.note) > 30, c.id


def test_committed_fixtures_and_cases_are_current(capsys):
    assert builder.main(["--check"]) == 0, capsys.readouterr().out


def test_javascript_implementation_passes_its_cases_over_json_lines():
    node = shutil.which("node")
    if node is None:
        pytest.skip("node (Node.js) is not installed: the JavaScript example implementation cannot run")
    skips = load_skips(JS_DIR / "skips.json")
    cases = load_cases()
    adapter = JsonlAdapter(f"{node} {JS_DIR / 'haptify.js'}", timeout_s=60.0)
    verdicts = run_cases(cases, adapter, skips)
    ran = [v for v in verdicts if v.case_id not in skips]
    assert {v.metric for v in ran} >= {
        "workspace.spec_box_volume",
        "vibration.rms",
        "vibration.spectral_centroid",
        "free_space.force_mean",
    }
    assert {v.case_id for v in ran} >= {c.id for c in cases if c.quantity != "value"}  # every uncertainty case (§19)
    assert [(v.case_id, v.message) for v in ran if v.status != "passed"] == []
    assert len(ran) >= 7
    assert adapter.implementation.get("name") == "haptify-js-example"
    summary = build_report(header("jsonl", adapter.implementation, "2026-01-01T00:00:00Z"), verdicts).summary
    negative = {c.id for c in cases if c.metric == "validate" and c.level == "MUST"}
    assert not summary.conforms and negative <= set(summary.must_skipped)  # skipping MUST cases never conforms


def test_the_linter_reports_a_fixture_edited_by_hand(tmp_path):
    from haptify_conform.lint import _stale_fixtures

    src = REPO_ROOT / "fixtures" / "conformance"
    root = tmp_path / "conformance"
    root.mkdir()
    shutil.copy(src / builder.DIGESTS, root / builder.DIGESTS)
    shutil.copytree(src / "ws-sphere", root / "ws-sphere")
    assert _stale_fixtures(root, {"conformance/ws-sphere"}) == []
    assert _stale_fixtures(root, set()) == ["fixture conformance/ws-sphere is used by no case"]
    manifest = json.loads((root / "ws-sphere" / "session.json").read_text())
    manifest["device"]["datasheet"]["workspace_box_m"] = [0.2, 0.12, 0.07]
    (root / "ws-sphere" / "session.json").write_text(json.dumps(manifest))
    assert "differs from what its builder recorded" in _stale_fixtures(root, {"conformance/ws-sphere"})[0]


@pytest.mark.parametrize("model", ["../ws-sphere/session.json", "/etc/passwd", "missing.json"])
def test_a_case_model_outside_the_session_or_missing_is_e702(model):
    from haptify.conform_adapter import analyse

    doc = analyse(str(REPO_ROOT / "fixtures" / "conformance" / "dyn-predict"), "dynamics.force_rmse", {"model": model})
    assert [(u["id"], u["code"]) for u in doc["unavailable"]] == [("dynamics.force_rmse", "E702")]
    assert doc["metrics"] == []


def test_the_spec_table_of_case_files_states_their_case_counts():
    """Spec §16.8.1 lists every case file with its number of cases: the table is prose, its counts must
    follow the files."""
    import re

    table = (REPO_ROOT / "spec" / "16-conformance.md").read_text(encoding="utf-8")
    stated = {m.group(1): int(m.group(2)) for m in re.finditer(r"^\| `(\w+\.json)` \| (\d+) \|", table, re.M)}
    actual = {
        p.name: len(json.loads(p.read_text(encoding="utf-8"))["cases"])
        for p in sorted((REPO_ROOT / "conformance" / "cases").glob("*.json"))
    }
    assert stated == actual
