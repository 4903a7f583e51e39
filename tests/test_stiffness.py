"""Stiffness rendering (spec chapter 13): presses of known shape — a linear spring with saturation, a
spring that gives way, one whose force falls with depth, one that kicks at contact — read on their
loading strokes."""

from __future__ import annotations

import json
import math
from dataclasses import replace

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
from haptify.metrics.stiffness import FitRule, compute, end_of_rise, find_presses, fit_stiffness, grid_rate, runs
from haptify.metrics.surface import contact_of, contact_signals, unit_normal
from haptify.pipeline.compute import ComputeContext
from haptify.pipeline.results import MetricResult, Unavailable
from haptify.report.figures.stiffness import report_figures
from haptify_conform.cases import REPO_ROOT

K_TRUE, F_SAT, K_CMD = 360.0, 2.7, 750.0
DEPTH, PRESS_S, GAP_S, N_PRESSES = 0.012, 1.2, 0.5, 5
RATE = 100.0


def press_depth(t: np.ndarray, durations=(PRESS_S,) * N_PRESSES) -> np.ndarray:
    """Penetration (m): presses of DEPTH·sin²(π τ / T) (T from ``durations``, s) separated by GAP_S hovering 5 mm above."""
    d = np.full(len(t), -0.005)
    start = GAP_S
    for dur in durations:
        tau = t - start
        inside = (tau >= 0) & (tau < dur)
        d[inside] = DEPTH * np.sin(np.pi * tau[inside] / dur) ** 2
        start += dur + GAP_S
    return d


def saturating(d: np.ndarray) -> np.ndarray:
    """The Touch's behaviour (paper §VI-F): linear, then a plateau at F_SAT."""
    return np.clip(K_TRUE * d, 0.0, F_SAT)


def giving_way(d: np.ndarray, k: float = 600.0, peak: float = 5.7) -> np.ndarray:
    """The Touch X's behaviour: linear up to a peak, then a sudden drop to 1 N."""
    return np.where(d < 0, 0.0, np.where(k * d <= peak, k * d, 1.0))


def arrays(force_law=saturating, rate=RATE, noise=0.0, seed=0, durations=(PRESS_S,) * N_PRESSES):
    t = np.arange(0, GAP_S + sum(dur + GAP_S for dur in durations) + 0.5, 1 / rate)
    d = press_depth(t, durations)
    f = force_law(d) + (np.random.default_rng(seed).normal(scale=noise, size=len(t)) if noise else 0.0)
    contact = contact_of(K_CMD * np.maximum(d, 0.0))
    return t, d, f, contact


def loading(t: np.ndarray, durations=(PRESS_S,) * N_PRESSES) -> np.ndarray:
    """True on the samples of the presses' loading strokes (penetration growing, up to the deepest sample)."""
    out = np.zeros(len(t), bool)
    start = GAP_S
    for dur in durations:
        out |= (t >= start) & (t <= start + dur / 2 + 1e-9)
        start += dur + GAP_S
    return out


def test_runs():
    assert runs(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]
    assert runs(np.zeros(3, bool)) == []


def test_end_of_rise_is_the_first_sample_not_exceeded_within_the_hold():
    f = np.array([0.0, 1.0, 2.0, 3.0, 2.5, 2.4, 2.6, 2.9, 3.5, 3.1])
    assert end_of_rise(f, 3) == 3  # 2.5, 2.4, 2.6 stay below 3.0
    assert end_of_rise(f, 5) == 8  # 3.5 comes within five samples of the first top
    assert end_of_rise(np.arange(6.0), 4) == 5  # still rising at the end: the last sample
    assert end_of_rise(f, 0) == 0


@pytest.mark.parametrize("rate, settle, hold", [(100.0, 4, 10), (150.0, 6, 15), (30.0, 1, 3), (62.5, 2, 6), (1000.0, 40, 100)])
def test_windows_round_to_whole_grid_samples(rate, settle, hold):
    """contact_settle_s = 0.04 s and rise_hold_s = 0.1 s in grid samples, rounded half to even (spec §13.2):
    6.0 → 6 at 150 Hz, 1.2 → 1 and 3.0 → 3 at 30 Hz, 2.5 → 2 (to even) at 62.5 Hz."""
    rule = FitRule.at_rate(rate)
    assert (rule.settle, rule.hold) == (settle, hold)


def test_linear_spring_with_saturation_is_recovered_exactly():
    t, d, f, contact = arrays()
    fit = fit_stiffness(t, d, f, contact)
    assert len(fit.presses) == N_PRESSES and fit.thin == []
    assert fit.stiffness == pytest.approx(K_TRUE, rel=1e-9)
    assert fit.intercept == pytest.approx(0.0, abs=1e-9)
    assert fit.peak_force == pytest.approx(F_SAT, rel=1e-12)
    assert fit.r2 == pytest.approx(1.0)
    for p in fit.presses:
        # the fit: the samples after the 4-sample contact transient up to 90 % of the rise that follows
        s = p.start + 4
        assert list(p.fit) == list(
            np.flatnonzero(
                (np.arange(len(f)) >= s) & (np.arange(len(f)) <= p.rise_end) & (f <= f[s] + 0.9 * (F_SAT - f[s]) + 1e-12)
            )
        )
        assert p.fit[0] == s and p.rise_end <= p.deepest
        assert f[p.rise_end] == pytest.approx(F_SAT)
        assert len(p.fit) >= 5 and p.overshoot == pytest.approx(0.0, abs=1e-12)


def test_a_force_that_saturates_then_falls_with_depth_is_fitted_on_its_loading_stroke():
    """Issue: the force rises at k = 360 N/m, saturates at 2.2 N at 6.1 mm, then falls with depth to 1.1 N at
    the press's bottom (12 mm); on the way back up it climbs the same branch 0.1 N higher, above the loading
    peak. Peak and fit come from the loading stroke only: the slope is k, the peak 2.2 N (spec §13.2, §13.4)."""
    k, f_sat = 360.0, 2.2
    d_sat = f_sat / k

    def law(d):
        return np.where(d < 0, 0.0, np.where(d <= d_sat, k * d, f_sat - (f_sat / 2) * (d - d_sat) / (DEPTH - d_sat)))

    t, d, _, contact = arrays()
    f = law(d) + np.where(loading(t), 0.0, 0.1 * (d > d_sat))  # the release stroke 0.1 N higher on the falling branch
    assert f[contact & ~loading(t)].max() > f_sat  # the whole press's largest force is on the release
    fit = fit_stiffness(t, d, f, contact)
    assert len(fit.presses) == N_PRESSES
    assert fit.stiffness == pytest.approx(k, rel=1e-9)
    top = law(d[contact & loading(t)]).max()  # the largest loading sample, just below the knee at 2.2 N
    assert f_sat - 0.12 < top < f_sat
    assert fit.peak_force == pytest.approx(top, rel=1e-12)
    for p in fit.presses:
        assert p.deepest_force == pytest.approx(f_sat / 2, rel=1e-3)  # the bottom of the falling branch


def test_a_spring_that_gives_way_is_fitted_on_its_rising_phase():
    t, d, f, contact = arrays(giving_way)
    fit = fit_stiffness(t, d, f, contact)
    assert fit.stiffness == pytest.approx(600.0, rel=1e-9)
    assert fit.peak_force == pytest.approx(5.7, abs=600.0 * DEPTH * 0.02)  # the last sample below the drop
    assert [p.overshoot for p in fit.presses] == pytest.approx([0.0] * N_PRESSES, abs=1e-12)


def test_a_plateau_that_dips_and_climbs_again_ends_the_rise_at_its_first_top():
    """The force saturates at 2.4 N at 6 mm, dips to 1.8 N and climbs to 3.0 N at the bottom (12 mm). The rise ends
    at the first top; the peak is the largest loading force, 3.0 N."""
    k = 400.0

    def law(d):
        dip = 2.4 - 0.6 * np.sin(np.pi * np.clip((d - 0.006) / 0.004, 0, 1))
        return np.where(d < 0, 0.0, np.where(d <= 0.006, k * d, np.where(d <= 0.010, dip, 2.4 + 300.0 * (d - 0.010))))

    t, d, f, contact = arrays(law)
    fit = fit_stiffness(t, d, f, contact)
    assert fit.stiffness == pytest.approx(k, rel=1e-9)
    assert fit.peak_force == pytest.approx(3.0, rel=1e-3)
    assert all(d[p.rise_end] <= 0.006 + 1e-4 for p in fit.presses)


def test_contact_overshoot_is_the_kick_above_the_line_and_enters_no_value():
    """At each onset the force kicks 4 N above the spring line (above the 2.7 N plateau) and decays in three
    samples (4, 2, 1 N). The contact overshoot of every press is 4 N (spec §13.4); slope and peak are the
    spring's."""
    t, d, f, contact = arrays()
    f = f.copy()
    for a, _ in runs(contact):
        f[a : a + 3] += [4.0, 2.0, 1.0]
    fit = fit_stiffness(t, d, f, contact)
    assert fit.stiffness == pytest.approx(K_TRUE, rel=1e-9)
    assert fit.peak_force == pytest.approx(F_SAT, rel=1e-12)
    assert [p.overshoot for p in fit.presses] == pytest.approx([4.0] * N_PRESSES, rel=1e-9)


def test_a_press_too_fast_for_the_grid_is_left_out():
    """Four presses at the protocol's pace and one in 0.25 s: the fast one reaches its plateau less than 5 grid
    samples after its contact transient, is left out (W415 at trial level) and the others give the spring."""
    durations = (PRESS_S, PRESS_S, 0.25, PRESS_S, PRESS_S)
    t, d, f, contact = arrays(durations=durations)
    fit = fit_stiffness(t, d, f, contact)
    assert len(fit.presses) == 4 and len(fit.thin) == 1
    assert 0 < len(fit.thin[0].fit) < 5
    assert fit.stiffness == pytest.approx(K_TRUE, rel=1e-9)
    t1, d1, f1, c1 = arrays(durations=(0.25, 0.25))
    with pytest.raises(HaptifyError) as err:
        fit_stiffness(t1, d1, f1, c1)
    assert err.value.code == "E315" and "2 press(es) had too few fit samples" in str(err.value)


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


def test_noise_leaves_the_slope_within_two_percent():
    t, d, f, contact = arrays(noise=0.02, seed=5)
    fit = fit_stiffness(t, d, f, contact)
    assert fit.stiffness == pytest.approx(K_TRUE, rel=0.02)


@settings(max_examples=30, deadline=None)
@given(st.floats(-1e4, 1e4), st.floats(1e-2, 1e2), st.floats(-2.0, 2.0))
def test_time_shift_and_force_offset_change_nothing_and_force_units_scale(shift, scale, offset):
    """A constant force offset (gravity, friction while pressing) moves the onset force with the rest: the
    window, being shares of the rise, keeps the same samples (spec §13.2)."""
    t, d, f, contact = arrays()
    base = fit_stiffness(t, d, f, contact)
    shifted = fit_stiffness(t + shift, d, f, contact)
    scaled = fit_stiffness(t, d, scale * f, contact)
    offset_fit = fit_stiffness(t, d, f + offset, contact)
    assert shifted.stiffness == pytest.approx(base.stiffness, rel=1e-9)
    assert scaled.stiffness == pytest.approx(scale * base.stiffness, rel=1e-9)
    assert scaled.peak_force == pytest.approx(scale * base.peak_force, rel=1e-9)
    assert offset_fit.stiffness == pytest.approx(base.stiffness, rel=1e-9)
    assert offset_fit.intercept == pytest.approx(base.intercept + offset, abs=1e-9)
    assert [list(p.fit) for p in offset_fit.presses] == [list(p.fit) for p in base.presses]


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


def session_fns(durations=(PRESS_S,) * N_PRESSES):
    def position(t):
        return PLANE - press_depth(t, durations)[:, None] * NORMAL

    def felt(t):
        side = np.array([0.1, 0.0, 0.0])
        return saturating(press_depth(t, durations))[:, None] * NORMAL + side - (side @ NORMAL) * NORMAL

    def commanded(t):
        return (K_CMD * np.maximum(press_depth(t, durations), 0.0))[:, None] * NORMAL

    return position, felt, commanded


def test_session_metrics(tmp_path):
    w = writer("stiffness")
    position, felt, commanded = session_fns()
    for i in (1, 2):
        add_handle_trial(
            w,
            f"stiff-{i}",
            "stiffness",
            repetition=i,
            duration_s=DURATION,
            powered=True,
            rendering=RENDERING,
            position=position,
            quaternion=spin(0.03),
            force_w=felt,
            commanded_w=commanded,
            accel=False,
        )
    ctx = ComputeContext(session=open_session(w.write(tmp_path / "s")))
    res = {m.id: m for m in compute(ctx)}
    assert all(isinstance(m, MetricResult) for m in res.values())
    assert res["stiffness.measured"].value == pytest.approx(K_TRUE, rel=0.02)
    assert res["stiffness.measured"].unit == "N/m"
    assert res["stiffness.accuracy"].value == pytest.approx(100 * K_TRUE / K_CMD, rel=0.02)
    assert res["stiffness.peak_force"].value == pytest.approx(F_SAT, rel=0.01)
    assert res["stiffness.measured"].diagnostics["presses"] == [N_PRESSES, N_PRESSES]
    assert res["stiffness.measured"].diagnostics["presses_left_out"] == [0, 0]
    assert all(o < 0.05 for trial in res["stiffness.peak_force"].diagnostics["press_overshoot_N"] for o in trial)
    assert res["stiffness.peak_force"].n == 2 and not ctx.warnings
    figures = report_figures(ctx, None)
    assert [f.name for f in figures] == ["stiffness"]
    plt.close("all")


def test_few_presses_warn_and_no_trial_is_unavailable(tmp_path):
    w = writer("stiffness-short")
    short = GAP_S + 1 * (PRESS_S + GAP_S)  # one press, two recommended
    position, felt, commanded = session_fns()
    add_handle_trial(
        w,
        "stiff-1",
        "stiffness",
        duration_s=short,
        powered=True,
        rendering=RENDERING,
        position=position,
        quaternion=spin(0.03),
        force_w=felt,
        commanded_w=commanded,
        accel=False,
    )
    ctx = ComputeContext(session=open_session(w.write(tmp_path / "s")))
    res = {m.id: m for m in compute(ctx)}
    assert "W414" in res["stiffness.measured"].warnings
    assert any(x.code == "W414" for x in ctx.warnings)
    w2 = writer("none")
    w2.add_trial("other-1", "other", powered=False, label="nothing")
    res2 = compute(ComputeContext(session=open_session(w2.write(tmp_path / "s2"))))
    assert [m.code for m in res2] == ["E310"] * 3 and all(isinstance(m, Unavailable) for m in res2)


def test_a_fast_press_in_a_session_raises_w415(tmp_path):
    durations = (PRESS_S, 0.25, PRESS_S)
    position, felt, commanded = session_fns(durations)
    w = writer("stiffness-fast")
    add_handle_trial(
        w,
        "stiff-1",
        "stiffness",
        duration_s=GAP_S + sum(x + GAP_S for x in durations) + 0.5,
        powered=True,
        rendering=RENDERING,
        position=position,
        quaternion=spin(0.03),
        force_w=felt,
        commanded_w=commanded,
        accel=False,
    )
    ctx = ComputeContext(session=open_session(w.write(tmp_path / "s")))
    res = {m.id: m for m in compute(ctx)}
    assert "W415" in res["stiffness.measured"].warnings
    assert [x.code for x in ctx.warnings] == ["W415"]
    assert res["stiffness.measured"].diagnostics["presses"] == [2]
    assert res["stiffness.measured"].value == pytest.approx(K_TRUE, rel=0.02)


# --- the conformance fixtures pin the window (spec §16.8.3: a plausible wrong reading moves ≥ 5× the tolerance) ---


def previous_rule(t, d, f, contact, valid):
    """The rule before this fit (spec 1.0 as first written): peak = the largest force of the whole contact run,
    fit samples = the run's samples up to that peak with 0.2·peak ≤ f ≤ 0.8·peak, at least 5 of them."""
    xs, ys, peaks = [], [], []
    for a, b in runs(contact):
        if (a > 0 and not valid[a - 1]) or t[b - 1] - t[a] < 0.2 - 1e-12 or d[a:b].max() < 0.002:
            continue
        k = a + int(np.argmax(f[a:b]))
        i = np.arange(a, k + 1)
        i = i[(f[i] >= 0.2 * f[k]) & (f[i] <= 0.8 * f[k])]
        if len(i) >= 5:
            xs.append(d[i]), ys.append(f[i]), peaks.append(f[k])
    return float(np.polyfit(np.concatenate(xs), np.concatenate(ys), 1)[0]), float(np.mean(peaks))


def whole_loading_stroke(t, d, f, contact, valid):
    """Every loading sample from the first contact sample to the deepest one, contact transient included."""
    xs, ys = [], []
    for p in find_presses(t, d, f, contact, valid):
        xs.append(d[p.start : p.deepest + 1]), ys.append(f[p.start : p.deepest + 1])
    return float(np.polyfit(np.concatenate(xs), np.concatenate(ys), 1)[0])


def case_of(cid):
    """A stiffness conformance case by id."""
    cases = json.loads((REPO_ROOT / "conformance" / "cases" / "stiffness.json").read_text())["cases"]
    return next(c for c in cases if c["id"] == cid)


@pytest.mark.parametrize("fixture", ["kick-dip", "falling-release"])
def test_the_window_fixtures_move_five_tolerances_under_each_plausible_wrong_reading(fixture):
    """stiff-kick-dip and stiff-falling-release (spec §16): the previous rule, the whole loading stroke, the contact
    transient kept and the peak over the whole contact run each miss the expected value by ≥ 5 tolerances."""
    measured, peak = case_of(f"stiffness.measured.{fixture}"), case_of(f"stiffness.peak_force.{fixture}")
    ctx = ComputeContext(session=open_session(REPO_ROOT / "fixtures" / "conformance" / f"stiff-{fixture}"))
    cs = contact_signals(ctx, "stiffness-1")
    args = (cs.t, cs.penetration, cs.normal_force, cs.contact)
    right = fit_stiffness(*args, valid=cs.valid)
    assert right.stiffness == pytest.approx(measured["expected"]["value"], rel=measured["tolerance"]["rel"])

    def off(value, c):
        return abs(value / c["expected"]["value"] - 1) / c["tolerance"]["rel"]

    old_k, old_peak = previous_rule(*args, cs.valid)
    assert off(old_k, measured) >= 5
    assert off(whole_loading_stroke(*args, cs.valid), measured) >= 5
    if fixture == "kick-dip":  # the contact transient kept: the rise from the first contact sample
        kept = fit_stiffness(*args, valid=cs.valid, rule=replace(FitRule.at_rate(grid_rate(cs.t)), settle=0))
        assert off(kept.stiffness, measured) >= 5
    else:  # the peak over the whole contact run lies on the release stroke
        assert off(old_peak, peak) >= 5
