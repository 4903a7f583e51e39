"""The conformance runner itself (spec chapter 16): judging, adapters, crash isolation, reports."""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import jsonschema
import pytest

from haptify import schemas
from haptify_conform.adapters import CmdAdapter, JsonlAdapter
from haptify_conform.cases import Case, Expected, Provenance, Tolerance
from haptify_conform.judge import judge_metric
from haptify_conform.report import build_report, header, to_junit, to_table
from haptify_conform.runner import run_cases

TOY = Path(__file__).parent / "conform_impls" / "toy_jsonl.py"


def case(cid: str, fixture: str, value=1.5, unit="N", tol=(0.01, 0.0), codes=None, metric="x.y") -> Case:
    return Case(
        id=cid,
        metric=metric,
        spec_section="9.9",
        level="MUST",
        fixture=fixture,
        expected=Expected(value=None if codes else value, unit=None if codes else unit, codes=codes),
        tolerance=None if codes else Tolerance(abs=tol[0], rel=tol[1]),
        provenance=Provenance(kind="analytic", note="test"),
        spec_versions=["1.0"],
        description="t",
    )


def results(value, unit="N", metric="x.y"):
    return {"metrics": [{"id": metric, "value": value, "unit": unit}]}


@pytest.mark.parametrize(
    "value,unit,status",
    [
        (1.505, "N", "passed"),
        (1.52, "N", "failed"),
        (1.5, "kN", "failed"),
        (float("nan"), "N", "failed"),
        ([1.5, 1.5], "N", "failed"),
        ("1.5", "N", "failed"),
    ],
)
def test_tolerance_rule_and_failures_of_their_own(value, unit, status):
    assert judge_metric(case("c", "f"), results(value, unit)).status == status


def test_relative_tolerance_and_vectors():
    c = case("c", "f", value=[10.0, -20.0], tol=(0.0, 0.01))
    assert judge_metric(c, results([10.09, -20.19])).status == "passed"
    v = judge_metric(c, results([10.0, -20.3]))
    assert v.status == "failed" and v.max_abs_error == pytest.approx(0.3) and v.max_rel_error == pytest.approx(0.015)


def test_missing_metric_says_why():
    v = judge_metric(case("c", "f"), {"metrics": [], "unavailable": [{"id": "x.y", "code": "E302", "reason": "no stream"}]})
    assert v.status == "failed" and "E302" in v.message


def _fixtures(tmp_path: Path, *names: str) -> Path:
    for n in names:
        (tmp_path / "fixtures" / n).mkdir(parents=True)
    return tmp_path


def test_jsonl_adapter_isolates_crashes_hangs_and_garbage(tmp_path):
    repo = _fixtures(tmp_path, "v1.5", "crash", "hang", "garbage", "skip", "reject", "v2.0")
    cases = [
        case("a", "v1.5"),
        case("b", "crash"),
        case("c", "hang"),
        case("d", "garbage"),
        case("e", "skip"),
        case("f", "reject", codes=["E203"]),
        case("g", "v2.0"),
        case("h", "missing"),
    ]
    adapter = JsonlAdapter(f"{sys.executable} {TOY}", timeout_s=2.0)
    verdicts = {v.case_id: v for v in run_cases(cases, adapter, repo=repo)}
    assert verdicts["a"].status == "passed"
    assert verdicts["b"].status == "error" and "exited" in verdicts["b"].message
    assert verdicts["c"].status == "error" and "no reply" in verdicts["c"].message
    assert verdicts["d"].status == "error" and "not JSON" in verdicts["d"].message
    assert verdicts["e"].status == "skipped"
    assert verdicts["f"].status == "passed"
    assert verdicts["g"].status == "failed"  # a fresh process after the crashes still answers, wrongly: 2.0 ≠ 1.5
    assert verdicts["h"].status == "error" and "fixture" in verdicts["h"].message
    assert adapter.restarts == 3


def test_jsonl_restarts_are_bounded(tmp_path):
    repo = _fixtures(tmp_path, "crash")
    adapter = JsonlAdapter(f"{sys.executable} {TOY}", timeout_s=2.0, max_restarts=1)
    verdicts = run_cases([case(f"c{i}", "crash") for i in range(4)], adapter, repo=repo)
    assert [v.status for v in verdicts] == ["error"] * 4
    assert "not restarted" in verdicts[-1].message


def test_cmd_adapter_reads_out_file_and_reports_no_output(tmp_path):
    repo = _fixtures(tmp_path, "s")
    prog = tmp_path / "impl.py"
    prog.write_text(
        "import json, sys\njson.dump({'metrics': [{'id': 'x.y', 'value': 1.5, 'unit': 'N'}]}, open(sys.argv[2], 'w'))\n"
    )
    verdicts = run_cases([case("a", "s")], CmdAdapter(f"{sys.executable} {prog} {{session}} {{out}}", 10), repo=repo)
    assert verdicts[0].status == "passed"
    silent = tmp_path / "silent.py"
    silent.write_text("import sys\nprint('boom', file=sys.stderr)\nsys.exit(4)\n")
    verdicts = run_cases([case("a", "s")], CmdAdapter(f"{sys.executable} {silent} {{session}} {{out}}", 10), repo=repo)
    assert verdicts[0].status == "error" and "exit 4" in verdicts[0].message and "boom" in verdicts[0].message
    with pytest.raises(ValueError):
        CmdAdapter("tool {session}", 10)


@pytest.mark.parametrize(
    "passed, runs",
    [
        ("", 2),  # the command line holds the session only: one run per fixture
        (" {params}", 3),  # the parameters too: the case with other parameters runs on its own
        (" {metric}", 3),  # the metric too: the case of another metric runs on its own
        (" {case}", 5),  # the case id: every case runs
    ],
)
def test_cmd_adapter_runs_each_command_line_once(tmp_path, passed, runs):
    # Five cases on two fixtures; c differs from a only by its parameters, d by its metric. The program logs
    # each of its runs and answers 1.5 N for both metrics, so every case passes however many runs it took.
    repo = _fixtures(tmp_path, "s", "t")
    log = tmp_path / "runs.log"
    prog = tmp_path / "impl.py"
    prog.write_text(
        "import json, sys\n"
        f"open({str(log)!r}, 'a').write(' '.join(sys.argv[1:]) + '\\n')\n"
        "json.dump({'metrics': [{'id': m, 'value': 1.5, 'unit': 'N'} for m in ('x.y', 'x.z')]}, open(sys.argv[2], 'w'))\n"
    )
    cases = [case("a", "s"), case("b", "s"), case("c", "s"), case("d", "s", metric="x.z"), case("e", "t")]
    cases[2] = cases[2].model_copy(update={"parameters": {"model": "other.json"}})
    adapter = CmdAdapter(f"{sys.executable} {prog} {{session}} {{out}}{passed}", 10)
    verdicts = run_cases(cases, adapter, repo=repo)
    assert [v.status for v in verdicts] == ["passed"] * 5
    assert len(log.read_text().splitlines()) == runs
    assert verdicts[0].duration_s > 0
    assert (verdicts[1].duration_s == 0.0) is (passed != " {case}")  # b answered by a's run: no time of its own


def test_skip_list_is_reported_not_dropped(tmp_path):
    repo = _fixtures(tmp_path, "v1.5")
    verdicts = run_cases([case("a", "v1.5")], JsonlAdapter(f"{sys.executable} {TOY}", 2.0), skips={"a": "not yet"}, repo=repo)
    assert verdicts[0].status == "skipped" and "not yet" in verdicts[0].message


def test_reports_validate_and_parse(tmp_path):
    repo = _fixtures(tmp_path, "v1.5", "v9")
    verdicts = run_cases([case("a", "v1.5"), case("b", "v9")], JsonlAdapter(f"{sys.executable} {TOY}", 2.0), repo=repo)
    report = build_report(header("jsonl", {"name": "toy"}, "2026-11-22T00:00:00Z"), verdicts)
    jsonschema.validate(json.loads(report.model_dump_json()), schemas.schema("conform-report"))
    assert report.summary.passed == 1 and report.summary.failed == 1 and not report.summary.conforms
    table = to_table(report)
    assert "FAILED" in table and "spec §9.9" in table and "DOES NOT CONFORM" in table
    suite = ET.fromstring(to_junit(report).split("?>", 1)[1])
    assert suite.get("tests") == "2" and suite.get("failures") == "1"
    assert suite.find("testcase[@name='b']/failure") is not None


@pytest.mark.parametrize("how", ["jsonl", "cmd"])
def test_reference_passes_the_protocol_self_test(how):
    from haptify_conform.cli import main

    server = f"{sys.executable} -m haptify.conform_adapter"
    args = ["--jsonl", server] if how == "jsonl" else ["--cmd", server + " {session} {out}"]
    assert main(args + ["--self-test"]) == 0


def test_self_test_fails_an_implementation_that_accepts_everything(tmp_path):
    from haptify_conform.cli import main

    prog = tmp_path / "yes.py"
    prog.write_text("import json, sys\njson.dump({'metrics': []}, open(sys.argv[2], 'w'))\n")
    assert main(["--cmd", f"{sys.executable} {prog} {{session}} {{out}}", "--self-test"]) == 1


def test_cmd_adapter_names_the_implementation_from_its_results(tmp_path):
    repo = _fixtures(tmp_path, "s")
    prog = tmp_path / "impl.py"
    prog.write_text(
        "import json, sys\njson.dump({'implementation': {'name': 'acme-haptify', 'version': '2.1'}, "
        "'metrics': [{'id': 'x.y', 'value': 1.5, 'unit': 'N'}]}, open(sys.argv[2], 'w'))\n"
    )
    adapter = CmdAdapter(f"{sys.executable} {prog} {{session}} {{out}}", 10)
    run_cases([case("a", "s")], adapter, repo=repo)
    assert adapter.implementation == {"name": "acme-haptify", "version": "2.1"}


@pytest.mark.parametrize(
    "document",
    [
        {"metrics": None},
        {"metrics": {"x.y": 1.5}},
        {"metrics": [], "unavailable": None},
        {"metrics": [], "warnings": 3},
        {"findings": "E203"},
        {"findings": None},
    ],
)
def test_a_document_whose_lists_are_not_arrays_is_an_error_of_the_implementation(document):
    # before: {"metrics": null} stopped the whole run with a TypeError; {"findings": "E203"} passed as an acceptance
    from haptify_conform.adapters import classify
    from haptify_conform.runner import judge

    answer = classify(document)
    assert answer.kind == "error" and "must be JSON arrays" in answer.message
    assert judge(case("c", "f"), answer).status == "error"


def test_the_linter_reports_a_case_file_that_is_not_utf8(tmp_path):
    # a Latin-1 case file stopped the linter with UnicodeDecodeError; it is one reported problem (spec §16.7)
    from haptify_conform.lint import lint

    (tmp_path / "cases").mkdir()
    (tmp_path / "cases" / "bad.json").write_bytes('{"cases": [], "note": "café"}'.encode("latin-1"))
    problems = lint(root=tmp_path, repo=tmp_path)
    assert any(p.startswith("bad.json: invalid case file") for p in problems)


def test_a_broken_suite_means_the_run_cannot_start(monkeypatch, capsys):
    # a case file that does not load raised out of main (a traceback, exit 1); it is exit 2 (spec §16.6)
    from haptify_conform import cli

    def broken(root=None):
        raise ValueError("cases/x.json: not a case file")

    monkeypatch.setattr(cli, "load_cases", broken)
    assert cli.main(["--python", "haptify.conform_adapter:analyse"]) == 2
    assert "not a case file" in capsys.readouterr().err


# --- conformance is not claimed by judging nothing or by skipping what must be answered (spec §16, §16.6) --


def _verdict(cid: str, metric: str, status: str, level: str = "MUST"):
    from haptify_conform.judge import Verdict

    return Verdict(case_id=cid, metric=metric, status=status, level=level)


@pytest.mark.parametrize(
    "verdicts, conforms, must_skipped",
    [
        ([("a", "m.x", "passed"), ("b", "m.y", "skipped")], True, []),  # m.y left out of the claim
        ([("a", "m.x", "passed"), ("b", "m.x", "skipped")], False, ["b"]),  # m.x reported, one case skipped
        ([("a", "m.x", "passed"), ("v", "validate", "skipped")], False, ["v"]),  # a negative case skipped
        ([("a", "m.x", "passed"), ("b", "m.x", "skipped", "SHOULD")], True, []),  # a SHOULD case may be skipped
        ([], False, []),  # nothing judged
    ],
)
def test_a_run_conforms_only_without_forbidden_skips(verdicts, conforms, must_skipped):
    report = build_report(header("cmd", {}, "2026-01-01T00:00:00Z"), [_verdict(*v) for v in verdicts])
    assert (report.summary.conforms, report.summary.must_skipped) == (conforms, must_skipped)
    assert ("DOES NOT CONFORM" in to_table(report)) == (not conforms)


def test_zero_selected_cases_cannot_start(capsys):
    from haptify_conform.cli import main

    assert main(["--python", "haptify.conform_adapter:analyse", "--metric", "no.such.metric"]) == 2
    assert "no case" in capsys.readouterr().err


def test_no_suite_found_cannot_start(tmp_path, monkeypatch, capsys):
    from haptify_conform.cli import main

    monkeypatch.setenv("HAPTIFY_CONFORMANCE_SUITE", str(tmp_path))
    assert main(["--python", "haptify.conform_adapter:analyse"]) == 2
    assert "no conformance suite" in capsys.readouterr().err
    assert main(["--lint"]) == 2


@pytest.mark.parametrize(
    "template, says",
    [
        ("/nonexistent/haptify-impl {session} {out}", "No such file"),
        (
            f"{sys.executable} -c \"import sys; sys.stderr.write('boom: missing module'); sys.exit(127)\" {{session}} {{out}}",
            "boom: missing module",
        ),
    ],
)
def test_an_implementation_that_cannot_start_is_exit_2_with_its_stderr(template, says, capsys):
    from haptify_conform.cli import main

    assert main(["--cmd", template, "--metric", "workspace.spec_box_volume"]) == 2
    assert says in capsys.readouterr().err


def test_a_jsonl_program_that_cannot_start_is_exit_2(capsys):
    from haptify_conform.cli import main

    assert main(["--jsonl", "/nonexistent/haptify-impl", "--metric", "workspace.spec_box_volume"]) == 2
    assert "cannot start" in capsys.readouterr().err


@pytest.mark.slow
def test_the_runner_installed_from_a_wheel_needs_and_finds_the_suite(tmp_path):
    """Built as a regular wheel and installed alone: no cases beside the package, so the suite is named."""
    import subprocess

    import shutil

    repo = Path(__file__).resolve().parents[1]
    source = tmp_path / "source"  # a copy: building writes build/ beside the sources
    for part in ("reference", "schemas", "tools", "conformance"):
        shutil.copytree(repo / part, source / part, ignore=shutil.ignore_patterns("__pycache__", "cases", "examples"))
    for part in ("pyproject.toml", "README.md"):
        shutil.copy(repo / part, source / part)
    wheels = tmp_path / "wheels"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(source)], check=True, capture_output=True
    )
    target = tmp_path / "site"
    (wheel,) = wheels.glob("haptify-*.whl")
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        check=True,
        capture_output=True,
    )
    env = {k: v for k, v in __import__("os").environ.items() if k != "HAPTIFY_CONFORMANCE_SUITE"}
    env["PYTHONPATH"] = str(target)

    def conform(*args):
        return subprocess.run(
            [
                sys.executable,
                "-c",
                "import sys, haptify_conform.cli as c; print(c.__file__, file=sys.stderr); sys.exit(c.main())",
                *args,
            ],
            capture_output=True,
            text=True,
            env=env,
            cwd=tmp_path,
        )

    alone = conform("--python", "haptify.conform_adapter:analyse")
    assert str(target) in alone.stderr and alone.returncode == 2 and "no conformance suite" in alone.stderr
    named = conform("--python", "haptify.conform_adapter:analyse", "--suite", str(repo), "--metric", "vibration.rms", "--quiet")
    assert named.returncode == 0 and "CONFORMS" in named.stdout, named.stdout + named.stderr
