"""Leaderboards of the registry: devices ranked by one metric (spec §17.5).

The per-device statistics are the registry's (:meth:`haptify_tools.registry.queries.RegistryQueries.device_results`:
mean and sd over every repetition of every current submission, lab means, between-lab sd, the pooled
uncertainty of the mean). This module groups the ranking into ties (spec §19.6) and otherwise only orders devices by one scalar metric's mean, using the direction stated in ``rankings.json`` next to
it: 'lower' or 'higher' is better, or closest to a target. Which way is better is registry presentation,
not part of the standard, so it lives here and not in the metric definitions; each entry cites the paper.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

from haptify.metrics.significance import ties, welch_difference


@lru_cache(maxsize=1)
def rankings() -> dict[str, dict]:
    """The leaderboard directions by metric id (``rankings.json``)."""
    text = resources.files("haptify_tools.registry").joinpath("rankings.json").read_text(encoding="utf-8")
    return json.loads(text)["metrics"]


@dataclass
class Row:
    """One leaderboard line: rank (None when the metric is unranked), the device and its metric aggregate."""

    rank: int | None
    device: dict  # {"slug", "manufacturer", "model"}
    metric: dict  # one entry of device_results()["metrics"]
    tie_group: int | None = None  # rows of one group are not significantly different (spec §17.5.3, §19.6)

    @property
    def label(self) -> str:
        return f"{self.device['manufacturer']} {self.device['model']}"

    def as_dict(self) -> dict:
        return {"rank": self.rank, "tie_group": self.tie_group, "device": self.device["slug"], "label": self.label, **self.metric}


def rule_text(metric_id: str) -> str:
    """How a metric's leaderboard is ordered, as a sentence for people."""
    rule = rankings().get(metric_id)
    if rule is None:
        return "Not ranked (no better direction is defined for this metric); ascending order."
    better = rule["better"]
    how = (
        "Lower is better"
        if better == "lower"
        else "Higher is better"
        if better == "higher"
        else f"Closest to {float(better['target']):g} is better"
    )
    return f"{how}: {rule['why']}."


def _badness(metric_id: str):
    """The sort key of a mean (smaller is better), or None when the metric has no direction."""
    rule = rankings().get(metric_id)
    if rule is None:
        return None
    better = rule["better"]
    if better == "lower":
        return lambda mean: mean
    if better == "higher":
        return lambda mean: -mean
    target = float(better["target"])
    return lambda mean: abs(mean - target)


def leaderboard(metric_id: str, device_results: list[dict]) -> list[Row]:
    """The devices whose current results have scalar ``metric_id``, best first (spec §17.5).

    ``device_results`` are :meth:`Registry.device_results` answers. Devices with equal means share a
    rank (1, 2, 2, 4); ties are listed by label. An unranked metric is listed by ascending mean. A ranked
    metric's rows are cut into numbered ``tie_group``s, best first (:func:`haptify.metrics.significance.ties`).
    """
    have = []
    for d in device_results:
        m = next((m for m in d["metrics"] if m["metric"] == metric_id), None)
        if m is not None and not isinstance(m["mean"], list):
            have.append((d["device"], m))
    key = _badness(metric_id)
    order = key or (lambda mean: mean)
    have.sort(key=lambda x: (order(x[1]["mean"]), f"{x[0]['manufacturer']} {x[0]['model']}".lower()))
    rows, rank, previous = [], 0, None
    for i, (device, m) in enumerate(have, start=1):
        if key is None:
            rows.append(Row(None, device, m))
            continue
        if order(m["mean"]) != previous:
            rank, previous = i, order(m["mean"])
        rows.append(Row(rank, device, m))
    if key is not None:
        for number, group in enumerate(ties(range(len(rows)), lambda i, j: indistinguishable(key, rows[i], rows[j])), 1):
            for i in group:
                rows[i].tie_group = number
    return rows


def indistinguishable(badness, a: Row, b: Row) -> bool:
    """Whether two rows are not significantly different (spec §19.6) in how good they are: the test on
    their badness (the mean, its negative, or its distance to the target: sensitivity ±1, so the same u),
    with the pooled uncertainty of each device's mean (:func:`interlab.pooled_uncertainty`). A row without
    an uncertainty is distinguishable from every other."""
    ua, ub = a.metric.get("uncertainty"), b.metric.get("uncertainty")
    if ua is None or ub is None:
        return False
    diff = welch_difference(
        badness(a.metric["mean"]),
        ua["u"],
        ua["dof_eff"],
        badness(b.metric["mean"]),
        ub["u"],
        ub["dof_eff"],
        min(ua["coverage_probability"], ub["coverage_probability"]),
    )
    return not diff.significant
