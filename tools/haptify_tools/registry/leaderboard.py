"""Read side of the registry: per-device aggregates, leaderboards and the N-device Table III (issue 9).

Pure functions over :class:`Entry` records (one current submission: a lab's results for one session),
so the statistics are testable without a database. Definitions (stated on the pages too):

* A **device** is a (manufacturer, model) pair; serial numbers and labs are repetitions of it. Its
  URL slug is the lower-cased label with every run of other characters than ``a-z0-9`` turned into ``-``.
* For a scalar metric of a device, every submission contributes its repetition values
  (``per_repetition``; the reported ``value`` when a metric has no repetitions, e.g. a modeled volume).
  A **lab's mean** is the mean over that lab's submissions' values; the device **mean** is the mean of
  the lab means (each lab weighs the same however often it submitted).
* Spreads (all ddof = 1, ``None`` when fewer than two values): ``sd`` over every repetition of every lab
  (the ``±`` of the comparison table); ``sd_labs`` between lab means; ``sd_repetitions`` pooled within
  submissions, sqrt(Σ(n_i − 1)·s_i² / Σ(n_i − 1)). ``min``/``max`` over every repetition.
* Per-axis (vector) metrics are not aggregated; device pages list them per submission.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from statistics import fmean, stdev

from haptify.compare import Table, build_table
from haptify.results import DeviceSummary, Implementation, MetricResult, ResultsFile

REGISTRY_IMPLEMENTATION = Implementation(name="haptify-registry", version="aggregate")


@dataclass(frozen=True)
class Figure:
    """A figure of ``haptify report`` shipped in a submission: its file name, caption and URL."""

    name: str
    caption: str
    url: str


@dataclass
class Entry:
    """One current (accepted, not superseded, not withdrawn) submission as the read side sees it."""

    submission_id: str
    lab: str
    results: ResultsFile
    verified: bool = False
    status: str = "accepted"
    created: str = ""
    has_raw: bool = False
    figures: list[Figure] = field(default_factory=list)
    bundle_url: str | None = None
    device_slug: str | None = None  # the registry's slug; derived from the label when None

    @property
    def device(self) -> DeviceSummary:
        return self.results.device or DeviceSummary(manufacturer="unknown", model=self.results.session_id)


def device_label(device: DeviceSummary) -> str:
    """The device's name without serial: 'Manufacturer Model'."""
    return f"{device.manufacturer} {device.model}"


def slugify(text: str) -> str:
    """URL slug: lower case, runs of characters outside a-z0-9 become '-', no leading/trailing '-'."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "device"


def device_slug(device: DeviceSummary) -> str:
    return slugify(device_label(device))


@dataclass
class MetricAggregate:
    """One scalar metric of one device, over labs and repetitions (units: the metric's SI unit)."""

    id: str
    unit: str
    definition_version: str
    mean: float
    sd: float | None
    sd_labs: float | None
    sd_repetitions: float | None
    min: float
    max: float
    n_labs: int
    n_submissions: int
    n_repetitions: int
    lab_means: dict[str, float]

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("id", "unit", "definition_version", "mean", "sd", "sd_labs",
                                              "sd_repetitions", "min", "max", "n_labs", "n_submissions",
                                              "n_repetitions", "lab_means")}


@dataclass
class DeviceAggregate:
    """A device: its slug, label, the current submissions and the aggregates of its scalar metrics."""

    slug: str
    label: str
    manufacturer: str
    model: str
    entries: list[Entry]
    metrics: dict[str, MetricAggregate]

    @property
    def labs(self) -> list[str]:
        return sorted({e.lab for e in self.entries})

    def as_dict(self) -> dict:
        return {"slug": self.slug, "label": self.label, "manufacturer": self.manufacturer, "model": self.model,
                "labs": self.labs, "n_submissions": len(self.entries),
                "submissions": [{"id": e.submission_id, "lab": e.lab, "verified": e.verified, "status": e.status,
                                 "created": e.created, "session_id": e.results.session_id,
                                 "implementation": f"{e.results.implementation.name} {e.results.implementation.version}",
                                 "has_raw": e.has_raw, "figures": [f.name for f in e.figures]}
                                for e in self.entries],
                "metrics": {k: m.as_dict() for k, m in sorted(self.metrics.items())}}

    def as_results(self) -> ResultsFile:
        """The aggregate as a results file (value = mean, sd = sd over all repetitions) for ``build_table``."""
        metrics = [MetricResult(id=m.id, value=m.mean, unit=m.unit, n=m.n_repetitions, sd=m.sd,
                                definition_version=m.definition_version) for m in self.metrics.values()]
        return ResultsFile(implementation=REGISTRY_IMPLEMENTATION, session_id=self.slug,
                           device=DeviceSummary(manufacturer=self.manufacturer, model=self.model),
                           manifest_sha256="0" * 64, metrics=metrics)


def _sd(values: list[float]) -> float | None:
    return stdev(values) if len(values) >= 2 else None


def _repetitions(m: MetricResult) -> list[float] | None:
    """Scalar repetition values of a metric, or None for a per-axis (vector) metric."""
    if isinstance(m.value, list):
        return None
    reps = m.per_repetition or [m.value]
    if any(isinstance(r, list) for r in reps):
        return None
    return [float(r) for r in reps]


def aggregate_metric(metric_id: str, samples: list[tuple[str, MetricResult]]) -> MetricAggregate | None:
    """Aggregate one scalar metric over ``(lab, result)`` samples (see the module docstring); None for vectors."""
    per_lab: dict[str, list[float]] = {}
    everything: list[float] = []
    pooled_num = pooled_den = 0.0
    for lab, m in samples:
        reps = _repetitions(m)
        if reps is None:
            return None
        per_lab.setdefault(lab, []).append(fmean(reps))
        everything += reps
        if len(reps) >= 2:
            pooled_num += (len(reps) - 1) * stdev(reps) ** 2
            pooled_den += len(reps) - 1
    lab_means = {lab: fmean(v) for lab, v in sorted(per_lab.items())}
    first = samples[0][1]
    return MetricAggregate(
        id=metric_id, unit=first.unit, definition_version=first.definition_version,
        mean=fmean(lab_means.values()), sd=_sd(everything), sd_labs=_sd(list(lab_means.values())),
        sd_repetitions=math.sqrt(pooled_num / pooled_den) if pooled_den else None,
        min=min(everything), max=max(everything), n_labs=len(lab_means), n_submissions=len(samples),
        n_repetitions=len(everything), lab_means=lab_means)


def aggregate_devices(entries: list[Entry]) -> dict[str, DeviceAggregate]:
    """Group current submissions by device and aggregate every scalar metric; keyed by slug, sorted by label."""
    groups: dict[str, list[Entry]] = {}
    for e in entries:
        groups.setdefault(e.device_slug or device_slug(e.device), []).append(e)
    devices = {}
    for slug, group in groups.items():
        samples: dict[str, list[tuple[str, MetricResult]]] = {}
        for e in group:
            for m in e.results.metrics:
                samples.setdefault(m.id, []).append((e.lab, m))
        metrics = {}
        for metric_id, s in samples.items():
            agg = aggregate_metric(metric_id, s)
            if agg is not None:
                metrics[metric_id] = agg
        dev = group[0].device
        devices[slug] = DeviceAggregate(slug=slug, label=device_label(dev), manufacturer=dev.manufacturer,
                                        model=dev.model, entries=group, metrics=metrics)
    return dict(sorted(devices.items(), key=lambda kv: kv[1].label.lower()))


@lru_cache(maxsize=1)
def rankings() -> dict[str, dict]:
    """The leaderboard directions (``rankings.json`` next to this module)."""
    text = resources.files("haptify_tools.registry").joinpath("rankings.json").read_text(encoding="utf-8")
    return json.loads(text)["metrics"]


@dataclass
class LeaderboardRow:
    rank: int | None
    device: DeviceAggregate
    metric: MetricAggregate


def leaderboard(metric_id: str, devices: dict[str, DeviceAggregate]) -> tuple[list[LeaderboardRow], str]:
    """Devices that have ``metric_id``, best first, with a sentence saying how they are ranked.

    Ranks follow ``rankings.json`` ('lower', 'higher' or closest to a target); equal means share a
    rank. A metric without a direction is listed in ascending order without ranks.
    """
    have = [(d, d.metrics[metric_id]) for d in devices.values() if metric_id in d.metrics]
    rule = rankings().get(metric_id)
    if rule is None:
        have.sort(key=lambda x: (x[1].mean, x[0].label.lower()))
        return [LeaderboardRow(None, d, m) for d, m in have], "Not ranked (no better direction is defined); ascending order."
    better = rule["better"]
    if better == "lower":
        key, how = (lambda m: m.mean), "Lower is better"
    elif better == "higher":
        key, how = (lambda m: -m.mean), "Higher is better"
    else:
        target = float(better["target"])
        key, how = (lambda m: abs(m.mean - target)), f"Closest to {target:g} is better"
    have.sort(key=lambda x: (key(x[1]), x[0].label.lower()))
    rows, rank, previous = [], 0, None
    for i, (d, m) in enumerate(have, start=1):
        if key(m) != previous:
            rank, previous = i, key(m)
        rows.append(LeaderboardRow(rank, d, m))
    return rows, f"{how}: {rule['why']}."


def comparison(devices: list[DeviceAggregate], with_paper: bool = False) -> Table:
    """The paper's Table III for the chosen devices: mean ± sd over all repetitions (spec §15.5, issue 9)."""
    return build_table([d.as_results() for d in devices], with_paper=with_paper)
