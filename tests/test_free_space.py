"""Global free-space forces (spec chapter 9): statistics, plate force, speeds, compliance and force field."""

from __future__ import annotations

import math

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.compute import ComputeContext
from haptify.conventions import quat_from_axis_angle, quat_to_matrix
from haptify.free_space import compute, exceedance, force_field, magnitude_stats, plate_force_about_weight, report_figures
from haptify.results import MetricResult, Unavailable
from haptify.storage import open_session
from metric_sessions import add_handle_trial, circle, spin, writer


def test_magnitude_statistics_of_a_known_force():
    # |F| = 1 + 0.5 sin: mean 1, sd known, extremes 0.5 and 1.5 (sampled on whole periods, both peaks hit)
    s = np.linspace(0, 2 * np.pi, 4001)[:-1]
    mag = 1.0 + 0.5 * np.sin(s)
    direction = np.column_stack([np.cos(3 * s), np.sin(3 * s), 0 * s])
    out = magnitude_stats(direction * mag[:, None])
    assert out["mean"] == pytest.approx(1.0, abs=1e-12)
    assert out["sd"] == pytest.approx(0.5 / math.sqrt(2) * math.sqrt(4000 / 3999), rel=1e-9)
    assert out["min"] == pytest.approx(0.5, abs=1e-6) and out["max"] == pytest.approx(1.5, abs=1e-6)


@settings(max_examples=40, deadline=None)
@given(
    st.integers(0, 2**32 - 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(0.1, 1), st.floats(0, math.pi), st.floats(1e-3, 1e3)
)
def test_rotation_leaves_magnitudes_unchanged_and_units_scale(seed, ax, ay, az, angle, scale):
    f = np.random.default_rng(seed).normal(size=(200, 3))
    r = quat_to_matrix(quat_from_axis_angle(np.array([ax, ay, az]), np.array(angle)))
    a, b, c = magnitude_stats(f), magnitude_stats(f @ r.T), magnitude_stats(scale * f)
    for key in a:
        assert b[key] == pytest.approx(a[key], rel=1e-9)
        assert c[key] == pytest.approx(scale * a[key], rel=1e-9)


def test_plate_force_loses_only_its_mean_vertical_component():
    t = np.linspace(0, 10, 1001)
    p = np.column_stack([0.3 * np.sin(t), 0.1 + 0 * t, -17.4 + 0.4 * np.cos(t)])
    out = plate_force_about_weight(p)
    np.testing.assert_allclose(out[:, :2], p[:, :2])
    assert out[:, 2].mean() == pytest.approx(0.0, abs=1e-12)


def test_exceedance_share():
    assert exceedance(np.array([0.1, 0.2, 0.15, 0.17]), 0.16) == 0.5
    assert exceedance(np.array([]), 0.16) == 0.0


def test_force_field_bins_on_the_world_lattice():
    b = 0.02
    pos = np.array([[0.001, 0.001, 0.001]] * 12 + [[0.021, -0.001, 0.0]] * 12 + [[0.5, 0.5, 0.5]] * 3)
    force = np.array([[1.0, 0.0, 0.0]] * 6 + [[0.0, 1.0, 0.0]] * 6 + [[0.0, 0.0, -2.0]] * 12 + [[9.0, 9.0, 9.0]] * 3)
    field = force_field(pos, force, bin_m=b, min_samples=10)
    np.testing.assert_allclose(field.centres, [[0.01, 0.01, 0.01], [0.03, -0.01, 0.01]])
    np.testing.assert_allclose(field.mean_force, [[0.5, 0.5, 0.0], [0.0, 0.0, -2.0]])
    np.testing.assert_array_equal(field.counts, [12, 12])  # the 3-sample bin is dropped
    assert field.to_dict()["bins"][1]["n"] == 12


# --- session level (spec §9.6) -------------------------------------------------------------------


def felt(t):
    """A force on the hand with |F| = √(0.5² + 0.4² + (0.3 + 0.2 sin 0.5t)²)."""
    return np.column_stack([0.5 + 0 * t, -0.4 + 0 * t, 0.3 + 0.2 * np.sin(0.5 * t)])


def plate(t):
    return np.column_stack([0.2 * np.cos(0.3 * t), 0 * t, -17.4 + 0.3 * np.sin(0.5 * t)])


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    w = writer("free-space")
    for i in (1, 2):
        add_handle_trial(
            w,
            f"fs-{i}",
            "free_space",
            repetition=i,
            duration_s=12.0,
            position=circle(0.05, 1.0),
            quaternion=spin(0.07),
            force_w=felt,
            plate_force_w=plate,
        )
    add_handle_trial(
        w,
        "fs-3",
        "free_space",
        repetition=3,
        duration_s=12.0,
        position=circle(0.05, 4.0),
        quaternion=spin(0.35),
        force_w=felt,
        plate_force_w=None,
    )  # too fast; no plate stream
    return open_session(w.write(tmp_path_factory.mktemp("fs") / "s"))


def test_session_values_match_the_truth(session):
    ctx = ComputeContext(session=session)
    res = {m.id: m for m in compute(ctx)}
    assert all(isinstance(m, MetricResult) for m in res.values())
    t = np.arange(0, 12.0 + 1e-9, 0.01)
    mag = np.linalg.norm(felt(t), axis=1)
    fm = res["free_space.force_mean"]
    assert fm.n == 3 and fm.unit == "N"
    for v in fm.per_repetition:
        assert v == pytest.approx(mag.mean(), rel=2e-3)
    assert res["free_space.force_sd"].value == pytest.approx(mag.std(ddof=1), rel=2e-2)
    assert res["free_space.force_min"].value == pytest.approx(mag.min(), rel=2e-3)
    assert res["free_space.force_max"].value == pytest.approx(mag.max(), rel=2e-3)
    speeds = res["free_space.speed_mean"].per_repetition
    assert speeds[0] == pytest.approx(0.05, rel=1e-3) and speeds[2] == pytest.approx(0.2, rel=1e-3)
    ang = res["free_space.angular_speed_mean"].per_repetition
    assert ang[0] == pytest.approx(0.07, rel=1e-3) and ang[2] == pytest.approx(0.35, rel=1e-3)
    # the plate metric rests on the two trials that have a plate stream; the third is reported as skipped
    pm = res["free_space.plate_force_mean"]
    assert pm.trials == ["fs-1", "fs-2"]
    expected_plate = np.linalg.norm(plate_force_about_weight(plate(np.arange(0, 12.0 + 1e-9, 0.01))), axis=1).mean()
    assert pm.value == pytest.approx(expected_plate, rel=5e-3)
    assert any(w.code == "W413" and w.trial == "fs-3" for w in ctx.warnings)
    # protocol compliance: only the fast trial is flagged, on both limits
    assert {(w.code, w.trial) for w in ctx.warnings if w.code in ("W411", "W412")} == {("W411", "fs-3"), ("W412", "fs-3")}
    assert "W411" in fm.warnings and "W412" in res["free_space.angular_speed_mean"].warnings
    # the force field: one mean vector per visited 2 cm bin, equal to the constant components of the truth
    bins = fm.diagnostics["force_field"]["bins"]
    assert len(bins) > 10
    for b in bins:
        assert b["mean_force_N"][0] == pytest.approx(0.5, abs=5e-3)
        assert b["mean_force_N"][1] == pytest.approx(-0.4, abs=5e-3)

    class Results:  # the part of a ResultsFile the figures read
        def get(self, metric_id):
            return res.get(metric_id)

    assert [f.name for f in report_figures(ctx, Results())] == ["free_space_fs-1", "free_space_force_field"]
    plt.close("all")


def test_no_free_space_trial_gives_e310(tmp_path):
    w = writer("empty")
    w.add_trial("other-1", "other", powered=False, label="nothing")
    res = compute(ComputeContext(session=open_session(w.write(tmp_path / "s"))))
    assert len(res) == 7 and all(isinstance(m, Unavailable) and m.code == "E310" for m in res)


def test_without_calibration_forces_are_unavailable_but_speeds_are_not(tmp_path):
    w = writer("no-calibration")
    w.manifest = {k: v for k, v in w.manifest.items() if k != "calibration"}
    add_handle_trial(w, "fs-1", "free_space", duration_s=6.0, position=circle(0.05, 1.0), quaternion=spin(0.07), force_w=felt)
    ctx = ComputeContext(session=open_session(w.write(tmp_path / "s")))
    res = {m.id: m for m in compute(ctx)}
    assert res["free_space.force_mean"].code == "E601"  # no handle calibration (spec chapter 6)
    assert res["free_space.speed_mean"].value == pytest.approx(0.05, rel=1e-3)
    assert res["free_space.plate_force_mean"].code == "E302"  # the trial has no plate stream
