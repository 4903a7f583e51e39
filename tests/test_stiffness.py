"""Stiffness rendering (spec chapter 13): a linear spring with saturation, and a spring that gives way."""

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
from haptify.errors import HaptifyError
from haptify.results import MetricResult, Unavailable
from haptify.stiffness import compute, find_presses, fit_stiffness, report_figures, runs
from haptify.storage import open_session
from haptify.surface import contact_of, unit_normal
from metric_sessions import add_handle_trial, spin, writer

K_TRUE, F_SAT, K_CMD = 360.0, 2.7, 750.0
DEPTH, PRESS_S, GAP_S, N_PRESSES = 0.012, 1.2, 0.5, 5


def press_depth(t: np.ndarray) -> np.ndarray:
    """Penetration (m): presses of DEPTH·sin²(π τ / PRESS_S) separated by GAP_S hovering 5 mm above."""
    period = PRESS_S + GAP_S
    tau = np.mod(t - GAP_S, period)
    inside = (t >= GAP_S) & (tau < PRESS_S) & (t < GAP_S + N_PRESSES * period)
    return np.where(inside, DEPTH * np.sin(np.pi * tau / PRESS_S) ** 2, -0.005)


def saturating(d: np.ndarray) -> np.ndarray:
    """The Touch's behaviour (paper §VI-F): linear, then a plateau at F_SAT."""
    return np.clip(K_TRUE * d, 0.0, F_SAT)


def giving_way(d: np.ndarray, k: float = 600.0, peak: float = 5.7) -> np.ndarray:
    """The Touch X's behaviour: linear up to a peak, then a sudden drop to 1 N."""
    return np.where(d < 0, 0.0, np.where(k * d <= peak, k * d, 1.0))


def arrays(force_law=saturating, rate=100.0, noise=0.0, seed=0):
    t = np.arange(0, GAP_S + N_PRESSES * (PRESS_S + GAP_S) + 0.5, 1 / rate)
    d = press_depth(t)
    f = force_law(d) + (np.random.default_rng(seed).normal(scale=noise, size=len(t)) if noise else 0.0)
    contact = contact_of(K_CMD * np.maximum(d, 0.0))
    return t, d, f, contact


def test_runs():
    assert runs(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]
    assert runs(np.zeros(3, bool)) == []


def test_linear_spring_with_saturation_is_recovered_exactly():
    t, d, f, contact = arrays()
    fit = fit_stiffness(t, d, f, contact)
    assert len(fit.presses) == N_PRESSES
    assert fit.stiffness == pytest.approx(K_TRUE, rel=1e-9)
    assert fit.intercept == pytest.approx(0.0, abs=1e-9)
    assert fit.peak_force == pytest.approx(F_SAT, rel=1e-12)
    assert fit.r2 == pytest.approx(1.0)
    # no fit sample comes from the plateau
    assert np.all(fit.normal_force <= 0.8 * F_SAT + 1e-12)


def test_the_remainder_of_a_press_cut_by_an_occlusion_is_not_a_press():
    """A press rises (f = K·d, 0 → 10 mm), motion capture drops out at its top, and the samples after the
    gap are its release with a friction bump at the reversal: the force rises while the hand withdraws.
    That remainder begins right after invalid samples and must not enter the fit (spec §13.2)."""
    rise_d = np.linspace(0.0, 0.010, 101)
    rel_d = np.linspace(0.0095, 0.005, 50)
    rel_f = np.concatenate([np.linspace(1.5, 2.0, 30), np.linspace(2.0, 1.2, 20)])
    d = np.concatenate([[-0.005] * 5, rise_d, [0.0099] * 5, rel_d, [-0.005] * 5])
    f = np.concatenate([[0.0] * 5, K_TRUE * rise_d, [K_TRUE * 0.0099] * 5, rel_f, [0.0] * 5])
    valid = np.concatenate([[True] * 106, [False] * 5, [True] * 55])  # the occlusion
    contact = valid & (d > 0)
    t = np.arange(len(d)) / 100.0
    fit = fit_stiffness(t, d, f, contact, valid=valid)
    assert len(fit.presses) == 1
    assert fit.stiffness == pytest.approx(K_TRUE, rel=1e-9)
    assert fit.peak_force == pytest.approx(K_TRUE * 0.010, rel=1e-12)


def test_a_spring_that_gives_way_is_fitted_on_its_rising_phase():
    t, d, f, contact = arrays(giving_way)
    fit = fit_stiffness(t, d, f, contact)
    assert fit.stiffness == pytest.approx(600.0, rel=1e-9)
    assert fit.peak_force == pytest.approx(5.7, abs=600.0 * DEPTH * 0.02)  # the last sample below the drop


def test_noise_leaves_the_slope_within_two_percent():
    t, d, f, contact = arrays(noise=0.02, seed=5)
    fit = fit_stiffness(t, d, f, contact)
    assert fit.stiffness == pytest.approx(K_TRUE, rel=0.02)


@settings(max_examples=30, deadline=None)
@given(st.floats(-1e4, 1e4), st.floats(1e-2, 1e2))
def test_time_shift_changes_nothing_and_force_units_scale(shift, scale):
    t, d, f, contact = arrays()
    base = fit_stiffness(t, d, f, contact)
    shifted = fit_stiffness(t + shift, d, f, contact)
    scaled = fit_stiffness(t, d, scale * f, contact)
    assert shifted.stiffness == pytest.approx(base.stiffness, rel=1e-9)
    assert scaled.stiffness == pytest.approx(scale * base.stiffness, rel=1e-9)
    assert scaled.peak_force == pytest.approx(scale * base.peak_force, rel=1e-9)


@settings(max_examples=20, deadline=None)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(0.1, 1), st.floats(0, math.pi))
def test_rotating_the_world_leaves_the_fit_unchanged(ax, ay, az, angle):
    """Positions and forces in 3-D around a tilted plane; rotating all of them with the plane changes nothing."""
    t, d, f, contact = arrays()
    n = unit_normal([0.1, -0.3, 1.0])
    p0 = np.array([0.02, 0.05, 0.1])
    lateral = np.column_stack([0.02 * np.cos(t), 0.02 * np.sin(t), 0 * t])
    lateral -= np.outer(lateral @ n, n)
    pos = p0 + lateral - d[:, None] * n
    force = f[:, None] * n + 0.3 * lateral / 0.02
    r = quat_to_matrix(quat_from_axis_angle(np.array([ax, ay, az]), np.array(angle)))
    for rot in (np.eye(3), r):
        nn, pp, ff, qq = rot @ n, pos @ rot.T, force @ rot.T, rot @ p0
        fit = fit_stiffness(t, (qq - pp) @ nn, ff @ nn, contact)
        assert fit.stiffness == pytest.approx(K_TRUE, rel=1e-9)


def test_shallow_or_short_touches_are_not_presses():
    t = np.arange(0, 3, 0.01)
    d = np.where((t > 1) & (t < 1.1), 0.01, np.where((t > 2) & (t < 2.8), 0.001, -0.005))
    assert find_presses(t, d, saturating(d), contact_of(K_CMD * np.maximum(d, 0))) == []
    with pytest.raises(HaptifyError) as err:
        fit_stiffness(t, d, saturating(d), contact_of(K_CMD * np.maximum(d, 0)))
    assert err.value.code == "E315"


# --- session level (spec §13.5) ------------------------------------------------------------------

NORMAL = unit_normal([0.0, -0.15, 1.0])
PLANE = np.array([0.01, 0.04, 0.11])
RENDERING = {"surface_point_m": PLANE.tolist(), "surface_normal": [0.0, -0.15, 1.0], "stiffness_N_per_m": K_CMD}
DURATION = GAP_S + N_PRESSES * (PRESS_S + GAP_S) + 0.5


def position(t):
    return PLANE - press_depth(t)[:, None] * NORMAL


def felt(t):
    return saturating(press_depth(t))[:, None] * NORMAL + np.array([0.1, 0.0, 0.0]) - (np.array([0.1, 0.0, 0.0]) @ NORMAL) * NORMAL


def commanded(t):
    return (K_CMD * np.maximum(press_depth(t), 0.0))[:, None] * NORMAL


def test_session_metrics(tmp_path):
    w = writer("stiffness")
    for i in (1, 2):
        add_handle_trial(w, f"stiff-{i}", "stiffness", repetition=i, duration_s=DURATION, powered=True, rendering=RENDERING,
                         position=position, quaternion=spin(0.03), force_w=felt, commanded_w=commanded, accel=False)
    ctx = ComputeContext(session=open_session(w.write(tmp_path / "s")))
    res = {m.id: m for m in compute(ctx)}
    assert all(isinstance(m, MetricResult) for m in res.values())
    assert res["stiffness.measured"].value == pytest.approx(K_TRUE, rel=0.02)
    assert res["stiffness.measured"].unit == "N/m"
    assert res["stiffness.accuracy"].value == pytest.approx(100 * K_TRUE / K_CMD, rel=0.02)
    assert res["stiffness.peak_force"].value == pytest.approx(F_SAT, rel=0.01)
    assert res["stiffness.measured"].diagnostics["presses"] == [N_PRESSES, N_PRESSES]
    assert res["stiffness.peak_force"].n == 2 and not ctx.warnings
    figures = report_figures(ctx, None)
    assert [f.name for f in figures] == ["stiffness"]
    plt.close("all")


def test_few_presses_warn_and_no_trial_is_unavailable(tmp_path):
    w = writer("stiffness-short")
    short = GAP_S + 1 * (PRESS_S + GAP_S)  # one press, two recommended
    add_handle_trial(w, "stiff-1", "stiffness", duration_s=short, powered=True, rendering=RENDERING,
                     position=position, quaternion=spin(0.03), force_w=felt, commanded_w=commanded, accel=False)
    ctx = ComputeContext(session=open_session(w.write(tmp_path / "s")))
    res = {m.id: m for m in compute(ctx)}
    assert "W414" in res["stiffness.measured"].warnings
    assert any(x.code == "W414" for x in ctx.warnings)
    w2 = writer("none")
    w2.add_trial("other-1", "other", powered=False, label="nothing")
    res2 = compute(ComputeContext(session=open_session(w2.write(tmp_path / "s2"))))
    assert [m.code for m in res2] == ["E310"] * 3 and all(isinstance(m, Unavailable) for m in res2)
