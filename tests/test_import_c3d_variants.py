"""C3D files as every system writes them (spec §5.5–5.6): analog-only files, header/data
disagreements, 25–2000 Hz, non-mm units, force platforms of types 1–4 with near-planar or meaningless
corners, and 6-DoF bodies from the ROTATION group — each built with ezc3d's writer from known values
(haptify_tools.c3d_variants) and imported, validated, and for 6-DoF bodies computed."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from haptify.cli.main import main
from haptify.errors import HaptifyError
from haptify.formats.importers import import_c3d, read_c3d
from haptify.formats.storage import open_session
from haptify.formats.validation import validate_session
from haptify_tools.c3d_variants import C3DSpec, Platform, float32, header_words, patch_header, rectangle_corners, write_c3d
from haptify_tools.example_session import TOUCH_DEVICE

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


def c3d_map(**members) -> dict:
    return {"source": "c3d", **json.loads(json.dumps(FACTS)), **members}


def valid(path: Path) -> None:
    report = validate_session(path)
    assert report.valid, [str(f) for f in report.errors]


def listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def refused(tmp_path: Path, code: str, *args, **kw) -> HaptifyError:
    before = listing(tmp_path)
    with pytest.raises(HaptifyError) as err:
        import_c3d(*args, **kw)
    assert err.value.code == code, str(err.value)
    assert listing(tmp_path) == before
    return err.value


def markers_spec(n: int = 30, rate: float = 100.0, units: str = "mm", scale: float = 1.0, **kw) -> C3DSpec:
    """Two markers on known straight lines: a_x = 10·k, b = (1, 2, 3) + k (in ``units`` × scale)."""
    k = np.arange(n, dtype=float)
    pts = np.zeros((n, 2, 3))
    pts[:, 0, 0] = 10.0 * k * scale
    pts[:, 1] = (np.array([1.0, 2.0, 3.0]) + k[:, None]) * scale
    return C3DSpec(point_rate=rate, point_units=units, labels=["a", "b"], points=float32(pts), **kw)


# --- 1. read what ezc3d reads --------------------------------------------------------------------


def analog_only(n_frames: int = 100, per_frame: int = 2, rate: float = 1000.0, **kw) -> C3DSpec:
    """No point, point rate 0: a trigger (V) and three accelerometer channels (g), known ramps."""
    n = n_frames * per_frame
    j = np.arange(n, dtype=float)
    analogs = np.vstack([np.where(j >= n // 2, 5.0, 0.0), 0.001 * j, -0.002 * j, 1.0 + 0 * j])
    return C3DSpec(
        point_rate=0.0,
        analog_rate=rate,
        analog_labels=["Sync", "AX", "AY", "AZ"],
        analog_units=["V", "g", "g", "g"],
        analogs=float32(analogs),
        frames=n_frames,
        **kw,
    )


def test_an_analog_only_file_imports_its_streams_at_analog_rate(tmp_path):
    spec = analog_only()
    path = write_c3d(tmp_path / "ao.c3d", spec)
    rec = read_c3d(path)
    assert (rec.point_rate, rec.analog_rate, rec.analogs.shape, rec.warnings) == (0.0, 1000.0, (4, 200), [])
    m = c3d_map(
        streams={
            "sync": {"columns": {"trigger": {"source": "Sync", "threshold": 2.5}}},
            "handle_accel": {"columns": {"ax": "AX", "ay": "AY", "az": "AZ"}},
        }
    )
    (tmp_path / "m.json").write_text(json.dumps(m))
    result = import_c3d(path, tmp_path / "s", tmp_path / "m.json")
    assert result.warnings == []
    valid(tmp_path / "s")
    s = open_session(tmp_path / "s")
    acc = s.read(result.trial_id, "handle_accel")
    np.testing.assert_array_equal(acc["t"].to_numpy(), np.arange(200) / 1000.0)
    np.testing.assert_array_equal(acc["ay"].to_numpy(), spec.analogs[2] * 9.80665)
    np.testing.assert_array_equal(s.read(result.trial_id, "sync")["trigger"].to_numpy(), (np.arange(200) >= 100) * 1.0)
    assert s.stream(result.trial_id, "sync").rate_hz == 1000.0


def test_an_analog_only_file_whose_header_counts_samples_imports_what_ezc3d_reads(tmp_path):
    """The vendor's header declares 2·frames + 1 'frames' (it counted analog samples): the data as
    ezc3d reads them are imported, and W501 names both counts."""
    spec = analog_only(n_frames=1984)
    path = patch_header(write_c3d(tmp_path / "vendor.c3d", spec), last_frame=3969)
    rec = read_c3d(path)
    assert rec.analogs.shape == (4, 3968)
    [w] = rec.warnings
    assert w.code == "W501" and (w.expected, w.found) == (3969, 1984) and "3969" in w.message and "1984" in w.message
    m = c3d_map(streams={"handle_accel": {"columns": {"ax": "AX", "ay": "AY", "az": "AZ"}}})
    result = import_c3d(path, tmp_path / "s", None, overrides=m)
    assert [x.code for x in result.warnings] == ["W501"]
    valid(tmp_path / "s")
    s = open_session(tmp_path / "s")
    np.testing.assert_array_equal(s.read(result.trial_id, "handle_accel")["ax"].to_numpy(), spec.analogs[1] * 9.80665)
    assert "W501" in s.trials[0].notes and "3969" in s.trials[0].notes


def test_a_truncated_file_imports_its_complete_frames_with_a_warning(tmp_path):
    spec = markers_spec(n=30)
    path = write_c3d(tmp_path / "full.c3d", spec)
    data = path.read_bytes()
    cut = tmp_path / "cut.c3d"
    frame_bytes = 2 * 4 * 4
    cut.write_bytes(data[: len(data) - 10 * frame_bytes - 3])  # ten whole frames and part of an eleventh gone
    rec = read_c3d(cut)
    held = rec.frames
    assert held < 30 and [w.code for w in rec.warnings] == ["W501"] and rec.warnings[0].found == held
    result = import_c3d(cut, tmp_path / "s", None, overrides=c3d_map())
    valid(tmp_path / "s")
    mk = open_session(tmp_path / "s").read(result.trial_id, "markers")
    assert len(mk) == held
    np.testing.assert_array_equal(mk["a_x"].to_numpy(), spec.points[:held, 0, 0] / 1000.0)


def test_a_zero_based_header_counts_like_a_one_based_one(tmp_path):
    path = patch_header(write_c3d(tmp_path / "z.c3d", markers_spec(n=29)), first_frame=0, last_frame=28)
    rec = read_c3d(path)
    assert rec.frames == 29 and rec.warnings == []


def test_header_rate_and_parameter_rate_disagree_ezc3d_followed(tmp_path):
    """ezc3d takes the rate from POINT:RATE; the header's other rate is reported."""
    path = patch_header(write_c3d(tmp_path / "r.c3d", markers_spec(n=10, rate=100.0)), rate=120.0)
    rec = read_c3d(path)
    assert rec.point_rate == 100.0 and "100 Hz is used" in rec.warnings[0].message
    [w] = rec.warnings
    assert w.code == "W501" and w.pointer == "/POINT/RATE" and (w.expected, w.found) == (120.0, 100.0)


@pytest.mark.parametrize(
    "rate,units,scale,div", [(25.0, "m", 0.001, 1.0), (2000.0, "cm", 0.1, 100.0), (120.0, "mm", 1.0, 1000.0)]
)
def test_rates_from_25_to_2000_hz_and_units_other_than_mm(tmp_path, rate, units, scale, div):
    spec = markers_spec(n=40, rate=rate, units=units, scale=scale, first_frame=7)
    path = write_c3d(tmp_path / "u.c3d", spec)
    result = import_c3d(path, tmp_path / "s", None, overrides=c3d_map())
    assert result.warnings == []
    valid(tmp_path / "s")
    s = open_session(tmp_path / "s")
    mk = s.read(result.trial_id, "markers")
    assert s.stream(result.trial_id, "markers").rate_hz == rate
    np.testing.assert_array_equal(mk["t"].to_numpy(), (7 + np.arange(40)) / rate)
    np.testing.assert_array_equal(mk["b_z"].to_numpy(), spec.points[:, 1, 2] / div)


# --- 2. force platforms as vendors write them ---------------------------------------------------

PLATE_CHANNELS = {1: 6, 2: 6, 3: 8, 4: 6}


def platform_spec(kind: int, corners: np.ndarray, origin=(0.0, 0.0, -40.0), cal: np.ndarray | None = None) -> C3DSpec:
    n_ch = PLATE_CHANNELS[kind]
    spec = markers_spec(n=10, analog_rate=1000.0)
    spec.analog_labels = [f"P{kind}_{i}" for i in range(n_ch)]
    spec.analog_units = ["V"] * n_ch
    spec.analogs = float32(np.arange(n_ch * 100, dtype=float).reshape(n_ch, 100))
    spec.platforms = [Platform(kind, corners, np.asarray(origin, float), list(range(1, n_ch + 1)), cal)]
    return spec


TWIST = np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, 1.0], [0, 0, -1.0]])


@pytest.mark.parametrize(
    "kind,cal", [(1, None), (2, None), (3, np.diag(np.arange(1.0, 9.0))), (4, np.arange(36.0).reshape(6, 6))]
)
def test_platform_types_1_to_4_define_w_and_the_plate(tmp_path, kind, cal):
    # platform x along lab +y, z down: W's x is lab +y, W's y is lab −x
    corners = rectangle_corners([500.0, 300.0, 0.0], 600.0, 400.0, x_axis=(0, 1, 0))
    path = write_c3d(tmp_path / f"t{kind}.c3d", platform_spec(kind, corners, cal=cal))
    rec = read_c3d(path)
    [p] = rec.platforms
    assert p.type == kind and p.channels == list(range(PLATE_CHANNELS[kind]))
    if cal is None:
        assert p.cal_matrix is None
    else:
        np.testing.assert_array_equal(p.cal_matrix, cal)  # row = output, as written
    result = import_c3d(path, tmp_path / "s", None, overrides=c3d_map())
    assert result.warnings == []
    valid(tmp_path / "s")
    s = open_session(tmp_path / "s")
    plate = s.manifest.rig.force_plate
    assert plate.size_m == pytest.approx([0.6, 0.4])
    assert {c.id: c.pose.position for c in plate.corners}["c1"] == pytest.approx([0.3, 0.2, -0.04])
    mk = s.read(result.trial_id, "markers")  # b = (1, 2, 3) + k mm in the lab → W: (y − 300, −(x − 500), z) mm
    k = np.arange(10)
    np.testing.assert_allclose(mk["b_x"], (2.0 + k - 300.0) / 1000.0, atol=1e-12)
    np.testing.assert_allclose(mk["b_y"], -(1.0 + k - 500.0) / 1000.0, atol=1e-12)
    assert result.source["force_platforms"][0]["channels"] == rec.analog_labels


def test_near_planar_corners_are_accepted_with_the_deviation(tmp_path):
    """A real calibration (a type-3 file): the corners twisted 1.28 mm off a plane — corners
    1 and 3 up, 2 and 4 down — so the best-fitting plane is the mean and every corner is 1.28 mm off it."""
    corners = rectangle_corners([0.0, 0.0, 0.0], 600.0, 400.0) + TWIST * 1.28
    path = write_c3d(tmp_path / "np.c3d", platform_spec(3, corners, origin=(210.0, 260.0, -45.0)))
    result = import_c3d(path, tmp_path / "s", None, overrides=c3d_map())
    [w] = result.warnings
    assert w.code == "W502" and w.pointer == "/FORCE_PLATFORM/CORNERS" and w.found == "1.28 mm"
    assert open_session(tmp_path / "s").manifest.rig.force_plate.size_m == pytest.approx([0.6, 0.4])
    valid(tmp_path / "s")
    assert "W502" in open_session(tmp_path / "s").trials[0].notes


@pytest.mark.parametrize(
    "why,edit",
    [
        ("coincide", lambda c: np.repeat(c[:1], 4, axis=0)),
        ("not in C3D order", lambda c: c[[0, 2, 1, 3]]),
        ("not finite", lambda c: np.where(np.arange(12).reshape(4, 3) == 4, np.nan, c)),
        ("from a flat rectangle", lambda c: c + TWIST * 50.0),  # 50 mm > 10 % of the 400 mm side
    ],
)
def test_meaningless_plate_geometry_is_refused_with_the_reason(tmp_path, why, edit):
    corners = edit(rectangle_corners([0.0, 0.0, 0.0], 600.0, 400.0))
    path = write_c3d(tmp_path / "bad.c3d", platform_spec(2, corners))
    err = refused(tmp_path, "E505", path, tmp_path / "s", None, overrides=c3d_map())
    assert why in str(err)
    # without the platform the same file imports in its lab frame
    result = import_c3d(path, tmp_path / "s", None, overrides=c3d_map(force_plate="none"))
    assert "lab frame" in result.world_frame


# --- 3. 6-DoF bodies -----------------------------------------------------------------------------


def rot_z(a: float) -> np.ndarray:
    return np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])


def sweep(n: int) -> np.ndarray:
    """A handle path through a 12 cm ball around (0, 0.05, 0.1) m (a workspace sweep), in mm."""
    k = np.arange(n)
    polar = np.arccos(1 - 2 * (k + 0.5) / n)
    azimuth = math.pi * (3 - math.sqrt(5)) * k
    r = 60.0 * (0.4 + 0.6 * ((k * 7919) % n) / n)
    return np.column_stack(
        [r * np.sin(polar) * np.cos(azimuth), 50.0 + r * np.sin(polar) * np.sin(azimuth), 100.0 + r * np.cos(polar)]
    )


def bodies_spec(n: int = 3000) -> tuple[C3DSpec, np.ndarray]:
    """6-DoF bodies only (no marker): 'Handle' sweeping a ball, turning about z by 0.001 rad a frame,
    invalid at frames 10–12; 'Link2' fixed, turned 90° about z. Returns the spec and the angles."""
    angles = 0.001 * np.arange(n)
    rot = np.zeros((n, 2, 4, 4))
    rot[:, :, 3, 3] = 1.0
    rot[:, 0, :3, :3] = np.array([rot_z(a) for a in angles])
    rot[:, 0, :3, 3] = sweep(n)
    rot[:, 1, :3, :3] = rot_z(math.pi / 2)
    rot[:, 1, :3, 3] = [10.0, 20.0, 30.0]
    rot[10:13, 0] = np.nan
    return C3DSpec(
        point_rate=100.0, rotation_labels=["Handle", "Link2"], rotations=float32(rot), company="Markerless", software="Bodies 1.0"
    ), angles


def test_a_session_of_6dof_bodies_alone_imports_validates_and_computes(tmp_path, capsys):
    spec, angles = bodies_spec()
    path = write_c3d(tmp_path / "bodies.c3d", spec)
    rec = read_c3d(path)
    assert rec.body_labels == ["Handle", "Link2"] and rec.point_labels == [] and rec.frames == 3000
    m = c3d_map(
        trial={"powered": False, "protocol": "workspace", "id": "ws"},
        lab_to_world={"position": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]},
        bodies={"handle": "Handle"},
    )
    (tmp_path / "m.json").write_text(json.dumps(m))
    device = tmp_path / "device.json"
    device.write_text(json.dumps(TOUCH_DEVICE))
    code = main(["--json", "import", "c3d", str(path), "-o", str(tmp_path / "s"), "--map", str(tmp_path / "m.json")])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and report["validation"]["valid"]
    s = open_session(tmp_path / "s")
    pose = s.read("ws", "handle_pose")
    np.testing.assert_allclose(pose[["px", "py", "pz"]].to_numpy()[:10], spec.rotations[:10, 0, :3, 3] / 1000.0, atol=1e-12)
    q = pose[["qw", "qx", "qy", "qz"]].to_numpy()
    ok = np.ones(3000, bool)
    ok[10:13] = False
    assert np.isnan(q[~ok]).all() and np.isnan(pose["px"].to_numpy()[~ok]).all()
    np.testing.assert_allclose(q[ok, 0], np.cos(angles[ok] / 2), atol=1e-6)
    np.testing.assert_allclose(q[ok, 3], np.sin(angles[ok] / 2), atol=1e-6)
    assert s.manifest.rig.motion_capture.rate_hz == 100.0 and s.manifest.rig.motion_capture.system == "Markerless Bodies 1.0"
    assert main(["validate", str(tmp_path / "s")]) == 0
    capsys.readouterr()
    assert main(["--json", "compute", str(tmp_path / "s"), "-o", str(tmp_path / "results.json")]) == 0
    results = {r["id"]: r for r in json.loads((tmp_path / "results.json").read_text())["metrics"]}
    measured = results["workspace.measured_volume"]
    assert measured["trials"] == ["ws"] and measured["diagnostics"]["points"] == [2997]  # 3 occluded frames
    ball = 4 / 3 * math.pi * 0.06**3  # the sweep fills a 60 mm ball: its sampled hull is a little smaller
    assert 0.8 * ball < measured["diagnostics"]["hull_volume_m3"][0] < ball


def test_link_bodies_become_link_poses_in_w(tmp_path):
    spec, _ = bodies_spec(n=50)
    path = write_c3d(tmp_path / "bodies.c3d", spec)
    # W: the lab turned −90° about z and shifted: the link's 90° turn cancels
    half = math.sqrt(0.5)
    m = c3d_map(
        lab_to_world={"position": [0.1, 0.0, 0.0], "quaternion": [half, 0.0, 0.0, -half]},
        markers={"rigid_bodies": [{"name": "link2", "markers": ["l2a", "l2b", "l2c"]}]},
        bodies={"handle": "Handle", "links": {"link2": "Link2"}},
    )
    result = import_c3d(path, tmp_path / "s", None, overrides=m)
    valid(tmp_path / "s")
    s = open_session(tmp_path / "s")
    assert s.stream(result.trial_id, "link_poses").entities == ["link2"]
    lp = s.read(result.trial_id, "link_poses")
    np.testing.assert_allclose(
        lp[["link2_qw", "link2_qx", "link2_qy", "link2_qz"]].to_numpy(), np.tile([1.0, 0, 0, 0], (50, 1)), atol=1e-7
    )
    # lab (10, 20, 30) mm turned −90° about z is (20, −10, 30) mm; plus 0.1 m in x
    np.testing.assert_allclose(
        lp[["link2_px", "link2_py", "link2_pz"]].to_numpy(), np.tile([0.12, -0.01, 0.03], (50, 1)), atol=1e-9
    )


def test_body_errors(tmp_path):
    spec, _ = bodies_spec(n=20)
    path = write_c3d(tmp_path / "bodies.c3d", spec)
    err = refused(tmp_path, "E503", path, tmp_path / "s", None, overrides=c3d_map(bodies={"handle": "Stylus"}))
    assert err.findings[0].expected == ["Handle", "Link2"]
    refused(tmp_path, "E502", path, tmp_path / "s", None, overrides=c3d_map(bodies={"links": {"link2": "Link2"}}))
    refused(tmp_path, "E502", path, tmp_path / "s", None, overrides=c3d_map())  # nothing to import
    bad = spec.rotations.copy()
    bad[5, 0, :3, :3] *= 2.0  # a scaled matrix is no rotation
    write_c3d(tmp_path / "scaled.c3d", C3DSpec(point_rate=100.0, rotation_labels=["Handle", "Link2"], rotations=bad))
    err = refused(tmp_path, "E501", tmp_path / "scaled.c3d", tmp_path / "s", None, overrides=c3d_map(bodies={"handle": "Handle"}))
    assert "frame 5" in str(err)
    assert header_words(path)[1] == 0  # no point in the file
