"""The common motion-capture exports (spec §5.10): Qualisys TSV (3-D and 6DOF), OptiTrack
Motive CSV (markers and rigid bodies) and Vicon Nexus CSV (devices, segments, trajectories, model
outputs), written here from the formats' published layouts with known values; each builds a session
that validates and computes, through ``haptify import FORMAT`` and ``haptify import auto``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_import_c3d_variants import rot_z, sweep

from haptify.cli.main import main
from haptify.errors import HaptifyError
from haptify.formats.conventions import matrix_to_quat
from haptify.formats.importers.exports import detect_format, import_export, read_export
from haptify.formats.storage import open_session
from haptify_tools.example_session import TOUCH_DEVICE

N = 2000
RATE = 100.0
FACTS = {
    "session": {
        "date": "2026-11-22",
        "lab": {"id": "lab-t"},
        "examiner": {"id": "ex-t"},
        "device": TOUCH_DEVICE,
        "device_placement": {"position": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]},
    },
    "trial": {"powered": False, "protocol": "workspace", "id": "ws"},
}
ANGLES = 0.001 * np.arange(N)
OCCLUDED = slice(20, 24)


def workspace_map(fmt: str, **members) -> dict:
    return {"source": fmt, **json.loads(json.dumps(FACTS)), "bodies": {"handle": "Handle"}, **members}


def fmt_row(values) -> list[str]:
    return ["" if not np.isfinite(v) else f"{v:.6f}" for v in values]


def run_pipeline(tmp_path: Path, capsys, fmt: str, path: Path, m: dict, cli_format: str | None = None) -> Path:
    """import (CLI) → validate → compute; returns the session; checks the workspace by construction."""
    (tmp_path / "m.json").write_text(json.dumps(m))
    word = [fmt] if cli_format is None else [cli_format] if cli_format else []  # "": no format word at all
    code = main(["--json", "import", *word, str(path), "-o", str(tmp_path / "s"), "--map", str(tmp_path / "m.json")])
    out = capsys.readouterr().out
    assert code == 0, out
    assert json.loads(out)["validation"]["valid"]
    assert main(["validate", str(tmp_path / "s")]) == 0
    assert main(["compute", str(tmp_path / "s"), "-o", str(tmp_path / "r.json")]) == 0
    capsys.readouterr()
    results = {r["id"]: r for r in json.loads((tmp_path / "r.json").read_text())["metrics"]}
    measured = results["workspace.measured_volume"]
    n_valid = N - (OCCLUDED.stop - OCCLUDED.start)
    assert measured["trials"] == ["ws"] and measured["diagnostics"]["points"] == [n_valid]
    ball = 4 / 3 * math.pi * 0.06**3
    assert 0.8 * ball < measured["diagnostics"]["hull_volume_m3"][0] < ball
    return tmp_path / "s"


def assert_handle(session: Path, scale_to_m: float, positions: np.ndarray) -> None:
    """handle_pose holds the known sweep (in m) and the known turn about z; occluded samples are NaN."""
    pose = open_session(session).read("ws", "handle_pose")
    ok = np.ones(N, bool)
    ok[OCCLUDED] = False
    p = pose[["px", "py", "pz"]].to_numpy()
    assert np.isnan(p[~ok]).all()
    np.testing.assert_allclose(p[ok], positions[ok] * scale_to_m, atol=2e-9)
    q = pose[["qw", "qx", "qy", "qz"]].to_numpy()
    np.testing.assert_allclose(q[ok, 0], np.cos(ANGLES[ok] / 2), atol=1e-6)
    np.testing.assert_allclose(q[ok, 3], np.sin(ANGLES[ok] / 2), atol=1e-6)


# --- Qualisys TSV --------------------------------------------------------------------------------


def qtm_header(kind: str, names_key: str, names: list[str], frames: int) -> list[str]:
    return [
        f"NO_OF_FRAMES\t{frames}",
        "NO_OF_CAMERAS\t8",
        f"NO_OF_{'BODIES' if kind == '6D' else 'MARKERS'}\t{len(names)}",
        f"FREQUENCY\t{RATE:g}",
        "NO_OF_ANALOG\t0",
        "ANALOG_FREQUENCY\t0",
        "DESCRIPTION\t--",
        "TIME_STAMP\t2026-11-22, 10:00:00.000\t0.000",
        f"DATA_INCLUDED\t{kind}",
        "\t".join([names_key, *names]),
    ]


def write_qtm_6d(path: Path, frames: int = N) -> np.ndarray:
    """A QTM 6D TSV: body 'Handle' (the sweep, turning about z; residual 0.8 mm, NaN while occluded)."""
    pos = sweep(frames)
    lines = qtm_header("6D", "BODY_NAMES", ["Handle"], frames)
    cols = ["X", "Y", "Z", "Roll", "Pitch", "Yaw", "Residual"] + [f"Rot[{i}]" for i in range(9)]
    lines.append("\t".join(["Frame", "Time"] + [f"Handle {c}" if c in "XYZ" else c for c in cols]))
    for k in range(frames):
        r = rot_z(ANGLES[k])
        row = [*pos[k], 0.0, 0.0, math.degrees(ANGLES[k]), 0.8, *r.T.ravel()]  # Rot[] column by column
        if OCCLUDED.start <= k < OCCLUDED.stop:
            row = [math.nan] * 16
        lines.append("\t".join([str(k + 1), f"{k / RATE:.3f}", *fmt_row(row)]))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return pos


def test_qualisys_6dof_tsv_session_validates_and_computes(tmp_path, capsys):
    pos = write_qtm_6d(tmp_path / "take_6D.tsv")
    assert detect_format(tmp_path / "take_6D.tsv") == "tsv"
    rec = read_export("tsv", tmp_path / "take_6D.tsv")
    assert rec.body_labels == ["Handle"] and rec.point_rate == RATE and rec.body_residuals[0, 0] == 0.8
    session = run_pipeline(tmp_path, capsys, "tsv", tmp_path / "take_6D.tsv", workspace_map("tsv"), cli_format="auto")
    assert_handle(session, 1e-3, np.round(pos, 6))


def test_qualisys_residual_threshold_occludes_samples(tmp_path):
    write_qtm_6d(tmp_path / "t.tsv", frames=50)
    m = workspace_map("tsv", bodies={"handle": "Handle", "max_residual": 0.5}, trial={"powered": False, "id": "ws"})
    import_export("tsv", tmp_path / "t.tsv", tmp_path / "s", None, overrides=m)
    assert np.isnan(open_session(tmp_path / "s").read("ws", "handle_pose")["qw"]).all()  # 0.8 mm > 0.5 mm everywhere


def test_qualisys_3d_tsv_markers_and_zero_gaps(tmp_path):
    frames = 30
    lines = qtm_header("3D", "MARKER_NAMES", ["h1", "h2"], frames)
    lines.append("\t".join(["Frame", "Time", "h1 X", "h1 Y", "h1 Z", "h2 X", "h2 Y", "h2 Z"]))
    for k in range(frames):
        h2 = [0.0, 0.0, 0.0] if k == 5 else [100.0, 200.0 + k, 300.0]  # QTM writes a gap as zeros
        lines.append("\t".join([str(k + 1), f"{k / RATE:.3f}", f"{10.0 * k:.3f}", "1.000", "2.000", *fmt_row(h2)]))
    (tmp_path / "m.tsv").write_text("\n".join(lines) + "\n")
    m = {"source": "tsv", **json.loads(json.dumps(FACTS)), "trial": {"powered": False, "id": "mk"}}
    result = import_export("tsv", tmp_path / "m.tsv", tmp_path / "s", None, overrides=m)
    assert result.warnings == []
    mk = open_session(tmp_path / "s").read("mk", "markers")
    np.testing.assert_array_equal(mk["h1_x"].to_numpy(), 10.0 * np.arange(frames) / 1000.0)
    assert np.isnan(mk["h2_y"][5]) and mk["h2_y"][6] == pytest.approx(0.206)
    np.testing.assert_array_equal(mk["t"].to_numpy(), np.arange(frames) / RATE)


def unreadable(fmt: str, path: Path, text: str) -> str:
    """The E501 message for a file of ``text`` read as ``fmt``."""
    path.write_text(text)
    with pytest.raises(HaptifyError) as err:
        read_export(fmt, path)
    assert err.value.code == "E501"
    return str(err.value)


def test_qualisys_bad_files(tmp_path):
    assert "FREQUENCY" in unreadable("tsv", tmp_path / "a.tsv", "NO_OF_FRAMES\t2\nMARKER_NAMES\ta\n1\t2\t3\n")
    write_qtm_6d(tmp_path / "b.tsv", frames=5)
    text = (tmp_path / "b.tsv").read_text().splitlines()
    text[12] = text[12].replace("0.800000", "abc", 1)
    (tmp_path / "b.tsv").write_text("\n".join(text) + "\n")
    with pytest.raises(HaptifyError) as err:
        read_export("tsv", tmp_path / "b.tsv")
    assert err.value.code == "E501" and "line 13" in str(err.value) and "'abc'" in str(err.value)


# --- OptiTrack Motive CSV ------------------------------------------------------------------------

Y_UP_TO_Z_UP = [math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0]  # Motive's y-up lab frame turned +90° about x into W


def write_motive(path: Path, frames: int = N, rotation_type: str = "Quaternion") -> np.ndarray:
    """A Motive 1.23 CSV in metres, y up: rigid body 'Handle' (the sweep with y and z swapped to
    Motive's axes) and one marker; a gap is empty cells."""
    pos_w = sweep(frames) / 1000.0  # metres, W (z up)
    to_lab = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # W → Motive lab (y up): R_x(−90°)
    meta = [
        "Format Version",
        "1.23",
        "Take Name",
        "take",
        "Capture Frame Rate",
        f"{RATE:.6f}",
        "Export Frame Rate",
        f"{RATE:.6f}",
        "Total Exported Frames",
        str(frames),
        "Rotation Type",
        rotation_type,
        "Length Units",
        "Meters",
        "Coordinate Space",
        "Global",
    ]
    head = [
        ",".join(meta),
        "",
        ",,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Marker,Marker,Marker",
        ",,Handle,Handle,Handle,Handle,Handle,Handle,Handle,Handle,Unlabeled 1000,Unlabeled 1000,Unlabeled 1000",
        ",,1,1,1,1,1,1,1,1,2,2,2",
        ",,Rotation,Rotation,Rotation,Rotation,Position,Position,Position,Mean Marker Error,Position,Position,Position",
        "Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,,X,Y,Z",
    ]
    rows = []
    for k in range(frames):
        q = matrix_to_quat(to_lab @ rot_z(ANGLES[k]))  # w, x, y, z
        p = to_lab @ pos_w[k]
        body = [q[1], q[2], q[3], q[0], *p, 0.0004]
        if OCCLUDED.start <= k < OCCLUDED.stop:
            body = [math.nan] * 8
        rows.append(",".join([str(k), f"{k / RATE:.6f}", *fmt_row(body), *fmt_row([0.1, 0.2 + 0.001 * k, 0.3])]))
    path.write_text("\n".join(head + rows) + "\n")
    return pos_w


def test_motive_csv_rigid_body_session_validates_and_computes(tmp_path, capsys):
    pos = write_motive(tmp_path / "take.csv")
    assert detect_format(tmp_path / "take.csv") == "motive"
    rec = read_export("motive", tmp_path / "take.csv")
    assert rec.body_labels == ["Handle"] and rec.point_labels == ["Unlabeled 1000"] and rec.point_units == "m"
    m = workspace_map("motive", lab_to_world={"position": [0, 0, 0], "quaternion": Y_UP_TO_Z_UP}, markers={"include": []})
    session = run_pipeline(tmp_path, capsys, "motive", tmp_path / "take.csv", m)
    assert_handle(session, 1.0, np.round(pos, 6))


def test_motive_markers_and_euler_export_refused(tmp_path):
    write_motive(tmp_path / "take.csv", frames=20)
    m = {
        "source": "motive",
        **json.loads(json.dumps(FACTS)),
        "trial": {"powered": False, "id": "mk"},
        "markers": {"rename": {"Unlabeled 1000": "u1"}},
    }
    import_export("motive", tmp_path / "take.csv", tmp_path / "s", None, overrides=m)
    mk = open_session(tmp_path / "s").read("mk", "markers")
    np.testing.assert_allclose(mk["u1_y"].to_numpy(), 0.2 + 0.001 * np.arange(20), atol=1e-12)
    write_motive(tmp_path / "euler.csv", frames=3, rotation_type="XYZ")
    with pytest.raises(HaptifyError) as err:
        read_export("motive", tmp_path / "euler.csv")
    assert err.value.code == "E501" and err.value.findings[0].expected == "Quaternion"


# --- Vicon Nexus CSV -----------------------------------------------------------------------------


def write_nexus(path: Path, frames: int = N) -> tuple[np.ndarray, np.ndarray]:
    """A Nexus CSV: Devices (a 1 kHz trigger, 10 samples a frame), Segments ('Rig:Handle', RX RY RZ a
    rotation vector in deg, TX TY TZ mm), Trajectories ('Rig:h1') and a Model Output in mm and one in deg."""
    pos = sweep(frames)
    ratio = 10
    lines = ["Devices", "1000", ",,Trigger - Voltage", "Frame,Sub Frame,Pin", ",,V"]
    trigger = np.where(np.arange(frames * ratio) >= frames * ratio // 2, 5.0, 0.0)
    for k in range(frames * ratio):
        lines.append(f"{k // ratio + 1},{k % ratio},{trigger[k]:.1f}")
    lines += ["", "Segments", f"{RATE:g}", ",,Rig:Handle,,,,,", "Frame,Sub Frame,RX,RY,RZ,TX,TY,TZ", ",,deg,deg,deg,mm,mm,mm"]
    for k in range(frames):
        row = [0.0, 0.0, math.degrees(ANGLES[k]), *pos[k]]
        if OCCLUDED.start <= k < OCCLUDED.stop:
            row = [math.nan] * 6
        lines.append(",".join([str(k + 1), "0", *fmt_row(row)]))
    lines += [
        "",
        "Model Outputs",
        f"{RATE:g}",
        ",,Rig:HJC,,,Rig:Angle,,",
        "Frame,Sub Frame,X,Y,Z,X,Y,Z",
        ",,mm,mm,mm,deg,deg,deg",
    ]
    for k in range(frames):
        lines.append(f"{k + 1},0,{5.0 + k:.3f},6.000,7.000,1.000,2.000,3.000")
    lines += ["", "Trajectories", f"{RATE:g}", ",,Rig:h1,,", "Frame,Sub Frame,X,Y,Z", ",,mm,mm,mm"]
    for k in range(frames):
        lines.append(f"{k + 1},0,{1.0 * k:.3f},,{3.0:.3f}" if k == 3 else f"{k + 1},0,{1.0 * k:.3f},2.000,3.000")
    path.write_text("\n".join(lines) + "\n")
    return pos, trigger


def test_nexus_csv_segments_session_validates_and_computes(tmp_path, capsys):
    pos, trigger = write_nexus(tmp_path / "trial.csv")
    assert detect_format(tmp_path / "trial.csv") == "nexus"
    rec = read_export("nexus", tmp_path / "trial.csv")
    assert rec.point_labels == ["Rig:h1", "Rig:HJC"]  # trajectories, then model outputs; the angle is no point
    assert rec.body_labels == ["Rig:Handle"] and rec.analog_labels == ["Trigger - Voltage - Pin"]
    assert (rec.analog_rate, rec.analog_first_sample, rec.point_first_frame) == (1000.0, 0, 0)
    m = workspace_map(
        "nexus",
        bodies={"handle": "Rig:Handle"},
        streams={"sync": {"columns": {"trigger": {"source": "Trigger - Voltage - Pin", "threshold": 2.5}}}},
    )
    m["trial"]["protocol"] = "workspace"
    session = run_pipeline(tmp_path, capsys, "nexus", tmp_path / "trial.csv", m, cli_format="")
    assert_handle(session, 1e-3, np.round(pos, 6))
    s = open_session(session)
    sync = s.read("ws", "sync")
    np.testing.assert_array_equal(sync["trigger"].to_numpy(), (trigger >= 2.5) * 1.0)
    np.testing.assert_allclose(sync["t"].to_numpy(), np.arange(N * 10) / 1000.0, atol=1e-12)
    mk = s.read("ws", "markers")
    assert np.isnan(mk["Rig.h1_y"][3]) and mk["Rig.HJC_x"][2] == pytest.approx(0.007)
    np.testing.assert_allclose(mk["t"].to_numpy(), np.arange(N) / RATE, atol=1e-12)


def test_nexus_bad_file_and_unknown_body(tmp_path):
    assert "Trajectories" in unreadable("nexus", tmp_path / "x.csv", "Something else\n1\n")
    write_nexus(tmp_path / "t.csv", frames=10)
    with pytest.raises(HaptifyError) as err:
        import_export("nexus", tmp_path / "t.csv", tmp_path / "s", None, overrides=workspace_map("nexus"))
    assert err.value.code == "E503" and err.value.findings[0].expected == ["Rig:Handle"]
    assert not (tmp_path / "s").exists()


def test_auto_refuses_an_unknown_format(tmp_path, capsys):
    (tmp_path / "x.txt").write_text("hello\n")
    assert main(["import", "auto", str(tmp_path / "x.txt"), "--list"]) == 2
    assert "E501" in capsys.readouterr().err
    assert main(["--json", "import", str(tmp_path / "x.txt"), "--list"]) == 2  # no format word: the same
    assert "E501" in capsys.readouterr().out


def test_without_a_format_word_each_format_is_recognised(tmp_path, capsys):
    from haptify_tools.c3d_variants import C3DSpec, write_c3d

    write_qtm_6d(tmp_path / "a.tsv")
    write_nexus(tmp_path / "b.csv", frames=10)
    write_c3d(tmp_path / "c.c3d", C3DSpec(labels=["m"], points=np.ones((5, 1, 3))))
    for name, fmt in (("a.tsv", "tsv"), ("b.csv", "nexus"), ("c.c3d", "c3d")):
        assert main(["import", str(tmp_path / name), "--list", "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["format"] == fmt
