"""Read side for the web pages: a cache over the core's queries and the leaderboard endpoints (spec §17.5).

The core API (``app.py``) already serves devices, per-device aggregates, the comparison and the CSV
export. This router adds the leaderboard of one metric (devices ranked by their mean, see
:mod:`haptify_tools.registry.leaderboard`) and the list of metrics that have a leaderboard.

:class:`ReadCache` keeps the answers of the core's read queries (``Registry.devices``,
``device_results``, ``submissions``, ``comparison``) for the pages. Records are append-only (no row of
``submissions``, ``withdrawals`` or ``challenge_results`` is ever updated or deleted, spec §17.5), so
the counts of those tables change with every change a reader can see: one count query per request
tells whether the cached answers still hold.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from functools import lru_cache
from typing import Any

from fastapi import APIRouter, Query, Request
from sqlalchemy import func, select

from haptify.metrics.metric_definitions import MetricDefinition, family
from haptify.schemas import list_dir
from haptify_tools.registry import db
from haptify_tools.registry.leaderboard import leaderboard, rule_text
from haptify_tools.registry.service import Registry

API = "/api/v1"
MAX_CACHED = 512  # answers kept per version (comparisons of many device sets)
MAX_LISTED = 1_000_000  # submissions listed at once


class ReadCache:
    """Answers of the registry's read queries, valid while no submission or withdrawal was added."""

    def __init__(self, reg: Registry) -> None:
        self.reg = reg
        self._version: tuple[int, int, int] | None = None
        self._store: dict[Any, Any] = {}
        self._lock = threading.Lock()

    def version(self) -> tuple[int, int, int]:
        """(submissions, withdrawals, answered challenges) now: the tables only grow, so any change a reader
        can see (a new record, a withdrawal, an implementation proven by a challenge) changes this triple."""
        with self.reg.engine.connect() as conn:
            return tuple(
                conn.execute(
                    select(
                        select(func.count()).select_from(db.Submission).scalar_subquery(),
                        select(func.count()).select_from(db.Withdrawal).scalar_subquery(),
                        select(func.count()).select_from(db.ChallengeResult).scalar_subquery(),
                    )
                ).one()
            )

    def get(self, key: Any, compute: Callable[[], Any]) -> Any:
        """The cached answer for ``key``, or ``compute()`` (run outside the lock; errors are not cached)."""
        version = self.version()
        with self._lock:
            if version != self._version:
                self._store, self._version = {}, version
            if key in self._store:
                return self._store[key]
        value = compute()
        with self._lock:
            if self._version == version and len(self._store) < MAX_CACHED:
                self._store[key] = value
        return value

    def devices(self) -> list[dict]:
        return self.get("devices", self.reg.devices)

    def device_results(self, slug: str, verification: str = "verified") -> dict:
        return self.get(("device", slug, verification), lambda: self.reg.device_results(slug, verification=verification))

    def all_device_results(self, verification: str = "verified") -> list[dict]:
        """:meth:`Registry.device_results` of every device (those without current results have no metrics)."""
        return self.get(
            ("all-devices", verification), lambda: [self.device_results(d["slug"], verification) for d in self.devices()]
        )

    def submissions(self) -> list[dict]:
        """Every submission summary (all states), newest first."""
        return self.get("submissions", lambda: self.reg.submissions(state="all", limit=MAX_LISTED))

    def comparison(self, slugs: tuple[str, ...], verification: str = "verified") -> list:
        return self.get(("compare", slugs, verification), lambda: self.reg.comparison(list(slugs), verification=verification))


@lru_cache(maxsize=1)
def metric_definitions() -> dict[str, MetricDefinition]:
    """Every metric definition of the spec by id, in definition-file order (titles, units, descriptions)."""
    out = {}
    for name in list_dir("metrics"):
        for m in family(name.removesuffix(".json")).metrics:
            out[m.id] = m
    return out


def reads(request: Request) -> ReadCache:
    """The app's read cache over ``app.state.registry`` (made on first use)."""
    state = request.app.state
    cache = getattr(state, "read_cache", None)
    if cache is None or cache.reg is not state.registry:
        cache = state.read_cache = ReadCache(state.registry)
    return cache


def leaderboard_menu(results: list[dict]) -> list[dict]:
    """Every scalar metric some device has (counted or listed apart), in definition order: id, title and
    number of devices."""
    defs = metric_definitions()
    counts: dict[str, int] = {}
    for d in results:
        have = {m["metric"] for m in d["metrics"] if not isinstance(m["mean"], list)}
        have |= {e["metric"] for e in d.get("not_counted", []) if not isinstance(e["submitted"], list)}
        for metric in have:
            counts[metric] = counts.get(metric, 0) + 1
    order = {mid: i for i, mid in enumerate(defs)}
    ids = sorted(counts, key=lambda m: (order.get(m, len(order)), m))
    return [{"id": m, "title": defs[m].title if m in defs else m, "devices": counts[m]} for m in ids]


router = APIRouter(prefix=API, tags=["devices"])


def not_counted_notes(apart: dict[str, list[dict]]) -> list[str]:
    """One note per device whose current results were left out of a verified-only comparison."""
    out = []
    for slug, entries in apart.items():
        subs = {e["submission"]: e["verification"] for e in entries}
        if subs:
            states = ", ".join(
                f"{n} {state}" for state in ("disagreeing", "unverified") if (n := sum(v == state for v in subs.values()))
            )
            out.append(
                f"{slug}: {len(subs)} current submission(s) not verified and not counted ({states}); "
                f"verification=all includes them"
            )
    return out


def not_ranked(metric_id: str, results: list[dict]) -> list[dict]:
    """The current results of ``metric_id`` left out of a ranking (not verified), with their device and
    state; a disagreeing one carries both the submitted and the recomputed value (spec §17.3.1)."""
    return [
        {**e, "device": d["device"]["slug"], "label": f"{d['device']['manufacturer']} {d['device']['model']}"}
        for d in results
        for e in d.get("not_counted", [])
        if e["metric"] == metric_id
    ]


@router.get("/leaderboards", name="api_leaderboards", summary="Metrics that have a leaderboard")
def api_leaderboards(request: Request) -> list[dict]:
    """Every scalar metric with current results: id, title and how many devices have it."""
    return leaderboard_menu(reads(request).all_device_results())


@router.get("/leaderboard/{metric_id}", name="api_leaderboard", summary="Devices ranked by one metric")
def api_leaderboard(metric_id: str, request: Request, verification: str = Query("verified", pattern="^(verified|all)$")) -> dict:
    """Devices with current results for ``metric_id``, best first, with each device's mean and spread:
    from verified submissions only (``verification=all``: from all); the results left out are listed in
    ``not_ranked`` with their state."""
    results = reads(request).all_device_results(verification)
    rows = leaderboard(metric_id, results)
    return {
        "metric": metric_id,
        "rule": rule_text(metric_id),
        "verification": verification,
        "rows": [r.as_dict() for r in rows],
        "not_ranked": not_ranked(metric_id, results),
    }
