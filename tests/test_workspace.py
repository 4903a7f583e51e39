"""Workspace volume operator and metrics (spec chapter 8): answers known by construction."""

from __future__ import annotations

import copy
import functools
import math
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull

from haptify.formats.conventions import pose_apply, quat_from_axis_angle, quat_rotate
from haptify.formats.session_format import Device
from haptify.formats.storage import SessionWriter, open_session
from haptify.metrics import volume_operator
from haptify.metrics.volume_operator import _blocks_near
from haptify.metrics.workspace import (
    compute,
    gap_regions,
    longest_occlusion_gap,
    modeled_solid,
    occlusion_gaps,
    overlap_volume,
    repaired_points,
    volume_solid,
)
from haptify.pipeline.compute import ComputeContext, compute_session
from haptify.pipeline.results import MetricResult, Unavailable
from haptify.processing.kinematics import configurations_from_unit, forward_positions
from haptify.report.figures.workspace import report_figures
from haptify_tools.conformance_fixtures.workspace_shapes import box_cloud, pose_cloud, sphere_sweep
from haptify_tools.conformance_fixtures.workspace_shapes import sphere_cloud as sphere_surface
from haptify_tools.example_session import IDENTITY, TOUCH_DEVICE, example_rig

DEG = math.pi / 180
RNG_SEED = 20261122


def touch_x_device() -> dict:
    """The Touch X of the paper's Table II (upper q3 limit −20° − 0.85·q2)."""
    dev = copy.deepcopy(TOUCH_DEVICE)
    dev["model"] = "Touch X"
    j1, j2, j3 = dev["kinematics"]["joints"]
    j1["lower"]["constant"], j1["upper"]["constant"] = -52 * DEG, 52 * DEG
    j2["a"], j2["upper"]["constant"] = 0.133, 100 * DEG
    j3["a"], j3["upper"]["constant"] = 0.133, -20 * DEG
    dev["datasheet"]["workspace_box_m"] = [0.16, 0.12, 0.12]
    return dev


def kin(dev: dict):
    return Device.model_validate(dev).kinematics


def box_surface(n: int, edges, rng, rotation=None, centre=(0.0131, -0.0217, 0.2033)) -> np.ndarray:
    """Samples on the faces of a box (area-weighted), rotated about its centre by ``rotation`` (wxyz)."""
    return box_cloud(n, edges, rng, np.array([1.0, 0.0, 0.0, 0.0]) if rotation is None else rotation, centre)


def pappus_volume(dev: dict, n: int = 1500) -> float:
    """Exact reference: the reachable set is a solid of revolution about the q1 axis of the planar (r, z)
    region swept by (q2, q3); V = Δq1 · ∬ |r| dA with dA = a2·a3·|sin q3| dq2 dq3 (midpoint rule; the
    map is one-to-one because sin q3 keeps its sign inside the limits)."""
    j1, j2, j3 = dev["kinematics"]["joints"]
    a2, a3 = j2["a"], j3["a"]
    q2 = j2["lower"]["constant"] + (np.arange(n) + 0.5) / n * (j2["upper"]["constant"] - j2["lower"]["constant"])
    dq2 = (j2["upper"]["constant"] - j2["lower"]["constant"]) / n
    s = (np.arange(n) + 0.5) / n
    lo3 = j3["lower"]["constant"] + 0 * q2
    hi3 = j3["upper"]["constant"] + j3["upper"].get("coefficients", {}).get("q2", 0.0) * q2
    Q2 = q2[:, None]
    Q3 = lo3[:, None] + s[None, :] * (hi3 - lo3)[:, None]
    dq3 = ((hi3 - lo3) / n)[:, None]
    r = a2 * np.cos(Q2) + a3 * np.cos(Q2 + Q3)
    area = a2 * a3 * np.abs(np.sin(Q3)) * dq2 * dq3
    return (j1["upper"]["constant"] - j1["lower"]["constant"]) * float(np.sum(np.abs(r) * area))


# --- the operator on analytic shapes (spec §8.4) ------------------------------------------------


@pytest.mark.parametrize("n", [20_000, 100_000])
def test_sphere_sampled_on_its_boundary(n):
    rng = np.random.default_rng(RNG_SEED)
    solid = volume_solid(sphere_surface(n, 0.1, [0.013, -0.021, 0.2], rng))
    assert solid.closed
    assert solid.volume == pytest.approx(4 / 3 * math.pi * 0.1**3, rel=0.01)


@pytest.mark.parametrize("rotation", [None, quat_from_axis_angle(np.array([1.0, 2.0, 3.0]), np.array(0.7))])
def test_box_sampled_on_its_faces(rotation):
    rng = np.random.default_rng(RNG_SEED)
    edges = (0.16, 0.12, 0.12)
    solid = volume_solid(box_surface(60_000, edges, rng, rotation))
    assert solid.closed
    assert solid.volume == pytest.approx(math.prod(edges), rel=0.02)


def two_lobes(n: int, rng, radius=0.06, gap=0.1):
    """Two overlapping spheres (centres ``gap`` apart): samples on the boundary of their union only."""
    c1, c2 = np.array([0.0, 0.0, 0.1]), np.array([gap, 0.0, 0.1])
    p = np.concatenate([sphere_surface(n, radius, c1, rng), sphere_surface(n, radius, c2, rng)])
    keep = (np.linalg.norm(p - c1, axis=1) >= radius - 1e-12) & (np.linalg.norm(p - c2, axis=1) >= radius - 1e-12)
    cap = math.pi * (radius - gap / 2) ** 2 * (3 * radius - (radius - gap / 2)) / 3  # one lens half
    return p[keep], 2 * (4 / 3 * math.pi * radius**3) - 2 * cap


def test_two_lobes_non_convex_volume_is_not_the_hull():
    rng = np.random.default_rng(RNG_SEED)
    pts, exact = two_lobes(40_000, rng)
    solid = volume_solid(pts)
    assert solid.closed
    # the closing fills a fillet of radius r into the crease between the lobes: a small excess
    assert solid.volume == pytest.approx(exact, rel=0.012)
    assert exact < 0.9 * ConvexHull(pts).volume  # a convex hull would be >10 % off: it bridges the waist


def test_open_shell_is_flagged_not_silently_tiny():
    rng = np.random.default_rng(RNG_SEED)
    p = sphere_surface(40_000, 0.1, [0.0, 0.0, 0.2], rng)
    p = p[p[:, 2] < 0.2 + 0.05]  # a cap of 60° half-angle cut away: the hole is far wider than 2r
    solid = volume_solid(p)
    assert not solid.closed
    assert solid.volume < 0.5 * solid.hull_volume


def test_sparse_sweep_seals_with_the_closing_radius():
    rng = np.random.default_rng(RNG_SEED)
    sparse = sphere_surface(2_000, 0.1, [0.0, 0.0, 0.2], rng)  # ~8 mm between samples, well below 2r
    solid = volume_solid(sparse)
    assert solid.closed
    assert solid.volume == pytest.approx(4 / 3 * math.pi * 0.1**3, rel=0.015)


def test_the_lattice_is_anchored_at_the_world_origin():
    rng = np.random.default_rng(RNG_SEED)
    pts = sphere_surface(5_000, 0.05, [0.3, 0.2, 0.1], rng)
    a = volume_solid(pts)
    k = 3 * volume_operator.PARAMETERS.closing_coarsening  # a whole number of coarse voxels: the same voxelisation
    b = volume_solid(pts + k * a.pitch)
    np.testing.assert_array_equal(np.add(a.origin, k), b.origin)
    np.testing.assert_allclose(a.fraction, b.fraction, atol=1e-5)


@settings(max_examples=4, deadline=None)
@given(
    st.floats(-3.0, 3.0),
    st.floats(-3.0, 3.0),
    st.floats(-3.0, 3.0),
    st.floats(0.0, math.pi),
    st.floats(-0.2, 0.2),
    st.floats(-0.2, 0.2),
)
def test_volume_does_not_depend_on_the_world_frame(ax, ay, az, angle, dx, dy):
    if ax * ax + ay * ay + az * az < 1e-6:
        ax = 1.0
    pts, base = box_reference()
    moved = quat_rotate(quat_from_axis_angle(np.array([ax, ay, az]), np.array(angle)), pts) + [dx, dy, 0.0]
    assert volume_solid(moved).volume == pytest.approx(base, rel=0.01)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.tuples(*[st.floats(2.0, 9.0, allow_nan=False)] * 3), min_size=1, max_size=4),
    st.sampled_from([1, 2, 3]),
    st.floats(0.5, 5.0),
)
def test_the_nearest_sample_search_skips_only_coarse_voxels_out_of_reach(points, c, reach):
    """§8.4 step 5's search is limited to the coarse voxels :func:`_blocks_near` marks: every fine voxel
    centre within ``reach`` fine voxels of a point (coordinates in fine voxels) lies in a marked one."""
    pts = np.array(points)
    shape = (12 // c + 1,) * 3
    near = _blocks_near(shape, np.floor(pts).astype(np.int64) // c, c, reach)
    centres = np.stack(np.meshgrid(*[np.arange(shape[0] * c)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) + 0.5
    within = (np.linalg.norm(centres[:, None, :] - pts[None], axis=2) <= reach).any(axis=1)
    blocks = (centres[within] // c).astype(np.int64)
    assert near[tuple(blocks.T)].all()


@functools.lru_cache(maxsize=1)
def box_reference():
    pts = box_surface(30_000, (0.12, 0.1, 0.08), np.random.default_rng(RNG_SEED))
    return pts, volume_solid(pts).volume


def test_coverage_of_half_a_sphere():
    rng = np.random.default_rng(RNG_SEED)
    whole = volume_solid(sphere_surface(30_000, 0.08, [0.0, 0.0, 0.2], rng))
    half_pts = sphere_surface(30_000, 0.08, [0.0, 0.0, 0.2], rng)
    half_pts = half_pts[half_pts[:, 2] >= 0.2]
    disc = rng.random((20_000, 2)) * 2 - 1
    disc = disc[np.sum(disc**2, axis=1) <= 1] * 0.08
    half = volume_solid(np.concatenate([half_pts, np.column_stack([disc, np.full(len(disc), 0.2)])]))
    assert half.volume == pytest.approx(whole.volume / 2, rel=0.02)
    assert overlap_volume(half, whole) / whole.volume == pytest.approx(0.5, abs=0.01)
    assert overlap_volume(whole, whole) == pytest.approx(whole.volume, rel=1e-12)


def test_too_few_points_and_absurd_extent_are_coded_errors():
    from haptify.errors import HaptifyError

    with pytest.raises(HaptifyError) as few:
        volume_solid(np.zeros((10, 3)))
    assert few.value.code == "E313"
    rng = np.random.default_rng(RNG_SEED)
    pts = sphere_surface(1_000, 0.1, [0.0, 0.0, 0.2], rng)
    pts[0] = [5.0, 5.0, 5.0]  # one marker swap throws a point metres away
    with pytest.raises(HaptifyError) as far:
        volume_solid(pts)
    assert far.value.code == "E313"


# --- the modeled workspace (spec §8.3) ----------------------------------------------------------


@pytest.fixture(scope="module")
def touch_model():
    return modeled_solid(kin(TOUCH_DEVICE))


def test_pappus_reference_reproduces_the_notes():
    assert pappus_volume(TOUCH_DEVICE) == pytest.approx(13.40e-3, rel=0.005)


def test_touch_model_matches_the_paper_and_pappus(touch_model):
    assert touch_model.closed
    assert touch_model.volume == pytest.approx(13_223e-6, rel=0.03)  # paper §VI-A
    assert touch_model.volume == pytest.approx(pappus_volume(TOUCH_DEVICE), rel=0.015)


def test_touch_x_model_matches_the_paper():
    dev = touch_x_device()
    solid = modeled_solid(kin(dev))
    assert solid.volume == pytest.approx(10_279e-6, rel=0.03)
    assert solid.volume == pytest.approx(pappus_volume(dev), rel=0.015)


def test_table_ii_sign_reading():
    """Table II lost its signs: only the upper limit −10° − 0.85·θ2 reproduces the paper's 13 223 cm³."""
    plus = copy.deepcopy(TOUCH_DEVICE)
    plus["kinematics"]["joints"][2]["upper"]["coefficients"] = {"q2": 0.85}
    assert pappus_volume(plus) > 1.3 * 13_223e-6
    assert pappus_volume(TOUCH_DEVICE) == pytest.approx(13_223e-6, rel=0.03)


def mini_device(scale: float = 0.45) -> dict:
    """The Touch scaled down (links × ``scale``): the same shape, a smaller grid, fast tests."""
    dev = copy.deepcopy(TOUCH_DEVICE)
    for j in dev["kinematics"]["joints"]:
        j["a"] *= scale
    return dev


@pytest.fixture(scope="module")
def mini_model():
    return modeled_solid(kin(mini_device()))


def test_model_volume_scales_with_the_cube_of_the_links(mini_model):
    assert mini_model.volume == pytest.approx(pappus_volume(mini_device()), rel=0.015)
    assert pappus_volume(mini_device()) == pytest.approx(0.45**3 * pappus_volume(TOUCH_DEVICE), rel=1e-9)


def test_model_placement_moves_the_solid_not_its_volume(mini_model):
    q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), np.array(math.pi / 2))
    placed = modeled_solid(kin(mini_device()), [0.05, -0.02, 0.03], q)
    assert placed.volume == pytest.approx(mini_model.volume, rel=0.01)
    assert overlap_volume(placed, mini_model) < 0.9 * mini_model.volume


# --- session level (spec §8.7) ------------------------------------------------------------------

PLACEMENT = {"position": [0.0, 0.05, 0.0], "quaternion": list(quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), np.array(0.3)))}


def boundary_sweep(dev: dict, n: int, rng, drop_lower_lobe: bool = False) -> np.ndarray:
    """An examiner sweeping the faces of the joint-limit box (paper §IV-A), in W via PLACEMENT."""
    k = kin(dev)
    s = rng.random((n, 3))
    s[np.arange(n), rng.integers(0, 3, n)] = rng.integers(0, 2, n)
    q = configurations_from_unit(k, s)
    p = forward_positions(k, q[~np.isnan(q).any(axis=1)])
    if drop_lower_lobe:  # the base blocks the lower lobe: the examiner slides along it (paper Fig. 5)
        p[:, 2] = np.maximum(p[:, 2], -0.5 * max(j["a"] for j in dev["kinematics"]["joints"]))
    return pose_apply(np.array(PLACEMENT["position"]), np.array(PLACEMENT["quaternion"]), p)


def workspace_session(tmp_path: Path, device: dict, clouds: list[np.ndarray]) -> Path:
    w = SessionWriter(
        manifest={
            "session_id": "ws-test",
            "date": "2026-11-22",
            "lab": {"id": "lab"},
            "examiner": {"id": "ex"},
            "device": device,
            "device_placement": PLACEMENT,
            "rig": example_rig(),
        }
    )
    for i, cloud in enumerate(clouds, start=1):
        w.add_trial(f"workspace-{i}", "workspace", powered=False, repetition=i)
        t = np.arange(len(cloud)) / 100.0
        cloud = cloud.copy()
        if i == 1:  # occlusions, in the first trial only: these clouds are boundary samples in random order, not
            cloud[::97] = np.nan  # sweeps, so a gap's reach (spec §8.7) would span the workspace and repair any trial
        w.add_stream(
            f"workspace-{i}",
            "handle_pose",
            {
                "t": t,
                "px": cloud[:, 0],
                "py": cloud[:, 1],
                "pz": cloud[:, 2],
                "qw": 1 + 0 * t,
                "qx": 0 * t,
                "qy": 0 * t,
                "qz": 0 * t,
            },
            rate_hz=100,
        )
    return w.write(tmp_path / "session")


def by_id(items):
    return {m.id: m for m in items}


def test_session_metrics_for_a_full_sweep_and_a_missing_lobe(tmp_path, mini_model):
    rng = np.random.default_rng(RNG_SEED)
    dev = mini_device()
    full = boundary_sweep(dev, 15_000, rng)
    lobeless = boundary_sweep(dev, 15_000, rng, drop_lower_lobe=True)
    ctx = ComputeContext(session=open_session(workspace_session(tmp_path, dev, [full, lobeless])))
    res = by_id(compute(ctx))
    assert all(isinstance(m, MetricResult) for m in res.values())
    modeled = res["workspace.modeled_volume"].value
    assert modeled == pytest.approx(mini_model.volume, rel=0.01)  # placement changes nothing
    assert res["workspace.spec_box_volume"].value == pytest.approx(0.16 * 0.12 * 0.07)
    measured = res["workspace.measured_volume"]
    assert measured.n == 2 and measured.trials == ["workspace-1", "workspace-2"]
    assert measured.per_repetition[0] == pytest.approx(modeled, rel=0.02)
    assert measured.per_repetition[1] < 0.97 * modeled
    assert measured.value == pytest.approx(np.mean(measured.per_repetition))
    assert measured.sd == pytest.approx(np.std(measured.per_repetition, ddof=1))
    cov = res["workspace.coverage"].per_repetition
    assert cov[0] == pytest.approx(1.0, abs=0.02)
    assert cov[1] < cov[0] - 0.02
    ratio = res["workspace.volume_ratio"].per_repetition
    assert ratio[0] == pytest.approx(measured.per_repetition[0] / modeled)
    # every 97th row of the first trial occluded (workspace_session): each gap is one row, its chord joins the
    # rows either side; the second trial has none
    rows = np.arange(97, len(full) - 1, 97)
    assert measured.diagnostics["longest_occlusion_gap_m"] == pytest.approx(
        [np.linalg.norm(full[rows + 1] - full[rows - 1], axis=1).max(), 0.0]
    )
    assert measured.diagnostics["repair_points"][1] == 0
    assert not ctx.warnings
    assert [f.name for f in report_figures(ctx, None)] == ["workspace"]
    plt.close("all")


def test_missing_kinematics_trials_and_datasheet_are_unavailable_with_codes(tmp_path):
    dev = copy.deepcopy(TOUCH_DEVICE)
    del dev["kinematics"]
    dev["datasheet"] = {}
    w = SessionWriter(
        manifest={
            "session_id": "ws-none",
            "date": "2026-11-22",
            "lab": {"id": "lab"},
            "examiner": {"id": "ex"},
            "device": dev,
            "device_placement": IDENTITY,
            "rig": example_rig(),
        }
    )
    w.add_trial("other-1", "other", powered=False, label="nothing")
    res = by_id(compute(ComputeContext(session=open_session(w.write(tmp_path / "s")))))
    assert all(isinstance(m, Unavailable) for m in res.values())
    assert res["workspace.modeled_volume"].code == "E311"
    assert res["workspace.spec_box_volume"].code == "E312"
    assert res["workspace.measured_volume"].code == "E310"
    assert set(res) == {
        "workspace.modeled_volume",
        "workspace.spec_box_volume",
        "workspace.measured_volume",
        "workspace.volume_ratio",
        "workspace.coverage",
    }


def test_an_open_sweep_is_left_out_when_a_closed_one_exists(tmp_path):
    rng = np.random.default_rng(RNG_SEED)
    dev = mini_device()
    full = boundary_sweep(dev, 15_000, rng)
    open_top = full[full[:, 2] > np.median(full[:, 2])]
    ctx = ComputeContext(
        session=open_session(workspace_session(tmp_path, dev, [full, open_top])), wanted={"workspace.measured_volume"}
    )
    res = by_id(compute(ctx))
    measured = res["workspace.measured_volume"]
    assert measured.trials == ["workspace-1"] and not measured.warnings
    assert {(w.code, w.trial) for w in ctx.warnings} == {("W410", "workspace-2"), ("W413", "workspace-2")}


def test_an_open_sweep_is_reported_with_w410(tmp_path):
    rng = np.random.default_rng(RNG_SEED)
    sparse_top = sphere_surface(3_000, 0.1, [0.0, 0.0, 0.2], rng)
    sparse_top = sparse_top[sparse_top[:, 2] > 0.23]
    ctx = ComputeContext(
        session=open_session(workspace_session(tmp_path, mini_device(), [sparse_top])), wanted={"workspace.measured_volume"}
    )
    res = by_id(compute(ctx))
    assert "W410" in res["workspace.measured_volume"].warnings
    assert any(w.code == "W410" and w.trial == "workspace-1" for w in ctx.warnings)


def _frozen_shoulder(joints: list) -> None:
    """The shoulder cannot move: the reachable set is a surface, no volume (a division by zero once)."""
    joints[1]["upper"]["constant"] = joints[1]["lower"]["constant"]
    joints[2]["upper"] = {"constant": joints[2]["lower"]["constant"]}


def _empty_elbow_range(joints: list) -> None:
    """An upper limit below the lower one: every sampled range is empty (np.max of nothing raised E999)."""
    joints[2]["upper"] = {"constant": joints[2]["lower"]["constant"] - 0.1}


@pytest.mark.parametrize("break_limits", [_frozen_shoulder, _empty_elbow_range], ids=["no-volume", "no-configuration"])
def test_degenerate_joint_limits_give_e311_and_the_measured_volume_stands(tmp_path, break_limits):
    """The model is unavailable with E311; the measured volume still stands (spec §8.3)."""
    dev = mini_device()
    break_limits(dev["kinematics"]["joints"])
    rng = np.random.default_rng(RNG_SEED)
    cloud = sphere_surface(3_000, 0.05, [0.1, 0.0, 0.1], rng)
    res = by_id(compute(ComputeContext(session=open_session(workspace_session(tmp_path, dev, [cloud])))))
    assert res["workspace.modeled_volume"].code == "E311"
    assert res["workspace.volume_ratio"].code == "E311" and res["workspace.coverage"].code == "E311"
    assert isinstance(res["workspace.measured_volume"], MetricResult)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 300), st.integers(1, 80), st.integers(1, 40), st.floats(0.01, 0.5), st.booleans())
def test_longest_occlusion_gap_is_the_chord_across_the_longest_gap(start, long_gap, short_gap, speed, occluded_ends):
    """A straight sweep at ``speed`` m/s, 100 Hz: the occlusion run of ``long_gap`` rows is bridged by a chord of
    (long_gap + 1) steps; a shorter run elsewhere and occluded first/last rows (no finite row beyond) do not count."""
    n = start + long_gap + 200
    step = speed / 100.0
    p = np.arange(n)[:, None] * np.array([step, 0.0, 0.0]) + np.array([0.01, -0.02, 0.15])
    p[start + 1 : start + 1 + long_gap] = np.nan
    short = min(short_gap, long_gap)
    p[start + long_gap + 50 : start + long_gap + 50 + short] = np.nan
    if occluded_ends:
        p[:1] = np.nan
        p[-20:] = np.nan
    expected = (long_gap + 1) * step if start >= 1 or not occluded_ends else (short + 1) * step
    assert longest_occlusion_gap(p) == pytest.approx(expected, rel=1e-9)
    assert longest_occlusion_gap(p[~np.isnan(p).any(axis=1)]) == 0.0


# --- occlusion gaps repaired from the other repetitions (spec §8.7) --------------------------------------

R_CLOSE = volume_operator.PARAMETERS.closing_radius_m
SEARCH = volume_operator.PARAMETERS.surface_search_voxels * volume_operator.PARAMETERS.voxel_pitch_m


def test_occlusion_gaps_are_the_runs_of_occluded_rows_with_their_finite_edges():
    p = np.zeros((12, 3))
    p[[0, 1, 5, 6, 7, 11]] = np.nan
    assert occlusion_gaps(p) == [(None, 2), (4, 8), (10, None)]
    assert occlusion_gaps(np.zeros((5, 3))) == []
    assert occlusion_gaps(np.full((5, 3), np.nan)) == []


@settings(max_examples=40, deadline=None)
@given(st.floats(0.02, 0.5), st.integers(2, 60), st.integers(1, 30), st.booleans())
def test_a_gap_region_reaches_the_speed_times_the_duration_plus_the_closing_radius(speed, rows, lead, turn):
    """A sweep at ``speed`` m/s, 100 Hz, along x; an interior gap of ``rows`` rows and ``lead`` occluded rows at
    the start. Straight: the chord is v·T, reach = v·T + 2r. Turned back at the gap's middle (``turn``): the
    chord is shorter than the path, and the reach is still v·T + 2r (spec §8.7 steps 1–3)."""
    n = lead + rows + 100
    t = np.arange(n) / 100.0
    x = speed * t
    i, j = lead + 40, lead + 40 + rows + 1  # the gap's finite edges
    if turn:  # the hand goes back inside the gap: after the middle it moves in −x
        mid = (t[i] + t[j]) / 2
        x = np.where(t > mid, 2 * speed * mid - speed * t, x)
    p = np.column_stack([x, np.zeros(n), np.zeros(n)]) + np.array([0.01, -0.02, 0.15])
    p[i + 1 : j] = np.nan
    p[:lead] = np.nan
    regions = gap_regions(t, p)
    assert len(regions) == 2
    (a0, b0, lead_reach), (a, b, reach) = regions
    assert np.array_equal(a0, p[lead]) and np.array_equal(b0, p[lead])
    assert lead_reach == pytest.approx(2 * (speed * t[lead] + R_CLOSE), rel=1e-9)
    assert np.array_equal(a, p[i]) and np.array_equal(b, p[j])
    assert reach == pytest.approx(speed * (t[j] - t[i]) + 2 * R_CLOSE, rel=1e-9)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_repair_takes_exactly_the_donors_in_a_region_with_no_own_sample_near(seed):
    """Brute force over random sweeps and donors: a donor is taken iff |x − p_a| + |x − p_b| ≤ reach for some
    gap and every finite own position is at least surface_search_voxels·h away (spec §8.7 step 4)."""
    rng = np.random.default_rng(seed)
    n = 300
    t = np.arange(n) / 100.0
    p = np.cumsum(rng.normal(0, 0.002, (n, 3)), axis=0)
    for _ in range(3):
        start = int(rng.integers(0, n - 20))
        p[start : start + int(rng.integers(1, 20))] = np.nan
    donors = rng.uniform(p[np.isfinite(p[:, 0])].min(axis=0) - 0.05, p[np.isfinite(p[:, 0])].max(axis=0) + 0.05, (400, 3))
    cloud, taken = repaired_points(t, p, donors)
    own = p[np.isfinite(p[:, 0])]
    in_region = np.zeros(len(donors), dtype=bool)
    for a, b, reach in gap_regions(t, p):
        in_region |= np.linalg.norm(donors - a, axis=1) + np.linalg.norm(donors - b, axis=1) <= reach
    far = np.linalg.norm(donors[:, None, :] - own[None], axis=2).min(axis=1) >= SEARCH
    expected = donors[in_region & far]
    assert taken == len(expected)
    assert np.array_equal(cloud[: len(own)], own)
    assert sorted(map(tuple, cloud[len(own) :])) == sorted(map(tuple, expected))


def test_a_band_lost_to_one_gap_is_repaired_to_the_sphere():
    """Two spiral sweeps of a sphere R = 6 cm; the first lost the 4 cm band about the equator to one gap. The
    other sweep repairs it to the sphere (4/3 πR³ within the operator's 0.5 %, §8.8); without the repair the
    closing bridges the band with a groove (> 5 % less)."""
    radius, centre = 0.06, np.array([0.01, -0.02, 0.15])
    first = sphere_sweep(8000, 24, radius, centre, 0.0)
    first[np.abs(first[:, 2] - centre[2]) < 0.02] = np.nan
    other = sphere_sweep(8000, 24, radius, centre, math.pi)
    cloud, taken = repaired_points(np.arange(len(first)) / 100.0, first, other)
    sphere = 4 / 3 * math.pi * radius**3
    assert 0 < taken < len(other)
    assert volume_solid(cloud).volume == pytest.approx(sphere, rel=5e-3)
    assert volume_solid(first[np.isfinite(first[:, 0])]).volume < 0.95 * sphere


def test_donors_outside_every_gap_region_add_nothing():
    """A short gap (0.6 s of the sweep at about 0.11 m/s: reach ≈ 7 cm + 2r) and a donor trial that also recorded
    a lobe 20 cm away: none of the lobe is taken, and the repaired trial's volume is the sphere's, not the lobe's too."""
    radius, centre = 0.06, np.array([0.01, -0.02, 0.15])
    first = sphere_sweep(8000, 24, radius, centre, 0.0)
    first[3970:4030] = np.nan
    lobe = sphere_surface(2000, 0.03, centre + [0.0, 0.0, 0.2], np.random.default_rng(RNG_SEED))
    t = np.arange(len(first)) / 100.0
    ((a, b, reach),) = gap_regions(t, first)
    assert reach < 0.15
    assert np.all(np.linalg.norm(lobe - a, axis=1) + np.linalg.norm(lobe - b, axis=1) > reach)
    cloud, _ = repaired_points(t, first, np.concatenate([sphere_sweep(8000, 24, radius, centre, math.pi), lobe]))
    assert np.all(np.linalg.norm(cloud - centre, axis=1) <= radius + 1e-9)
    assert volume_solid(cloud).volume == pytest.approx(4 / 3 * math.pi * radius**3, rel=5e-3)


def test_a_session_repairs_each_trial_from_the_others_and_reports_the_donors(tmp_path):
    """At session level (spec §8.7): the repaired trial counts its donors in ``repair_points``; a trial with fewer
    than min_points finite positions of its own stays E313 (W413) even though donors could fill it."""
    radius, centre = 0.06, np.array([0.01, -0.02, 0.15])
    first = sphere_sweep(8000, 24, radius, centre, 0.0)
    first[np.abs(first[:, 2] - centre[2]) < 0.02] = np.nan
    other = sphere_sweep(8000, 24, radius, centre, math.pi)
    scarce = sphere_sweep(8000, 24, radius, centre, 1.0)
    scarce[50:] = np.nan  # 50 finite positions, then one long gap whose region holds everything
    w = SessionWriter(
        manifest={
            "session_id": "ws-repair",
            "date": "2026-11-26",
            "lab": {"id": "lab"},
            "examiner": {"id": "ex"},
            "device": mini_device(),
            "device_placement": PLACEMENT,
            "rig": example_rig(),
        }
    )
    for i, cloud in enumerate((first, other, scarce), start=1):
        pose_cloud(w, f"workspace-{i}", cloud, "parquet", repetition=i)
    ctx = ComputeContext(session=open_session(w.write(tmp_path / "s")), wanted={"workspace.measured_volume"})
    measured = by_id(compute(ctx))["workspace.measured_volume"]
    assert measured.trials == ["workspace-1", "workspace-2"]
    assert measured.per_repetition == pytest.approx([4 / 3 * math.pi * radius**3] * 2, rel=5e-3)
    repair = measured.diagnostics["repair_points"]
    assert repair[0] > 0 and repair[1] == 0
    assert any(w.code == "W413" and w.trial == "workspace-3" and "E313" in w.message for w in ctx.warnings)
    # spec §19.1, §19.3: the repaired trials' metrics carry a Type A record and the mocap_noise bias (its arithmetic:
    # tests/test_uncertainty.py); these noise-free sweeps have no track noise, so the bias is nil
    res = compute_session(ctx.session, ["workspace.measured_volume", "workspace.coverage"], uncertainty=True)
    for metric_id in ("workspace.measured_volume", "workspace.coverage"):
        rec = res.get(metric_id)
        assert rec.trials == ["workspace-1", "workspace-2"]
        assert rec.uncertainty.method == "type_a" and [t.source for t in rec.uncertainty.budget] == ["repeatability"]
        bias = rec.uncertainty.bias
        assert bias.source == "mocap_noise" and bias.u_input < 1e-6
        assert abs(bias.estimate) <= 1e-4 * rec.value
        assert rec.uncertainty.U == pytest.approx(rec.uncertainty.k * rec.uncertainty.u + abs(bias.estimate), rel=1e-12)


def test_strokes_farther_apart_than_the_normal_radius_take_the_indicator_normal():
    """A sphere swept by a spiral whose turns lie farther apart than the normal radius: each boundary sample's
    neighbours lie along one stroke, whose plane fit says nothing of the surface (spec §8.4 step 5,
    ``min_normal_planarity``). With the smoothed-indicator normal the volume is within 0.6 % of 4/3 π r³ (1 %
    over it when the line's curvature sets the normal), and white noise of 0.1 mm moves it by under 0.1 %."""
    radius, centre = 0.1, np.array([0.0, 0.0, 0.15])
    sweep = sphere_sweep(20000, 20, radius, centre, 0.3)  # turns 1.6 cm apart: 6 voxels, > normal_radius_voxels
    exact = 4 / 3 * math.pi * radius**3
    clean = volume_solid(sweep).volume
    assert clean == pytest.approx(exact, rel=6e-3)
    noisy = volume_solid(sweep + np.random.default_rng(2).normal(0.0, 1e-4, sweep.shape)).volume
    assert noisy == pytest.approx(clean, rel=1e-3)
