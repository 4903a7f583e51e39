"""The spec's third-party example (spec/examples/write_session.js, spec chapters 2–3): a session written
from the specification alone, in JavaScript, validates with no finding and reads back with the values
its analytic signals define.

The expected values below are derived from the signal definitions documented in the writer (sines of
time around the Touch's workspace centre); they are not taken from the writer's output.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from haptify.formats.conventions import STANDARD_GRAVITY, quat_to_matrix
from haptify.formats.storage import open_session
from haptify.formats.validation import validate_session
from haptify.processing.kinematics import forward_positions

REPO = Path(__file__).resolve().parents[1]
WRITER = REPO / "spec" / "examples" / "write_session.js"
NODE = shutil.which("node")

pytestmark = pytest.mark.skipif(NODE is None, reason="node (Node.js) is not installed; the JS example writer cannot run")

G_W = np.array([0.0, 0.0, -STANDARD_GRAVITY])
Q_TILT = [0.96, 0.28, 0.0, 0.0]  # the handle's orientation at the start of both trials
Q_CENTRE = np.array([[0.0, 0.7, -1.0]])  # joint angles of the workspace centre
AMP, FREQ = np.array([0.03, 0.02, 0.015]), np.array([0.25, 0.4, 0.3])  # free-space Lissajous, m and Hz
YAW_RATE_0 = 0.2 * 2 * np.pi * 0.2  # rad/s: yaw θ = 0.2·sin(2π·0.2·τ), so θ̇(0)
VISCOUS = 2.0  # N·s/m, force on the hand −VISCOUS·v
DEVICE_MASS_KG, PLATE_BIAS = 1.6, np.array([0.5, -0.3, 1.2, 0.01, -0.02, 0.003])
K_RENDER, TRACKING = 750.0, 0.92
FS, ST = "free_space-1", "stiffness-1"
T0 = {FS: 10.0, ST: 20.0}


@pytest.fixture(scope="module")
def session_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("js") / "session"
    done = subprocess.run([NODE, str(WRITER), str(out)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return out


@pytest.fixture(scope="module")
def folder(session_dir):
    return open_session(session_dir)


@pytest.fixture(scope="module")
def manifest(session_dir) -> dict:
    return json.loads((session_dir / "session.json").read_text(encoding="utf-8"))


def _centre_w(folder) -> np.ndarray:
    """Gimbal centre in W at Q_CENTRE: the reference's DH forward kinematics plus the device placement."""
    place = folder.manifest.device_placement
    return quat_to_matrix(np.array(place.quaternion)) @ forward_positions(folder.device().kinematics, Q_CENTRE)[0] + np.array(
        place.position
    )


def test_validates_without_any_finding(session_dir):
    report = validate_session(session_dir)
    assert [f.code for f in report.errors] == []
    assert [f.code for f in report.warnings] == []
    assert report.exit_code == 0


def test_manifest_carries_touch_table_and_calibration(folder, manifest):
    kin = folder.device().kinematics
    q3 = kin.joints[2]
    assert (q3.upper.constant, q3.upper.coefficients) == (-0.1745, {"q2": -0.85})
    assert [t["protocol"] for t in manifest["trials"]] == ["free_space", "stiffness"]
    (record,) = manifest["calibration"]
    assert record["kind"] == "handle_gravity" and record["gravity_m_per_s2"] == STANDARD_GRAVITY
    assert len(manifest["rig"]["force_plate"]["corners"]) == 4


def test_every_stream_has_exact_times_and_declared_rows(folder, manifest):
    for trial in manifest["trials"]:
        for s in trial["streams"]:
            df = folder.read(trial["id"], s["kind"])
            assert len(df) == s["rows"]
            expected_t = T0[trial["id"]] + np.arange(s["rows"]) / s["rate_hz"]
            np.testing.assert_array_equal(df["t"].to_numpy(), expected_t)
            assert list(df.columns) == [c["name"] for c in s["columns"]]


def test_occlusion_gaps_are_exactly_where_written(folder):
    pose = folder.read(FS, "handle_pose")
    occluded = pose[["px", "py", "pz", "qw", "qx", "qy", "qz"]].isna()
    assert (occluded.all(axis=1) == occluded.any(axis=1)).all()  # whole samples only
    np.testing.assert_array_equal(np.flatnonzero(occluded.all(axis=1)), np.arange(120, 135))
    markers = folder.read(FS, "markers")
    assert not markers[["h1_x", "h1_y", "h1_z"]].isna().any().any()
    np.testing.assert_array_equal(np.flatnonzero(markers["h2_x"].isna()), np.arange(40, 50))
    q = pose[["qw", "qx", "qy", "qz"]].dropna().to_numpy()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)


def test_free_space_first_samples(folder, manifest):
    centre = _centre_w(folder)
    rot = quat_to_matrix(np.array(Q_TILT))
    rig, (hg,) = manifest["rig"], manifest["calibration"]

    pose0 = folder.read(FS, "handle_pose").iloc[0]
    assert [pose0[c] for c in ("qw", "qx", "qy", "qz")] == Q_TILT  # exact: yaw 0 at τ = 0
    np.testing.assert_allclose([pose0.px, pose0.py, pose0.pz], centre, rtol=0, atol=1e-15)

    m0 = folder.read(FS, "markers").iloc[0]
    np.testing.assert_allclose([m0.h1_x, m0.h1_y, m0.h1_z], centre + rot @ [0.02, 0, 0.01], rtol=0, atol=1e-15)

    # paper eq. 1 plus the device's viscous force on the hand, v(0) = AMP·2πf
    force_on_hand = -VISCOUS * AMP * 2 * np.pi * FREQ
    r_s = rot @ quat_to_matrix(np.array(rig["handle"]["ft_sensor"]["pose"]["quaternion"]))
    weight_s = r_s.T @ (hg["connector_mass_kg"] * G_W)
    dev_s = r_s.T @ force_on_hand
    gimbal_in_s = -np.array(rig["handle"]["ft_sensor"]["pose"]["position"])
    f = np.array(hg["force_bias_N"]) + weight_s + dev_s
    tq = np.array(hg["torque_bias_Nm"]) + np.cross(hg["connector_com_m"], weight_s) + np.cross(gimbal_in_s, dev_s)
    w0 = folder.read(FS, "handle_wrench").iloc[0]
    np.testing.assert_allclose(w0[["fx", "fy", "fz", "tx", "ty", "tz"]].to_numpy(float), np.r_[f, tq], rtol=0, atol=1e-14)

    # specific force: centripetal acceleration of the offset accelerometer (yaw rate θ̇(0), no θ̈) minus g
    r_a = rot @ np.array(rig["handle"]["accelerometer"]["pose"]["position"])
    centripetal = YAW_RATE_0**2 * np.array([-r_a[0], -r_a[1], 0.0])
    a0 = folder.read(FS, "handle_accel").iloc[0]
    expected_a = np.array(hg["accel_bias_m_per_s2"]) + rot.T @ (centripetal - G_W)
    np.testing.assert_allclose(a0[["ax", "ay", "az"]].to_numpy(float), expected_a, rtol=0, atol=1e-14)
    assert np.linalg.norm(expected_a - hg["accel_bias_m_per_s2"]) == pytest.approx(STANDARD_GRAVITY, rel=1e-3)

    # plate: the device's weight minus its force on the hand, shared 0.2/0.8 in x (base at x = −0.15 m)
    # and 0.5/0.5 in y over the corners; corner torques are their bias
    p0 = folder.read(FS, "plate_wrench").iloc[0]
    load = np.array([0.0, 0.0, -DEVICE_MASS_KG * STANDARD_GRAVITY]) - force_on_hand
    for corner, share in zip(("c1", "c2", "c3", "c4"), (0.1, 0.4, 0.4, 0.1)):
        got = p0[[f"{corner}_{a}" for a in ("fx", "fy", "fz", "tx", "ty", "tz")]].to_numpy(float)
        np.testing.assert_allclose(got, PLATE_BIAS + np.r_[share * load, 0, 0, 0], rtol=0, atol=1e-13)


def test_stiffness_trial_commands_exact_presses(folder, manifest):
    rendering = manifest["trials"][1]["rendering"]
    assert (rendering["stiffness_N_per_m"], rendering["surface_normal"]) == (K_RENDER, [0, 0, 1])
    sx, sy, sz = rendering["surface_point_m"]
    cmd = folder.read(ST, "commanded_wrench")
    pose = folder.read(ST, "handle_pose")
    # z(τ) = sz + 0.005 − 0.009·(1 − cos πτ)/2: 5 mm above the surface at τ = 0, 4 mm into it at τ = 1 s
    assert (pose.px.iloc[0], pose.py.iloc[0], pose.pz.iloc[0]) == (sx, sy, sz + 0.005)
    deepest = sz + 0.005 - 0.009 * (1 - -1.0) / 2
    assert pose.pz.iloc[100] == deepest
    assert cmd.fz.iloc[0] == 0.0
    assert cmd.fz.iloc[1000] == K_RENDER * (sz - deepest)
    assert cmd.fz.max() == cmd.fz.iloc[1000] and cmd.fz.min() == 0.0
    assert (cmd[["fx", "fy", "tx", "ty", "tz"]] == 0).all().all()
    # the handle sensor sees 92 % of the commanded force on top of the connector's weight
    wrench = folder.read(ST, "handle_wrench")
    r_s = quat_to_matrix(np.array(Q_TILT))
    delta = wrench[["fx", "fy", "fz"]].iloc[1000].to_numpy(float) - wrench[["fx", "fy", "fz"]].iloc[0].to_numpy(float)
    np.testing.assert_allclose(delta, r_s.T @ [0, 0, TRACKING * cmd.fz.iloc[1000]], rtol=0, atol=1e-14)


def test_writer_refuses_an_existing_output(session_dir):
    before = (session_dir / "session.json").read_bytes()
    done = subprocess.run([NODE, str(WRITER), str(session_dir)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "exists" in done.stderr
    assert (session_dir / "session.json").read_bytes() == before
    assert not any(p.name.startswith(f".{session_dir.name}.tmp") for p in session_dir.parent.iterdir())
