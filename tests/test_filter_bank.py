"""The filter bank of the Hammerstein–Wiener fit (haptify.processing.filter_bank; spec §11.3, §11.4.3)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter

from haptify.processing.filter_bank import FilterBank, lfilter_columns


def test_first_order_impulse_response_is_the_geometric_sequence():
    # 1 / (1 − p q^-1) driven by a unit impulse: p^t, known in closed form.
    poles = np.array([0.5, -0.9, 0.0])
    x = np.zeros((30, 3))
    x[0] = 1.0
    y = lfilter_columns(np.ones((3, 1)), np.column_stack([np.ones(3), -poles]), x)
    t = np.arange(30)[:, None]
    np.testing.assert_allclose(y, poles[None, :] ** t, rtol=0, atol=1e-15)


def test_fir_with_delay_shifts_and_scales():
    # B(q) = 0·1 + 0·q^-1 + 2 q^-2 with F = 1: y(t) = 2 x(t − 2), zeros before.
    x = np.arange(1.0, 11.0)[:, None]
    y = lfilter_columns([[0.0, 0.0, 2.0]], [[1.0]], x)
    np.testing.assert_array_equal(y[:, 0], np.r_[0.0, 0.0, 2.0 * x[:-2, 0]])


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    order_b=st.integers(1, 4),
    order_a=st.integers(0, 3),
    columns=st.integers(1, 9),
    n=st.integers(1, 300),
)
def test_every_column_is_scipy_lfilter_bitwise_when_recursive(seed, order_b, order_a, columns, n):
    rng = np.random.default_rng(seed)
    b = rng.standard_normal((columns, order_b))
    poles = rng.uniform(-0.95, 0.95, (columns, order_a))
    a = np.array([np.poly(p) for p in poles]).reshape(columns, order_a + 1)
    x = rng.standard_normal((n, columns))
    y = lfilter_columns(b, a, x)
    for m in range(columns):
        expected = lfilter(b[m], a[m], x[:, m])
        if order_a:
            assert np.array_equal(y[:, m], expected)
        else:  # scipy computes a pure FIR filter by convolution: another order of the sums
            np.testing.assert_allclose(y[:, m], expected, rtol=1e-13, atol=1e-14)


def test_gain_scales_each_output_sample_and_out_may_be_a_strided_view():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((200, 4))
    b, a = rng.standard_normal((4, 2)), np.tile([1.0, -1.6, 0.64], (4, 1))
    gain = rng.uniform(0.5, 2.0, 200)
    big = np.full((200, 9), np.nan)
    lfilter_columns(b, a, x, out=big[:, 2:6], gain=gain)
    expected = np.column_stack([lfilter(b[m], a[m], x[:, m]) * gain for m in range(4)])
    np.testing.assert_array_equal(big[:, 2:6], expected)
    assert np.isnan(big[:, :2]).all() and np.isnan(big[:, 6:]).all()


@pytest.mark.parametrize(
    "b, a, x, message",
    [
        (np.ones((2, 1)), np.ones((3, 1)), np.ones((5, 2)), "one numerator and one denominator per column"),
        (np.ones((2, 1)), np.array([[2.0, 0.1], [1.0, 0.1]]), np.ones((5, 2)), "start with 1"),
    ],
)
def test_inconsistent_filters_are_refused(b, a, x, message):
    with pytest.raises(ValueError, match=message):
        lfilter_columns(b, a, x)


def test_source_feeds_one_signal_to_several_filters():
    rng = np.random.default_rng(5)
    x = rng.standard_normal((120, 2))
    b = rng.standard_normal((3, 2))
    a = np.tile([1.0, -0.5], (3, 1))
    y = lfilter_columns(b, a, x, source=[1, 0, 1])
    for m, src in enumerate([1, 0, 1]):
        assert np.array_equal(y[:, m], lfilter(b[m], a[m], x[:, src]))
    with pytest.raises(ValueError, match="source must pick"):
        lfilter_columns(b, a, x, source=[0, 1, 2])


def test_stacked_records_restart_from_rest_at_their_starts():
    rng = np.random.default_rng(8)
    lengths = [50, 1, 80, 2]
    x = rng.standard_normal((sum(lengths), 3))
    b = rng.standard_normal((3, 3))
    a = np.tile([1.0, -1.2, 0.5], (3, 1))
    starts = np.cumsum([0] + lengths[:-1])
    y = lfilter_columns(b, a, x, starts=starts)
    for s, n in zip(starts, lengths):
        for m in range(3):
            assert np.array_equal(y[s : s + n, m], lfilter(b[m], a[m], x[s : s + n, m]))
    with pytest.raises(ValueError, match="starts must be rows"):
        lfilter_columns(b, a, x, starts=[len(x)])


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    order=st.integers(0, 3),
    cuts=st.lists(st.integers(0, 120), max_size=4),
    starts=st.lists(st.integers(0, 119), max_size=3),
)
def test_a_bank_filtering_blocks_in_turn_equals_one_call_over_all_rows(seed, order, cuts, starts):
    rng = np.random.default_rng(seed)
    b = rng.standard_normal((5, order + 1))
    a = np.column_stack([np.ones(5), rng.uniform(-0.4, 0.4, (5, order))])
    x = rng.standard_normal((120, 5))
    gain = rng.uniform(0.5, 2.0, 120)
    whole = lfilter_columns(b, a, x, gain=gain, starts=starts)
    bank, edges = FilterBank(b, a), [0, *sorted(cuts), 120]
    out = np.full((120, 5), np.nan)
    for lo, hi in zip(edges, edges[1:]):
        local = [s - lo for s in starts if lo <= s < hi]
        bank(x[lo:hi], out=out[lo:hi], gain=gain[lo:hi], starts=local)
    np.testing.assert_array_equal(out, whole)


def test_signals_are_used_in_turn_when_the_filters_are_a_multiple_of_them_and_may_have_strided_rows():
    rng = np.random.default_rng(9)
    wide = rng.standard_normal((150, 7))
    x = wide[:, 2:5]  # rows 7 apart in memory
    b = rng.standard_normal((6, 2))
    a = np.column_stack([np.ones(6), rng.uniform(-0.5, 0.5, (6, 2))])
    y = lfilter_columns(b, a, x)
    for m in range(6):
        assert np.array_equal(y[:, m], lfilter(b[m], a[m], x[:, m % 3]))
    with pytest.raises(ValueError, match="a multiple of"):
        lfilter_columns(b[:4], a[:4], x)


@pytest.mark.parametrize("order", [1, 3])  # the order-2 loop and the general loop
def test_single_precision_output_zeroes_values_below_the_floor_and_keeps_nan(order):
    # 1 / (1 − q^-1/2) driven by a unit impulse gives 2^-t (exact in single precision down to 2^-149): with the
    # floor 2^-63, rows 0 … 63 are kept exactly and later rows are 0. Higher orders add poles at 0 (no effect).
    # A NaN input in the second column is not a value below the floor: it stays NaN from its row on.
    n = 120
    x = np.zeros((n, 2))
    x[0] = 1.0
    x[5, 1] = np.nan
    a = np.tile(np.r_[1.0, -0.5, np.zeros(order - 1)], (2, 1))
    out = np.full((n, 3), -1.0, dtype=np.float32)
    FilterBank(np.ones((2, 1)), a)(x, out=out[:, :2], floor=2.0**-63)
    t = np.arange(n)
    np.testing.assert_array_equal(out[:, 0], np.where(t <= 63, 2.0 ** -t.astype(float), 0.0).astype(np.float32))
    np.testing.assert_array_equal(out[:5, 1], (2.0 ** -t[:5].astype(float)).astype(np.float32))
    assert np.isnan(out[5:, 1]).all()
    assert (out[:, 2] == -1.0).all()  # nothing written outside the view


def test_sums_accumulate_the_weighted_results_in_double_precision_across_blocks():
    # 1 / (1 − p q^-1) from an impulse gives p^t; with unit weights Σ_t p^t = (1 − p^N) / (1 − p), and with
    # weights (−1)^t Σ_t (−p)^t = (1 − (−p)^N) / (1 + p), whatever the blocks the rows come in and even when the
    # results are stored in single precision.
    n, poles = 90, np.array([0.9, -0.7])
    x = np.zeros((n, 2))
    x[0] = 1.0
    bank = FilterBank(np.ones((2, 1)), np.column_stack([np.ones(2), -poles]))
    out = np.empty((n, 2), dtype=np.float32)
    plain, alternating = np.zeros(2), np.zeros(2)
    for lo, hi in [(0, 7), (7, 50), (50, n)]:
        bank(x[lo:hi], out=out[lo:hi], weights=np.ones(hi - lo), sums=plain)
    bank = FilterBank(np.ones((2, 1)), np.column_stack([np.ones(2), -poles]))
    bank(x, out=out, weights=(-1.0) ** np.arange(n), sums=alternating)
    np.testing.assert_allclose(plain, (1 - poles**n) / (1 - poles), rtol=1e-14)
    np.testing.assert_allclose(alternating, (1 - (-poles) ** n) / (1 + poles), rtol=1e-14)
    np.testing.assert_array_equal(out, (poles[None, :] ** np.arange(n)[:, None]).astype(np.float32))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"out": np.empty((10, 2), dtype=np.int64)}, "float64 or float32"),
        ({"weights": np.ones(10)}, "go together"),
        ({"weights": np.ones(9), "sums": np.zeros(2)}, r"weights must be \(10,\)"),
        ({"weights": np.ones(10), "sums": np.zeros(2, dtype=np.float32)}, "sums contiguous float64"),
    ],
)
def test_inconsistent_outputs_and_sums_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        FilterBank(np.ones((2, 1)), np.tile([1.0, -0.5], (2, 1)))(np.ones((10, 2)), **kwargs)
