"""The rerun session viewer: .rrd completeness, entity paths, exact rows and timestamps,
blueprints per protocol, --compare, results table, the CLI, web-viewer smoke and screenshot tests.

Every expectation comes from the analytic session built here (known by construction), never from a
previous run of the viewer.
"""

from __future__ import annotations

import argparse
import copy
import functools
import json
import math
import os
import subprocess
import sys
import tempfile
import time
import urllib.request
import warnings
from pathlib import Path

import numpy as np
import pytest
import rerun.blueprint as rrb
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from rerun.chunk import RrdReader

from haptify.cli.main import UI
from haptify.errors import HaptifyError
from haptify.formats.session_format import STREAM_KINDS
from haptify.formats.storage import open_session
from haptify.pipeline.results import Implementation, MetricResult, ResultsFile, Unavailable, load_results
from haptify_tools.example_session import TOUCH_DEVICE, example_writer
from haptify_tools.viewer import blueprints, cmd_view
from haptify_tools.viewer.arrays import columns_of, nan_split, plane_rectangle, raw_pose_at, side_by_side
from haptify_tools.viewer.documents import results_markdown
from haptify_tools.viewer.plan import HAND_FORCE_M_PER_N, PLATE_FORCE_M_PER_N, decimation_factor, envelope, time_ns
from haptify_tools.viewer.recording import plan_recording, write_rrd
from haptify_tools.viewer.save import build

CHROMIUM = Path("/usr/bin/chromium")
SURFACE_Z = 0.05
OCCLUDED = slice(40, 47)  # pose/marker rows set to NaN in the stiffness trial (70 ms: longer than any bridged gap)
SPHERE_R, SPHERE_C = 0.04, np.array([0.0, 0.0, 0.1])  # the workspace trial sweeps this sphere (m)
FREE_SPACE_S = 2.5  # duration of the example free-space trial: long enough for the vibration chapter's trimming
COMPARE_LAG_S = 3.25  # clock offset of the compared session's stiffness trial
FORCE_BIAS = 0.25  # N, the handle_gravity record's force bias on the sensor's x axis


def small_device() -> dict:
    """The Touch with 3 cm links and q1 within ±0.5 rad: a modeled workspace that is quick to voxelise."""
    device = copy.deepcopy(TOUCH_DEVICE)
    for joint in device["kinematics"]["joints"][1:]:
        joint["a"] = 0.03
    device["kinematics"]["joints"][0]["lower"] = {"constant": -0.5}
    device["kinematics"]["joints"][0]["upper"] = {"constant": 0.5}
    return device


def rich_writer(session_id: str = "viewer-0001", force_scale: float = 1.0):
    """The example free-space trial plus a workspace trial and a stiffness trial with every stream."""
    w = example_writer(session_id=session_id, duration_s=FREE_SPACE_S)
    w.manifest["device"] = small_device()
    w.manifest["calibration"] = [  # known parameters: 0.25 N force bias on x, no connector weight, zero plate bias
        {
            "kind": "handle_gravity",
            "id": "hg",
            "force_bias_N": [FORCE_BIAS, 0.0, 0.0],
            "connector_mass_kg": 0.0,
            "connector_com_m": [0.0, 0.0, 0.0],
            "torque_bias_Nm": [0.0, 0.0, 0.0],
            "accel_bias_m_per_s2": [0.0, 0.0, 0.0],
            "gravity_m_per_s2": 9.81,
        },
        {"kind": "plate_bias", "id": "pb", "bias": [0.0] * 24},
    ]
    mc = w.manifest["rig"]["motion_capture"]
    mc["rigid_bodies"] += [{"name": "link1", "markers": ["l1a", "l1b"]}, {"name": "link2", "markers": ["l2a", "l2b"]}]
    mc["markers"] += ["l1a", "l1b", "l2a", "l2b"]
    # workspace: a spiral sweep over a sphere of radius SPHERE_R centred at SPHERE_C, 100 Hz
    n = 600
    t = np.arange(n) / 100.0
    z = 1 - 2 * (np.arange(n) + 0.5) / n
    phi = np.sqrt(n * np.pi) * np.arcsin(z)
    xyz = SPHERE_C + SPHERE_R * np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])
    w.add_trial("workspace-1", "workspace", powered=False)
    w.add_stream(
        "workspace-1",
        "handle_pose",
        {"t": t, "px": xyz[:, 0], "py": xyz[:, 1], "pz": xyz[:, 2], "qw": 1 + 0 * t, "qx": 0 * t, "qy": 0 * t, "qz": 0 * t},
        rate_hz=100,
    )
    # stiffness: presses into the plane z = SURFACE_Z; the handle is turned 90° about z
    w.add_trial(
        "stiffness-1",
        "stiffness",
        powered=True,
        rendering={"surface_point_m": [0.0, 0.0, SURFACE_Z], "surface_normal": [0.0, 0.0, 1.0], "stiffness_N_per_m": 500.0},
    )
    t100 = np.arange(100) / 100.0
    pz = SURFACE_Z - 0.003 * np.sin(2 * np.pi * t100)
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    pose = {
        "t": t100,
        "px": 0 * t100,
        "py": 0 * t100,
        "pz": pz,
        "qw": c + 0 * t100,
        "qx": 0 * t100,
        "qy": 0 * t100,
        "qz": s + 0 * t100,
    }
    for k in ("px", "py", "pz", "qw", "qx", "qy", "qz"):
        pose[k] = pose[k].copy()
        pose[k][OCCLUDED] = np.nan
    w.add_stream("stiffness-1", "handle_pose", pose, rate_hz=100)
    t1k = np.arange(1000) / 1000.0
    wrench = {
        "t": t1k,
        "fx": force_scale * (1.0 + 0 * t1k),
        "fy": 0 * t1k,
        "fz": force_scale * 2.0 * np.sin(2 * np.pi * t1k),
        "tx": 0 * t1k,
        "ty": 0 * t1k,
        "tz": 0.01 + 0 * t1k,
    }
    w.add_stream("stiffness-1", "handle_wrench", wrench, rate_hz=1000)
    w.add_stream(
        "stiffness-1",
        "commanded_wrench",
        {"t": t1k, "fx": 0 * t1k, "fy": 0 * t1k, "fz": 1.5 + 0 * t1k, "tx": 0 * t1k, "ty": 0 * t1k, "tz": 0 * t1k},
        rate_hz=1000,
    )
    w.add_stream(
        "stiffness-1",
        "device_joint_angles",
        {"t": t1k, "q1": 0.1 + 0 * t1k, "q2": 0.5 + 0 * t1k, "q3": -0.8 + 0 * t1k},
        rate_hz=1000,
    )
    w.add_stream("stiffness-1", "sync", {"t": t1k, "trigger": (t1k >= 0.25).astype(float)}, rate_hz=1000)
    markers = {"t": t100}
    for name, off in (("h1", 0.01), ("h2", 0.02), ("h3", 0.03), ("l2a", -0.05), ("l2b", -0.06)):
        markers[f"{name}_x"] = off + 0 * t100
        markers[f"{name}_y"] = 0 * t100
        markers[f"{name}_z"] = pz.copy()
    for axis in "xyz":  # an occluded marker loses all three coordinates together (spec §2.7)
        markers[f"h2_{axis}"][OCCLUDED] = np.nan
    w.add_stream("stiffness-1", "markers", markers, rate_hz=100, entities=["h1", "h2", "h3", "l2a", "l2b"])
    links = {"t": t100}
    for link in ("link1", "link2"):
        links.update(
            {
                f"{link}_px": 0 * t100,
                f"{link}_py": 0 * t100,
                f"{link}_pz": 0.1 + 0 * t100,
                f"{link}_qw": 1 + 0 * t100,
                f"{link}_qx": 0 * t100,
                f"{link}_qy": 0 * t100,
                f"{link}_qz": 0 * t100,
            }
        )
    w.add_stream("stiffness-1", "link_poses", links, rate_hz=100, entities=["link1", "link2"])
    return w


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    root = tmp_path_factory.mktemp("viewer")
    main = rich_writer().write(root / "main")
    sim = rich_writer("viewer-sim", force_scale=0.5)
    sim.manifest["calibration"] += [  # the simulated stiffness trial runs 3.25 s later on its session clock
        {
            "kind": "clock_offset",
            "id": f"late-{i}",
            "stream_file": f"trials/stiffness-1/{kind}.parquet",
            "offset_s": COMPARE_LAG_S,
        }
        for i, kind in enumerate(
            ("handle_pose", "handle_wrench", "commanded_wrench", "device_joint_angles", "sync", "markers", "link_poses")
        )
    ]
    other = sim.write(root / "sim")
    return open_session(main), open_session(other), root


def results_for(session_id: str) -> ResultsFile:
    return ResultsFile(
        implementation=Implementation(name="haptify-reference", version="0.1.0"),
        session_id=session_id,
        manifest_sha256="0" * 64,
        metrics=[
            MetricResult(
                id="workspace.volume", value=0.000123456, unit="m^3", n=1, definition_version="1.0", trials=["workspace-1"]
            ),
            MetricResult(
                id="stiffness.k_mean", value=[480.0, 470.0], unit="N/m", n=2, sd=7.07, definition_version="1.0", warnings=["W401"]
            ),
        ],
        unavailable=[Unavailable(id="vibration.rms", code="E302", reason="no handle_accel | stream")],
    )


@pytest.fixture(scope="module")
def recorded(sessions):
    main, other, root = sessions
    results = results_for(main.session_id)
    plan = plan_recording(main, results=results, other=other, derived="full")  # kept whole: the meshes are inspected
    out = write_rrd(plan, root / "all.rrd", blueprints.blueprint_for(plan))
    return plan, out


@functools.lru_cache(maxsize=4)
def temporal_batches(path: Path) -> dict[str, list]:
    """Every temporal chunk of an .rrd as a record batch, grouped by entity path (read once per file)."""
    out: dict[str, list] = {}
    for ch in RrdReader(path).stream().filter(is_static=False):
        out.setdefault(ch.entity_path, []).append(ch.to_record_batch())
    return out


def temporal(path: Path, entity: str, component: str) -> tuple[np.ndarray, list]:
    """(time in int64 ns, component values per row) of an entity's temporal rows, in time order."""
    times, values = [], []
    for rb in temporal_batches(path).get(entity, []):
        if component not in rb.schema.names:
            continue
        times.append(rb.column("time").cast("int64").to_numpy())
        values += rb.column(component).to_pylist()
    t = np.concatenate(times) if times else np.empty(0, np.int64)
    order = np.argsort(t, kind="stable")
    return t[order], [values[i] for i in order]


def static_labels(path: Path, entity: str) -> list[str]:
    [ch] = list(RrdReader(path).stream().filter(content=entity, is_static=True, components="Points3D:labels"))
    return ch.to_record_batch().column("Points3D:labels").to_pylist()[0]


def static_text(path: Path, entity: str) -> str:
    [ch] = list(RrdReader(path).stream().filter(content=entity, is_static=True, components="TextDocument:text"))
    return ch.to_record_batch().column("TextDocument:text").to_pylist()[0][0]


# --- the .rrd file -----------------------------------------------------------------------------------


def test_rrd_verify_accepts_the_file_and_rejects_it_truncated(recorded, tmp_path):
    """`python -m rerun rrd verify` exits 0 on the recording, and not on the same file cut short
    (which loses its footer): the completeness check can fail. Both run at once."""
    _, out = recorded
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(out.read_bytes()[: out.stat().st_size // 2])
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "rerun", "rrd", "verify", str(f)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        for f in (out, cut)
    ]
    results = [(p.wait(timeout=60), p.communicate()[1]) for p in procs]
    assert results[0][0] == 0, results[0][1]
    assert results[1][0] != 0


def test_expected_entity_paths(recorded):
    _, out = recorded
    [entry] = RrdReader(out).recordings()
    assert entry.recording_id == "viewer-0001+viewer-sim"
    paths = set(RrdReader(out).store().schema().entity_paths())
    expected = {
        "/world",
        "/world/plate",
        "/world/plate/corners",
        "/world/device",
        "/session",
        "/results",
        "/world/workspace-1/measured/workspace/points",
        "/world/workspace-1/measured/trajectory",
        "/world/workspace-1/measured/workspace/measured",
        "/world/workspace-1/measured/workspace/modeled",
        "/world/workspace-1/compare/workspace/measured",
        "/world/free_space-1/measured/handle",
        "/world/free_space-1/measured/hand_force/calibrated",
        "/world/free_space-1/measured/force_field",
        "/world/free_space-1/measured/plate_force",
        "/series/free_space-1/measured/hand_force/calibrated",
        "/series/free_space-1/measured/hand_torque/calibrated",
        "/series/free_space-1/measured/accel/world",
        "/series/free_space-1/measured/plate/force",
        "/series/free_space-1/measured/plate/cop",
        "/world/stiffness-1/measured/virtual_surface",
        "/world/stiffness-1/measured/markers/handle",
        "/world/stiffness-1/measured/markers/link2",
        "/world/stiffness-1/measured/links/link1",
        "/world/stiffness-1/measured/links/link2",
        "/series/free_space-1/measured/handle/force_raw",
        "/series/free_space-1/measured/handle/torque_raw",
        "/series/free_space-1/measured/accel/raw",
        "/series/free_space-1/measured/plate/corner_force_raw",
        "/series/free_space-1/measured/plate/corner_torque_raw",
        "/series/stiffness-1/measured/commanded/force",
        "/series/stiffness-1/measured/penetration",
        "/series/stiffness-1/measured/device/joint_angles",
        "/series/stiffness-1/measured/sync/trigger",
        "/series/stiffness-1/compare/handle/force_raw",
        "/world/stiffness-1/compare/handle",
    }
    assert expected <= paths, sorted(expected - paths)
    assert not any("/world/stiffness-1/measured/force_field" == p for p in paths)  # only for free space


def test_each_series_has_one_row_per_sample_at_exact_ns(recorded, sessions):
    plan, out = recorded
    main, other, _ = sessions
    series = [e for e in plan.entries if e.series is not None and e.stream in STREAM_KINDS]
    assert len(series) >= 15
    truncation_would_differ = False
    for e in series:
        role, trial_id = e.path.split("/")[3], e.path.split("/")[2]
        session = main if role == "measured" else other
        frame = session.read(trial_id, e.stream)
        declared = session.stream(trial_id, e.stream).rows
        t_ns, rows = temporal(out, e.path, "Scalars:scalars")
        assert len(t_ns) == declared == len(frame), e.path
        expected = np.round(frame["t"].to_numpy() * 1e9).astype(np.int64)
        if role == "compare" and trial_id == "stiffness-1":  # aligned with the measured trial's start
            expected = expected - round(COMPARE_LAG_S * 1e9)
        np.testing.assert_array_equal(t_ns, expected, err_msg=e.path)
        truncation_would_differ |= bool(np.any(np.trunc(frame["t"].to_numpy() * 1e9).astype(np.int64) != expected))
        assert all(len(r) == len(rows[0]) for r in rows)
    assert truncation_would_differ  # the data would expose float truncation of timestamps


def test_series_values_are_the_stream_values(recorded, sessions):
    _, out = recorded
    main, other, _ = sessions
    _, rows = temporal(out, "/series/stiffness-1/measured/handle/force_raw", "Scalars:scalars")
    w = main.read("stiffness-1", "handle_wrench")
    np.testing.assert_array_equal(np.array(rows), w[["fx", "fy", "fz"]].to_numpy())
    t_ns, rows = temporal(out, "/series/stiffness-1/compare/handle/force_raw", "Scalars:scalars")
    np.testing.assert_array_equal(np.array(rows)[:, 0], 0.5 * np.ones(1000))
    np.testing.assert_array_equal(t_ns, time_ns(np.arange(1000) / 1000.0))  # aligned with the measured trial
    _, rows = temporal(out, "/series/stiffness-1/measured/penetration", "Scalars:scalars")
    depth = np.array(rows)[:, 0]
    t100 = np.arange(100) / 100.0
    expected = 0.003 * np.sin(2 * np.pi * t100)
    expected[OCCLUDED] = np.nan
    np.testing.assert_allclose(depth, expected, atol=1e-15)


def test_three_d_entities_skip_unknown_poses(recorded):
    _, out = recorded
    t_ns, _ = temporal(out, "/world/stiffness-1/measured/handle", "Transform3D:translation")
    all_ns = time_ns(np.arange(100) / 100.0)
    np.testing.assert_array_equal(t_ns, np.delete(all_ns, np.arange(100)[OCCLUDED]))
    # the handle's markers h1, h2, h3 in one labelled cloud: every frame (h1, h3 are always seen), h2 NaN when occluded
    assert static_labels(out, "/world/stiffness-1/measured/markers/handle") == ["h1", "h2", "h3"]
    t_ns, pts = temporal(out, "/world/stiffness-1/measured/markers/handle", "Points3D:positions")
    np.testing.assert_array_equal(t_ns, all_ns)
    pts = np.array(pts, dtype=float)
    assert pts.shape == (100, 3, 3) and pts[0, 1, 0] == pytest.approx(0.02)
    h2_seen = np.isfinite(pts[:, 1]).all(axis=1)
    np.testing.assert_array_equal(h2_seen, ~np.isin(np.arange(100), np.arange(100)[OCCLUDED]))
    assert np.isfinite(pts[:, [0, 2]]).all()
    t_ns, pts = temporal(out, "/world/stiffness-1/measured/markers/link2", "Points3D:positions")
    assert len(t_ns) == 100 and all(len(p) == 2 for p in pts)


def test_session_and_results_documents(recorded):
    _, out = recorded
    md = static_text(out, "/results")
    assert "| workspace.volume | 0.0001235 | m^3 | 1 |" in md
    assert "| stiffness.k_mean | [480, 470] | N/m | 2 | 7.07 |" in md
    assert "no handle_accel \\| stream" in md
    text = static_text(out, "/session")
    assert "viewer-0001" in text and "viewer-sim" in text and "stiffness-1" in text
    assert "stiffness-1 (compare) shifted by -3.25 s" in text


def test_results_markdown_warns_about_another_session():
    md = results_markdown(results_for("someone-else"), "viewer-0001")
    assert "not `viewer-0001`" in md


def test_load_results_errors(tmp_path):
    with pytest.raises(HaptifyError) as err:
        load_results(tmp_path / "missing.json")
    assert err.value.findings[0].code == "E903"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"session_id": "x"}))
    with pytest.raises(HaptifyError) as err:
        load_results(bad)
    assert {f.code for f in err.value.findings} == {"E104"}
    good = tmp_path / "good.json"
    good.write_text(results_for("viewer-0001").model_dump_json())
    assert load_results(good).metrics[0].id == "workspace.volume"


def view_named(container, name: str):
    """The view called ``name`` anywhere inside a blueprint container."""
    for item in container.contents:
        if getattr(item, "name", None) == name and not hasattr(item, "column_shares"):
            return item
        if hasattr(item, "column_shares"):
            found = view_named(item, name)
            if found is not None:
                return found
    return None


def test_write_is_atomic_with_ordinary_permissions(tmp_path):
    import rerun as rr

    from haptify_tools.viewer.plan import Entry, Plan

    good = Plan("atomic-ok")
    good.add(Entry("/a", times_ns=np.array([0, 1, 2]), archetype=rr.Scalars, fields={"scalars": np.ones(3)}))
    out = write_rrd(good, tmp_path / "ok.rrd", None)
    umask = os.umask(0)
    os.umask(umask)
    assert out.stat().st_mode & 0o777 == 0o666 & ~umask
    bad = Plan("atomic-bad")  # 3 timestamps for 5 values: the writer raises half-way
    bad.add(Entry("/a", times_ns=np.array([0, 1, 2]), archetype=rr.Scalars, fields={"scalars": np.ones(3)}))
    bad.add(Entry("/b", times_ns=np.array([0, 1, 2]), archetype=rr.Scalars, fields={"scalars": np.ones(5)}))
    with pytest.raises(ValueError):
        write_rrd(bad, tmp_path / "bad.rrd", None)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.rrd"]  # no partial file, no temp file


# --- blueprints -------------------------------------------------------------------------------------


def test_blueprint_per_protocol(recorded):
    plan, _ = recorded
    tabs = {tp.trial.protocol: blueprints.trial_tab(plan, tp) for tp in plan.trials}
    stiff = tabs["stiffness"]
    assert isinstance(stiff.contents[0], rrb.Vertical) and isinstance(stiff.contents[1], rrb.Spatial3DView)
    first = stiff.contents[0].contents[0]
    assert first.origin == "/series/stiffness-1" and first.name == "normal force: commanded vs felt"
    assert list(first.contents) == ["+ $origin/measured/contact/normal_force", "+ $origin/compare/contact/normal_force"]
    ws = tabs["workspace"]
    assert isinstance(ws.contents[0], rrb.Spatial3DView)
    assert list(ws.contents[0].contents) == ["+ /world", "+ /world/plate/**", "+ /world/device/**", "+ /world/workspace-1/**"]
    assert ws.column_shares == [3.0, 1.0]
    free = tabs["free_space"]
    names = [v.name for v in free.contents[1].contents if isinstance(v, rrb.TimeSeriesView)]
    assert names[:2] == ["hand force in W", "hand torque in W (calibrated)"]
    assert "/series/free_space-1/measured/hand_force/raw_world" not in plan.paths()  # calibrated instead
    felt = view_named(stiff, "commanded vs felt force (W)")
    assert "+ $origin/measured/commanded/force" in felt.contents and "+ $origin/compare/commanded/force" in felt.contents
    assert "+ $origin/measured/hand_force/calibrated" in felt.contents  # felt = calibrated when available
    assert "+ $origin/measured/hand_force/raw_world" not in felt.contents
    free_tp = next(tp for tp in plan.trials if tp.trial.protocol == "free_space")
    assert blueprints.series_view(plan, free_tp, *blueprints.VIEWS["hand_force"]) is not None
    assert blueprints.series_view(plan, free_tp, *blueprints.VIEWS["commanded_vs_felt"]) is None  # nothing commanded
    for protocol in blueprints.LAYOUTS:  # every protocol has a layout naming only known views
        assert set(blueprints.LAYOUTS[protocol].views) <= set(blueprints.VIEWS)


def test_every_protocol_has_a_layout():
    from haptify.formats.session_format import PROTOCOLS

    assert set(PROTOCOLS) == set(blueprints.LAYOUTS)


# --- helpers known by construction ---------------------------------------------------------------------


def test_raw_pose_at_interpolates_without_filtering():
    t = np.array([0.0, 1.0, 2.0])
    p = np.array([[0, 0, 0], [1, 0, 0], [2, 2, 0]], float)
    half = [math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)]  # 90° about z
    q = np.array([[1, 0, 0, 0], half, [0, 0, 0, 1]], float)
    pose = raw_pose_at(t, p, q, np.array([0.5, 1.5, 2.0, -0.1, 2.1]))
    np.testing.assert_allclose(pose.position[:3], [[0.5, 0, 0], [1.5, 1, 0], [2, 2, 0]])
    np.testing.assert_allclose(pose.quaternion[0], [math.cos(math.pi / 8), 0, 0, math.sin(math.pi / 8)], atol=1e-12)
    assert np.isnan(pose.position[3:]).all() and np.isnan(pose.quaternion[3:]).all()
    p[1] = np.nan
    assert np.isnan(raw_pose_at(t, p, q, np.array([0.5, 1.5])).position).all()


def test_time_ns_rounds_to_the_nearest_nanosecond():
    assert time_ns(np.array([0.29, 1e-9, 140.0]))[0] == 290_000_000
    assert time_ns(np.array([0.29, 1e-9, 140.0])).tolist() == [290_000_000, 1, 140_000_000_000]


def test_nan_split():
    line = np.array([[0, 0, 0], [1, 0, 0], [np.nan] * 3, [2, 0, 0], [np.nan] * 3, [3, 0, 0], [4, 0, 0], [5, 0, 0]], float)
    assert [len(s) for s in nan_split(line)] == [2, 3]


def test_plane_rectangle_lies_in_the_plane_and_covers_the_path():
    normal = np.array([0.0, 1.0, 1.0]) / math.sqrt(2)
    point = np.array([0.1, 0.0, 0.0])
    rng = np.random.default_rng(1)
    around = rng.uniform(-0.2, 0.2, (50, 3))
    corners = plane_rectangle(point, normal, around)
    np.testing.assert_allclose((corners - point) @ normal, 0.0, atol=1e-12)
    e1, e2 = corners[1] - corners[0], corners[3] - corners[0]
    assert abs(e1 @ e2) < 1e-12
    proj = around - np.outer((around - point) @ normal, normal)
    a = (proj - corners[0]) @ e1 / (e1 @ e1)
    b = (proj - corners[0]) @ e2 / (e2 @ e2)
    assert (a > 0).all() and (a < 1).all() and (b > 0).all() and (b < 1).all()


def test_calibrated_hand_force_on_the_signal_grid(recorded):
    """Calibrated: bias removed, then rotated by the handle's 90° yaw: (1 − 0.25, 0, ·) N → (0, 0.75, ·) N in W."""
    plan, out = recorded
    t_ns, rows = temporal(out, "/series/stiffness-1/measured/hand_force/calibrated", "Scalars:scalars")
    np.testing.assert_array_equal(t_ns, 10_000_000 * np.arange(100))  # the 100 Hz grid over the overlap 0 … 0.99 s
    f = np.array(rows, dtype=float)
    valid = np.all(np.isfinite(f), axis=1)
    assert not valid[OCCLUDED].any() and valid.sum() >= 80
    np.testing.assert_allclose(f[valid, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(f[valid, 1], 1.0 - FORCE_BIAS, atol=1e-9)
    arrows_ns, _ = temporal(out, "/world/stiffness-1/measured/hand_force/calibrated", "Arrows3D:vectors")
    np.testing.assert_array_equal(arrows_ns, t_ns[valid])
    assert "/world/stiffness-1/measured/hand_force/raw" not in plan.paths()  # calibrated replaces the raw arrow
    # along the rendered normal (0, 0, 1): commanded 1.5 N throughout; penetration 3 mm · sin(2πt) on the grid
    _, normal = temporal(out, "/series/stiffness-1/measured/contact/normal_force", "Scalars:scalars")
    np.testing.assert_allclose(np.array(normal, dtype=float)[:, 0], 1.5, atol=1e-12)
    _, depth = temporal(out, "/series/stiffness-1/measured/contact/penetration", "Scalars:scalars")
    depth = np.array(depth, dtype=float)[:, 0]
    np.testing.assert_allclose(depth[valid], 0.003 * np.sin(2 * np.pi * np.arange(100)[valid] / 100.0), atol=5e-5)


def test_plate_force_and_cop(recorded):
    """Four equal corner loads summing to 18.5 N downward: force (0, 0, −18.5) N at the plate centre."""
    _, out = recorded
    n = int(FREE_SPACE_S * 1000)
    t_ns, rows = temporal(out, "/series/free_space-1/measured/plate/force", "Scalars:scalars")
    assert len(t_ns) == n
    np.testing.assert_allclose(np.array(rows), np.tile([0.0, 0.0, -18.5], (n, 1)), atol=1e-12)
    _, cop = temporal(out, "/series/free_space-1/measured/plate/cop", "Scalars:scalars")
    np.testing.assert_allclose(np.array(cop), 0.0, atol=1e-12)
    _, origins = temporal(out, "/world/free_space-1/measured/plate_force", "Arrows3D:origins")
    np.testing.assert_allclose(np.array(origins)[:, 0], np.tile([0.0, 0.0, 18.5 * PLATE_FORCE_M_PER_N], (n, 1)), atol=1e-6)


def test_dft321_of_a_single_axis_tone(recorded):
    """Only ax carries a 150 Hz tone (0.05 m/s²); ay, az are constant: DFT321 returns the high-passed ax,
    i.e. the tone itself, on the accelerometer samples left after trimming 0.5 s at each end (spec §10.2–10.3)."""
    _, out = recorded
    t_ns, rows = temporal(out, "/series/free_space-1/measured/accel/dft321", "Scalars:scalars")
    t = np.arange(int(FREE_SPACE_S * 2000)) / 2000.0
    kept = t[1000:-1000]
    np.testing.assert_array_equal(t_ns, np.round(kept * 1e9).astype(np.int64))
    np.testing.assert_allclose(np.array(rows)[:, 0], 0.05 * np.sin(2 * np.pi * 150 * kept), atol=2e-3)


def test_missing_calibration_is_reported_not_hidden(sessions, tmp_path):
    w = rich_writer("viewer-nocal")
    w.manifest["calibration"] = []
    session = open_session(w.write(tmp_path / "nocal"))
    plan = plan_recording(session, derived="full")
    assert "/series/stiffness-1/measured/hand_force/raw_world" in plan.paths()
    assert "/world/stiffness-1/measured/hand_force/raw" in plan.paths()
    assert not any("calibrated" in p for p in plan.paths())
    assert any("E601" in n for n in plan.notes) and any("E621" in n for n in plan.notes)
    out = write_rrd(plan, tmp_path / "nocal.rrd", blueprints.blueprint_for(plan))
    _, rows = temporal(out, "/series/stiffness-1/measured/hand_force/raw_world", "Scalars:scalars")
    f = np.array(rows, dtype=float)
    ok = np.all(np.isfinite(f), axis=1)
    assert len(f) == 1000 and ok.sum() > 800  # one row per F/T sample; NaN where the pose is unknown
    np.testing.assert_allclose(f[ok, :2], np.tile([0.0, 1.0], (ok.sum(), 1)), atol=1e-12)  # +90° yaw: sensor x → W y
    t_ns, vecs = temporal(out, "/world/stiffness-1/measured/hand_force/raw", "Arrows3D:vectors")
    assert len(t_ns) == ok.sum()
    np.testing.assert_allclose(np.array(vecs)[:, 0, 1], HAND_FORCE_M_PER_N, atol=1e-7)  # 1 N along world y
    commanded_vs_felt = view_named(blueprints.trial_tab(plan, plan.trials[2]), "commanded vs felt force (W)")
    assert list(commanded_vs_felt.contents) == ["+ $origin/measured/commanded/force", "+ $origin/measured/hand_force/raw_world"]
    doc = next(e for e in plan.entries if e.path == "/session").static[0]
    assert "E601" in str(doc.text.as_arrow_array().to_pylist())


def test_workspace_meshes_enclose_the_solids(recorded, sessions):
    """The drawn surfaces enclose exactly the voxels the volume operator counts as inside (spec §8.4),
    and the measured one is close to the swept sphere's 4/3·π·r³."""
    plan, _ = recorded
    main, _, _ = sessions
    from haptify.metrics import workspace
    from haptify_tools.viewer.voxel_mesh import SurfaceMesh

    solid = workspace.volume_solid(workspace.measured_points(main, "workspace-1"))
    for name, expected in (("measured", solid), ("modeled", None)):
        [entry] = [e for e in plan.entries if e.path == f"/world/workspace-1/measured/workspace/{name}"]
        mesh = entry.static[0]
        vertices = np.array(mesh.vertex_positions.as_arrow_array().to_pylist(), dtype=float)
        triangles = np.array(mesh.triangle_indices.as_arrow_array().to_pylist(), dtype=np.int64)
        volume = SurfaceMesh(vertices, triangles, vertices).enclosed_volume()
        if expected is not None:
            inside = float((expected.fraction >= 0.5).sum()) * expected.pitch**3
            assert volume == pytest.approx(inside, rel=1e-4)  # float32 vertices in the archetype
            assert volume == pytest.approx(expected.volume, rel=0.05)
            assert volume == pytest.approx(4 / 3 * np.pi * SPHERE_R**3, rel=0.10)
        else:
            assert volume > 0


@settings(max_examples=40, deadline=None)
@given(
    arrays(np.bool_, st.tuples(st.integers(1, 5), st.integers(1, 5), st.integers(1, 5))),
    st.tuples(st.integers(-50, 50), st.integers(-50, 50), st.integers(-50, 50)),
)
def test_voxel_boundary_mesh_is_closed_and_outward(grid, origin):
    from haptify_tools.viewer.voxel_mesh import SurfaceMesh, boundary_mesh

    pitch = 0.004
    mesh = boundary_mesh(grid, origin, pitch)
    assert mesh.enclosed_volume() == pytest.approx(grid.sum() * pitch**3, rel=1e-9, abs=1e-15)
    padded = np.pad(grid, 1)
    exposed = sum(int((padded & ~np.roll(padded, s, axis=a)).sum()) for a in range(3) for s in (1, -1))
    assert len(mesh.triangles) == 2 * exposed
    # every edge is used once in each direction (closed and consistently wound)
    keys = np.round(mesh.vertices / pitch).astype(np.int64)
    edges = {}
    for tri in mesh.triangles:
        for a, b in ((0, 1), (1, 2), (2, 0)):
            e = (tuple(keys[tri[a]]), tuple(keys[tri[b]]))
            edges[e] = edges.get(e, 0) + 1
    assert all(edges.get((b, a), 0) == n for (a, b), n in edges.items())
    # the compact form: each lattice corner once, the same closed surface
    vertices, triangles = mesh.shared(pitch)
    assert len(np.unique(np.round(vertices / pitch), axis=0)) == len(vertices)
    assert len(triangles) == len(mesh.triangles)
    assert SurfaceMesh(vertices, triangles, vertices).enclosed_volume() == pytest.approx(
        grid.sum() * pitch**3, rel=1e-9, abs=1e-15
    )


# --- the command -------------------------------------------------------------------------------------


def view_args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    cmd_view.register(parser.add_subparsers())
    return parser.parse_args(["view", *argv])


def test_cli_save_one_trial_with_results(sessions, tmp_path, capsys):
    main, _, root = sessions
    res = tmp_path / "results.json"
    res.write_text(results_for(main.session_id).model_dump_json())
    out = tmp_path / "one.rrd"
    args = view_args(str(main.root), "--trial", "workspace-1", "--results", str(res), "--save", str(out))
    assert args.func(args, UI()) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    paths = set(RrdReader(out).store().schema().entity_paths())
    assert "/world/workspace-1/measured/workspace/points" in paths and "/results" in paths
    assert not any(p.startswith("/world/stiffness-1") for p in paths)


def test_cli_without_display_explains_save_and_web(sessions, monkeypatch, capsys):
    main, _, _ = sessions
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(cmd_view.sys, "platform", "linux")
    args = view_args(str(main.root))
    assert args.func(args, UI()) == 2
    err = capsys.readouterr().err
    assert "--save" in err and "--web" in err


def test_cli_usage_errors(sessions):
    main, _, _ = sessions
    for argv, code in (
        (["--port", "9000", "--save", "x.rrd"], "E903"),
        (["--web", "--port", "70000"], "E903"),
        (["--trial", "nope", "--save", "x.rrd"], "E903"),
    ):
        args = view_args(str(main.root), *argv)
        with pytest.raises(HaptifyError) as err:
            args.func(args, UI())
        assert err.value.findings[0].code == code


# --- serving --------------------------------------------------------------------------------------------


def test_web_viewer_on_a_busy_port_is_a_coded_error(recorded):
    import socket

    _, out = recorded
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        viewer = cmd_view.serve_web(out, port)
        with pytest.raises(HaptifyError) as err:
            viewer.wait_until_serving(timeout_s=20)
        assert err.value.findings[0].code == "E904"
        assert viewer.proc.poll() is not None


# The child is the command as typed at a terminal: Ctrl-C raises KeyboardInterrupt there even when this test
# runs where SIGINT is ignored (a background job of a non-interactive shell passes SIG_IGN on to its children).
VIEW_WEB = (
    "import argparse, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "from haptify.cli.main import UI; from haptify_tools.viewer import cmd_view; "
    "p = argparse.ArgumentParser(); cmd_view.register(p.add_subparsers()); "
    "a = p.parse_args(sys.argv[1:]); sys.exit(a.func(a, UI()))"
)


def start_view_web(session_root: Path, port: int, wait_s: float = 90) -> tuple[subprocess.Popen, str]:
    """`haptify view SESSION --trial free_space-1 --web --port PORT` in a child process, and the line that
    announces the web viewer. Its stderr (progress, messages) goes to a file, never to a pipe no one reads:
    a full pipe would block the child's next message."""
    log = tempfile.TemporaryFile("w+")
    proc = subprocess.Popen(
        [sys.executable, "-c", VIEW_WEB, "view", str(session_root), "--trial", "free_space-1", "--web", "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=log,
        text=True,
    )
    line = ""
    deadline = time.monotonic() + wait_s
    while "web viewer:" not in line and time.monotonic() < deadline and proc.poll() is None:
        line = proc.stdout.readline()
    if "web viewer:" not in line:  # what the child said instead, for the failing assertion
        log.seek(0)
        line += log.read()[-2000:]
    return proc, line


def stop_child(proc: subprocess.Popen) -> None:
    """A failed check: SIGTERM stops `haptify view --web` with its viewer (a bare kill would orphan it)."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def test_view_web_command_serves_until_interrupted(sessions, tmp_path):
    """`haptify view SESSION --web --port N` end to end: prints the address, answers, and Ctrl-C stops
    the viewer (no rerun process keeps the port)."""
    import signal
    import socket

    main, _, _ = sessions
    port = cmd_view.free_port()
    proc, line = start_view_web(main.root, port)
    try:
        assert f"http://127.0.0.1:{port}/?url=" in line, line
        assert "rerun%2Bhttp%3A%2F%2F127.0.0.1%3A" in line  # the viewer is pointed at a loopback gRPC proxy
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as resp:
            assert resp.status == 200
            assert b"<html" in resp.read(4096).lower()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
    finally:
        stop_child(proc)
    with socket.socket() as s:  # the port is free again: the rerun binary is gone
        s.bind(("127.0.0.1", port))


def test_a_simulate_output_folder_opens_as_its_session(sessions, tmp_path):
    main, _, _ = sessions
    dossier = tmp_path / "dossier"
    dossier.mkdir()
    (dossier / "session").symlink_to(main.root, target_is_directory=True)
    assert cmd_view.open_session_or_dossier(str(dossier)).session_id == main.session_id
    assert cmd_view.open_session_or_dossier(str(main.root)).session_id == main.session_id


@pytest.mark.skipif(not CHROMIUM.exists(), reason=f"screenshot test needs Chromium at {CHROMIUM} (not installed here)")
def test_web_viewer_screenshot(recorded, tmp_path):
    """The web viewer really draws the recording in a headless browser (software WebGL).

    Chromium's ``--screenshot`` fires after *virtual* time, before the viewer's WebAssembly has compiled
    in real time, so Playwright drives the system Chromium and screenshots until the UI has drawn
    (thousands of distinct colours; the loading screen has a few hundred), within a bounded time.
    """
    from matplotlib.image import imread
    from playwright.sync_api import sync_playwright

    _, out = recorded
    port = cmd_view.free_port()
    viewer = cmd_view.serve_web(out, port)
    shot = tmp_path / "viewer.png"
    colours = 0
    try:
        viewer.wait_until_serving(timeout_s=20)
        with sync_playwright() as pw:
            browser = pw.chromium.launch(
                executable_path=str(CHROMIUM),
                args=[
                    "--no-sandbox",
                    "--use-angle=swiftshader",
                    "--enable-unsafe-swiftshader",
                    "--no-first-run",
                    "--disable-background-networking",
                    "--disable-component-update",
                    "--disable-sync",
                ],
            )
            try:
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(viewer.url, timeout=30_000)
                deadline = time.monotonic() + 120
                while colours <= 1500 and time.monotonic() < deadline:
                    page.wait_for_timeout(2000)
                    page.screenshot(path=str(shot))
                    img = imread(shot)
                    colours = len(np.unique(img.reshape(-1, img.shape[-1]), axis=0))
            finally:
                browser.close()
    finally:
        viewer.stop()
    assert shot.is_file() and shot.stat().st_size > 0, "Chromium wrote no screenshot"
    assert colours > 1500, f"the viewer did not draw the recording within 120 s ({colours} colours: loading screen)"


# --- streaming, chunks and derived modes -------------------------------------------------

# Raw stream kind → the time series that show its columns exactly (None: every column of the stream).
RAW_SERIES = {
    "handle_pose": [("handle/position", ["px", "py", "pz"])],
    "handle_wrench": [("handle/force_raw", ["fx", "fy", "fz"]), ("handle/torque_raw", ["tx", "ty", "tz"])],
    "commanded_wrench": [("commanded/force", ["fx", "fy", "fz"]), ("commanded/torque", ["tx", "ty", "tz"])],
    "handle_accel": [("accel/raw", ["ax", "ay", "az"])],
    "plate_wrench": [
        ("plate/corner_force_raw", [f"c{i}_f{a}" for i in range(1, 5) for a in "xyz"]),
        ("plate/corner_torque_raw", [f"c{i}_t{a}" for i in range(1, 5) for a in "xyz"]),
    ],
    "device_joint_angles": [("device/joint_angles", None)],
    "sync": [("sync/trigger", ["trigger"])],
}
DERIVED_PARTS = (
    "calibrated",
    "raw_world",
    "dft321",
    "accel/world",
    "plate/force",
    "plate/cop",
    "plate_force",
    "contact/",
    "force_field",
    "workspace/measured",
    "workspace/modeled",
    "hand_force/raw",
)


def column_values(path: Path, entity: str, component: str) -> tuple[np.ndarray, np.ndarray]:
    t_ns, rows = temporal(path, entity, component)
    return t_ns, np.array(rows, dtype=np.float64).reshape(len(t_ns), -1)


@pytest.fixture(scope="module")
def raw_only(sessions):
    """The default recording (derived signals off) written by `haptify view --save` through the gate."""
    main, _, root = sessions
    out = root / "raw.rrd"
    args = view_args(str(main.root), "--save", str(out))
    assert args.derived == "off"
    assert args.func(args, UI()) == 0
    return out


def test_raw_only_recording_holds_every_raw_value_exactly(raw_only, sessions):
    """Every column of every stream of every trial is in the recording, value for value (float64, NaN
    kept in series) at its exact nanosecond; nothing derived is recorded."""
    main, _, _ = sessions
    paths = set(RrdReader(raw_only).store().schema().entity_paths())
    for trial in main.trials:
        for stream in trial.streams:
            frame = main.read_stream(stream)
            cols = [c for c in frame.columns if c != "t"]
            t_ns = time_ns(frame["t"].to_numpy())
            covered: list[str] = []
            if stream.kind in RAW_SERIES:
                for key, names in RAW_SERIES[stream.kind]:
                    names = names or cols
                    got_t, got = column_values(raw_only, f"/series/{trial.id}/measured/{key}", "Scalars:scalars")
                    np.testing.assert_array_equal(got_t, t_ns, err_msg=f"{trial.id} {key}")
                    np.testing.assert_array_equal(got, frame[names].to_numpy(), err_msg=f"{trial.id} {key}")
                    covered += names
            if stream.kind == "handle_pose":  # the orientation is the handle's transform (float32, rows of known pose)
                q = frame[["qw", "qx", "qy", "qz"]].to_numpy()
                ok = np.all(np.isfinite(frame[["px", "py", "pz", "qw", "qx", "qy", "qz"]].to_numpy()), axis=1)
                got_t, got_q = column_values(raw_only, f"/world/{trial.id}/measured/handle", "Transform3D:quaternion")
                np.testing.assert_array_equal(got_t, t_ns[ok])
                np.testing.assert_array_equal(got_q, q[ok][:, [1, 2, 3, 0]].astype(np.float32))
                covered += ["qw", "qx", "qy", "qz"]
            elif stream.kind == "markers":  # one labelled cloud per link; frames where any of its markers is known
                for entity in sorted(p for p in paths if p.startswith(f"/world/{trial.id}/measured/markers/")):
                    labels = static_labels(raw_only, entity)
                    xyz = np.stack([frame[[f"{m}_{a}" for a in "xyz"]].to_numpy() for m in labels], axis=1)
                    ok = np.isfinite(xyz).all(axis=2).any(axis=1)
                    got_t, rows = temporal(raw_only, entity, "Points3D:positions")
                    np.testing.assert_array_equal(got_t, t_ns[ok])
                    got = np.array(rows, dtype=np.float32).reshape(xyz[ok].shape)
                    np.testing.assert_array_equal(got, xyz[ok].astype(np.float32))  # rerun stores positions as float32
                    covered += [f"{m}_{a}" for m in labels for a in "xyz"]
            elif stream.kind == "link_poses":
                for link in stream.entities:
                    p = frame[[f"{link}_p{a}" for a in "xyz"]].to_numpy()
                    q = frame[[f"{link}_q{a}" for a in "wxyz"]].to_numpy()
                    got_t, got_p = column_values(raw_only, f"/world/{trial.id}/measured/links/{link}", "Transform3D:translation")
                    _, got_q = column_values(raw_only, f"/world/{trial.id}/measured/links/{link}", "Transform3D:quaternion")
                    np.testing.assert_array_equal(got_t, t_ns)
                    np.testing.assert_array_equal(got_p, p.astype(np.float32))
                    np.testing.assert_array_equal(got_q, q[:, [1, 2, 3, 0]].astype(np.float32))
                    covered += [f"{link}_p{a}" for a in "xyz"] + [f"{link}_q{a}" for a in "wxyz"]
            assert sorted(covered) == sorted(cols), (trial.id, stream.kind)
    derived = sorted(p for p in paths if any(part in p for part in DERIVED_PARTS))
    assert not derived, derived
    assert "/world/stiffness-1/measured/handle" in paths and "/series/stiffness-1/measured/penetration" in paths
    assert RrdReader(raw_only).blueprints()  # the blueprint, sent after the data, is in the file


def test_streamed_in_small_chunks_equals_the_recording_kept_whole(recorded, sessions, tmp_path):
    """build() streaming entity by entity in chunks of 7 rows writes the same entities, times and values as
    write_rrd() of the plan kept in memory (one send per entity)."""
    plan, whole = recorded
    main, other, _ = sessions
    out = tmp_path / "chunked.rrd"
    streamed = build(main, out, results=results_for(main.session_id), other=other, derived="full", chunk_rows=7)
    assert [(e.path, e.rows, e.series, e.stream) for e in streamed.entries] == [
        (e.path, e.rows, e.series, e.stream) for e in plan.entries
    ]
    assert max(ch.num_rows for ch in RrdReader(out).stream().filter(is_static=False)) <= 7
    a, b = temporal_batches(whole), temporal_batches(out)
    assert sorted(a) == sorted(b)
    for entity, batches in a.items():
        components = {n for rb in batches for n in rb.schema.names if ":" in n}
        for component in components:
            ta, va = temporal(whole, entity, component)
            tb, vb = temporal(out, entity, component)
            np.testing.assert_array_equal(ta, tb, err_msg=entity)
            assert va == vb or np.array_equal(np.array(va, dtype=float), np.array(vb, dtype=float), equal_nan=True), entity
    assert static_text(out, "/results") == static_text(whole, "/results")


def test_compact_derived_signals(recorded, sessions, tmp_path):
    """compact: raw series unchanged; derived series as float32, at most 100 Hz — the 1 kHz plate force as a
    min/max envelope of 10-sample bins, the 2 kHz DFT321 of 20-sample bins — and 1 kHz arrows every 10th."""
    _, whole = recorded
    main, _, _ = sessions
    out = tmp_path / "compact.rrd"
    build(main, out, derived="compact")
    for entity in ("/series/stiffness-1/measured/handle/force_raw", "/series/free_space-1/measured/plate/corner_force_raw"):
        np.testing.assert_array_equal(
            column_values(out, entity, "Scalars:scalars")[1], column_values(whole, entity, "Scalars:scalars")[1]
        )
    n = int(FREE_SPACE_S * 1000)
    t_ns, f = column_values(out, "/series/free_space-1/measured/plate/force", "Scalars:scalars")
    all_ns = time_ns(np.arange(n) / 1000.0)
    np.testing.assert_array_equal(t_ns, np.sort(np.concatenate([all_ns[0::10], all_ns[5::10]])))
    np.testing.assert_array_equal(f, np.tile([0.0, 0.0, -18.5], (n // 5, 1)))
    for entity, k in (
        ("/series/free_space-1/measured/accel/dft321", 20),
        ("/series/stiffness-1/measured/hand_force/calibrated", 1),
    ):
        full_t, full = column_values(whole, entity, "Scalars:scalars")
        t_ns, env = column_values(out, entity, "Scalars:scalars")
        if k == 1:  # already at 100 Hz: only float32
            np.testing.assert_array_equal(t_ns, full_t)
            np.testing.assert_array_equal(env, full.astype(np.float32).astype(np.float64))
            continue
        bins = -(-len(full) // k)
        assert len(t_ns) == 2 * bins
        for b in range(bins):
            chunk = full[b * k : (b + 1) * k].astype(np.float32)
            np.testing.assert_array_equal(env[2 * b], chunk.min(axis=0))
            np.testing.assert_array_equal(env[2 * b + 1], chunk.max(axis=0))
    arrows_t, _ = temporal(out, "/world/free_space-1/measured/plate_force", "Arrows3D:origins")
    np.testing.assert_array_equal(arrows_t, all_ns[::10])
    from haptify_tools.viewer.voxel_mesh import SurfaceMesh

    for name in ("measured", "modeled"):  # the workspace meshes: shared corners, no normals, the same volume
        meshes = []
        for path in (whole, out):
            [ch] = list(RrdReader(path).stream().filter(content=f"/world/workspace-1/measured/workspace/{name}", is_static=True))
            rb = ch.to_record_batch()
            v = np.array(rb.column("Mesh3D:vertex_positions").to_pylist()[0], dtype=float)
            tri = np.array(rb.column("Mesh3D:triangle_indices").to_pylist()[0], dtype=np.int64)
            meshes.append((v, tri, "Mesh3D:vertex_normals" in rb.schema.names))
        (v_full, t_full, normals_full), (v_compact, t_compact, normals_compact) = meshes
        assert normals_full and not normals_compact and len(v_compact) < len(v_full) / 2
        assert SurfaceMesh(v_compact, t_compact, v_compact).enclosed_volume() == pytest.approx(
            SurfaceMesh(v_full, t_full, v_full).enclosed_volume(), rel=1e-5
        )
    assert out.stat().st_size < whole.stat().st_size


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 120), st.integers(1, 4), st.integers(1, 15), st.data())
def test_envelope_holds_each_bins_extremes(n, c, k, data):
    values = data.draw(arrays(np.float64, (n, c), elements=st.floats(-1e6, 1e6) | st.just(np.nan)))
    t = np.cumsum(data.draw(arrays(np.int64, n, elements=st.integers(1, 10**7))))
    t_env, env = envelope(t, values, k)
    bins = -(-n // k)
    assert env.shape == (2 * bins, c) and len(t_env) == 2 * bins
    assert np.all(np.diff(t_env) >= 0)
    for b in range(bins):
        chunk = values[b * k : (b + 1) * k]
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            np.testing.assert_array_equal(env[2 * b], np.nanmin(chunk, axis=0))
            np.testing.assert_array_equal(env[2 * b + 1], np.nanmax(chunk, axis=0))
        assert t_env[2 * b] == t[b * k] and t[b * k] <= t_env[2 * b + 1] <= t[min((b + 1) * k, n) - 1]


def test_decimation_factor_brings_the_rate_to_at_most_100_hz():
    for rate, k in ((100.0, 1), (50.0, 1), (1000.0, 10), (2000.0, 20), (150.0, 2), (1001.0, 11)):
        assert decimation_factor(time_ns(np.arange(50) / rate)) == k, rate
    assert decimation_factor(np.array([5], dtype=np.int64)) == 1


def test_unknown_derived_mode_and_chunk_size_are_usage_errors(sessions, tmp_path):
    main, _, _ = sessions
    for kw in ({"derived": "most"}, {"chunk_rows": 0}):
        with pytest.raises(HaptifyError) as err:
            build(main, tmp_path / "x.rrd", **kw)
        assert err.value.findings[0].code == "E903"
    assert not any(tmp_path.iterdir())


def test_forget_trial_drops_only_that_trials_memos(sessions):
    from haptify.pipeline.compute import ComputeContext

    main, _, _ = sessions
    ctx = ComputeContext(session=main)
    for key in (
        ("handle_calibration",),
        ("handle_signals", "stiffness-1", 100.0),
        ("plate_signals", "free_space-1"),
        ("vibration", "stiffness-1"),
    ):
        ctx.cached(key, lambda: object())
    ctx.forget_trial("stiffness-1")
    assert set(ctx._cache) == {("handle_calibration",), ("plate_signals", "free_space-1")}


def test_view_web_command_stopped_by_sigterm_leaves_no_viewer(sessions):
    """`kill` (SIGTERM) of `haptify view --web` stops the rerun viewer it started, as Ctrl-C does: the port is
    free again afterwards (an orphaned viewer would keep it and a CPU core)."""
    import signal
    import socket

    main, _, _ = sessions
    port = cmd_view.free_port()
    proc, line = start_view_web(main.root, port)
    try:
        assert "web viewer:" in line, line
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
    finally:
        stop_child(proc)
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))


@settings(max_examples=60, deadline=None)
@given(
    width=st.integers(1, 12),
    rows=st.integers(0, 40),
    picks=st.lists(st.integers(0, 11), min_size=1, max_size=8),
    layout=st.sampled_from(["stream reader", "separate columns"]),
)
def test_columns_of_is_the_stacked_columns_and_a_read_only_view_when_they_lie_side_by_side(width, rows, picks, layout):
    import pandas as pd
    import pyarrow as pa

    from haptify.formats.storage.stream_files import arrow_frame

    names = [f"c{k}" for k in range(width)]
    chosen = [names[k % width] for k in picks]
    data = {name: np.arange(rows, dtype=np.float64) * (k + 1) + k / 8 for k, name in enumerate(names)}
    if layout == "stream reader":  # one (columns × rows) block, as a stream is read
        frame = arrow_frame(pa.table(data))
    else:
        frame = pd.DataFrame({name: column.copy() for name, column in data.items()})
    got = columns_of(frame, chosen)
    np.testing.assert_array_equal(got, np.column_stack([data[name] for name in chosen]))
    shared = np.shares_memory(got, frame[chosen[0]].to_numpy())
    assert not (shared and got.flags.writeable)  # a view of the table is read-only
    if layout == "stream reader" and rows:  # a view exactly when the columns are evenly spaced in the block
        positions = [names.index(name) for name in chosen]
        assert shared == (len(set(np.diff(positions))) <= 1)


def test_side_by_side_refuses_columns_that_are_not_evenly_spaced_in_one_block():
    block = np.arange(40.0).reshape(4, 10)
    view = side_by_side([block[3], block[2], block[1]])  # in reverse order: a negative step
    assert view is not None and not view.flags.writeable
    np.testing.assert_array_equal(view, block[::-1][:3].T)
    assert side_by_side([block[0], block[1], block[3]]) is None  # uneven spacing
    assert side_by_side([block[0], block[1, ::2]]) is None  # another length and stride
    other = np.arange(40.0).reshape(4, 10)
    assert side_by_side([block[0], other[1]]) is None  # two owners
    assert side_by_side([block[0], block[1].astype(np.float32)]) is None  # another dtype
