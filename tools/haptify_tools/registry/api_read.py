"""Read-side JSON API of the registry: devices, per-device aggregates, leaderboards, comparison, CSV (issue 9).

Only *current* submissions count: accepted, not superseded by a later submission, not withdrawn (the
records themselves stay, spec §17.5). Submissions are immutable, so each one's parsed results are cached
by id for the life of the process; the aggregates are cached under the set of current submissions
(one small query per request decides whether they are still valid).
"""

from __future__ import annotations

import threading
from functools import lru_cache
from dataclasses import dataclass

from fastapi import APIRouter, Query, Request
from fastapi.responses import JSONResponse, PlainTextResponse
from sqlalchemy import exists, select
from sqlalchemy.engine import Engine
from sqlalchemy.orm import aliased

from haptify.compare import to_csv
from haptify.errors import fail
from haptify.metric_definitions import MetricDefinition, family
from haptify.results import ResultsFile
from haptify.schemas import list_dir
from haptify_tools.registry import db
from haptify_tools.registry.aggregate import DeviceAggregate, Entry, aggregate_devices, comparison, leaderboard

MAX_COMPARED = 50  # devices in one comparison request


@dataclass
class Snapshot:
    """The current submissions and their device aggregates at one moment."""

    key: tuple
    entries: list[Entry]
    devices: dict[str, DeviceAggregate]


class ReadModel:
    """Current submissions of one database, read through caches (thread-safe)."""

    def __init__(self, engine: Engine):
        self.engine = engine
        self._results: dict[str, ResultsFile] = {}
        self._snapshot: Snapshot | None = None
        self._lock = threading.Lock()

    def _rows(self) -> list:
        s, w = db.Submission, db.Withdrawal
        newer = aliased(db.Submission)
        query = (select(s.id, s.lab_id, db.Device.slug, s.verification, s.received_at, s.has_raw)
                 .join(db.Device, db.Device.id == s.device_id)
                 .where(~exists().where(w.submission_id == s.id))
                 .where(~exists().where(newer.supersedes_id == s.id))
                 .order_by(s.received_at, s.id))
        with self.engine.connect() as conn:
            return list(conn.execute(query))

    def _load_results(self, ids: list[str]) -> None:
        missing = [i for i in ids if i not in self._results]
        if not missing:
            return
        with self.engine.connect() as conn:
            for start in range(0, len(missing), 500):
                chunk = missing[start:start + 500]
                for sid, text in conn.execute(select(db.Submission.id, db.Submission.results_json)
                                              .where(db.Submission.id.in_(chunk))):
                    self._results[sid] = ResultsFile.model_validate_json(text)

    def snapshot(self) -> Snapshot:
        """The current submissions and device aggregates (recomputed only when the current set changed)."""
        rows = self._rows()
        key = tuple((r.id, r.verification) for r in rows)
        snap = self._snapshot
        if snap is not None and snap.key == key:
            return snap
        with self._lock:
            self._load_results([r.id for r in rows])
            entries = [Entry(submission_id=r.id, lab=r.lab_id, results=self._results[r.id], verified=r.verification == "verified",
                             status=r.verification, created=_iso(r.received_at), has_raw=bool(r.has_raw), device_slug=r.slug)
                       for r in rows]
            snap = Snapshot(key=key, entries=entries, devices=aggregate_devices(entries))
            self._snapshot = snap
            return snap


def _iso(t) -> str:
    return t.isoformat(timespec="seconds") if t is not None else ""


def read_model(request: Request) -> ReadModel:
    """The app's read model, made on first use from the app's engine."""
    state = request.app.state
    model = getattr(state, "read_model", None)
    if model is None:
        model = state.read_model = ReadModel(state.engine)
    return model


@lru_cache(maxsize=1)
def metric_definitions() -> dict[str, MetricDefinition]:
    """Every metric definition of the spec, by id (titles and descriptions for the pages)."""
    out = {}
    for name in list_dir("metrics"):
        for m in family(name.removesuffix(".json")).metrics:
            out[m.id] = m
    return out


def device_or_404(snap: Snapshot, slug: str) -> DeviceAggregate:
    """The device with this slug, or E973 (not found) naming it."""
    if slug not in snap.devices:
        raise fail("E973", f"no device '{slug}' has current results in this registry", pointer="/device",
                   expected="a device slug from /api/devices", found=slug)
    return snap.devices[slug]


def chosen_devices(snap: Snapshot, slugs: list[str]) -> list[DeviceAggregate]:
    """The devices named in a comparison request, in the order given (E975 when none or too many, E973 unknown)."""
    if not slugs:
        raise fail("E975", "name at least one device to compare", pointer="/device", expected="?device=SLUG (repeatable)", found="none")
    if len(slugs) > MAX_COMPARED:
        raise fail("E975", f"at most {MAX_COMPARED} devices can be compared at once", pointer="/device",
                   expected=f"≤ {MAX_COMPARED}", found=str(len(slugs)))
    return [device_or_404(snap, s) for s in dict.fromkeys(slugs)]


router = APIRouter(prefix="/api", tags=["read"])


@router.get("/devices", name="api_devices", summary="Devices with current results")
def api_devices(request: Request) -> JSONResponse:
    snap = read_model(request).snapshot()
    return JSONResponse([{"slug": d.slug, "label": d.label, "manufacturer": d.manufacturer, "model": d.model,
                          "labs": d.labs, "n_submissions": len(d.entries),
                          "n_verified": sum(e.verified for e in d.entries)} for d in snap.devices.values()])


@router.get("/devices/{slug}", name="api_device",
            summary="A device's aggregated results: mean and spread over labs and repetitions")
def api_device(slug: str, request: Request) -> JSONResponse:
    snap = read_model(request).snapshot()
    return JSONResponse(device_or_404(snap, slug).as_dict())


@router.get("/leaderboard/{metric_id}", name="api_leaderboard", summary="Devices ranked by one metric")
def api_leaderboard(metric_id: str, request: Request) -> JSONResponse:
    snap = read_model(request).snapshot()
    rows, rule = leaderboard(metric_id, snap.devices)
    return JSONResponse({"metric": metric_id, "rule": rule,
                         "rows": [{"rank": r.rank, "device": r.device.slug, "label": r.device.label, **r.metric.as_dict()}
                                  for r in rows]})


@router.get("/compare", name="api_compare", summary="The paper's Table III for any devices")
def api_compare(request: Request, device: list[str] = Query(default=[]), paper: bool = False) -> JSONResponse:
    snap = read_model(request).snapshot()
    table = comparison(chosen_devices(snap, device), with_paper=paper)
    return JSONResponse({"header": table.header, "rows": table.rows, "notes": table.notes})


@router.get("/compare.csv", name="api_compare_csv", summary="The comparison table as CSV")
def api_compare_csv(request: Request, device: list[str] = Query(default=[]), paper: bool = False) -> PlainTextResponse:
    snap = read_model(request).snapshot()
    table = comparison(chosen_devices(snap, device), with_paper=paper)
    return PlainTextResponse(to_csv(table), media_type="text/csv; charset=utf-8",
                             headers={"Content-Disposition": 'attachment; filename="haptify-compare.csv"'})


@router.get("/export.csv", name="api_export_csv", summary="Every device's aggregated metrics as CSV (one row per device and metric)")
def api_export_csv(request: Request) -> PlainTextResponse:
    import csv
    import io

    snap = read_model(request).snapshot()
    buf = io.StringIO()
    out = csv.writer(buf, lineterminator="\n")
    out.writerow(["device", "label", "metric", "unit", "mean", "sd", "sd_labs", "sd_repetitions", "min", "max",
                  "n_labs", "n_submissions", "n_repetitions"])
    for d in snap.devices.values():
        for m in sorted(d.metrics.values(), key=lambda m: m.id):
            out.writerow([d.slug, d.label, m.id, m.unit, repr(m.mean), _opt(m.sd), _opt(m.sd_labs), _opt(m.sd_repetitions),
                          repr(m.min), repr(m.max), m.n_labs, m.n_submissions, m.n_repetitions])
    return PlainTextResponse(buf.getvalue(), media_type="text/csv; charset=utf-8",
                             headers={"Content-Disposition": 'attachment; filename="haptify-registry.csv"'})


def _opt(x: float | None) -> str:
    return "" if x is None else repr(x)
