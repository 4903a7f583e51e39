"""Inter-laboratory statistics of one metric of one device model: ISO 5725-2 (spec §17.5.3).

Pure functions on numbers, no database: each lab contributes its repetitions of the metric (a cell, in
ISO 5725-2's words). From the cells: the repeatability standard deviation s_r (pooled within-lab), the
between-lab s_L and the reproducibility s_R = √(s_L² + s_r²) (ISO 5725-2 §7.4, unbalanced cells allowed),
and Mandel's consistency statistics h (between labs) and k (within labs) with their critical values at
5 % (stragglers) and 1 % (outliers) (ISO 5725-2 §7.3.1). The registry shows them per device model and metric
(:func:`table`, spec §17.5.3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import stats

from haptify.codes import Code
from haptify.errors import fail
from haptify.metrics.uncertainty import coverage_factor, welch_satterthwaite


@dataclass
class LabCell:
    """One lab's repetitions of the metric (same device model, same unit)."""

    lab: str
    values: list[float]

    @property
    def n(self) -> int:
        return len(self.values)

    @property
    def mean(self) -> float:
        return float(np.mean(self.values))

    @property
    def sd(self) -> float:
        return float(np.std(self.values, ddof=1))


@dataclass
class Precision:
    """ISO 5725-2 precision of one metric: grand mean, s_r, s_L, s_R, and per lab Mandel's h and k with their
    flags ('' consistent, 'straggler' beyond the 5 % critical value, 'outlier' beyond 1 %)."""

    labs: list[str]
    grand_mean: float
    s_r: float
    s_L: float
    s_R: float
    h: list[float]
    k: list[float]
    h_critical: dict[str, float]
    k_critical: dict[str, float]
    h_flags: list[str] = field(default_factory=list)
    k_flags: list[str] = field(default_factory=list)


def mandel_h_critical(p: int, alpha: float) -> float:
    """Two-sided critical value of Mandel's h for p labs: (p − 1)·t / √(p·(p − 2 + t²)), t = t_{1−α/2}(p − 2)
    (ISO 5725-2 §7.3.1)."""
    t = stats.t.ppf(1 - alpha / 2, p - 2)
    return float((p - 1) * t / math.sqrt(p * (p - 2 + t * t)))


def mandel_k_critical(p: int, n: int, alpha: float) -> float:
    """Critical value of Mandel's k for p labs of n repetitions: √(p / (1 + (p − 1)/F)), F the upper α quantile
    of F(n − 1, (p − 1)(n − 1)) (ISO 5725-2 §7.3.1)."""
    f = stats.f.ppf(1 - alpha, n - 1, (p - 1) * (n - 1))
    return float(math.sqrt(p / (1 + (p - 1) / f)))


def _flag(value: float, critical: dict[str, float]) -> str:
    if abs(value) > critical["1%"]:
        return "outlier"
    return "straggler" if abs(value) > critical["5%"] else ""


def components(cells: Sequence[LabCell]) -> tuple[float, float, float, float]:
    """(grand mean, s_r, s_L, s_R) of ``cells`` (ISO 5725-2 §7.4, unbalanced cells allowed): s_r² the pooled
    within-lab variance, s_L² = max(0, (s_d² − s_r²)/n̄), s_d² the weighted variance of the lab means. E903
    with fewer than two labs or a lab with fewer than two repetitions."""
    if len(cells) < 2 or any(c.n < 2 for c in cells):
        raise fail(
            Code.USAGE,
            "s_r and s_R need at least two labs with at least two repetitions each",
            expected="≥ 2 labs × ≥ 2 repetitions",
            found=[c.n for c in cells],
        )
    p = len(cells)
    n = np.array([c.n for c in cells], float)
    means = np.array([c.mean for c in cells])
    sds = np.array([c.sd for c in cells])
    s_r2 = float(np.sum((n - 1) * sds**2) / np.sum(n - 1))
    grand = float(np.sum(n * means) / np.sum(n))
    s_d2 = float(np.sum(n * (means - grand) ** 2) / (p - 1))
    n_bar = float((n.sum() - np.sum(n**2) / n.sum()) / (p - 1))
    s_l2 = max(0.0, (s_d2 - s_r2) / n_bar)
    return grand, math.sqrt(s_r2), math.sqrt(s_l2), math.sqrt(s_l2 + s_r2)


def precision(cells: Sequence[LabCell]) -> Precision:
    """s_r, s_L, s_R and Mandel's h, k of ``cells`` (ISO 5725-2 §7.3–7.4). E903 with fewer than three labs or a
    lab with fewer than two repetitions (h needs p ≥ 3; s_r needs repetitions)."""
    if len(cells) < 3 or any(c.n < 2 for c in cells):
        raise fail(
            Code.USAGE,
            "ISO 5725-2 statistics need at least three labs with at least two repetitions each",
            expected="≥ 3 labs × ≥ 2 repetitions",
            found=[c.n for c in cells],
        )
    grand, s_r, s_L, s_R = components(cells)
    p = len(cells)
    n = np.array([c.n for c in cells], float)
    means = np.array([c.mean for c in cells])
    sds = np.array([c.sd for c in cells])
    spread = float(np.std(means, ddof=1))
    h = (means - means.mean()) / spread if spread > 0 else np.zeros(p)
    k = sds / math.sqrt(float(np.mean(sds**2))) if np.any(sds > 0) else np.ones(p)
    n_typ = int(round(float(np.median(n))))
    h_crit = {"5%": mandel_h_critical(p, 0.05), "1%": mandel_h_critical(p, 0.01)}
    k_crit = {"5%": mandel_k_critical(p, n_typ, 0.05), "1%": mandel_k_critical(p, n_typ, 0.01)}
    return Precision(
        labs=[c.lab for c in cells],
        grand_mean=grand,
        s_r=s_r,
        s_L=s_L,
        s_R=s_R,
        h=[float(x) for x in h],
        k=[float(x) for x in k],
        h_critical=h_crit,
        k_critical=k_crit,
        h_flags=[_flag(x, h_crit) for x in h],
        k_flags=[_flag(x, k_crit) for x in k],
    )


def table(per_lab: dict[str, list[float]]) -> dict | None:
    """The registry's inter-lab record of one scalar metric of one device model (spec §17.5.3), from each
    lab's repetitions: None with fewer than two labs of ≥ 2 repetitions (labs with one repetition are left
    out and named in ``labs_left_out``); s_r, s_L, s_R from two labs; Mandel's h and k with their critical
    values and flags per lab from three."""
    cells = [LabCell(lab, list(v)) for lab, v in per_lab.items() if len(v) >= 2]
    if len(cells) < 2:
        return None
    left_out = sorted(lab for lab, v in per_lab.items() if len(v) < 2)
    if len(cells) < 3:
        grand, s_r, s_L, s_R = components(cells)
        labs = [
            {"lab": c.lab, "n": c.n, "mean": c.mean, "sd": c.sd, "h": None, "k": None, "h_flag": "", "k_flag": ""} for c in cells
        ]
        return {
            "labs": labs,
            "grand_mean": grand,
            "s_r": s_r,
            "s_L": s_L,
            "s_R": s_R,
            "h_critical": None,
            "k_critical": None,
            "outlying": [],
            "labs_left_out": left_out,
            "note": "Mandel's h and k need at least three labs",
        }
    got = precision(cells)
    labs = [
        {"lab": c.lab, "n": c.n, "mean": c.mean, "sd": c.sd, "h": h, "k": k, "h_flag": hf, "k_flag": kf}
        for c, h, k, hf, kf in zip(cells, got.h, got.k, got.h_flags, got.k_flags)
    ]
    return {
        "labs": labs,
        "grand_mean": got.grand_mean,
        "s_r": got.s_r,
        "s_L": got.s_L,
        "s_R": got.s_R,
        "h_critical": got.h_critical,
        "k_critical": got.k_critical,
        "outlying": [x["lab"] for x in labs if x["h_flag"] or x["k_flag"]],
        "labs_left_out": left_out,
        "note": "",
    }


def pooled_uncertainty(records: Sequence[tuple[int, dict | None]]) -> dict | None:
    """The uncertainty of a device's registry mean (spec §17.5.3) from its submissions' ``(repetitions,
    uncertainty record)``: the mean weights submission i by wᵢ = nᵢ/N, so u = √Σ(wᵢuᵢ)² with ν by
    Welch–Satterthwaite (GUM G.4) and U = t_{(1+p)/2}(ν)·u. None when any submission lacks a record (such a
    mean is never tied, spec §19.6). The submissions are taken as independent."""
    known = [(n, r) for n, r in records if r is not None and not isinstance(r.get("u"), list)]
    if not records or len(known) < len(records):
        return None
    total = sum(n for n, _ in known)
    contributions = [n / total * float(r["u"]) for n, r in known]
    dofs = [math.inf if r.get("dof_eff") is None else float(r["dof_eff"]) for _, r in known]
    nu = float(welch_satterthwaite(contributions, dofs))
    p = min(float(r["coverage_probability"]) for _, r in known)
    u = math.sqrt(sum(c * c for c in contributions))
    k = coverage_factor(nu, p)
    return {
        "u": u,
        "U": k * u,
        "k": k,
        "coverage_probability": p,
        "dof_eff": None if math.isinf(nu) else nu,
        "submissions": len(records),
    }
