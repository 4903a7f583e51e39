"""Read-side JSON endpoints the web pages need beyond the core API (issue 9, spec §17.5).

The core API (``app.py``) already serves devices, per-device aggregates, the comparison and the CSV
export. This router adds the leaderboard of one metric (devices ranked by their mean, see
:mod:`haptify_tools.registry.leaderboard`) and the list of metrics that have a leaderboard.
"""

from __future__ import annotations

from functools import lru_cache

from fastapi import APIRouter, Request

from haptify.metric_definitions import MetricDefinition, family
from haptify.schemas import list_dir
from haptify_tools.registry.leaderboard import leaderboard, rule_text
from haptify_tools.registry.service import Registry

API = "/api/v1"


@lru_cache(maxsize=1)
def metric_definitions() -> dict[str, MetricDefinition]:
    """Every metric definition of the spec by id, in definition-file order (titles, units, descriptions)."""
    out = {}
    for name in list_dir("metrics"):
        for m in family(name.removesuffix(".json")).metrics:
            out[m.id] = m
    return out


def registry(request: Request) -> Registry:
    return request.app.state.registry


def all_device_results(reg: Registry) -> list[dict]:
    """:meth:`Registry.device_results` of every device (those without current results have no metrics)."""
    return [reg.device_results(d["slug"]) for d in reg.devices()]


def leaderboard_menu(results: list[dict]) -> list[dict]:
    """Every scalar metric some device has, in definition order: id, title, unit and number of devices."""
    defs = metric_definitions()
    counts: dict[str, int] = {}
    for d in results:
        for m in d["metrics"]:
            if not isinstance(m["mean"], list):
                counts[m["metric"]] = counts.get(m["metric"], 0) + 1
    order = {mid: i for i, mid in enumerate(defs)}
    ids = sorted(counts, key=lambda m: (order.get(m, len(order)), m))
    return [{"id": m, "title": defs[m].title if m in defs else m, "devices": counts[m]} for m in ids]


router = APIRouter(prefix=API, tags=["devices"])


@router.get("/leaderboards", name="api_leaderboards", summary="Metrics that have a leaderboard")
def api_leaderboards(request: Request) -> list[dict]:
    """Every scalar metric with current results: id, title and how many devices have it."""
    return leaderboard_menu(all_device_results(registry(request)))


@router.get("/leaderboard/{metric_id}", name="api_leaderboard", summary="Devices ranked by one metric")
def api_leaderboard(metric_id: str, request: Request) -> dict:
    """Devices with current results for ``metric_id``, best first, with each device's mean and spread."""
    rows = leaderboard(metric_id, all_device_results(registry(request)))
    return {"metric": metric_id, "rule": rule_text(metric_id), "rows": [r.as_dict() for r in rows]}
