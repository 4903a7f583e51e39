"""Frictionless surface rendering (spec chapter 12): contact rule and planar forces known by construction."""

from __future__ import annotations

import math

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from hypothesis import given, settings
from hypothesis import strategies as st
from metric_sessions import add_handle_trial, spin, writer

from haptify.errors import HaptifyError
from haptify.formats.conventions import quat_from_axis_angle, quat_to_matrix
from haptify.formats.storage import open_session
from haptify.metrics import surface
from haptify.metrics.surface import compute, contact_of, guarded, planar_force, planar_stats, unit_normal
from haptify.pipeline.compute import ComputeContext
from haptify.pipeline.results import MetricResult, Unavailable
from haptify.report.figures.surface import report_figures

NORMAL = unit_normal([0.0, 0.2, 1.0])
PLANE_POINT = np.array([0.0, 0.05, 0.12])
T_ON, T_OFF = 1.0, 9.0


def tangent_basis(n):
    u = np.cross(n, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def test_planar_force_removes_exactly_the_normal_part():
    u, v = tangent_basis(NORMAL)
    f = 2.0 * NORMAL + 0.3 * u - 0.4 * v
    np.testing.assert_allclose(planar_force(f[None, :], NORMAL), [0.3 * u - 0.4 * v], atol=1e-15)


@settings(max_examples=40, deadline=None)
@given(
    st.integers(0, 2**32 - 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(0.1, 1), st.floats(0, math.pi), st.floats(1e-3, 1e3)
)
def test_planar_stats_ignore_the_world_frame_and_scale_with_units(seed, ax, ay, az, angle, scale):
    f = np.random.default_rng(seed).normal(size=(100, 3))
    r = quat_to_matrix(quat_from_axis_angle(np.array([ax, ay, az]), np.array(angle)))
    a = planar_stats(f, NORMAL)
    b = planar_stats(f @ r.T, r @ NORMAL)
    c = planar_stats(scale * f, NORMAL)
    for key in a:
        assert b[key] == pytest.approx(a[key], rel=1e-9)
        assert c[key] == pytest.approx(scale * a[key], rel=1e-9)


def test_contact_threshold_and_guard():
    thr = surface.PARAMETERS.contact_force_threshold_N
    assert list(contact_of(np.array([0.0, thr, thr * 1.01]))) == [False, False, True]
    t_cmd = np.arange(0, 2.0001, 0.001)
    contact = (t_cmd >= 0.5) & (t_cmd <= 1.5)
    grid = np.arange(0, 2.0001, 0.01)
    used = guarded(t_cmd, contact, grid, 0.05)
    np.testing.assert_array_equal(used, (grid >= 0.55 - 1e-9) & (grid <= 1.45 + 1e-9))


def test_zero_normal_is_a_coded_error():
    with pytest.raises(HaptifyError) as err:
        unit_normal([0.0, 0.0, 0.0], "t1")
    assert err.value.code == "E303"


# --- session level (spec §12.4) ------------------------------------------------------------------


def in_contact(t):
    return (t >= T_ON) & (t <= T_OFF)


def position(t):
    """Circles of 3 cm radius in the plane, 2 mm below it while in contact, 1 cm above it before and after."""
    u, v = tangent_basis(NORMAL)
    depth = np.where(in_contact(t), 0.002, -0.01)
    return PLANE_POINT + 0.03 * (np.cos(2 * t)[:, None] * u + np.sin(2 * t)[:, None] * v) - depth[:, None] * NORMAL


def planar_magnitude(t):
    return np.where(in_contact(t), 0.53 + 0.1 * np.sin(2 * np.pi * 0.5 * t), 2.0)


def felt(t):
    """Planar force against the motion, of the magnitude above, plus 1.5 N normal while in contact."""
    u, v = tangent_basis(NORMAL)
    direction = np.sin(2 * t)[:, None] * u - np.cos(2 * t)[:, None] * v
    return planar_magnitude(t)[:, None] * direction + np.where(in_contact(t), 1.5, 0.0)[:, None] * NORMAL


def commanded(t):
    return np.where(in_contact(t), 1.5, 0.0)[:, None] * NORMAL


RENDERING = {"surface_point_m": PLANE_POINT.tolist(), "surface_normal": [0.0, 0.2, 1.0], "stiffness_N_per_m": 750.0}


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    w = writer("surface")
    for i in (1, 2):
        add_handle_trial(
            w,
            f"surf-{i}",
            "frictionless_surface",
            repetition=i,
            duration_s=10.0,
            powered=True,
            rendering=RENDERING,
            position=position,
            quaternion=spin(0.05),
            force_w=felt,
            commanded_w=commanded,
        )
    add_handle_trial(
        w,
        "surf-3",
        "frictionless_surface",
        repetition=3,
        duration_s=10.0,
        powered=True,
        rendering=RENDERING,
        position=position,
        quaternion=spin(0.05),
        force_w=felt,
        commanded_w=lambda t: 0 * commanded(t),
    )
    return open_session(w.write(tmp_path_factory.mktemp("surf") / "s"))


def test_planar_force_over_the_contact_samples_only(session):
    ctx = ComputeContext(session=session)
    res = {m.id: m for m in compute(ctx)}
    mean, sd = res["surface.planar_force_mean"], res["surface.planar_force_sd"]
    assert isinstance(mean, MetricResult) and mean.trials == ["surf-1", "surf-2"]
    g = surface.PARAMETERS.contact_guard_s
    t = np.arange(0, 10.0 + 1e-9, 0.01)
    used = (t >= T_ON + g - 1e-9) & (t <= T_OFF - g + 1e-9)
    truth = planar_magnitude(t[used])
    for v in mean.per_repetition:
        assert v == pytest.approx(truth.mean(), rel=5e-3)
    assert sd.value == pytest.approx(truth.std(ddof=1), rel=3e-2)
    assert mean.diagnostics["normal_force_mean_N"][0] == pytest.approx(1.5, rel=5e-3)
    # the trial whose renderer never touched the surface is skipped with its own code
    assert any(w.code == "W413" and w.trial == "surf-3" and "E314" in w.message for w in ctx.warnings)
    assert [f.name for f in report_figures(ctx, None)] == ["surface_surf-1", "surface_surf-2"]
    plt.close("all")


def test_no_surface_trial_gives_e310(tmp_path):
    w = writer("none")
    w.add_trial("other-1", "other", powered=False, label="nothing")
    res = compute(ComputeContext(session=open_session(w.write(tmp_path / "s"))))
    assert [m.code for m in res] == ["E310", "E310"] and all(isinstance(m, Unavailable) for m in res)
