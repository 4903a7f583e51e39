"""ISO 5725-2 statistics (tools/haptify_tools/registry/interlab.py) against hand-computed cells, ISO's
tabulated Mandel critical values and a simulated round robin with known repeatability and reproducibility."""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptify.errors import HaptifyError
from haptify_tools.registry.interlab import LabCell, mandel_h_critical, mandel_k_critical, precision


def test_three_labs_by_hand():
    """Cells [1, 3], [5, 7], [3, 5]: s_i² = 2 each → s_r² = 2; means 2, 6, 4 (grand 4), s_d² = 2·(4 + 4 + 0)/2 = 8,
    n̄ = 2 → s_L² = (8 − 2)/2 = 3, s_R² = 5; h = (−2, 2, 0)/2; k = 1 for every lab."""
    got = precision([LabCell("a", [1, 3]), LabCell("b", [5, 7]), LabCell("c", [3, 5])])
    assert got.grand_mean == pytest.approx(4.0)
    assert got.s_r == pytest.approx(math.sqrt(2))
    assert got.s_L == pytest.approx(math.sqrt(3))
    assert got.s_R == pytest.approx(math.sqrt(5))
    np.testing.assert_allclose(got.h, [-1, 1, 0])
    np.testing.assert_allclose(got.k, [1, 1, 1])


def test_between_lab_variance_is_not_negative():
    """Means closer than repeatability predicts: s_L² estimate < 0 is set to 0 (ISO 5725-2 §7.4.5), s_R = s_r."""
    got = precision([LabCell("a", [0, 10]), LabCell("b", [5.1, 4.9]), LabCell("c", [5, 5.2])])
    assert got.s_L == 0.0 and got.s_R == pytest.approx(got.s_r)


@pytest.mark.parametrize("p, h1, h5", [(3, 1.15, 1.15), (4, 1.49, 1.42), (5, 1.72, 1.57), (8, 2.06, 1.75), (10, 2.18, 1.80)])
def test_mandel_h_critical_values_of_iso_5725_2(p, h1, h5):
    """ISO 5725-2 Table 6, h at 1 % and 5 %."""
    assert mandel_h_critical(p, 0.01) == pytest.approx(h1, abs=0.006)
    assert mandel_h_critical(p, 0.05) == pytest.approx(h5, abs=0.006)


@pytest.mark.parametrize("p, n", [(4, 2), (8, 3), (12, 5)])
def test_mandel_k_critical_values_are_the_null_quantiles(p, n):
    """Under the null (every lab the same normal noise) a lab's k exceeds the α critical value with probability α:
    the empirical 95 % and 99 % quantiles of k over 40 000 simulated round robins match."""
    x = np.random.default_rng(p * n).normal(size=(40_000, p, n))
    var = x.var(axis=2, ddof=1)
    k = np.sqrt(var[:, 0] / var.mean(axis=1))
    assert np.quantile(k, 0.95) == pytest.approx(mandel_k_critical(p, n, 0.05), rel=0.01)
    assert np.quantile(k, 0.99) == pytest.approx(mandel_k_critical(p, n, 0.01), rel=0.015)


def test_simulated_round_robin_recovers_s_r_and_s_R():
    """120 labs × 4 repetitions: lab bias N(0, 0.03²), repetition noise N(0, 0.04²) → s_r = 0.04, s_R = 0.05.
    The estimates' relative standard errors are ≈ 2 % (s_r) and ≈ 5 % (s_R): within 20 % by a wide margin."""
    rng = np.random.default_rng(5725)
    cells = [LabCell(f"lab{i}", list(1.0 + rng.normal(0, 0.03) + rng.normal(0, 0.04, 4))) for i in range(120)]
    got = precision(cells)
    assert got.s_r == pytest.approx(0.04, rel=0.2)
    assert got.s_R == pytest.approx(0.05, rel=0.2)
    assert got.s_L == pytest.approx(0.03, rel=0.3)


def test_an_outlying_lab_is_flagged():
    rng = np.random.default_rng(1)
    cells = [LabCell(f"lab{i}", list(rng.normal(0, 1, 5))) for i in range(9)]
    cells.append(LabCell("biased", list(rng.normal(8, 1, 5))))
    cells.append(LabCell("noisy", list(rng.normal(0, 6, 5))))
    got = precision(cells)
    assert got.h_flags[got.labs.index("biased")] == "outlier"
    assert got.k_flags[got.labs.index("noisy")] == "outlier"
    assert [f for lab, f in zip(got.labs, got.h_flags) if lab.startswith("lab")].count("outlier") == 0


def test_too_few_labs_or_repetitions_are_refused():
    with pytest.raises(HaptifyError):
        precision([LabCell("a", [1, 2]), LabCell("b", [1, 2])])
    with pytest.raises(HaptifyError):
        precision([LabCell("a", [1, 2]), LabCell("b", [1, 2]), LabCell("c", [1])])
