"""The validation gate (spec §4.8): every command that reads a session refuses one that does not validate
— exit 1, the validator's codes, nothing written — and `haptify compute` is a conforming --cmd program."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from haptify.cli.main import main
from haptify.errors import HaptifyError
from haptify.formats.validation import validate_session
from haptify.pipeline.gate import SessionRefused, open_checked_session
from haptify_tools import build_invalid_fixtures as fx
from haptify_tools.invalid_fixtures import cases

REPO = Path(__file__).resolve().parents[1]
INVALID = REPO / "fixtures" / "invalid"
VALID_SESSION = REPO / "fixtures" / "valid" / "parquet-basic"
MODEL = REPO / "fixtures" / "conformance" / "dyn-predict" / "model-a.json"


def _refused_fixtures() -> list[tuple[str, list[str]]]:
    out = []
    for sidecar in sorted(INVALID.glob("*.expected.json")):
        meta = json.loads(sidecar.read_text(encoding="utf-8"))
        if meta["exit_code"] == 1:
            out.append((sidecar.name.removesuffix(".expected.json"), sorted(c for c in meta["codes"] if c.startswith("E"))))
    return out


REFUSED = _refused_fixtures()


def _build(name: str, tmp_path: Path) -> Path:
    folder = tmp_path / name
    fx.build_case(next(c for c in cases.CASES if c.name == name), folder)
    return folder


def _tree(root: Path) -> dict[str, int]:
    """Every file under ``root`` with its size (symbolic links as links, never followed)."""
    return {str(p.relative_to(root)): (p.lstat().st_size if not p.is_symlink() else -1) for p in root.rglob("*")}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """The valid side inputs the commands need besides the session: a twin, a results file."""
    root = tmp_path_factory.mktemp("inputs")
    assert main(["twin", "export", "--preset", "touch", "-o", str(root / "twin.json")]) == 0
    assert main(["compute", str(VALID_SESSION), "-o", str(root / "results.json")]) == 0
    return {"twin": root / "twin.json", "results": root / "results.json"}


COMMANDS = {
    "compute": lambda s, out, inp: ["compute", s, "-o", str(out / "results.json")],
    "report": lambda s, out, inp: ["report", s, "-o", str(out / "report")],
    "view": lambda s, out, inp: ["view", s, "--save", str(out / "session.rrd")],
    "dynamics fit": lambda s, out, inp: ["dynamics", "fit", s, "-o", str(out / "model.json")],
    "dynamics predict": lambda s, out, inp: ["dynamics", "predict", str(MODEL), s, "-o", str(out / "pred.parquet")],
    "rig-check": lambda s, out, inp: ["rig-check", s],
    "discrepancy": lambda s, out, inp: ["discrepancy", "--session", s, "--twin", str(inp["twin"]), "-o", str(out / "disc")],
    "submit": lambda s, out, inp: ["submit", s, "--results", str(inp["results"]), "--dry-run"],
}


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_refuses_every_invalid_fixture_with_its_codes_and_writes_nothing(command, inputs, tmp_path, capsys):
    before = _tree(INVALID)
    wrong = []
    for name, codes in REFUSED:
        out = tmp_path / name
        out.mkdir()
        status = main(["--json", *COMMANDS[command](str(INVALID / name), out, inputs)])
        printed = capsys.readouterr().out
        reported = {f["code"] for f in json.loads(printed)["findings"]} if printed.strip() else set()
        written = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
        if command == "compute":  # -o was given: the findings document of §16.4.1, and nothing else
            doc = json.loads((out / "results.json").read_text(encoding="utf-8"))
            written = [] if set(doc) == {"findings"} and {f["code"] for f in doc["findings"]} >= set(codes) else written
        if status != 1 or not set(codes) <= reported or written:
            wrong.append((name, status, codes, sorted(reported), written))
    assert wrong == []
    assert _tree(INVALID) == before


def test_compute_without_output_writes_nothing_beside_a_refused_session(tmp_path):
    folder = _build("checksum-mismatch", tmp_path)
    before = _tree(tmp_path)
    assert main(["compute", str(folder)]) == 1
    assert _tree(tmp_path) == before


# --- the gate reads each stream once and checks the streams no metric reads -----------------------------


def test_a_broken_stream_no_metric_reads_still_refuses_the_session(tmp_path):
    """The vibration metrics read only handle_accel; a corrupted handle_wrench must refuse them too."""
    folder = _build("checksum-mismatch", tmp_path)
    out = tmp_path / "r.json"
    assert main(["compute", str(folder), "--metrics", "vibration.rms", "-o", str(out)]) == 1
    assert [f["code"] for f in json.loads(out.read_text())["findings"]] == ["E111"]


def test_reading_a_stream_through_the_gate_is_its_validation(tmp_path):
    folder = _build("checksum-mismatch", tmp_path)
    session = open_checked_session(folder)
    wrench = session.stream("free_space-1", "handle_wrench")
    accel = session.stream("free_space-1", "handle_accel")
    assert len(session.read_stream(accel)) == accel.rows  # a sound stream reads
    with pytest.raises(SessionRefused) as refused:
        session.read_stream(wrench)
    assert refused.value.exit_code == 1
    assert [f.code for f in refused.value.findings] == [f.code for f in validate_session(folder).findings] == ["E111"]


def test_compute_stops_after_the_family_whose_read_refused_the_session(tmp_path, monkeypatch):
    # The first family reads the corrupted handle_wrench and, as every family does with a trial's coded error,
    # carries on; compute_session refuses the session as soon as that family ends, and no later family runs.
    import importlib

    from haptify.pipeline.compute import compute_session
    from haptify.pipeline.families import family_modules

    folder = _build("checksum-mismatch", tmp_path)
    session = open_checked_session(folder)
    (_, first_module), (_, second_module) = family_modules()[:2]

    def reads_the_broken_stream(ctx):
        try:
            ctx.session.read_stream(ctx.session.stream("free_space-1", "handle_wrench"))
        except HaptifyError:
            pass  # the trial's metrics would be unavailable
        return []

    later_runs = []
    monkeypatch.setattr(importlib.import_module(first_module), "compute", reads_the_broken_stream)
    monkeypatch.setattr(importlib.import_module(second_module), "compute", lambda ctx: later_runs.append(1) or [])
    with pytest.raises(SessionRefused) as refused:
        compute_session(session)
    assert [f.code for f in refused.value.findings] == ["E111"] and later_runs == []


def test_a_folder_that_is_not_there_cannot_run_rather_than_being_refused(tmp_path):
    with pytest.raises(HaptifyError) as err:
        open_checked_session(tmp_path / "missing")
    assert not isinstance(err.value, SessionRefused) and err.value.code == "E101" and err.value.exit_code == 2


def test_validation_warnings_pass_into_the_results_file(tmp_path):
    folder = _build("irregular-intervals", tmp_path)
    out = tmp_path / "r.json"
    assert main(["compute", str(folder), "-o", str(out)]) == 0
    warnings = json.loads(out.read_text())["warnings"]
    assert {"code": "W402", "trial": "free_space-1"}.items() <= next(w for w in warnings if w["code"] == "W402").items()


def test_params_must_be_a_json_object(tmp_path, capsys):
    params = tmp_path / "p.json"
    params.write_text("[1, 2]", encoding="utf-8")
    out = tmp_path / "r.json"
    assert main(["--json", "compute", str(VALID_SESSION), "-o", str(out), "--params", str(params)]) == 2
    assert json.loads(capsys.readouterr().out)["findings"][0]["code"] == "E903"
    assert [f["code"] for f in json.loads(out.read_text())["findings"]] == ["E903"]


# --- the reference through its own suite ----------------------------------------------------------------


@pytest.mark.slow(longest=True)
def test_the_reference_command_passes_every_case_through_cmd(tmp_path):
    """The exact line of spec §16.4.1 and the README's tour."""
    bindir = Path(sys.executable).parent
    env = {**os.environ, "PATH": f"{bindir}{os.pathsep}{os.environ.get('PATH', '')}"}
    assert shutil.which("haptify", path=env["PATH"]), "the haptify console script is not installed beside python"
    report = tmp_path / "report.json"
    run = subprocess.run(
        [
            str(bindir / "haptify-conform"),
            "--cmd",
            "haptify compute {session} -o {out} --params {params}",
            "--quiet",
            "--json-report",
            str(report),
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=1500,
    )
    summary = json.loads(report.read_text())["summary"]
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert summary["failed"] == summary["error"] == summary["skipped"] == 0 and summary["passed"] >= 179, summary


# --- start-up: the parser imports only what the command needs -------------------------------------------

HEAVY = (
    "rerun",
    "fastapi",
    "matplotlib",
    "numba",
    "haptify_tools.discrepancy",
    "haptify_tools.viewer",
    "haptify_tools.registry",
    "haptify_tools.twin",
    "sqlalchemy",
    "scipy",
)


@pytest.mark.parametrize("argv", [[], ["validate"], ["compute"], ["--json", "validate", "--help"]])
def test_building_the_parser_imports_none_of_the_heavy_packages(argv):
    code = (
        "import sys; from haptify.cli.main import build_parser, split_global_flags; "
        f"rest, flags, command = split_global_flags({argv!r}); build_parser(command); "
        f"print(sorted(m for m in sys.modules if m.split('.')[0] in {{h.split('.')[0] for h in {HEAVY!r}}} "
        f"and any(m == h or m.startswith(h + '.') for h in {HEAVY!r})))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_help_lists_every_command_without_loading_them(capsys):
    assert main(["--help"]) == 0
    text = capsys.readouterr().out
    for name in ("compute", "discrepancy", "registry", "validate", "view"):
        assert f"\n    {name}" in text


# --- global flags where users put them (spec §0.5) ------------------------------------------------------


@pytest.mark.parametrize("before, after", [(["--json", "validate"], ["validate"]), (["-q", "validate"], ["validate"])])
def test_global_flags_work_before_and_after_the_command(before, after, capsys):
    flag = before[0]
    assert main([*before, str(INVALID / "time-nan")]) == 1
    first = capsys.readouterr()
    assert main([*after, str(INVALID / "time-nan"), flag]) == 1
    second = capsys.readouterr()
    assert (first.out, first.err) == (second.out, second.err)
    if flag == "--json":
        assert json.loads(second.out)["valid"] is False
    else:
        assert "INVALID" not in second.out and "E203" in second.out


def test_json_after_compute_and_compare(tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["compute", str(VALID_SESSION), "-o", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["session_id"] == "fixture-parquet-basic"
    assert main(["compare", str(out), str(out), "--json"]) == 0
    assert isinstance(json.loads(capsys.readouterr().out), (dict, list))
