"""Measurement uncertainty (spec chapter 19): GUM arithmetic against textbook values, the Monte Carlo
propagation through the free-space family against the analytic sensitivity of a known force, and the
method table against the metric definitions."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.formats.storage import open_session
from haptify.metrics import significance
from haptify.metrics import uncertainty as unc
from haptify.metrics.metric_definitions import all_families
from haptify.pipeline.compute import ComputeContext, compute_session
from haptify.pipeline.results import BudgetTerm, ResultsFile
from haptify.processing import preprocessing

# --- the definition file (§19.1) -------------------------------------------------------------------


def test_every_metric_has_exactly_one_method():
    ids = {m.id for f in all_families() for m in f.metrics}
    assert set(unc.definitions().metrics) == ids


def test_methods_name_known_sources_and_reasons():
    d = unc.definitions()
    for mid, m in d.metrics.items():
        if m.method == "type_a_mc":
            assert m.sources and all(d.sources[s].type == "B" for s in m.sources), mid
        else:
            assert not m.sources and m.reason, mid
    for sid, s in d.sources.items():
        assert (s.type == "A") == (s.figure is None), sid


# --- GUM arithmetic (§19.2, §19.4) -----------------------------------------------------------------


def test_type_a_of_four_values():
    u, dof = unc.type_a([1.0, 2.0, 3.0, 4.0])
    assert dof == 3
    assert u == pytest.approx(math.sqrt(5.0 / 3.0) / 2.0, rel=1e-12)  # s² = 5/3, n = 4


def test_type_a_per_component():
    u, dof = unc.type_a([[0.0, 10.0], [2.0, 10.0]])
    assert dof == 1
    np.testing.assert_allclose(u, [1.0, 0.0])  # s = √2, /√2


def test_type_a_needs_two():
    with pytest.raises(ValueError):
        unc.type_a([1.0])


def test_coverage_factors_of_gum_table_g2():
    assert unc.coverage_factor(2, 0.95) == pytest.approx(4.30, abs=0.005)
    assert unc.coverage_factor(10, 0.95) == pytest.approx(2.23, abs=0.005)
    assert unc.coverage_factor(math.inf, 0.95) == pytest.approx(1.960, abs=0.0005)


@settings(max_examples=50, deadline=None)
@given(u=st.floats(1e-6, 1e6), nu=st.floats(1.0, 1e4))
def test_welch_satterthwaite_two_equal_terms_double_the_dof(u, nu):
    assert float(unc.welch_satterthwaite([u, u], [nu, nu])) == pytest.approx(2 * nu, rel=1e-9)
    assert float(unc.welch_satterthwaite([u], [nu])) == pytest.approx(nu, rel=1e-9)
    assert math.isinf(float(unc.welch_satterthwaite([u, u], [math.inf, math.inf])))


def test_combine_gum_example():
    """u_A = 3 (ν = 4) and u_B = 4 (ν = ∞): u = 5, ν_eff = 5⁴ / (3⁴/4) = 30.86, k = t_0.975(30.86)."""
    terms = [
        BudgetTerm(
            source="repeatability", type="A", distribution="t", u_input=3.0, unit="N", sensitivity=1.0, contribution=3.0, dof=4
        ),
        BudgetTerm(source="b", type="B", distribution="normal", u_input=4.0, unit="N", sensitivity=1.0, contribution=4.0),
    ]
    u, big_u, k, nu = unc.combine(terms, 0.95)
    assert u == pytest.approx(5.0)
    assert nu == pytest.approx(625 / (81 / 4))
    assert k == pytest.approx(2.039, abs=0.002)
    assert big_u == pytest.approx(5.0 * k)


def test_delay_of_a_ramp_and_a_sine():
    t = np.arange(0.0, 2.0, 0.001)
    x = np.column_stack([3.0 * t, np.sin(2 * np.pi * t)])
    valid = np.ones(len(t), bool)
    out = unc.delayed(t, x, valid, 0.01)
    inner = slice(20, -20)
    np.testing.assert_allclose(out[inner, 0], 3.0 * (t[inner] - 0.01), atol=1e-12)
    np.testing.assert_allclose(out[inner, 1], np.sin(2 * np.pi * (t[inner] - 0.01)), atol=1e-5)


def test_draws_have_the_declared_distributions():
    inputs = [unc.Input("handle_force_calibration", 0.1, 0.1), unc.Input("sync_offset", 0.003, 0.003 / math.sqrt(3))]
    x = unc.draw_inputs(inputs, 20000, np.random.default_rng(1))
    assert x.shape == (20000, 4)
    np.testing.assert_allclose(x[:, :3].std(axis=0), 0.1, rtol=0.03)
    assert np.abs(x[:, 3]).max() <= 0.003 and x[:, 3].std() == pytest.approx(0.003 / math.sqrt(3), rel=0.03)


# --- Monte Carlo through the free-space family (§19.3) --------------------------------------------


@pytest.fixture(scope="module")
def two_rep_free_space():
    """The fixture ``unc-fs-two-reps``: two free-space repetitions, F = (0.5, −0.4, 0.3 + 0.2 sin 0.5t) N on the
    hand and 1.1 × it, noise-free, no rig trial (its conformance cases: spec §19.2, §19.4)."""
    return Path(__file__).resolve().parents[1] / "fixtures" / "conformance" / "unc-fs-two-reps"


def mean_direction(gain: float = 1.0) -> np.ndarray:
    """Mean unit vector of the fs-typical force over its 100 Hz grid (∂ mean|F+δ| / ∂δ at δ = 0)."""
    from haptify_tools.conformance_fixtures.free_space import felt

    f = gain * felt(np.arange(0.0, 12.0, 0.01))
    return (f / np.linalg.norm(f, axis=1, keepdims=True)).mean(axis=0)


def test_mc_sensitivity_of_mean_force_is_the_mean_direction(two_rep_free_space):
    ctx = ComputeContext(session=open_session(two_rep_free_space))
    compute_session(ctx.session, ctx=ctx)
    inputs = [unc.Input("handle_force_calibration", 0.02, 0.02)]
    x = unc.draw_inputs(inputs, 400, np.random.default_rng(7))
    y = unc.draw_values(ctx, ["free_space.force_mean"], inputs, x)["free_space.force_mean"]
    (term,) = unc.mc_terms(inputs, x, y)
    s = np.linalg.norm(mean_direction())  # both repetitions point the same way
    assert term.sensitivity == pytest.approx(s, rel=0.01)
    # the sample sd of |s|·δ over 400 draws: within 3σ of its expectation (σ_rel = 1/√(2·399))
    assert term.contribution == pytest.approx(s * 0.02, rel=3 / math.sqrt(2 * 399))
    assert term.dof == 399


def test_attach_without_rig_figures_is_type_a_only(two_rep_free_space):
    ctx = ComputeContext(session=open_session(two_rep_free_space))
    res = compute_session(ctx.session, ["free_space.force_mean", "free_space.speed_mean"], ctx=ctx, uncertainty=True)
    rec = res.get("free_space.force_mean")
    # the two repetitions are x and 1.1 x: s/√2 = 0.1 x / 2 with x the first repetition's value
    x1 = rec.per_repetition[0]
    assert rec.per_repetition[1] == pytest.approx(1.1 * x1, rel=1e-4)
    assert rec.uncertainty.u == pytest.approx(0.05 * x1, rel=1e-3)
    assert rec.uncertainty.k == pytest.approx(12.706, abs=0.001)  # t_0.975(1)
    assert rec.uncertainty.dof_eff == pytest.approx(1.0)
    assert rec.uncertainty.sources_missing == ["handle_force_calibration"]
    assert [t.source for t in rec.uncertainty.budget] == ["repeatability"]
    assert res.get("free_space.speed_mean").uncertainty.method == "type_a"
    assert res.get("workspace.modeled_volume") is None


def test_attach_with_a_rig_figure_combines_a_and_b(two_rep_free_space, monkeypatch):
    """With an offset-uncertainty figure of 0.05 N (rig.handle_force_offset_u): u² = u_A² + u_B², ν_eff by Welch–Satterthwaite."""
    ctx = ComputeContext(session=open_session(two_rep_free_space))
    res = compute_session(ctx.session, ["free_space.force_mean"], ctx=ctx)
    monkeypatch.setattr(unc, "rig_figure", lambda c, r, mid: type("Fig", (), {"value": 0.05})())
    unc.attach(ctx, res, draws=200)
    rec = res.get("free_space.force_mean")
    a, b = rec.uncertainty.budget
    assert (a.source, b.source) == ("repeatability", "handle_force_calibration")
    assert b.u_input == 0.05
    assert b.contribution == pytest.approx(0.05 * np.linalg.norm(mean_direction()), rel=3 / math.sqrt(2 * 199))
    assert rec.uncertainty.u == pytest.approx(math.hypot(a.contribution, b.contribution), rel=1e-12)
    nu = rec.uncertainty.u**4 / (a.contribution**4 / 1 + b.contribution**4 / 199)
    assert rec.uncertainty.dof_eff == pytest.approx(nu, rel=1e-9)
    assert rec.uncertainty.mc_draws == 200 and not rec.uncertainty.sources_missing


def test_results_round_trip_through_the_schema(two_rep_free_space):
    import jsonschema

    from haptify import schemas

    ctx = ComputeContext(session=open_session(two_rep_free_space))
    res = compute_session(ctx.session, ["free_space.force_mean"], ctx=ctx, uncertainty=True)
    doc = res.model_dump(mode="json", exclude_none=True)
    jsonschema.validate(doc, schemas.schema("results"))
    assert ResultsFile.model_validate(doc).get("free_space.force_mean").uncertainty is not None


# --- conformance: judging u, U and k (spec §16.3, §19.7) --------------------------------------------


def test_the_judge_reads_the_uncertainty_record():
    from haptify_conform.cases import load_cases
    from haptify_conform.judge import judge_metric

    case = next(c for c in load_cases() if c.id == "free_space.force_mean.uncertainty-k.two-reps")
    record = {"id": case.metric, "value": 0.7, "unit": "N"}
    assert "no uncertainty k" in judge_metric(case, {"metrics": [record]}).message
    record["uncertainty"] = {"u": 0.036, "U": 0.457, "k": 12.7062047}
    assert judge_metric(case, {"metrics": [record]}).status == "passed"
    record["uncertainty"]["k"] = 1.96
    assert judge_metric(case, {"metrics": [record]}).status == "failed"


# --- comparing (spec §19.6) ------------------------------------------------------------------------


def _record(value: float, u: float, dof: float | None):
    from haptify.pipeline.results import MetricResult, MetricUncertainty

    k = unc.coverage_factor(math.inf if dof is None else dof, 0.95)
    return MetricResult(
        id="free_space.force_mean",
        value=value,
        unit="N",
        n=3,
        definition_version="1.0.0",
        uncertainty=MetricUncertainty(method="type_a", u=u, U=k * u, k=k, coverage_probability=0.95, dof_eff=dof, budget=[]),
    )


def test_difference_test_welch():
    """u₁ = 0.3, u₂ = 0.4 with 4 and 9 dof: u_d = 0.5, ν = 0.0625 / (0.0081/4 + 0.0256/9) = 12.82, k = t_0.975(12.82)."""
    d = significance.compared(_record(10.0, 0.3, 4), _record(11.0, 0.4, 9))
    assert d.u == pytest.approx(0.5)
    assert d.dof == pytest.approx(0.0625 / (0.0081 / 4 + 0.0256 / 9))
    assert d.k == pytest.approx(2.165, abs=0.002)
    assert not d.significant  # |−1| < 2.165 × 0.5 = 1.08
    assert significance.compared(_record(10.0, 0.3, 4), _record(11.2, 0.4, 9)).significant
    assert significance.compared(_record(10.0, 0.3, 4), None) is None


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-1e3, 1e3), u=st.floats(1e-3, 10.0), nu=st.floats(1.0, 100.0))
def test_a_value_never_differs_from_itself_and_the_test_is_symmetric(x, u, nu):
    a, b = _record(x, u, nu), _record(x + 3 * u, u, nu)
    assert not significance.compared(a, a).significant
    assert significance.compared(a, b).significant == significance.compared(b, a).significant


def test_compare_shows_u_and_marks_significant_pairs():
    from haptify.pipeline.compare import SIGNIFICANCE, build_table
    from haptify.pipeline.results import DeviceSummary, Implementation

    def results(label: str, value: float, u: float) -> ResultsFile:
        return ResultsFile(
            implementation=Implementation(name="t", version="1"),
            session_id=label,
            device=DeviceSummary(manufacturer="M", model=label),
            manifest_sha256="0" * 64,
            metrics=[_record(value, u, None)],
        )

    table = build_table([results("A", 1.0, 0.01), results("B", 1.5, 0.01), results("C", 1.01, 0.01)])
    row = next(r for r in table.rows if r[0].startswith("Mean free-space force"))
    assert table.header[4] == SIGNIFICANCE
    assert row[1] == "1 ± 0.02 (U)"  # U = 1.96 × 0.01
    assert row[4] == "1–2, 2–3"  # |1 − 1.01| = 0.01 < 1.96·√2·0.01
    assert any("Welch" in n for n in table.notes)
    assert SIGNIFICANCE not in build_table([results("A", 1.0, 0.01)]).header


def test_ties_group_indistinguishable_devices():
    """u = 0.01, ν = ∞: two values tie when they differ by less than 1.96·√2·0.01 = 0.0277."""
    recs = [
        _record(1.00, 0.01, None),
        _record(1.50, 0.01, None),
        _record(1.02, 0.01, None),
        _record(1.04, 0.01, None),
        _record(1.51, 0.01, None),
    ]
    assert significance.tie_groups(recs) == [[0, 2], [3], [1, 4]]  # 1.04 − 1.00 = 0.04 > 0.0277: a new group
    plain = recs[0].model_copy(update={"uncertainty": None})
    assert significance.tie_groups([plain, recs[2]]) == [[0], [1]]


def test_compute_command_writes_the_records_only_when_asked(two_rep_free_space, tmp_path):
    import json

    from haptify.cli.main import main

    out = tmp_path / "r.json"
    assert main(["compute", str(two_rep_free_space), "--metrics", "free_space.force_mean", "-o", str(out)]) == 0
    assert json.loads(out.read_text())["metrics"][0].get("uncertainty") is None
    assert main(["compute", str(two_rep_free_space), "--metrics", "free_space.force_mean", "--uncertainty", "-o", str(out)]) == 0
    rec = json.loads(out.read_text())["metrics"][0]["uncertainty"]
    assert rec["k"] == pytest.approx(12.706, abs=0.001) and rec["U"] == pytest.approx(rec["k"] * rec["u"])


def test_type_a_records_of_a_vector_and_of_placements():
    """rig.plate_natural_frequency from two impacts (per axis s/√2) and rig.cop_error whose n counts 10 placements
    (sd/√10, 9 dof); no Type B source is involved, so no session is read."""
    from haptify.pipeline.results import Implementation, MetricResult

    freq = MetricResult(
        id="rig.plate_natural_frequency",
        value=[2.0, 2.0, 4.0],
        unit="Hz",
        per_repetition=[[1, 2, 3], [3, 2, 5]],
        n=2,
        sd=[math.sqrt(2), 0.0, math.sqrt(2)],
        definition_version="1.0.0",
    )
    cop = MetricResult(
        id="rig.cop_error", value=0.004, unit="m", per_repetition=[0.0035, 0.0045], n=10, sd=0.002, definition_version="1.0.0"
    )
    res = unc.attach(
        None,
        ResultsFile(
            implementation=Implementation(name="t", version="1"), session_id="s", manifest_sha256="0" * 64, metrics=[freq, cop]
        ),
    )
    f, c = res.metrics[0].uncertainty, res.metrics[1].uncertainty
    np.testing.assert_allclose(f.u, [1.0, 0.0, 1.0])
    assert f.k == pytest.approx(12.706, abs=0.001) and f.U == pytest.approx([12.7062, 0.0, 12.7062], abs=1e-3)
    assert c.u == pytest.approx(0.002 / math.sqrt(10)) and c.dof_eff == pytest.approx(9)
    assert c.k == pytest.approx(2.262, abs=0.001)  # t_0.975(9)


# --- the noise maximum, a one-sided bias (§19.3) ------------------------------------------------------

GRID = np.arange(0.0, 2.4, 0.01)  # a press's s … m: 2.4 s on the 100 Hz grid, as the Touch's plateau


def test_force_noise_has_unit_sd_and_the_lowpass_autocorrelation():
    """The draws' lag-τ correlation is that of white noise through the forward–backward Butterworth of §7.2:
    ∫|H|⁴ cos(2πfτ) df / ∫|H|⁴ df, from the filter's frequency response (not from its time-domain code)."""
    from scipy.signal import sosfreqz

    from haptify.processing.preprocessing import butter_lowpass, effective_cutoff

    e = unc.force_noise(GRID, 1000.0, 2000, np.random.default_rng(3))
    assert e.shape == (len(GRID), 2000) and e.std() == pytest.approx(1.0, abs=1e-12)
    sos = butter_lowpass(
        preprocessing.PARAMETERS.filter_order, effective_cutoff(preprocessing.PARAMETERS.wrench_cutoff_hz, 1000.0, 100.0), 1000.0
    )
    f, h = sosfreqz(sos, worN=20000, fs=1000.0)
    p = np.abs(h) ** 4
    for lag in (1, 2, 4):
        expected = np.sum(p * np.cos(2 * np.pi * f * lag * 0.01)) / np.sum(p)
        got = np.mean(e[:-lag] * e[lag:]) / np.mean(e * e)
        assert got == pytest.approx(expected, abs=0.02), lag


def test_noise_maximum_excess_of_a_flat_plateau_is_the_noise_maximum():
    """On a flat force c + σe the maximum reads high by σ·E[max e]; added noise makes it √2·σ·E[max e], so the
    SIMEX estimate is unbiased: its mean over 60 plateaus matches the excess of 4000 independent draws."""
    sigma = 0.004
    excess = sigma * unc.force_noise(GRID, 1000.0, 4000, np.random.default_rng(1)).max(axis=0).mean()
    rng = np.random.default_rng(2)
    est = [
        unc.noise_maximum_excess(
            2.7 + sigma * unc.force_noise(GRID, 1000.0, 1, rng)[:, 0], unc.force_noise(GRID, 1000.0, 48, rng), sigma
        )
        for _ in range(60)
    ]
    assert excess == pytest.approx(2.3 * sigma, rel=0.25)  # ~ E[max] of a few dozen independent normals
    assert np.mean(est) == pytest.approx(excess, abs=4 * np.std(est) / math.sqrt(len(est)))


def test_noise_maximum_excess_of_a_sharp_top_is_nil():
    """A top 0.1 N above its neighbours: only the top sample can be the maximum, whose noise averages to 0."""
    sigma = 0.004
    f = 5.6 - 0.1 * np.abs(np.arange(len(GRID)) - 120)
    b = unc.noise_maximum_excess(f, unc.force_noise(GRID, 1000.0, 2000, np.random.default_rng(4)), sigma)
    assert abs(b) < 0.2 * sigma  # scatter of 2000 draws: σ/√2000/(√2 − 1) ≈ 0.05 σ


def test_bias_estimate_is_the_mean_over_trials_and_never_negative(monkeypatch):
    """b of a metric: per trial the mean over its maxima, then the mean over the trials its value rests on; 0
    where a sharp top gives a negative Monte Carlo scatter."""
    from types import SimpleNamespace

    from haptify.metrics import stiffness
    from haptify.pipeline.results import MetricResult

    plateau, top = np.full(len(GRID), 2.7), 5.6 - 0.1 * np.abs(np.arange(len(GRID)) - 120)
    windows = {"a": [(GRID, plateau), (GRID, plateau)], "b": [(GRID, plateau)], "c": [(GRID, top)]}
    monkeypatch.setattr(stiffness, "maximum_windows", lambda ctx, tid: windows[tid])
    monkeypatch.setattr(unc, "rig_figure", lambda c, r, mid: SimpleNamespace(value=[0.004, 0.1, 0.001]))
    ctx = SimpleNamespace(session=SimpleNamespace(stream=lambda tid, kind: SimpleNamespace(rate_hz=1000.0)))

    def rec(trials):
        return MetricResult(
            id="stiffness.peak_force",
            value=2.7,
            unit="N",
            per_repetition=[2.7] * len(trials),
            n=len(trials),
            sd=0.0,
            trials=trials,
            definition_version="1.0.0",
        )

    def estimate(trials, seed):
        got = unc.noise_maximum_bias(ctx, None, rec(trials), np.random.default_rng(seed), 48)
        assert got is not None
        return got.estimate

    flat = np.mean([unc.noise_maximum_excess(plateau, unc.force_noise(GRID, 1000.0, 48, np.random.default_rng(9)), 0.004)])
    assert estimate(["b"], 9) == pytest.approx(flat, rel=1e-12)  # the force figure is component 0
    assert estimate(["b"], 9) > 0.002  # a noise-free plateau still gets σ·E[max] of the added noise
    assert min(estimate(["c"], s) for s in range(8)) == 0.0  # some seeds scatter below 0: clipped
    assert estimate(["a", "b"], 5) > estimate(["a", "b", "c"], 5) > 0


def test_attach_adds_the_one_sided_bias_to_U(two_rep_free_space, monkeypatch):
    from haptify.pipeline.results import UncorrectedBias

    ctx = ComputeContext(session=open_session(two_rep_free_space))
    res = compute_session(ctx.session, ["free_space.force_mean"], ctx=ctx)
    monkeypatch.setattr(
        unc, "bias_estimate", lambda *a: UncorrectedBias(source="noise_maximum", estimate=0.01, u_input=0.004, unit="N")
    )
    rec = unc.attach(ctx, res).get("free_space.force_mean").uncertainty
    assert rec.U == pytest.approx(rec.k * rec.u + 0.01, rel=1e-12) and rec.bias.estimate == 0.01


def test_the_biases_are_named_by_the_metrics_they_affect():
    d = unc.definitions()
    named = {m: x.bias for m, x in d.metrics.items() if x.bias}
    assert named == {
        "stiffness.peak_force": "noise_maximum",
        "workspace.measured_volume": "mocap_noise",
        "workspace.volume_ratio": "mocap_noise",
        "workspace.coverage": "mocap_noise",
    }
    assert set(named.values()) == set(d.biases)


# --- the motion-capture noise through a cloud's metrics (§19.3) ----------------------------------------


def smooth_track(n: int = 6000, rate_hz: float = 100.0) -> np.ndarray:
    """A hand's path at ``rate_hz`` (m, W): slow sinusoids of a few cm, jerk ≲ 1 m/s³."""
    t = np.arange(n) / rate_hz
    return np.column_stack([0.05 * np.sin(0.7 * t), 0.04 * np.cos(0.5 * t + 1.0), 0.15 + 0.03 * np.sin(0.9 * t)])


@settings(max_examples=20, deadline=None)
@given(
    sd=st.tuples(*[st.floats(2e-5, 5e-4)] * 3),
    shift=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
    seed=st.integers(0, 2**31),
)
def test_track_noise_sd_recovers_white_noise_on_a_smooth_path(sd, shift, seed):
    """Known noise on a smooth path: the estimate per axis is within 6 % (6000 samples: the MAD's scatter is
    about 1.7 %; the path's jerk adds < 1e-6 m to a third difference), wherever the path lies."""
    rng = np.random.default_rng(seed)
    track = smooth_track() + np.asarray(shift) + rng.standard_normal((6000, 3)) * np.asarray(sd)
    assert unc.track_noise_sd(track) == pytest.approx(np.asarray(sd), rel=0.06)


def test_track_noise_sd_skips_occlusions_and_needs_enough_differences():
    sd = np.array([1e-4, 2e-4, 5e-5])
    track = smooth_track() + np.random.default_rng(3).standard_normal((6000, 3)) * sd
    track[::7] = np.nan  # every seventh row occluded: no difference spans one
    assert unc.track_noise_sd(track) == pytest.approx(sd, rel=0.06)
    assert np.all(np.isnan(unc.track_noise_sd(smooth_track(unc.PARAMETERS.min_noise_differences + 2))))
    assert unc.track_noise_sd(smooth_track(unc.PARAMETERS.min_noise_differences + 3)) == pytest.approx(0.0, abs=1e-6)


def test_mocap_noise_bias_is_the_mean_shift_of_the_recomputed_values(monkeypatch):
    """b of a cloud metric: per trial the mean of its recomputations with the track's noise added once more, less
    the trial's value; then the mean over the trials, signed (spec §19.3). The recomputations see the track's
    own noise sd and are shared by the family's metrics."""
    from types import SimpleNamespace

    from haptify.metrics import workspace
    from haptify.pipeline.results import MetricResult

    sd = {"a": np.array([1e-4, 1e-4, 1e-4]), "b": np.array([2e-4, 2e-4, 2e-4])}
    tracks = {
        tid: (None, smooth_track() + np.random.default_rng(i).standard_normal((6000, 3)) * s)
        for i, (tid, s) in enumerate(sd.items())
    }
    seen = []

    def noisy(ctx, trial_id, noise_sd, rng):
        seen.append((trial_id, noise_sd))
        shift = {"a": -3e-6, "b": -1e-6}[trial_id] + rng.normal(0.0, 1e-9)
        return {"workspace.measured_volume": 0.0116 + shift, "workspace.volume_ratio": (0.0116 + shift) / 0.0134}

    monkeypatch.setattr(workspace, "trial_track", lambda ctx, tid: tracks[tid])
    monkeypatch.setattr(workspace, "noisy_trial_values", noisy)
    ctx = ComputeContext(session=SimpleNamespace())

    def rec(metric_id, values):
        return MetricResult(
            id=metric_id,
            value=float(np.mean(values)),
            unit="1",
            per_repetition=values,
            n=2,
            sd=float(np.std(values, ddof=1)),
            trials=["a", "b"],
            definition_version="1.0.0",
        )

    volume = unc.mocap_noise_bias(ctx, rec("workspace.measured_volume", [0.0116, 0.0116]), 2, 7)
    assert volume.estimate == pytest.approx(-2e-6, abs=1e-8) and volume.source == "mocap_noise"
    assert volume.u_input == pytest.approx(1.5e-4, rel=0.06)
    ratio = unc.mocap_noise_bias(ctx, rec("workspace.volume_ratio", [0.0116 / 0.0134] * 2), 2, 7)
    assert ratio.estimate == pytest.approx(-2e-6 / 0.0134, rel=1e-3)
    assert len(seen) == 4  # 2 trials × 2 draws, shared by both metrics
    assert [np.mean(s) for _, s in seen[::2]] == pytest.approx([1e-4, 2e-4], rel=0.06)


def test_attach_adds_the_magnitude_of_a_negative_bias_to_U(two_rep_free_space, monkeypatch):
    from haptify.pipeline.results import UncorrectedBias

    ctx = ComputeContext(session=open_session(two_rep_free_space))
    res = compute_session(ctx.session, ["free_space.force_mean"], ctx=ctx)
    monkeypatch.setattr(
        unc, "bias_estimate", lambda *a: UncorrectedBias(source="mocap_noise", estimate=-0.01, u_input=1e-4, unit="m")
    )
    rec = unc.attach(ctx, res).get("free_space.force_mean").uncertainty
    assert rec.U == pytest.approx(rec.k * rec.u + 0.01, rel=1e-12) and rec.bias.estimate == -0.01
