"""Comparing two measured values with their uncertainties (spec §19.6): the difference, its Welch test, and
the ties of a ranking."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

from haptify.metrics import uncertainty
from haptify.metrics.uncertainty import coverage_factor, scalar, welch_satterthwaite
from haptify.pipeline.results import MetricResult, MetricUncertainty


@dataclass
class Difference:
    """The difference of two measured values and its test (spec §19.6): d = x₁ − x₂, u_d = √(u₁² + u₂²), ν by
    Welch–Satterthwaite, k = t_{(1+p)/2}(ν); significant when |d| > k·u_d."""

    d: float
    u: float
    dof: float | None
    k: float

    @property
    def expanded(self) -> float:
        return self.k * self.u

    @property
    def significant(self) -> bool:
        return abs(self.d) > self.expanded


def difference(a: MetricUncertainty, x_a: float, b: MetricUncertainty, x_b: float, p: float | None = None) -> Difference:
    """The test of spec §19.6 for two scalar values with their uncertainty records (p defaults to the
    definition file's coverage probability); each record's ν_eff is its u's degrees of freedom (absent: ∞)."""
    return welch_difference(x_a, scalar(a.u, None), a.dof_eff, x_b, scalar(b.u, None), b.dof_eff, p)


def welch_difference(
    x_a: float, u_a: float, dof_a: float | None, x_b: float, u_b: float, dof_b: float | None, p: float | None = None
) -> Difference:
    """The test of spec §19.6 on two values with their standard uncertainties and degrees of freedom (None: ∞)."""
    p = uncertainty.PARAMETERS.coverage_probability if p is None else p
    dofs = [math.inf if d is None else d for d in (dof_a, dof_b)]
    nu = float(welch_satterthwaite([u_a, u_b], dofs))
    return Difference(d=x_a - x_b, u=math.hypot(u_a, u_b), dof=None if math.isinf(nu) else nu, k=coverage_factor(nu, p))


def compared(ra: MetricResult | None, rb: MetricResult | None) -> Difference | None:
    """:func:`difference` of two scalar metric records when both carry an uncertainty, else None (spec §19.6)."""
    if (
        ra is None
        or rb is None
        or ra.uncertainty is None
        or rb.uncertainty is None
        or isinstance(ra.value, list)
        or isinstance(rb.value, list)
    ):
        return None
    return difference(ra.uncertainty, float(ra.value), rb.uncertainty, float(rb.value))


def tie_groups(records: Sequence[MetricResult]) -> list[list[int]]:
    """Indices of ``records`` grouped into ties for a ranking by ascending value (spec §19.6, :func:`ties`); a
    record without an uncertainty can never be shown indistinguishable and is a group of its own."""
    order = sorted(range(len(records)), key=lambda i: scalar(records[i].value, None))

    def same(i: int, j: int) -> bool:
        diff = compared(records[i], records[j])
        return diff is not None and not diff.significant

    return ties(order, same)


def ties(order: Sequence[int], same: Callable[[int, int], bool]) -> list[list[int]]:
    """Ranking ``order`` (indices, best first) cut into ties (spec §19.6): an index joins the current group
    while ``same(first of the group, index)`` (not significantly different), else it starts a new group."""
    groups: list[list[int]] = []
    for i in order:
        if groups and same(groups[-1][0], i):
            groups[-1].append(i)
        else:
            groups.append([i])
    return groups
