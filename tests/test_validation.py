"""Validation (spec chapter 4): the bad-input fixtures, the thresholds, the command and path safety."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from jsonschema import Draft202012Validator

from haptify.cli import main as cli
from haptify.errors import catalogue
from haptify.formats.conventions import QUATERNION_NORM_TOLERANCE
from haptify.formats.validation import (
    OCCLUSION_WARNING_SHARE,
    RATE_TOLERANCE,
    ValidationReportModel,
    validate_session,
)
from haptify_tools import build_invalid_fixtures as fx
from haptify_tools.example_session import example_writer
from haptify_tools.invalid_fixtures import cases, defects, session_edits

REPO = Path(__file__).resolve().parents[1]
INVALID = REPO / "fixtures" / "invalid"
VALID = REPO / "fixtures" / "valid"
SIDECARS = sorted(INVALID.glob("*.expected.json"))


def _name(sidecar: Path) -> str:
    return sidecar.name[: -len(".expected.json")]


def _expected(sidecar: Path) -> dict:
    return json.loads(sidecar.read_text(encoding="utf-8"))


# --- the fixtures -----------------------------------------------------------------------------------


def test_there_are_at_least_30_invalid_fixtures_each_with_catalogued_codes():
    assert len(SIDECARS) >= 30
    codes = catalogue()
    for side in SIDECARS:
        exp = _expected(side)
        assert (INVALID / _name(side)).is_dir(), side
        assert exp["codes"] and all(c in codes for c in exp["codes"]), side
        assert exp["exit_code"] == (1 if any(codes[c]["severity"] == "error" for c in exp["codes"]) else 0)
    # the defects every validator must catch are covered
    must = {
        "malformed-json",
        "wrong-types",
        "unknown-protocol",
        "stream-file-missing",
        "truncated-parquet",
        "csv-wrong-header",
        "time-not-increasing",
        "wrong-units",
        "non-unit-quaternion",
        "nan-in-force",
        "checksum-mismatch",
        "empty-stream",
        "path-traversal",
        "absolute-path",
        "symlink-absolute",
        "symlink-relative-escape",
        "absurd-rows",
        "oversized-file",
    }
    assert must <= {_name(s) for s in SIDECARS}


@pytest.mark.parametrize("sidecar", SIDECARS, ids=_name)
def test_invalid_fixture_yields_exactly_its_expected_codes(sidecar: Path):
    exp = _expected(sidecar)
    report = validate_session(INVALID / _name(sidecar))
    assert "E999" not in report.codes
    assert report.codes == exp["codes"], [str(f) for f in report.findings]
    assert report.exit_code == exp["exit_code"]
    for f in report.findings:  # every finding is located and explained
        assert f.file and f.message and f.hint and f.spec_section


@pytest.mark.parametrize("name", [c.name for c in cases.VALID])
def test_valid_fixtures_have_no_findings(name: str):
    report = validate_session(VALID / name)
    assert report.findings == [], [str(f) for f in report.findings]
    assert report.exit_code == 0
    assert report.streams_checked >= 4


def test_committed_fixtures_are_current(tmp_path: Path, monkeypatch):
    """Rebuilding gives the same logical content (JSON, table bits, symlink targets) as the committed tree."""
    monkeypatch.setattr(os, "fsync", lambda fd: None)  # content matters here, not durability: 2x faster
    stale = fx.stale_fixtures(REPO / "fixtures", tmp_path)
    assert not stale, f"stale fixtures {stale[:5]}: run python -m haptify_tools.build_invalid_fixtures"


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
@pytest.mark.parametrize("nudge, agree", [(4, True), (10**8, False)])
def test_rebuilt_trees_agree_up_to_the_cpus_rounding(tmp_path: Path, fmt: str, nudge: int, agree: bool):
    """A rebuild whose numbers differ from the committed tree by a few units in the last place (numpy's
    vectorised sin and exp round differently on different CPUs) is the same fixture; a real change is not."""
    import numpy as np

    from haptify.formats.storage import read_table, sha256_file, write_table

    committed = example_writer(duration_s=0.2, fmt=fmt).write(tmp_path / "committed")
    rebuilt = example_writer(duration_s=0.2, fmt=fmt).write(tmp_path / "rebuilt")
    manifest = json.loads((rebuilt / "session.json").read_text(encoding="utf-8"))
    stream = next(s for s in manifest["trials"][0]["streams"] if s["kind"] == "handle_wrench")
    path = rebuilt / stream["file"]
    frame = read_table(path, fmt, [c["name"] for c in stream["columns"]], label=stream["file"])
    x = frame["fx"].to_numpy().copy()
    x[50] = x[50] + nudge * np.spacing(np.abs(x).max())
    frame["fx"] = x
    write_table(path, frame, fmt)
    stream["sha256"] = sha256_file(path)
    (rebuilt / "session.json").write_text(json.dumps(manifest), encoding="utf-8")
    assert fx.trees_agree(rebuilt, committed) is agree
    assert fx.trees_agree(committed, committed)


# --- thresholds of spec §4.4, by construction ------------------------------------------------------


def _session(tmp_path: Path, name: str = "s", **kw) -> Path:
    return example_writer(duration_s=0.2, **kw).write(tmp_path / name)


@pytest.mark.parametrize(
    "factor, flagged",
    [
        (1 + 0.9 * RATE_TOLERANCE, False),
        (1 - 0.9 * RATE_TOLERANCE, False),
        (1 + 1.2 * RATE_TOLERANCE, True),
        (1 - 1.2 * RATE_TOLERANCE, True),
    ],
)
def test_rate_tolerance_is_one_percent_of_the_mean_rate(tmp_path: Path, factor: float, flagged: bool):
    folder = _session(tmp_path)
    session_edits.rewrite_data(folder, "handle_wrench", defects._retime(1000.0 * factor))
    assert ("E206" in validate_session(folder).codes) is flagged


@pytest.mark.parametrize("excess, flagged", [(0.9 * QUATERNION_NORM_TOLERANCE, False), (1.5 * QUATERNION_NORM_TOLERANCE, True)])
def test_quaternion_norm_tolerance(tmp_path: Path, excess: float, flagged: bool):
    folder = _session(tmp_path)

    def scale(df):
        df["qw"] = df["qw"] * (1 + excess)  # qx = qy = 0 at t = 0 and the norm scales with every component
        df["qz"] = df["qz"] * (1 + excess)
        return df

    session_edits.rewrite_data(folder, "handle_pose", scale)
    report = validate_session(folder)
    assert ("E207" in report.codes) is flagged
    if flagged:
        (f,) = [f for f in report.findings if f.code == "E207"]
        assert f.found == pytest.approx(1 + excess, abs=1e-12)


@pytest.mark.parametrize("occluded, flagged", [(4, False), (5, True)])
def test_occlusion_warning_above_twenty_percent(tmp_path: Path, occluded: int, flagged: bool):
    # 20 samples: 4 occluded = 20 % (not above the share), 5 = 25 %
    assert OCCLUSION_WARNING_SHARE == 0.2
    w = example_writer(duration_s=0.2)
    session_edits.add_markers_trial(w, ["h1", "h2"])
    folder = w.write(tmp_path / "s")
    defects._markers_nan(slice(0, occluded), ["h1_x", "h1_y", "h1_z"])(folder)
    report = validate_session(folder)
    assert report.codes == (["W405"] if flagged else [])


def test_interval_outliers_are_a_warning_and_name_their_time_range(tmp_path: Path):
    folder = _session(tmp_path)
    session_edits.rewrite_data(folder, "handle_wrench", defects._jitter)
    report = validate_session(folder)
    (f,) = report.findings
    assert (f.code, f.column, f.found) == ("W402", "t", 4)  # 4 intervals: both sides of the two moved samples
    assert f.time_range == pytest.approx((0.049, 0.121))
    assert report.exit_code == 0


def test_sensor_range_counts_the_exceeding_samples(tmp_path: Path):
    folder = _session(tmp_path)
    session_edits.rewrite_data(folder, "handle_wrench", session_edits.set_column("handle_wrench", "fz", slice(100, 110), -170.0))
    (f,) = validate_session(folder).findings
    assert (f.code, f.column, f.found) == ("W401", "fz", 170.0)
    assert "10 samples" in f.message
    assert f.time_range == pytest.approx((0.100, 0.109))


def test_clock_offset_records_put_streams_on_the_session_clock(tmp_path: Path):
    folder = _session(tmp_path)
    session_edits.rewrite_data(folder, "handle_pose", defects._shift_time(10.0))
    assert validate_session(folder).codes == ["E305"]
    pose_file = session_edits.stream_of(session_edits.manifest(folder), "handle_pose")["file"]
    session_edits.edit(
        folder,
        lambda m: m.__setitem__(
            "calibration", [{"kind": "clock_offset", "id": "sync-pose", "stream_file": pose_file, "offset_s": -10.0}]
        ),
    )
    assert validate_session(folder).codes == []


def test_a_stream_without_time_column_is_a_column_finding_not_a_crash(tmp_path: Path):
    folder = _session(tmp_path)
    session_edits.rewrite_data(folder, "handle_wrench", lambda df: df.drop(columns=["t"]))
    session_edits.edit(folder, lambda m: session_edits.stream_of(m, "handle_wrench")["columns"].pop(0))
    assert validate_session(folder).codes == ["E201"]


def test_all_findings_are_reported_not_only_the_first():
    report = validate_session(INVALID / "several-problems")
    assert [f.code for f in report.findings].count("W404") == 1
    assert {f.file for f in report.errors} == {
        "trials/free_space-1/handle_wrench.parquet",
        "trials/free_space-1/handle_accel.parquet",
        "trials/free_space-1/handle_pose.parquet",
    }
    groups = report.groups()
    assert all(trial == "free_space-1" for trial, _, _ in groups)
    assert groups[0][1] == "session.json"


def test_schema_errors_carry_json_pointers():
    report = validate_session(INVALID / "wrong-types")
    assert sorted(f.pointer for f in report.findings) == [
        "/trials/0/powered",
        "/trials/0/repetition",
        "/trials/0/streams/0/rate_hz",
    ]
    assert {f.code for f in validate_session(INVALID / "unknown-protocol").findings} == {"E301"}
    (rows,) = validate_session(INVALID / "absurd-rows").findings
    assert (rows.code, rows.pointer, rows.found) == ("E113", "/trials/0/streams/0/rows", 10**12)


# --- path safety: nothing outside the folder is opened ---------------------------------------------

_OPENED: list[str] | None = None


def _audit(event: str, args: tuple) -> None:
    if _OPENED is not None and event == "open" and args and isinstance(args[0], (str, bytes, os.PathLike)):
        _OPENED.append(os.fsdecode(args[0]))


sys.addaudithook(_audit)


def test_symlink_targets_outside_the_folder_are_never_opened(tmp_path: Path, monkeypatch):
    global _OPENED
    outside = tmp_path / "outside"
    outside.mkdir()
    folder = _session(tmp_path, "session")
    m = session_edits.manifest(folder)
    wrench = folder / session_edits.stream_of(m, "handle_wrench")["file"]
    accel = folder / session_edits.stream_of(m, "handle_accel")["file"]
    shutil.move(wrench, outside / "secret.parquet")
    shutil.move(accel, outside / "secret-accel.parquet")
    os.symlink(outside / "secret.parquet", wrench)  # absolute link out
    os.symlink("../../../outside/secret-accel.parquet", accel)  # relative link out
    arrow_reads: list[str] = []
    real_read = pq.read_table

    def audited_read(source, *a, **k):  # Arrow opens paths itself, beyond Python's audit hook
        if isinstance(source, (str, bytes, os.PathLike)):
            arrow_reads.append(os.fsdecode(source))
        return real_read(source, *a, **k)

    monkeypatch.setattr(pq, "read_table", audited_read)
    _OPENED = []
    try:
        report = validate_session(folder)
        opened = list(_OPENED)
    finally:
        _OPENED = None
    assert report.codes == ["E109"] and len(report.errors) == 2
    touched = [os.path.realpath(p) for p in opened + arrow_reads]
    assert any(p.endswith("session.json") for p in touched)  # the audit sees the files validation does read
    assert not [p for p in touched if not p.startswith(os.path.realpath(folder) + os.sep)], touched


def test_symlinks_that_stay_inside_the_folder_are_accepted(tmp_path: Path):
    folder = _session(tmp_path)
    wrench = folder / session_edits.stream_of(session_edits.manifest(folder), "handle_wrench")["file"]
    (folder / "data").mkdir()
    shutil.move(wrench, folder / "data" / "w.parquet")
    os.symlink("../../data/w.parquet", wrench)
    assert validate_session(folder).findings == []


def test_a_fifo_stream_file_is_reported_without_blocking(tmp_path: Path):
    folder = _session(tmp_path)
    wrench = folder / session_edits.stream_of(session_edits.manifest(folder), "handle_wrench")["file"]
    wrench.unlink()
    os.mkfifo(wrench)
    assert validate_session(folder).codes == ["E112"]


# --- the command --------------------------------------------------------------------------------------


@pytest.mark.parametrize("sidecar", SIDECARS[::4], ids=_name)
def test_cli_exit_codes_and_json_report(sidecar: Path, capsys):
    exp = _expected(sidecar)
    folder = str(INVALID / _name(sidecar))
    assert cli.main(["validate", folder]) == exp["exit_code"]
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    assert all(code in out for code in exp["codes"])
    assert cli.main(["validate", folder, "--json"]) == exp["exit_code"]
    out, _ = capsys.readouterr()
    payload = json.loads(out)
    Draft202012Validator(ValidationReportModel.model_json_schema()).validate(payload)
    model = ValidationReportModel.model_validate(payload)
    assert sorted({f.code for f in model.findings}) == exp["codes"]
    assert model.exit_code == exp["exit_code"]


def test_cli_exit_code_0_for_a_valid_session_and_2_when_it_cannot_run(tmp_path: Path, capsys):
    assert cli.main(["validate", str(VALID / "parquet-basic")]) == 0
    assert "valid" in capsys.readouterr().out
    assert cli.main(["validate", str(tmp_path / "nowhere")]) == 2
    assert "E101" in capsys.readouterr().out
    (tmp_path / "a-file").write_text("x")
    assert cli.main(["--json", "validate", str(tmp_path / "a-file")]) == 2
    assert json.loads(capsys.readouterr().out)["findings"][0]["code"] == "E101"


@pytest.mark.parametrize("name", ["malformed-json", "truncated-parquet"])
def test_no_traceback_reaches_the_user(name: str):
    proc = subprocess.run(
        [sys.executable, "-m", "haptify.cli.main", "validate", str(INVALID / name)], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 1
    assert "Traceback" not in proc.stdout + proc.stderr
    assert proc.stderr == ""


@pytest.mark.parametrize("q", [[1e308, 0.0, 0.0, 0.0], [10**400, 0, 0, 0]])
def test_a_huge_static_quaternion_is_e207_not_an_overflow(tmp_path: Path, q):
    # squaring 1e308 overflowed (E999); an integer beyond the float range cannot even be converted (spec §1.3, §4.3.3)
    folder = _session(tmp_path)
    manifest = json.loads((folder / "session.json").read_text(encoding="utf-8"))
    manifest["device_placement"]["quaternion"] = q
    (folder / "session.json").write_text(json.dumps(manifest), encoding="utf-8")
    codes = validate_session(folder).codes
    assert "E207" in codes and "E999" not in codes
