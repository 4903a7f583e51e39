"""Known answers for the Hammerstein–Wiener model (spec §11.2–11.5): maps, prediction, file formats, fitting."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.io import loadmat
from scipy.signal import lfilter

from haptify.dynamics import (
    Channel,
    FitOptions,
    HWModelFile,
    PiecewiseLinearMap,
    TransferFunction,
    UnitGainMap,
    export_mat,
    fit,
    fitting,
    jacobian,
    load_model,
    place_breakpoints,
    predict,
    pwl_basis,
    pwl_eval,
    rmse,
    save_model,
)
from haptify.errors import HaptifyError

# ---------------------------------------------------------------------------------------------
# helpers: a known model and smooth random inputs
# ---------------------------------------------------------------------------------------------


def smooth_inputs(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """Low-passed white noise (first-order, pole 0.9), standard deviation ≈ 0.57."""
    return lfilter([0.1], [1.0, -0.9], rng.standard_normal((n, k)), axis=0) * 2.5


def known_model(
    rng: np.random.Generator, nu: int, ny: int, input_map: bool = True, output_map: bool = True, nk: int = 0
) -> HWModelFile:
    """A H-W model: saturating input maps, expanding output maps, stable 2nd-order blocks."""
    bpi = np.linspace(-1.5, 1.5, 9)
    bpo = np.linspace(-2.0, 2.0, 9)
    ins = [
        PiecewiseLinearMap(breakpoints=bpi.tolist(), values=(bpi + 0.5 * np.tanh(2 * bpi)).tolist())
        if input_map
        else UnitGainMap()
        for _ in range(nu)
    ]
    outs = [
        PiecewiseLinearMap(breakpoints=bpo.tolist(), values=(bpo + 0.2 * bpo * np.abs(bpo)).tolist())
        if output_map
        else UnitGainMap()
        for _ in range(ny)
    ]
    lin = [
        [TransferFunction(b=(0.4 * rng.standard_normal(2)).tolist(), f=[-0.6, 0.2], nk=nk) for _ in range(nu)] for _ in range(ny)
    ]
    return HWModelFile(
        sample_rate_hz=100.0,
        inputs=[Channel(name=f"u{i}", unit="1") for i in range(nu)],
        outputs=[Channel(name=f"y{j}", unit="N") for j in range(ny)],
        input_maps=ins,
        output_maps=outs,
        linear=lin,
    )


def reference_simulation(model: HWModelFile, u: np.ndarray) -> np.ndarray:
    """Spec §11.3 written as explicit loops over samples (an independent implementation)."""
    n = len(u)
    w = np.zeros_like(u)
    for i, m in enumerate(model.input_maps):
        w[:, i] = u[:, i] if m.type == "unit_gain" else np.array([_pwl_scalar(m, x) for x in u[:, i]])
    y = np.zeros((n, model.ny))
    for j in range(model.ny):
        x = np.zeros(n)
        for i, tf in enumerate(model.linear[j]):
            z = np.zeros(n)
            for t in range(n):
                acc = sum(b * w[t - tf.nk - k, i] for k, b in enumerate(tf.b) if t - tf.nk - k >= 0)
                acc -= sum(f * z[t - lag - 1] for lag, f in enumerate(tf.f) if t - lag - 1 >= 0)
                z[t] = acc
            x += z
        m = model.output_maps[j]
        y[:, j] = x if m.type == "unit_gain" else np.array([_pwl_scalar(m, v) for v in x])
    return y


def _pwl_scalar(m: PiecewiseLinearMap, x: float) -> float:
    bp, v = m.breakpoints, m.values
    k = 0
    while k < len(bp) - 2 and x >= bp[k + 1]:
        k += 1
    return v[k] + (x - bp[k]) * (v[k + 1] - v[k]) / (bp[k + 1] - bp[k])


# ---------------------------------------------------------------------------------------------
# static maps
# ---------------------------------------------------------------------------------------------


def test_pwl_interpolates_and_extends_linearly():
    bp = np.array([-1.0, 0.0, 2.0])
    v = np.array([3.0, 1.0, 5.0])
    x = np.array([-3.0, -1.0, -0.5, 0.0, 1.0, 2.0, 4.0])
    # slopes: -2 on the first segment, +2 on the second; extended beyond the ends
    assert np.allclose(pwl_eval(bp, v, x), [7.0, 3.0, 2.0, 1.0, 3.0, 5.0, 9.0])


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=1, max_size=30), st.lists(st.floats(-3, 3), min_size=4, max_size=4))
def test_basis_times_values_is_the_map(xs, values):
    bp = np.array([-1.0, -0.2, 0.5, 2.0])
    x = np.array(xs)
    assert np.allclose(pwl_basis(bp, x) @ np.array(values), pwl_eval(bp, np.array(values), x), atol=1e-9)
    assert np.allclose(pwl_basis(bp, x).sum(axis=1), 1.0)  # the basis reproduces constants


def test_breakpoints_follow_quantiles_and_stay_increasing():
    x = np.arange(1001.0)
    assert np.allclose(place_breakpoints(x, 5, (0.0, 1.0)), [0, 250, 500, 750, 1000])
    const = place_breakpoints(np.full(50, 3.0), 10, (0.01, 0.99))
    assert np.all(np.diff(const) > 0) and abs(const.mean() - 3.0) < 1e-12
    lumpy = place_breakpoints(np.r_[np.zeros(90), np.linspace(1, 2, 10)], 10, (0.01, 0.99))
    assert np.all(np.diff(lumpy) > 0)


# ---------------------------------------------------------------------------------------------
# prediction and the parameter file
# ---------------------------------------------------------------------------------------------


def test_prediction_is_the_difference_equation_of_the_spec():
    rng = np.random.default_rng(3)
    model = known_model(rng, nu=2, ny=2, nk=1)
    model.linear[1][0] = TransferFunction(b=[0.3, -0.1, 0.05], f=[-0.5], nk=2)  # orders differ per pair
    model.input_maps[1] = UnitGainMap()
    u = smooth_inputs(rng, 150, 2)
    assert np.allclose(predict(model, u), reference_simulation(model, u), rtol=0, atol=1e-12)


def test_parameter_file_reproduces_its_outputs_exactly(tmp_path):
    rng = np.random.default_rng(4)
    model = known_model(rng, nu=3, ny=2)
    u = smooth_inputs(rng, 500, 3)
    path = save_model(model, tmp_path / "model.json")
    again = load_model(path)
    assert again == model
    assert np.array_equal(predict(again, u), predict(model, u))


def test_mat_export_holds_the_same_model(tmp_path):
    """Rebuild the model from the .mat with MATLAB's conventions (B with nk leading zeros, F with its 1)."""
    rng = np.random.default_rng(5)
    model = known_model(rng, nu=2, ny=2, nk=1)
    model.output_maps[0] = UnitGainMap()
    u = smooth_inputs(rng, 300, 2)
    s = loadmat(export_mat(model, tmp_path / "model.mat"), squeeze_me=True, struct_as_record=False)["model"]
    assert s.Ts == pytest.approx(0.01)
    assert list(s.InputName) == ["u0", "u1"] and list(s.OutputUnit) == ["N", "N"]

    def apply(nl, x):
        return x if nl.Type == "unit_gain" else pwl_eval(nl.BreakPoints[0], nl.BreakPoints[1], x)

    w = np.column_stack([apply(s.InputNonlinearity[i], u[:, i]) for i in range(2)])
    y = np.column_stack(
        [
            apply(
                s.OutputNonlinearity[j],
                sum(lfilter(np.atleast_1d(s.B[j, i]), np.atleast_1d(s.F[j, i]), w[:, i]) for i in range(2)),
            )
            for j in range(2)
        ]
    )
    assert np.allclose(y, predict(model, u), atol=1e-12)
    assert s.nk[0, 0] == 1 and np.atleast_1d(s.B[0, 0])[0] == 0.0 and np.atleast_1d(s.F[0, 0])[0] == 1.0


def test_invalid_model_file_is_a_coded_error(tmp_path):
    rng = np.random.default_rng(6)
    data = json.loads(known_model(rng, 2, 1).model_dump_json())
    data["input_maps"][1]["breakpoints"][3] = -10.0  # no longer increasing
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    with pytest.raises(HaptifyError) as err:
        load_model(bad)
    assert err.value.code == "E702" and err.value.findings[0].pointer.startswith("/input_maps/1")
    data = json.loads(known_model(rng, 2, 1).model_dump_json())
    data["linear"][0].pop()  # ny × nu block with a missing entry
    bad.write_text(json.dumps(data))
    with pytest.raises(HaptifyError, match="linear must be"):
        load_model(bad)
    with pytest.raises(HaptifyError) as err:
        load_model(tmp_path / "missing.json")
    assert err.value.code == "E702"


def test_inputs_that_do_not_fit_the_model_are_rejected():
    model = known_model(np.random.default_rng(7), 2, 1)
    with pytest.raises(HaptifyError) as err:
        predict(model, np.zeros((10, 3)))
    assert err.value.code == "E703"
    u = np.zeros((10, 2))
    u[4, 1] = np.nan
    with pytest.raises(HaptifyError, match="sample 4"):
        predict(model, u)


def test_quaternion_sign_does_not_change_the_prediction():
    """q and −q are one orientation: the hemisphere rule makes the prediction identical (spec §11.3)."""
    rng = np.random.default_rng(8)
    n = 2000
    ang = 0.3 * np.sin(np.arange(n) / 50.0)
    q = np.column_stack([np.cos(ang / 2), np.sin(ang / 2), np.zeros(n), np.zeros(n)])
    u = np.column_stack([q, smooth_inputs(rng, n, 1)])
    y = np.column_stack([np.sin(ang) + u[:, 4]])
    model, _ = fit(u, y, sample_rate_hz=100.0, quaternion_columns=[0, 1, 2, 3])
    flipped = u.copy()
    flipped[::3, :4] *= -1.0
    assert np.array_equal(predict(model, flipped), predict(model, u))


# ---------------------------------------------------------------------------------------------
# fitting: data from a known model with known white noise
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "input_map, output_map",
    [(True, True), (True, False), (False, True)],
    ids=["hammerstein-wiener", "pure-hammerstein", "pure-wiener"],
)
@pytest.mark.parametrize("seed", [0, 1])
def test_fit_reaches_the_noise_floor_on_held_out_data(input_map, output_map, seed):
    """Held-out RMSE within 10 % of the known noise σ, for the matching structure and for the default H-W."""
    rng = np.random.default_rng(seed)
    truth = known_model(rng, nu=3, ny=2, input_map=input_map, output_map=output_map)
    u_train, u_test = smooth_inputs(rng, 4000, 3), smooth_inputs(rng, 2000, 3)
    y_train0, y_test0 = predict(truth, u_train), predict(truth, u_test)
    sigma = 0.1 * y_train0.std(axis=0)
    y_train = y_train0 + sigma * rng.standard_normal(y_train0.shape)
    y_test = y_test0 + sigma * rng.standard_normal(y_test0.shape)
    structure = FitOptions.from_definition(
        input_map="piecewise_linear" if input_map else "unit_gain", output_map="piecewise_linear" if output_map else "unit_gain"
    )
    for options in (structure, FitOptions.from_definition()):
        model, report = fit(u_train, y_train, sample_rate_hz=100.0, options=options)
        ratio = rmse(y_test, predict(model, u_test)) / sigma
        assert np.all(np.abs(ratio - 1.0) < 0.10), (options.input_map, options.output_map, ratio)
        assert report.cost_history == sorted(report.cost_history, reverse=True)  # LM never goes uphill
        assert model.fit.samples == 4000 and len(model.fit.rmse) == 2


def test_fit_of_several_records_matches_one_long_record():
    """Records split by a gap are each simulated from rest; the fit still reaches the noise floor."""
    rng = np.random.default_rng(11)
    truth = known_model(rng, nu=2, ny=1)
    parts = [smooth_inputs(rng, 2000, 2), smooth_inputs(rng, 1500, 2)]
    sigma = 0.05
    ys = [predict(truth, p) + sigma * rng.standard_normal((len(p), 1)) for p in parts]
    model, _ = fit(parts, ys, sample_rate_hz=100.0)
    u_test = smooth_inputs(rng, 2000, 2)
    y_test = predict(truth, u_test) + sigma * rng.standard_normal((2000, 1))
    assert abs(rmse(y_test, predict(model, u_test))[0] / sigma - 1.0) < 0.10
    assert model.fit.samples == 3500


def test_fitted_model_is_stable_and_valid_against_its_schema():
    rng = np.random.default_rng(12)
    u = smooth_inputs(rng, 3000, 2)
    y = np.cumsum(u[:, :1], axis=0) * 0.02 + 0.01 * rng.standard_normal((3000, 1))  # near-integrator
    model, _ = fit(u, y, sample_rate_hz=100.0)
    radius = FitOptions.from_definition().stability_radius
    for tf in model.linear[0]:
        poles = np.roots(np.r_[1.0, tf.f]) if tf.f else np.zeros(0)
        assert np.all(np.abs(poles) < radius)
    HWModelFile.model_validate_json(model.model_dump_json())


def test_training_data_must_be_finite_and_paired():
    u = np.zeros((100, 2))
    with pytest.raises(HaptifyError) as err:
        fit(u, np.zeros((99, 1)), sample_rate_hz=100.0)
    assert err.value.code == "E703"
    y = np.zeros((100, 1))
    y[5] = np.inf
    with pytest.raises(HaptifyError) as err:
        fit(u, y, sample_rate_hz=100.0)
    assert err.value.code == "E703"


coefficients = st.lists(st.floats(-1.0, 1.0), min_size=1, max_size=3)
poles = st.lists(st.floats(-0.9, 0.9), min_size=0, max_size=2)


@settings(max_examples=40, deadline=None)
@given(coefficients, poles, st.integers(0, 3), st.integers(1, 20), st.floats(-3.0, 3.0))
def test_unit_gain_model_is_linear_and_time_invariant(b, p, nk, shift, gain):
    """With unit-gain maps the model is the LTI block: superposition and delay-shift hold exactly (spec §11.3)."""
    f = np.poly(p)[1:].tolist() if p else []
    model = HWModelFile(
        sample_rate_hz=100.0,
        inputs=[Channel(name="u", unit="1"), Channel(name="v", unit="1")],
        outputs=[Channel(name="y", unit="1")],
        input_maps=[UnitGainMap(), UnitGainMap()],
        output_maps=[UnitGainMap()],
        linear=[[TransferFunction(b=b, f=f, nk=nk), TransferFunction(b=b[::-1], f=f, nk=0)]],
    )
    rng = np.random.default_rng(len(b) + nk)
    u1, u2 = rng.standard_normal((60, 2)), rng.standard_normal((60, 2))
    y1, y2 = predict(model, u1), predict(model, u2)
    assert np.allclose(predict(model, u1 + gain * u2), y1 + gain * y2, atol=1e-9)
    delayed = np.vstack([np.zeros((shift, 2)), u1])[:60]
    assert np.allclose(predict(model, delayed)[shift:], y1[: 60 - shift], atol=1e-9)


# ---------------------------------------------------------------------------------------------
# the batched simulation and Jacobian of the fit (spec §11.4.3)
# ---------------------------------------------------------------------------------------------


def _random_structure(rng: np.random.Generator, nk: int):
    u = smooth_inputs(rng, 400, 3)
    in_bp = [np.sort(rng.uniform(-1.0, 1.0, 5)), None, np.linspace(-0.8, 0.8, 4)]  # a unit-gain input among maps
    out_bp = [np.linspace(-1.5, 1.5, 6), None]
    st_ = jacobian._Structure(nu=3, ny=2, nb=2, nf=2, nk=nk, in_bp=in_bp, out_bp=out_bp)
    theta = rng.normal(0.0, 0.5, st_.size)
    for j in range(2):
        for i in range(3):
            theta[st_.f_idx[j, i]] = np.poly(rng.uniform(-0.8, 0.8, 2))[1:]  # stable real poles
        if out_bp[j] is not None:
            theta[st_.c_idx[j]] = np.sort(rng.normal(0.0, 1.0, 6))
    return st_, theta, jacobian._Record.of(st_, u, np.zeros((len(u), 2)))


@pytest.mark.parametrize("nk", [0, 2])
def test_batched_simulation_is_the_prediction_of_the_same_parameters(nk):
    st_, theta, rec = _random_structure(np.random.default_rng(10 + nk), nk)
    model = fitting._assemble(
        st_,
        theta,
        100.0,
        None,
        [Channel(name=f"u{i}", unit="1") for i in range(3)],
        [Channel(name=f"y{j}", unit="1") for j in range(2)],
    )
    np.testing.assert_allclose(jacobian._simulate(st_, theta, rec), predict(model, rec.u), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("nk", [0, 1])
def test_analytic_jacobian_matches_central_differences(nk):
    st_, theta, rec = _random_structure(np.random.default_rng(20 + nk), nk)
    h = 1e-6
    for j in range(2):
        yhat, jac = jacobian._output_jacobian(st_, theta, rec, j, weight=0.5)
        np.testing.assert_allclose(yhat, jacobian._simulate(st_, theta, rec)[:, j], rtol=1e-12, atol=1e-12)
        own = st_.own(j)
        columns = list(range(st_.n_shared)) + list(range(own.start, own.stop))
        assert jac.shape == (len(rec.u), len(columns))
        for col, p in enumerate(columns):
            step = np.zeros(st_.size)
            step[p] = h
            plus, minus = jacobian._simulate(st_, theta + step, rec), jacobian._simulate(st_, theta - step, rec)
            numeric = (plus[:, j] - minus[:, j]) / (2 * h)
            np.testing.assert_allclose(jac[:, col], 0.5 * numeric, rtol=0, atol=2e-6 * max(1.0, np.abs(numeric).max()))


@pytest.mark.parametrize("block_rows", [37, 400])
def test_normal_equations_by_blocks_of_rows_are_those_of_the_whole_jacobian(monkeypatch, block_rows):
    # Blocks of 37 rows cut the stacked records (starting at rows 0, 150 and 151) mid-block, and a record of one
    # row lies inside a block: the filters' delays carry across blocks and restart at every record's first row.
    st_, theta, rec = _random_structure(np.random.default_rng(30), 1)
    rec = jacobian._Record.of(st_, rec.u, np.random.default_rng(31).normal(size=(len(rec.u), 2)), starts=[0, 150, 151])
    monkeypatch.setattr(jacobian, "BLOCK_ROWS", block_rows)
    sim = jacobian._simulation(st_, theta, rec)
    weights = np.array([0.7, 1.3])
    width = st_.n_shared + max(st_.own(j).stop - st_.own(j).start for j in range(2)) + 2
    buffer = np.full((block_rows, width), np.nan, dtype=np.float32)
    for j, (gram, jac_e) in enumerate(jacobian._normal_equations(st_, theta, rec, weights, sim, buffer)):
        yhat, jac = jacobian._output_jacobian(st_, theta, rec, j, weight=weights[j], sim=sim)
        e = (rec.y[:, j] - yhat) * weights[j]
        # JᵀJ from J rounded to single precision (a few single-precision ulps of its largest entry); Jᵀe in double
        np.testing.assert_allclose(gram, jac.T @ jac, rtol=0, atol=1e-6 * np.abs(jac.T @ jac).max())
        np.testing.assert_allclose(jac_e, e @ jac, rtol=1e-12, atol=1e-12 * np.abs(e @ jac).max())


def test_single_precision_block_rounds_like_numpy_and_zeroes_values_below_the_floor():
    # By construction: 2^-64, 2^-127 and 2^-200 lie below the floor 2^-63 (zeroed), 2^-63 and 1.5 · 2^-63 on or
    # above it (kept exactly); 1/3 and -2.5e30 round as numpy rounds them.
    floor = jacobian.SINGLE_PRECISION_FLOOR
    assert floor == 2.0**-63 and np.float32(floor) ** 2 == np.float32(2.0**-126) == np.finfo(np.float32).smallest_normal
    block = np.array([[2.0**-64, -(2.0**-127), floor, 1 / 3], [-1.5 * floor, 2.0**-200, -2.5e30, 0.0]])
    wide = np.full((2, 6), np.nan, dtype=np.float32)
    out = jacobian._single_precision(block, wide[:, :4])  # a view with strided rows, as the normal equations pass
    expected = np.array([[0.0, 0.0, floor, np.float32(1 / 3)], [-1.5 * floor, 0.0, np.float32(-2.5e30), 0.0]], dtype=np.float32)
    np.testing.assert_array_equal(out, expected)
    assert np.isnan(wide[:, 4:]).all()  # nothing written outside the view


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64), min_size=1, max_size=64))
def test_single_precision_is_numpy_rounding_without_products_below_the_smallest_normal(values):
    block = np.array(values)[None, :]
    with np.errstate(over="ignore"):  # beyond single precision's range both give ±inf
        rounded = block.astype(np.float32)
        expected = np.where(np.abs(rounded) >= jacobian.SINGLE_PRECISION_FLOOR, rounded, np.float32(0.0))
        out = jacobian._single_precision(block, np.empty(block.shape, dtype=np.float32))
    np.testing.assert_array_equal(out, expected)
    kept = np.abs(out[out != 0])
    if kept.size:  # the smallest product of two kept values is a normal number
        assert kept.min() * kept.min() >= np.finfo(np.float32).smallest_normal


def test_parameter_layout_puts_each_outputs_own_parameters_in_jacobian_order():
    st_, _, _ = _random_structure(np.random.default_rng(40), 0)
    nu, nb, nf = 3, 2, 2
    for j in range(2):
        own = st_.own(j)
        expected = np.concatenate(
            [st_.b_idx[j].T.ravel(), st_.f_idx[j].T.ravel()] + ([] if st_.c_idx[j] is None else [st_.c_idx[j]])
        )
        np.testing.assert_array_equal(expected, np.arange(own.start, own.stop))  # b_1 of every input first
        assert st_.b_idx[j, 1, 0] == own.start + 1 and st_.f_idx[j, 0, 1] == own.start + nb * nu + nu
    every = np.concatenate([np.arange(st_.n_shared)] + [np.arange(st_.own(j).start, st_.own(j).stop) for j in range(2)])
    np.testing.assert_array_equal(every, np.arange(st_.size))  # θ covered once, no gap
    assert nf == st_.nf
