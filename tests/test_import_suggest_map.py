"""``--suggest-map`` (spec §5.11): a map guessed from labels, bodies, platforms and headers, with
placeholders for the facts no source holds, and the notes on what it could not place; filled in, the
suggested map imports."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from haptify.cli.main import main
from haptify.formats.importers import import_c3d, import_csv
from haptify.formats.storage import open_session
from haptify.formats.suggest_map import guess_streams
from haptify_tools.c3d_variants import C3DSpec, Platform, float32, rectangle_corners, write_c3d
from haptify_tools.example_session import TOUCH_DEVICE

REPO = Path(__file__).resolve().parents[1]
FILLED = {
    "date": "2026-11-22",
    "lab": {"id": "lab-t"},
    "examiner": {"id": "ex-t"},
    "device": TOUCH_DEVICE,
    "device_placement": {"position": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]},
}


def suggest(argv, capsys) -> tuple[dict, list[str]]:
    assert main(["--json", "import", *argv, "--suggest-map"]) == 0
    out = json.loads(capsys.readouterr().out)
    return out["map"], out["unplaced"]


def test_rules_place_known_names_and_leave_the_rest():
    streams, left = guess_streams(["Sync", "AccX", "acc_y", "ACCEL Z", "C2 Fz", "corner3_My", "Fx (N)", "EMG1"])
    assert streams["sync"] == {"trigger": "Sync"}
    assert streams["handle_accel"] == {"ax": "AccX", "ay": "acc_y", "az": "ACCEL Z"}
    assert streams["plate_wrench"] == {"c2_fz": "C2 Fz", "c3_ty": "corner3_My"}
    assert streams["handle_wrench"] == {"fx": "Fx (N)"}
    assert left == ["EMG1"]


def test_c3d_suggestion_places_bodies_platform_and_channels_and_imports_once_filled(tmp_path, capsys):
    n = 20
    rot = np.tile(np.eye(4), (n, 2, 1, 1))
    spec = C3DSpec(
        point_rate=100.0,
        labels=["h1"],
        points=float32(np.ones((n, 1, 3))),
        analog_rate=1000.0,
        analog_labels=["Trigger", "ACC_X", "ACC_Y", "ACC_Z", "EMG", *[f"P{i}" for i in range(6)]],
        analog_units=["V", "g", "g", "g", "V", *["N"] * 6],
        analogs=float32(np.zeros((11, 10 * n))),
        rotation_labels=["Stylus", "Link 2"],
        rotations=rot,
        platforms=[Platform(2, rectangle_corners([0, 0, 0], 600.0, 400.0), np.array([0, 0, -40.0]), list(range(6, 12)))],
    )
    path = write_c3d(tmp_path / "f.c3d", spec)
    m, unplaced = suggest(["c3d", str(path)], capsys)
    assert m["bodies"] == {"handle": "Stylus", "links": {"link2": "Link 2"}}
    assert m["force_plate"] == 1 and m["markers"] == {"include": ["h1"]}
    assert m["streams"]["sync"]["columns"]["trigger"] == {"source": "Trigger", "threshold": 2.5}
    assert m["streams"]["handle_accel"]["columns"] == {"ax": "ACC_X", "ay": "ACC_Y", "az": "ACC_Z"}
    assert m["session"]["lab"] == {"id": "<lab id>"} and m["trial"]["powered"] == "<true or false>"
    assert any("'EMG'" in u for u in unplaced) and any("force platform 1" in u for u in unplaced)
    assert any("link2" in u and "rigid_bodies" in u for u in unplaced)
    # the lab fills in its facts and the link's rigid body: the map imports
    m["session"] = FILLED
    m["trial"]["powered"] = False
    m["markers"]["rigid_bodies"] = [{"name": "link2", "markers": ["h1"]}]
    (tmp_path / "m.json").write_text(json.dumps(m))
    result = import_c3d(path, tmp_path / "s", tmp_path / "m.json")
    kinds = {s["kind"] for s in result.streams}
    assert kinds == {"markers", "handle_pose", "link_poses", "sync", "handle_accel"}


def test_csv_suggestion_finds_preamble_time_and_stated_units(tmp_path, capsys):
    m, unplaced = suggest(["csv", str(REPO / "fixtures" / "import" / "ati-log.csv")], capsys)
    assert m["csv"] == {"delimiter": ",", "skip_rows": 2} and m["time"] == {"source": "Time (ms)", "unit": "ms"}
    cols = m["streams"]["handle_wrench"]["columns"]
    assert cols["fx"] == {"source": "Fx (N)", "unit": "N"} and cols["tz"] == {"source": "Tz (N-mm)", "unit": "N-mm"}
    assert unplaced == []
    m["session"] = FILLED
    m["trial"]["powered"] = False
    (tmp_path / "m.json").write_text(json.dumps(m))
    result = import_csv(REPO / "fixtures" / "import" / "ati-log.csv", tmp_path / "s", tmp_path / "m.json")
    assert result.streams[0]["rows"] == 20
    assert open_session(tmp_path / "s").trials[0].streams[0].kind == "handle_wrench"


def test_an_unedited_suggestion_is_refused_naming_the_placeholders(tmp_path, capsys):
    m, _ = suggest(["csv", str(REPO / "fixtures" / "import" / "ati-log.csv")], capsys)
    (tmp_path / "m.json").write_text(json.dumps(m))
    code = main(
        [
            "import",
            "csv",
            str(REPO / "fixtures" / "import" / "ati-log.csv"),
            "-o",
            str(tmp_path / "s"),
            "--map",
            str(tmp_path / "m.json"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "E502" in err and "/session/date" in err and not (tmp_path / "s").exists()


def test_a_platform_whose_channel_units_are_stated_is_suggested_as_plate_wrench(tmp_path, capsys):
    from haptify_tools.c3d_variants import PLATFORM_UNITS

    spec = C3DSpec(
        point_rate=0.0,
        frames=5,
        analog_rate=1000.0,
        analog_labels=[f"F{i}" for i in range(6)],
        analog_units=PLATFORM_UNITS[2],
        analogs=float32(np.ones((6, 50))),
        platforms=[Platform(2, rectangle_corners([0, 0, 0], 600.0, 400.0), np.array([0, 0, -40.0]), list(range(1, 7)))],
    )
    path = write_c3d(tmp_path / "p.c3d", spec)
    m, unplaced = suggest(["c3d", str(path)], capsys)
    assert m["force_plate"] == 1 and m["platform_wrench"] == {}
    assert any("become plate_wrench" in u for u in unplaced)
    m["session"] = FILLED
    m["trial"]["powered"] = False
    (tmp_path / "m.json").write_text(json.dumps(m))
    result = import_c3d(path, tmp_path / "s", tmp_path / "m.json")
    assert [s["kind"] for s in result.streams] == ["plate_wrench"]
