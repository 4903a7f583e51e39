"""Importers (spec chapter 5): real C3D files, a synthetic C3D and CSV logs with known values, units,
the import command, and every bad input's code (with nothing written)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haptify.cli import cmd_import
from haptify.cli import main as cli
from haptify.errors import HaptifyError
from haptify.formats.conventions import STANDARD_GRAVITY
from haptify.formats.importers import ImportMap, import_c3d, import_csv, read_c3d, sanitize_id
from haptify.formats.storage import open_session
from haptify.formats.validation import validate_session
from haptify_tools.example_session import TOUCH_DEVICE, example_rig

REPO = Path(__file__).resolve().parents[1]
C3D_DIR = REPO.parent / "shared" / "data" / "c3d"
FIX = REPO / "fixtures" / "import"
VICON, QUALISYS = C3D_DIR / "Vicon.c3d", C3D_DIR / "Qualisys.c3d"
needs_c3d = pytest.mark.skipif(
    not (VICON.is_file() and QUALISYS.is_file()),
    reason=f"the real C3D recordings (GPL-3.0) are read from {C3D_DIR}, which is absent",
)

DATE = {"session": {"date": "2026-11-22"}}
FACTS = {
    "session": {
        "date": "2026-11-22",
        "lab": {"id": "lab-t"},
        "examiner": {"id": "ex-t"},
        "device": TOUCH_DEVICE,
        "device_placement": {"position": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]},
    },
    "trial": {"powered": False},
}


def assert_valid(path: Path) -> None:
    """The session validates (no error findings) and every stream reads back with its declared rows."""
    report = validate_session(path)
    assert report.valid, [str(f) for f in report.errors]
    session = open_session(path)
    for trial in session.trials:
        for s in trial.streams:
            assert len(session.read_stream(s, verify=True)) == s.rows


def raw(path: Path):
    import ezc3d

    return ezc3d.c3d(str(path), extract_forceplat_data=False)


def write_map(tmp: Path, name: str, payload: dict) -> Path:
    p = tmp / name
    p.write_text(json.dumps(payload), encoding="utf-8")
    return p


def listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    """The haptify command with the import plugin registered (as the entry point does)."""
    parser = argparse.ArgumentParser(prog="haptify")
    parser.add_argument("--version", action="store_true")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--quiet", "-q", action="store_true")
    cmd_import.register(parser.add_subparsers(dest="command"))
    original = cli.build_parser
    cli.build_parser = lambda command=None: parser
    try:
        code = cli.main(argv)
    finally:
        cli.build_parser = original
    out = capsys.readouterr()
    return code, out.out, out.err


# --- real recordings ---------------------------------------------------------------------------


@needs_c3d
def test_vicon_without_map_imports_every_marker_in_metres(tmp_path, capsys):
    device = write_map(tmp_path, "device.json", TOUCH_DEVICE)
    code, out, err = run_cli(
        [
            "--json",
            "import",
            "c3d",
            str(VICON),
            "-o",
            str(tmp_path / "s"),
            "--device",
            str(device),
            "--lab",
            "lab-t",
            "--examiner",
            "ex-t",
            "--date",
            "2026-11-22",
            "--placement",
            "0,0,0.1",
            "--powered",
            "no",
        ],
        capsys,
    )
    assert code == 0, err
    report = json.loads(out)
    assert report["validation"]["valid"] and report["session_id"] == "Vicon"
    assert report["source"]["markers"]["count"] == 51 and report["source"]["markers"]["rate_hz"] == 100.0
    assert report["source"]["analog"]["count"] == 38 and report["source"]["analog"]["rate_hz"] == 2000.0
    assert report["source"]["force_platforms"] == []
    assert_valid(tmp_path / "s")
    session = open_session(tmp_path / "s")
    [trial] = session.trials
    assert (trial.protocol, trial.label, trial.powered) == ("other", "Vicon", False)
    assert session.device().model == "Touch" and session.manifest.device_placement.position == [0.0, 0.0, 0.1]
    stream = session.stream(trial.id, "markers")
    c = raw(VICON)
    labels = c["parameters"]["POINT"]["LABELS"]["value"]
    assert stream.entities == [lab.replace(":", ".") for lab in labels]
    assert stream.rate_hz == 100.0 and stream.rows == 580
    table = session.read(trial.id, "markers")
    np.testing.assert_array_equal(table["t"].to_numpy(), np.arange(580) / 100.0)
    pts, res = c["data"]["points"], c["data"]["meta_points"]["residuals"][0]
    for j in (0, 8, 50):  # W is the lab frame without a platform: values are exactly raw mm / 1000
        ent = stream.entities[j]
        for k, axis in enumerate("xyz"):
            expect = np.where(res[j] < 0, np.nan, pts[k, j] / 1000.0)
            np.testing.assert_array_equal(table[f"{ent}_{axis}"].to_numpy(), expect)
    occluded = np.isnan(table[[f"{e}_x" for e in stream.entities]].to_numpy())
    assert occluded.sum() == (res < 0).sum() > 0


@needs_c3d
def test_qualisys_map_plate_defines_world_and_sync_is_2khz(tmp_path):
    result = import_c3d(QUALISYS, tmp_path / "q", FIX / "qualisys-map.json", overrides=DATE)
    assert result.source["markers"]["count"] == 55 and result.source["markers"]["rate_hz"] == 200.0
    assert result.source["analog"]["rate_hz"] == 2000.0
    assert [(p["number"], p["type"]) for p in result.source["force_platforms"]] == [(1, 2), (2, 2)]
    assert_valid(tmp_path / "q")
    session = open_session(tmp_path / "q")
    plate = session.manifest.rig.force_plate
    # platform 1: corners (508,464), (508,0), (0,0), (0,464) mm; its x axis is the lab's +y, its z points down
    assert plate.size_m == pytest.approx([0.464, 0.508], abs=1e-7)  # the file stores float32 corners
    for corner in plate.corners:
        sx, sy = {"c1": (1, 1), "c2": (-1, 1), "c3": (-1, -1), "c4": (1, -1)}[corner.id]
        assert corner.pose.position == pytest.approx([sx * 0.232, sy * 0.254, -0.034036], abs=1e-6)
        assert corner.pose.quaternion == pytest.approx([0.0, 1.0, 0.0, 0.0], abs=1e-12)
    c = raw(QUALISYS)
    table = session.read("qualisys-gait", "markers")
    np.testing.assert_allclose(table["t"].to_numpy(), (704 + np.arange(340)) / 200.0, rtol=0, atol=1e-12)
    pts = c["data"]["points"] / 1000.0
    centre = c["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"][:, :, 0].mean(axis=1) / 1000.0  # ≈ (0.254, 0.232, 0)
    for j, ent in enumerate(session.stream("qualisys-gait", "markers").entities[:5]):
        np.testing.assert_allclose(table[f"{ent}_x"], pts[1, j] - centre[1], atol=1e-12)
        np.testing.assert_allclose(table[f"{ent}_y"], -(pts[0, j] - centre[0]), atol=1e-12)
        np.testing.assert_allclose(table[f"{ent}_z"], pts[2, j], atol=1e-12)
    sync = session.read("qualisys-gait", "sync")
    assert len(sync) == 3400 and session.stream("qualisys-gait", "sync").rate_hz == 2000.0
    np.testing.assert_allclose(sync["t"].to_numpy(), (7040 + np.arange(3400)) / 2000.0, rtol=0, atol=1e-12)
    sync_raw = c["data"]["analogs"][0, c["parameters"]["ANALOG"]["LABELS"]["value"].index("Sync")]
    np.testing.assert_array_equal(sync["trigger"].to_numpy(), (sync_raw >= 2.5).astype(float))


@needs_c3d
def test_qualisys_second_platform_and_real_newton_millimetre_channels(tmp_path):
    # The AMTI channels of platform 2 (N and Nmm in the file) stand in for a commanded wrench here: this
    # throwaway session only checks that the file's own units convert exactly.
    labels = read_c3d(QUALISYS).analog_labels
    amti = [lab for lab in labels if lab.startswith("Amti Gen 5 OR6-5-1000 3582")]
    cols = dict(zip(["fx", "fy", "fz", "tx", "ty", "tz"], amti))
    overrides = {
        **FACTS,
        "trial": {"powered": False, "id": "amti"},
        "force_plate": 2,
        "markers": {"include": ["L_*"], "exclude": ["L_WAND*"], "rename": {"L_IAS": "pelvis_left"}},
        "streams": {"commanded_wrench": {"columns": cols}},
    }
    import_c3d(QUALISYS, tmp_path / "q2", None, overrides={"source": "c3d", **overrides})
    assert_valid(tmp_path / "q2")
    session = open_session(tmp_path / "q2")
    ents = session.stream("amti", "markers").entities
    assert ents[0] == "pelvis_left" and all(e.startswith("L_") and "WAND" not in e for e in ents[1:])
    assert session.manifest.rig.motion_capture.markers == ents
    corners = {c.id: c.pose.position for c in session.manifest.rig.force_plate.corners}
    assert corners["c1"] == pytest.approx([0.232, 0.254, -0.036322], abs=1e-6)
    c = raw(QUALISYS)
    an = c["data"]["analogs"][0]
    idx = [labels.index(lab) for lab in amti]
    table = session.read("amti", "commanded_wrench")
    for k, col in enumerate(["fx", "fy", "fz"]):
        np.testing.assert_array_equal(table[col].to_numpy(), an[idx[k]])
    for k, col in enumerate(["tx", "ty", "tz"]):
        np.testing.assert_array_equal(table[col].to_numpy(), an[idx[3 + k]] / 1000.0)


@needs_c3d
def test_vicon_map_and_cli_overrides(tmp_path, capsys):
    code, out, err = run_cli(
        [
            "import",
            "c3d",
            str(VICON),
            "-o",
            str(tmp_path / "v"),
            "--map",
            str(FIX / "vicon-map.json"),
            "--date",
            "2026-11-22",
            "--trial-id",
            "box-2",
            "--repetition",
            "2",
        ],
        capsys,
    )
    assert code == 0, err
    assert "markers" in out and "580 rows" in out and "the session validates" in out
    assert_valid(tmp_path / "v")
    session = open_session(tmp_path / "v")
    assert session.session_id == "vicon-demo" and session.manifest.date == "2026-11-22"
    [trial] = session.trials
    assert (trial.id, trial.repetition) == ("box-2", 2)
    assert session.manifest.rig.motion_capture.system == "Vicon Nexus 2.4"
    assert (tmp_path / "v" / "device.json").read_text() == (FIX / "touch-device.json").read_text()
    inline = {**json.loads((FIX / "vicon-map.json").read_text()), "session": {**FACTS["session"]}}
    minimal = write_map(
        tmp_path,
        "minimal-device.json",
        {"manufacturer": "Force Dimension", "model": "omega.3", "dof": 3, "mechanism": "parallel"},
    )
    code, out, err = run_cli(
        [
            "import",
            "c3d",
            str(VICON),
            "-o",
            str(tmp_path / "w"),
            "--map",
            str(write_map(tmp_path, "inline.json", inline)),
            "--device",
            str(minimal),
        ],
        capsys,
    )
    assert code == 0, err  # --device replaces the map's inline device as a whole
    assert open_session(tmp_path / "w").device().model == "omega.3"


# --- a synthetic C3D with known values -----------------------------------------------------------


def synthetic_c3d(path: Path) -> dict:
    """A C3D whose every value is known: 3 markers (mm, one occluded), 24 plate channels (N, Nmm),
    an accelerometer in g, a trigger in V, and one type-2 platform centred at lab (1000, 500, 0) mm
    with its x axis along lab +x and its y axis along lab −y (so its z points down)."""
    import ezc3d

    n, ratio = 20, 10
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("rig:h1", "h2", "*3")
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, 3, n))
    frames = np.arange(n, dtype=float)
    pts[0] = 1000.0 + np.array([[10.0], [20.0], [30.0]]) * frames
    pts[1] = 500.0 - np.array([[1.0], [2.0], [3.0]]) * frames
    pts[2] = np.array([[100.0], [200.0], [300.0]]) + frames
    pts[:3, 1, 5:8] = np.nan
    c["data"]["points"] = pts
    labels, units, values = [], [], []
    k = np.arange(n * ratio, dtype=float)
    for corner in range(1, 5):
        for axis, unit in (("FX", "N"), ("FY", "N"), ("FZ", "N"), ("MX", "Nmm"), ("MY", "Nmm"), ("MZ", "Nmm")):
            labels.append(f"C{corner}{axis}")
            units.append(unit)
            values.append(corner * 100.0 + len(values) + 0.5 * k)
    for axis, base in (("X", 0.0), ("Y", 0.0), ("Z", 1.0)):
        labels.append(f"ACC{axis}")
        units.append("g")
        values.append(base + 0.01 * np.sin(k))
    labels.append("TRIG")
    units.append("V")
    values.append(np.where(k >= 100, 5.0, 0.0))
    c["parameters"]["ANALOG"]["RATE"]["value"] = [1000]
    c["parameters"]["ANALOG"]["LABELS"]["value"] = tuple(labels)
    c["parameters"]["ANALOG"]["UNITS"]["value"] = units
    values = np.array(values).astype(np.float32).astype(np.float64)  # C3D stores float32: keep values exact
    c["data"]["analogs"] = values[None]
    c.add_parameter("FORCE_PLATFORM", "USED", [1])
    c.add_parameter("FORCE_PLATFORM", "TYPE", [2])
    corners = np.array([[1300, 300, 0], [700, 300, 0], [700, 700, 0], [1300, 700, 0]], float).T.reshape(3, 4, 1)
    c.add_parameter("FORCE_PLATFORM", "CORNERS", corners)
    c.add_parameter("FORCE_PLATFORM", "ORIGIN", np.array([[0.0], [0.0], [40.0]]))
    c.write(str(path))
    return {"labels": labels, "values": values, "points": pts}


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    path = tmp_path_factory.mktemp("c3d") / "synthetic.c3d"
    return path, synthetic_c3d(path)


def full_map(labels: list[str]) -> dict:
    plate = {
        f"c{i}_{ax}": f"C{i}{src}"
        for i in range(1, 5)
        for ax, src in (("fx", "FX"), ("fy", "FY"), ("fz", "FZ"), ("tx", "MX"), ("ty", "MY"), ("tz", "MZ"))
    }
    return {
        "source": "c3d",
        **FACTS,
        "session": {**FACTS["session"], "rig": {"handle": example_rig()["handle"]}},
        "trial": {"id": "syn", "protocol": "free_space", "powered": False},
        "markers": {"rename": {"*3": "h3"}, "rigid_bodies": [{"name": "handle", "markers": ["rig.h1", "h2", "h3"]}]},
        "streams": {
            "plate_wrench": {"columns": plate},
            "handle_accel": {"columns": {"ax": "ACCX", "ay": "ACCY", "az": "ACCZ"}},
            "handle_wrench": {
                "columns": {
                    c: {"value": 0.0, "unit": u}
                    for c, u in (("fx", "N"), ("fy", "N"), ("fz", "N"), ("tx", "N*m"), ("ty", "N*m"), ("tz", "N*m"))
                }
            },
            "sync": {"columns": {"trigger": {"source": "TRIG", "threshold": 2.5}}},
        },
    }


def test_synthetic_c3d_every_value_known(tmp_path, synthetic):
    path, truth = synthetic
    m = full_map(truth["labels"])
    m["streams"].pop("handle_wrench")
    m["trial"]["protocol"] = "other"
    import_c3d(path, tmp_path / "s", write_map(tmp_path, "m.json", m))
    assert_valid(tmp_path / "s")
    session = open_session(tmp_path / "s")
    rig = session.manifest.rig
    assert rig.force_plate.size_m == pytest.approx([0.6, 0.4])
    corners = {c.id: c.pose for c in rig.force_plate.corners}
    assert corners["c1"].position == pytest.approx([0.3, 0.2, -0.04])
    assert corners["c4"].position == pytest.approx([0.3, -0.2, -0.04])  # C3D corner 1 (plate +x, +y) is W's +x, −y
    assert corners["c1"].quaternion == pytest.approx([0.0, 1.0, 0.0, 0.0])
    assert [b.name for b in rig.motion_capture.rigid_bodies] == ["handle"]
    mk = session.read("syn", "markers")
    assert session.stream("syn", "markers").entities == ["rig.h1", "h2", "h3"]
    pts = truth["points"]
    for j, ent in enumerate(["rig.h1", "h2", "h3"]):  # W = lab shifted by the platform centre (1, 0.5, 0) m
        np.testing.assert_allclose(mk[f"{ent}_x"], pts[0, j] / 1000.0 - 1.0, atol=1e-12)
        np.testing.assert_allclose(mk[f"{ent}_y"], pts[1, j] / 1000.0 - 0.5, atol=1e-12)
        np.testing.assert_allclose(mk[f"{ent}_z"], pts[2, j] / 1000.0, atol=1e-12)
    assert np.isnan(mk["h2_x"].to_numpy()[5:8]).all() and not np.isnan(mk["h2_x"].to_numpy()[:5]).any()
    pw = session.read("syn", "plate_wrench")
    vals = truth["values"]
    np.testing.assert_array_equal(pw["c2_fz"].to_numpy(), vals[truth["labels"].index("C2FZ")])
    np.testing.assert_array_equal(pw["c3_ty"].to_numpy(), vals[truth["labels"].index("C3MY")] / 1000.0)
    acc = session.read("syn", "handle_accel")
    np.testing.assert_array_equal(acc["az"].to_numpy(), vals[truth["labels"].index("ACCZ")] * STANDARD_GRAVITY)
    np.testing.assert_array_equal(acc["t"].to_numpy(), np.arange(200) / 1000.0)
    trig = session.read("syn", "sync")["trigger"].to_numpy()
    np.testing.assert_array_equal(trig, (np.arange(200) >= 100).astype(float))


def test_synthetic_c3d_free_space_trial_validates(tmp_path, synthetic):
    path, truth = synthetic
    m = full_map(truth["labels"])  # free_space needs handle_wrench, handle_accel, handle_pose
    with pytest.raises(HaptifyError) as err:
        import_c3d(path, tmp_path / "s", write_map(tmp_path, "m.json", m))
    assert err.value.code == "E502" and "handle_pose" in str(err.value)
    assert not (tmp_path / "s").exists()


def test_a_sync_trigger_in_volts_without_threshold_is_refused_before_writing(tmp_path, synthetic):
    """The trigger column holds 0 or 1 (spec §2.6, E214); a raw 0–5 V channel needs the map's ``threshold``."""
    path, truth = synthetic
    m = full_map(truth["labels"])
    m["trial"]["protocol"] = "other"
    for kind in ("handle_wrench", "handle_accel", "plate_wrench"):
        m["streams"].pop(kind)
    m["streams"]["sync"]["columns"]["trigger"] = {"source": "TRIG", "unit": "1"}
    with pytest.raises(HaptifyError) as err:
        import_c3d(path, tmp_path / "s", write_map(tmp_path, "m.json", m))
    f = err.value.findings[0]
    assert f.code == "E214" and f.column == "TRIG" and f.expected == [0.0, 1.0] and f.found not in (0.0, 1.0)
    assert not (tmp_path / "s").exists()


# --- CSV logs --------------------------------------------------------------------------------


def test_ati_fixture_converts_newton_millimetres_exactly(tmp_path):
    result = import_csv(FIX / "ati-log.csv", tmp_path / "a", FIX / "ati-map.json")
    assert result.streams[0]["rows"] == 20
    assert_valid(tmp_path / "a")
    w = open_session(tmp_path / "a").read("ati-log", "handle_wrench")
    k = np.arange(20.0)
    np.testing.assert_array_equal(w["t"].to_numpy(), k / 1000.0)
    np.testing.assert_array_equal(w["fx"].to_numpy(), 0.5 * k)
    np.testing.assert_array_equal(w["fz"].to_numpy(), 10 + 0.25 * k)
    np.testing.assert_array_equal(w["tx"].to_numpy(), (100 * k) / 1000.0)
    np.testing.assert_array_equal(w["ty"].to_numpy(), np.full(20, -37.5 / 1000.0))
    np.testing.assert_array_equal(w["tz"].to_numpy(), np.full(20, 2.5 / 1000.0))


def test_chai3d_fixture_degrees_offset_and_constant_torques(tmp_path):
    import_csv(FIX / "chai3d-log.csv", tmp_path / "c", FIX / "chai3d-map.json")
    assert_valid(tmp_path / "c")
    session = open_session(tmp_path / "c")
    [trial] = session.trials
    assert trial.rendering.stiffness_N_per_m == 750.0 and trial.powered
    k = np.arange(20.0)
    cw = session.read("chai3d-plane", "commanded_wrench")
    np.testing.assert_array_equal(cw["t"].to_numpy(), k / 1000.0 + 12.5)
    np.testing.assert_array_equal(cw["fz"].to_numpy(), 0.75 * k)
    assert (cw[["tx", "ty", "tz"]].to_numpy() == 0).all()
    q = session.read("chai3d-plane", "device_joint_angles")
    np.testing.assert_array_equal(q["q3"].to_numpy(), (-30 - k) * (math.pi / 180.0))
    assert session.stream("chai3d-plane", "commanded_wrench").rate_hz == 1000.0


def test_chai3d_forces_in_the_device_frame_rotate_into_world(tmp_path):
    # device frame D turned +90° about z in W: D's x axis is W's y axis, so a logged (0, 0, 0.75 k) N stays
    # vertical and a logged force along D's x appears along W's y.
    m = json.loads((FIX / "chai3d-map.json").read_text())
    h = math.sqrt(0.5)
    m["session"]["device_placement"] = {"position": [0.0, 0.0, 0.0], "quaternion": [h, 0.0, 0.0, h]}
    m["session"]["device"] = {"file": str(FIX / "touch-device.json")}
    m["streams"]["commanded_wrench"]["columns"]["fx"] = {"source": "force_z", "unit": "N"}
    m["streams"]["commanded_wrench"]["columns"]["fz"] = {"value": 0.0, "unit": "N"}
    import_csv(FIX / "chai3d-log.csv", tmp_path / "c", write_map(tmp_path, "m.json", m))
    assert_valid(tmp_path / "c")
    cw = open_session(tmp_path / "c").read("chai3d-plane", "commanded_wrench")
    k = np.arange(20.0)
    np.testing.assert_allclose(cw["fy"].to_numpy(), 0.75 * k, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(cw[["fx", "fz"]].to_numpy(), 0.0, atol=1e-12)
    m["streams"]["device_joint_angles"]["from_frame"] = "device"
    expect_code(tmp_path, "E502", import_csv, FIX / "chai3d-log.csv", tmp_path / "d", write_map(tmp_path, "m.json", m))


def csv_map(columns: dict, kind: str = "handle_accel", time_unit: str = "s", **extra) -> dict:
    return {
        "source": "csv",
        **FACTS,
        "trial": {"id": "t1", "powered": False},
        "time": {"source": "time", "unit": time_unit},
        "streams": {kind: {"columns": columns, "format": "csv"}},
        **extra,
    }


def write_csv(path: Path, header: list[str], rows: list[list]) -> Path:
    path.write_text("\n".join([",".join(header)] + [",".join(map(repr, r)) for r in rows]) + "\n", encoding="utf-8")
    return path


def test_csv_millimetres_g_and_pose(tmp_path):
    rows = [[0.1 * i, 1000.0 + i, -250.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.25 * i, -1.0, 1.0] for i in range(10)]
    src = write_csv(tmp_path / "log.csv", ["time", "px", "py", "pz", "qw", "qx", "qy", "qz", "ax", "ay", "az"], rows)
    m = csv_map({"ax": {"source": "ax", "unit": "g"}, "ay": {"source": "ay", "unit": "g"}, "az": {"source": "az", "unit": "g"}})
    m["streams"]["handle_pose"] = {
        "columns": {
            **{c: {"source": c, "unit": "mm"} for c in ("px", "py", "pz")},
            **{c: {"source": c, "unit": "1"} for c in ("qw", "qx", "qy", "qz")},
        }
    }
    import_csv(src, tmp_path / "s", write_map(tmp_path, "m.json", m))
    assert_valid(tmp_path / "s")
    s = open_session(tmp_path / "s")
    assert s.stream("t1", "handle_accel").rate_hz == 10.0  # 1 / median(Δt), 6 significant digits
    pose = s.read("t1", "handle_pose")
    np.testing.assert_array_equal(pose["px"].to_numpy(), (1000.0 + np.arange(10)) / 1000.0)
    np.testing.assert_array_equal(pose["py"].to_numpy(), np.full(10, -0.25))
    acc = s.read("t1", "handle_accel")
    np.testing.assert_array_equal(acc["ax"].to_numpy(), 0.25 * np.arange(10) * STANDARD_GRAVITY)
    np.testing.assert_array_equal(acc["ay"].to_numpy(), np.full(10, -STANDARD_GRAVITY))


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(st.tuples(finite, finite, finite), min_size=2, max_size=12),
    st.sampled_from([("N", 1.0, 1.0), ("kN", 1000.0, 1.0), ("lbf", 4.4482216152605, 1.0)]),
    st.sampled_from([("N*m", 1.0, 1.0), ("N-mm", 1.0, 1000.0), ("Nmm", 1.0, 1000.0), ("lbf-in", 0.1129848290276167, 1.0)]),
)
def test_csv_import_is_exact_under_unit_scaling(tmp_path_factory, values, force_unit, torque_unit):
    tmp = tmp_path_factory.mktemp("h")
    rows = [[i / 1000.0 * 1000.0, f, t, g] for i, (f, t, g) in enumerate(values)]  # time in ms: 0, 1, 2, …
    src = write_csv(tmp / "log.csv", ["time", "f", "t", "g"], rows)
    cols = {
        **{c: {"source": "f", "unit": force_unit[0]} for c in ("fx", "fy", "fz")},
        **{c: {"source": "t", "unit": torque_unit[0]} for c in ("tx", "ty", "tz")},
    }
    m = csv_map(
        cols, kind="handle_wrench", time_unit="ms", session={**FACTS["session"], "rig": {"handle": example_rig()["handle"]}}
    )
    m["streams"]["handle_accel"] = {"columns": {c: {"source": "g", "unit": "g"} for c in ("ax", "ay", "az")}}
    import_csv(src, tmp / "s", write_map(tmp, "m.json", m))
    s = open_session(tmp / "s")
    arr = np.array(values, dtype=np.float64)
    w = s.read("t1", "handle_wrench")
    np.testing.assert_array_equal(w["t"].to_numpy(), np.arange(len(values)) / 1000.0)
    np.testing.assert_array_equal(w["fy"].to_numpy(), arr[:, 0] * force_unit[1] / force_unit[2])
    np.testing.assert_array_equal(w["tz"].to_numpy(), arr[:, 1] * torque_unit[1] / torque_unit[2])
    np.testing.assert_array_equal(s.read("t1", "handle_accel")["az"].to_numpy(), arr[:, 2] * STANDARD_GRAVITY)


# --- bad input: a code, and nothing written ------------------------------------------------------


def expect_code(tmp_path: Path, code: str, fn, *args, **kw) -> HaptifyError:
    before = listing(tmp_path)
    with pytest.raises(HaptifyError) as err:
        fn(*args, **kw)
    assert err.value.code == code, str(err.value)
    assert listing(tmp_path) == before  # nothing written, no temporary folder left behind
    return err.value


def test_missing_source_and_not_a_c3d(tmp_path, synthetic):
    m = write_map(tmp_path, "m.json", {"source": "c3d", **FACTS})
    expect_code(tmp_path, "E501", import_c3d, tmp_path / "nope.c3d", tmp_path / "s", m)
    text = tmp_path / "text.c3d"
    text.write_text("not a c3d file at all\n")
    expect_code(tmp_path, "E501", import_c3d, text, tmp_path / "s", m)
    expect_code(
        tmp_path,
        "E501",
        import_csv,
        tmp_path / "nope.csv",
        tmp_path / "s",
        write_map(tmp_path, "c.json", csv_map({"ax": "a", "ay": "a", "az": "a"})),
    )


def test_bad_maps(tmp_path, synthetic):
    path = synthetic[0]
    broken = tmp_path / "broken.json"
    broken.write_text('{"source": "c3d", "session": ')
    assert "line 1" in str(expect_code(tmp_path, "E502", import_c3d, path, tmp_path / "s", broken))
    expect_code(tmp_path, "E502", import_c3d, path, tmp_path / "s", tmp_path / "absent.json")
    wrong_type = write_map(tmp_path, "w.json", {"source": "c3d", **FACTS, "trial": {"powered": "maybe"}})
    err = expect_code(tmp_path, "E502", import_c3d, path, tmp_path / "s", wrong_type)
    assert err.findings[0].pointer == "/trial/powered"
    other = write_map(tmp_path, "o.json", csv_map({"ax": "a", "ay": "a", "az": "a"}))
    expect_code(tmp_path, "E502", import_c3d, path, tmp_path / "s", other)
    no_date = write_map(tmp_path, "d.json", {"source": "c3d", **FACTS, "session": {**FACTS["session"], "date": None}})
    assert expect_code(tmp_path, "E502", import_c3d, path, tmp_path / "s", no_date).findings[0].pointer == "/session/date"


def test_unknown_labels_list_what_the_source_has(tmp_path, synthetic):
    path, truth = synthetic
    m = {"source": "c3d", **FACTS, "streams": {"sync": {"columns": {"trigger": {"source": "TRIGGER", "threshold": 1}}}}}
    err = expect_code(tmp_path, "E503", import_c3d, path, tmp_path / "s", write_map(tmp_path, "m.json", m))
    assert err.findings[0].found == "TRIGGER" and err.findings[0].expected == truth["labels"]
    m = {"source": "c3d", **FACTS, "markers": {"include": ["nose*"]}}
    err = expect_code(tmp_path, "E503", import_c3d, path, tmp_path / "s", write_map(tmp_path, "m.json", m))
    assert err.findings[0].expected == ["rig:h1", "h2", "*3"]
    m = {"source": "c3d", **FACTS, "force_plate": 3}
    expect_code(tmp_path, "E503", import_c3d, path, tmp_path / "s", write_map(tmp_path, "m.json", m))
    src = write_csv(tmp_path / "log.csv", ["time", "a"], [[0.0, 1.0], [0.1, 2.0]])
    m = csv_map({"ax": "a", "ay": "a", "az": {"source": "b", "unit": "g"}})
    err = expect_code(tmp_path, "E503", import_csv, src, tmp_path / "s", write_map(tmp_path, "c.json", m))
    assert err.findings[0].expected == ["time", "a"]


def test_units_unknown_or_of_the_wrong_dimension(tmp_path, synthetic):
    path = synthetic[0]
    volts = {"source": "c3d", **FACTS, "streams": {"handle_accel": {"columns": {"ax": "TRIG", "ay": "TRIG", "az": "TRIG"}}}}
    err = expect_code(tmp_path, "E504", import_c3d, path, tmp_path / "s", write_map(tmp_path, "m.json", volts))
    assert err.findings[0].found == "V" and "g" in err.findings[0].expected
    src = write_csv(tmp_path / "log.csv", ["time", "a"], [[0.0, 1.0], [0.1, 2.0]])
    furlongs = csv_map({c: {"source": "a", "unit": "furlong/fortnight^2"} for c in ("ax", "ay", "az")})
    expect_code(tmp_path, "E504", import_csv, src, tmp_path / "s", write_map(tmp_path, "c.json", furlongs))
    length = csv_map({c: {"source": "a", "unit": "mm"} for c in ("ax", "ay", "az")})
    expect_code(tmp_path, "E504", import_csv, src, tmp_path / "s", write_map(tmp_path, "c.json", length))
    no_unit = csv_map({c: "a" for c in ("ax", "ay", "az")})
    expect_code(tmp_path, "E502", import_csv, src, tmp_path / "s", write_map(tmp_path, "c.json", no_unit))


def test_bad_csv_rows(tmp_path):
    m = write_map(tmp_path, "c.json", csv_map({c: {"source": "a", "unit": "g"} for c in ("ax", "ay", "az")}))
    back = write_csv(tmp_path / "back.csv", ["time", "a"], [[0.0, 1.0], [0.2, 2.0], [0.1, 3.0]])
    expect_code(tmp_path, "E203", import_csv, back, tmp_path / "s", m)
    (tmp_path / "text.csv").write_text("time,a\n0.0,1.0\n0.1,heavy\n")
    assert "row 2" in str(expect_code(tmp_path, "E501", import_csv, tmp_path / "text.csv", tmp_path / "s", m))
    (tmp_path / "empty.csv").write_text("time,a\n0.0,1.0\n0.1,\n")
    assert "row 2" in str(expect_code(tmp_path, "E501", import_csv, tmp_path / "empty.csv", tmp_path / "s", m))
    (tmp_path / "nan.csv").write_text("time,a\n0.0,1.0\n0.1,NaN\n")
    expect_code(tmp_path, "E204", import_csv, tmp_path / "nan.csv", tmp_path / "s", m)


def test_output_exists_is_e901_unless_overwrite(tmp_path):
    out = tmp_path / "a"
    import_csv(FIX / "ati-log.csv", out, FIX / "ati-map.json")
    marker = out / "lab-notes.txt"
    marker.write_text("kept?")
    expect_code(tmp_path, "E901", import_csv, FIX / "ati-log.csv", out, FIX / "ati-map.json")
    import_csv(FIX / "ati-log.csv", out, FIX / "ati-map.json", overwrite=True)
    assert not marker.exists()  # --overwrite replaces the folder as a whole
    assert_valid(out)


def test_cli_without_map_names_every_missing_option(tmp_path, synthetic, capsys):
    code, out, err = run_cli(["--json", "import", "c3d", str(synthetic[0]), "-o", str(tmp_path / "s"), "--lab", "lab-t"], capsys)
    assert code == 2
    finding = json.loads(out)["findings"][0]
    assert finding["code"] == "E903"
    joined = " ".join(finding["expected"])
    for option in ("--device", "--examiner", "--date", "--placement", "--powered"):
        assert option in joined
    assert "--lab" not in joined and not (tmp_path / "s").exists()
    code, out, err = run_cli(["import", "csv", str(FIX / "ati-log.csv"), "-o", str(tmp_path / "s")], capsys)
    assert code == 2 and not (tmp_path / "s").exists()  # csv needs --map


def test_cli_list_describes_without_writing(tmp_path, synthetic, capsys):
    code, out, err = run_cli(["--json", "import", "c3d", str(synthetic[0]), "--list"], capsys)
    assert code == 0
    summary = json.loads(out)
    assert summary["markers"]["count"] == 3 and summary["analog"]["count"] == 28
    assert summary["force_platforms"][0]["type"] == 2


def test_sanitised_ids():
    assert sanitize_id("boite:gauche_ext", "m1") == "boite.gauche_ext"
    assert sanitize_id("*12", "m1") == "m_12"
    assert sanitize_id("Sensor 12.EMG12", "m1") == "Sensor_12.EMG12"
    assert sanitize_id("  ", "m7") == "m7"
    assert len(sanitize_id("x" * 100, "m1")) == 64


def test_example_maps_are_valid_import_maps_and_the_schema_agrees():
    import jsonschema

    schema = ImportMap.model_json_schema(mode="validation")
    jsonschema.Draft202012Validator.check_schema(schema)
    for name in ("vicon-map.json", "qualisys-map.json", "ati-map.json", "chai3d-map.json"):
        doc = json.loads((FIX / name).read_text())
        ImportMap.model_validate(doc)
        jsonschema.Draft202012Validator(schema).validate(doc)
    bad = json.loads((FIX / "ati-map.json").read_text())
    bad["streams"]["handle_wrench"]["colums"] = {}
    assert list(jsonschema.Draft202012Validator(schema).iter_errors(bad))


# --- appending a trial to an existing session (spec §5.9) ----------------------------------------


def unchanged(folder: Path):
    """A snapshot of a folder's files and bytes, to show a refused append changed nothing."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@needs_c3d
def test_append_a_second_recording_as_another_trial(tmp_path, capsys):
    out = tmp_path / "q"
    import_c3d(QUALISYS, out, FIX / "qualisys-map.json", overrides=DATE)
    before = unchanged(out)
    code, _, err = run_cli(
        [
            "import",
            "c3d",
            str(QUALISYS),
            "-o",
            str(out),
            "--map",
            str(FIX / "qualisys-map.json"),
            "--append",
            "--date",
            "2026-11-22",
            "--trial-id",
            "gait-2",
            "--repetition",
            "2",
        ],
        capsys,
    )
    assert code == 0, err
    assert_valid(out)
    after = unchanged(out)
    assert all(after[name] == data for name, data in before.items() if name != "session.json")
    session = open_session(out)
    assert [(t.id, t.repetition) for t in session.trials] == [("qualisys-gait", 1), ("gait-2", 2)]
    first, second = (session.read(t, "markers") for t in ("qualisys-gait", "gait-2"))
    assert first.equals(second)
    assert json.loads(before["session.json"])["rig"] == session.raw["rig"]


@needs_c3d
def test_refused_appends_change_nothing(tmp_path):
    out = tmp_path / "q"
    import_c3d(QUALISYS, out, FIX / "qualisys-map.json", overrides=DATE)
    before = unchanged(out)
    cases = [
        ("E107", QUALISYS, {**DATE}),  # the trial id exists
        ("E502", QUALISYS, {"session": {"date": "2026-11-23"}, "trial": {"id": "t2"}}),  # another sitting
        (
            "E502",
            VICON,
            {
                "session": {"date": "2026-11-22", "session_id": "qualisys-demo"},  # no platform: its
                "trial": {"id": "t3"},
            },
        ),  # markers would not be in the session's W
    ]
    for code, source, overrides in cases:
        with pytest.raises(HaptifyError) as err:
            import_c3d(
                source,
                out,
                FIX / ("vicon-map.json" if source == VICON else "qualisys-map.json"),
                overrides=overrides,
                append=True,
            )
        assert err.value.code == code, str(err.value)
        if source == VICON:
            assert "lab frame" in str(err.value)
        assert unchanged(out) == before
        assert sorted(p.name for p in tmp_path.iterdir()) == ["q"]  # no staging folder left
    with pytest.raises(HaptifyError) as err:
        import_c3d(QUALISYS, tmp_path / "absent", FIX / "qualisys-map.json", overrides=DATE, append=True)
    assert err.value.code == "E101"
    with pytest.raises(HaptifyError) as err:
        import_c3d(QUALISYS, out, FIX / "qualisys-map.json", overrides=DATE, append=True, overwrite=True)
    assert err.value.code == "E903"


def test_append_unites_marker_lists_and_adds_rig_parts(tmp_path, synthetic):
    path, truth = synthetic
    base = {"source": "c3d", **FACTS, "trial": {"id": "a", "powered": False}, "markers": {"include": ["rig:h1"]}}
    import_c3d(path, tmp_path / "s", write_map(tmp_path, "a.json", base))
    second = {
        "source": "c3d",
        "trial": {"id": "b", "powered": False},
        "markers": {"include": ["h2", "[*]3"]},
        "session": {"rig": {"handle": example_rig()["handle"]}},
    }
    import_c3d(path, tmp_path / "s", write_map(tmp_path, "b.json", second), append=True)
    assert_valid(tmp_path / "s")
    session = open_session(tmp_path / "s")
    assert session.manifest.rig.motion_capture.markers == ["rig.h1", "h2", "m_3"]
    assert session.manifest.rig.handle is not None and session.manifest.rig.force_plate is not None
    assert session.stream("b", "markers").entities == ["h2", "m_3"]
    other_rate = {
        **second,
        "trial": {"id": "c", "powered": False},
        "session": {
            "rig": {
                "handle": {
                    **example_rig()["handle"],
                    "ft_sensor": {"pose": {"position": [0.0, 0.0, -0.04], "quaternion": [1.0, 0.0, 0.0, 0.0]}},
                }
            }
        },
    }
    err = expect_code(tmp_path, "E502", import_c3d, path, tmp_path / "s", write_map(tmp_path, "c.json", other_rate), append=True)
    assert err.findings[0].pointer == "/session/rig/handle"


def test_append_csv_log_to_a_csv_session(tmp_path):
    import_csv(FIX / "chai3d-log.csv", tmp_path / "s", FIX / "chai3d-map.json")
    import_csv(
        FIX / "ati-log.csv",
        tmp_path / "s",
        FIX / "ati-map.json",
        overrides={"session": {"session_id": "chai3d-log-demo"}},
        append=True,
    )
    assert_valid(tmp_path / "s")
    session = open_session(tmp_path / "s")
    assert [t.id for t in session.trials] == ["chai3d-plane", "ati-log"]
    assert session.manifest.rig.handle is not None
