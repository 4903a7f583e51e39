"""Web pages of the registry, served by the same app as the JSON API (spec §17.5).

* ``/`` — the devices (check boxes to compare them) and the leaderboards;
* ``/leaderboard/{metric}`` — one metric's leaderboard (ranking rule from ``rankings.json``);
* ``/devices/{slug}`` — a device's metrics with their spread over labs and repetitions, its submissions,
  the figures of ``haptify report`` when a submission shipped them, and how to open its recording in
  the viewer;
* ``/compare?device=a&device=b…`` — the paper's Table III for the chosen devices
  (``haptify.pipeline.compare.build_table`` / ``to_html`` over :meth:`Registry.comparison`);
* ``/submissions/{id}/report/index.html`` — for a submission with raw streams, the output of
  ``haptify report`` (figures, sounds) drawn by the reference from its session and results on first
  request, and ``/submissions/{id}/recording.rrd`` — its recording for the viewer (rerun), built with
  ``haptify_tools.viewer.save.build``. Both are derived data, kept next to the unpacked session
  (:meth:`Registry.session_folder`) and written atomically.

Every number comes from the same queries as the JSON API (``app.state.registry``).
``register(app)`` adds the pages, the read-side endpoints of :mod:`~haptify_tools.registry.api_read`
and the stylesheet; ``create_app`` calls it.
"""

from __future__ import annotations

import logging
import os
import re
import threading
import uuid
from importlib import resources
from pathlib import Path
from urllib.parse import urlencode

from fastapi import APIRouter, FastAPI, Query, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.pipeline.compare import _fmt, build_table, to_html
from haptify.versions import SPEC_VERSION
from haptify_tools.registry import api_read
from haptify_tools.registry.leaderboard import leaderboard, rule_text

log = logging.getLogger("haptify.registry")
_HERE = resources.files("haptify_tools.registry")
templates = Jinja2Templates(directory=str(_HERE / "templates"))
templates.env.globals["spec_version"] = SPEC_VERSION
MAX_COMPARED = 50  # devices in one comparison


def num(value) -> str:
    """A value for people: 5 significant digits like the comparison table; vectors per component; '—' for none."""
    if isinstance(value, list):
        return "[" + ", ".join(num(v) for v in value) + "]"
    return _fmt(value)


templates.env.filters["num"] = num

STATUS_OF_CODE: dict[str, int] = {Code.NOT_FOUND: 404, Code.REQUEST_INVALID: 400}
REPORT_FILE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,200}$")  # a file of a report folder (no '/', no '..')
_derive_lock = threading.Lock()  # one report or recording built at a time (matplotlib's pyplot is not thread-safe)

router = APIRouter(include_in_schema=False)


def _render(request: Request, name: str, status_code: int = 200, **context) -> HTMLResponse:
    return templates.TemplateResponse(request, name, context, status_code=status_code)


def _error_page(request: Request, err: HaptifyError) -> HTMLResponse:
    """A refusal as a page: its code and message, HTTP status by code."""
    f = err.findings[0]
    status = STATUS_OF_CODE.get(f.code, 500)
    log.warning(
        "refused %s %s from %s: %s %s",
        request.method,
        request.url.path,
        request.client.host if request.client else "-",
        f.code,
        f.message,
    )
    title = {404: "Not found", 400: "Bad request"}.get(status, "Error")
    return _render(request, "error.html", status_code=status, code=f.code, title=title, message=f.message)


def _label(device: dict) -> str:
    return f"{device['manufacturer']} {device['model']}"


@router.get("/", name="page_index", response_class=HTMLResponse)
def page_index(request: Request) -> HTMLResponse:
    """The devices with current results (labs, submissions, verified ones) and the leaderboards (spec §17.5)."""
    reads = api_read.reads(request)
    current = [s for s in reads.submissions() if s["state"] == "current"]
    by_device: dict[str, list[dict]] = {}
    for s in current:
        by_device.setdefault(s["device"]["slug"], []).append(s)
    devices = [
        {
            "slug": d["slug"],
            "label": _label(d),
            "labs": sorted({s["lab"] for s in by_device[d["slug"]]}),
            "submissions": len(by_device[d["slug"]]),
            "verified": sum(s["verification"] == "verified" for s in by_device[d["slug"]]),
        }
        for d in reads.devices()
        if d["slug"] in by_device
    ]
    menu = api_read.leaderboard_menu(reads.all_device_results())
    return _render(
        request, "index.html", devices=devices, metrics=menu, n_labs=len({s["lab"] for s in current}), n_submissions=len(current)
    )


@router.get("/leaderboard", name="page_leaderboard_redirect")
def page_leaderboard_redirect(request: Request, metric: str | None = None, verification: str = "verified") -> Response:
    """``/leaderboard?metric=ID`` (the metric picker) → ``/leaderboard/ID`` (keeping ``verification=all``);
    without a metric, the first one."""
    if metric is None:
        menu = api_read.leaderboard_menu(api_read.reads(request).all_device_results())
        if not menu:
            return RedirectResponse(request.url_for("page_index"), status_code=303)
        metric = menu[0]["id"]
    target = str(request.url_for("page_leaderboard", metric_id=metric))
    return RedirectResponse(target + ("?verification=all" if _ranked(verification) == "all" else ""), status_code=303)


def _ranked(verification: str) -> str:
    """The aggregation filter of a page's query (``verified``, the default, or ``all``)."""
    return "all" if verification == "all" else "verified"


@router.get("/leaderboard/{metric_id}", name="page_leaderboard", response_class=HTMLResponse)
def page_leaderboard(metric_id: str, request: Request, verification: str = "verified") -> HTMLResponse:
    """One metric's leaderboard: devices best first, each with its mean and spread (spec §17.5), from
    verified results unless ``verification=all``; the results left out are listed apart, marked with
    their state (spec §17.3.1). E973 unknown metric."""
    verification = _ranked(verification)
    results = api_read.reads(request).all_device_results(verification)
    defs = api_read.metric_definitions()
    if metric_id not in defs:
        return _error_page(
            request,
            fail(
                Code.NOT_FOUND,
                f"there is no metric {metric_id!r}",
                pointer="/metric",
                expected="a metric id such as vibration.rms",
                found=metric_id,
            ),
        )
    rows = leaderboard(metric_id, results)
    definition = defs[metric_id]
    return _render(
        request,
        "leaderboard.html",
        metric_id=metric_id,
        title=definition.title,
        description=definition.description,
        unit=rows[0].metric["unit"] if rows else definition.unit,
        rule=rule_text(metric_id),
        rows=rows,
        metrics=api_read.leaderboard_menu(results),
        verification=verification,
        not_ranked=api_read.not_ranked(metric_id, results),
    )


@router.get("/devices/{slug}", name="page_device", response_class=HTMLResponse)
def page_device(slug: str, request: Request, verification: str = "verified") -> HTMLResponse:
    """A device: its metrics with spread over labs and repetitions (of verified submissions unless
    ``verification=all``; the others listed apart with their state), every submission (current,
    superseded, withdrawn), the report figures and viewer recordings of submissions with raw streams
    (spec §17.5, §17.3.1)."""
    reads = api_read.reads(request)
    verification = _ranked(verification)
    try:
        agg = reads.device_results(slug, verification)
    except HaptifyError as err:
        return _error_page(request, err)
    defs = api_read.metric_definitions()
    order = {mid: i for i, mid in enumerate(defs)}
    metrics = sorted(agg["metrics"], key=lambda m: (order.get(m["metric"], len(order)), m["metric"]))
    submissions = [s for s in reads.submissions() if s["device"]["slug"] == slug]
    current = [s for s in submissions if s["state"] == "current"]
    return _render(
        request,
        "device.html",
        device=agg["device"],
        label=_label(agg["device"]),
        metrics=metrics,
        verification=verification,
        not_counted=agg["not_counted"],
        titles={k: v.title for k, v in defs.items()},
        submissions=submissions,
        labs=sorted({s["lab"] for s in current}),
        current=current,
        raw=[s for s in current if s["has_raw"]],
        figures=report_figures(reads.reg, [s for s in current if s["has_raw"]]),
    )


@router.get("/compare", name="page_compare", response_class=HTMLResponse)
def page_compare(
    request: Request, device: list[str] = Query(default=[]), paper: bool = False, verification: str = "verified"
) -> HTMLResponse:
    """Table III (spec §15.5) for the chosen devices (``?device=a&device=b``, optionally ``&paper=true``),
    from verified results unless ``verification=all``; a note counts the results left out."""
    reads = api_read.reads(request)
    verification = _ranked(verification)
    chosen = list(dict.fromkeys(device))
    table_html = csv_url = json_url = None
    if len(chosen) > MAX_COMPARED:
        return _error_page(
            request,
            fail(
                Code.REQUEST_INVALID,
                f"at most {MAX_COMPARED} devices can be compared at once",
                pointer="/device",
                expected=f"≤ {MAX_COMPARED}",
                found=len(chosen),
            ),
        )
    if chosen:
        try:
            table = build_table(reads.comparison(tuple(chosen), verification), with_paper=paper)
            table.notes.extend(
                api_read.not_counted_notes({s: reads.device_results(s, verification)["not_counted"] for s in chosen})
            )
        except HaptifyError as err:
            return _error_page(request, err)
        table_html = to_html(table)
        query = urlencode({"devices": ",".join(chosen), "paper": "true" if paper else "false", "verification": verification})
        csv_url = f"{api_read.API}/compare?{query}&format=csv"
        json_url = f"{api_read.API}/compare?{query}"
    devices = [{"slug": d["slug"], "label": _label(d)} for d in reads.devices()]
    return _render(
        request,
        "compare.html",
        devices=devices,
        chosen_slugs=set(chosen),
        with_paper=paper,
        verification=verification,
        table_html=table_html,
        csv_url=csv_url,
        json_url=json_url,
    )


def _raw_submission(reg, sid: str) -> dict:
    """The submission ``sid`` when it includes raw streams (E973 when unknown or without them)."""
    sub = reg.submission(sid)
    if not sub["has_raw"]:
        raise fail(
            Code.NOT_FOUND,
            f"submission {sid} has no raw streams, so there is no report or recording of it",
            expected="a submission made with --include-raw",
            found="results only",
        )
    return sub


def derived_folder(reg, sid: str) -> Path:
    """The folder of a submission's derived data: where :meth:`Registry.session_folder` unpacks its session
    (``DATA/cache/<archive name>/``); computed without unpacking anything."""
    return reg.data / "cache" / reg.archive(sid).name[: -len(".tar.gz")]


def report_folder(reg, sid: str) -> Path:
    """Where the report of submission ``sid`` is (or will be): next to its unpacked session."""
    return derived_folder(reg, sid) / "report"


def ensure_report(reg, sid: str) -> Path:
    """The ``haptify report`` folder of a submission with raw streams, drawn once (spec §15.6)."""
    sub = _raw_submission(reg, sid)
    out = report_folder(reg, sid)
    if out.is_dir():
        return out
    from haptify.formats.storage import open_session
    from haptify.pipeline.compute import ComputeContext
    from haptify.pipeline.results import ResultsFile
    from haptify.report.document import write_report

    with _derive_lock:
        if not out.is_dir():
            session = open_session(reg.session_folder(sid))
            write_report(ComputeContext(session=session), ResultsFile.model_validate(sub["results"]), out)
    return out


def ensure_recording(reg, sid: str) -> Path:
    """The viewer recording (.rrd) of a submission with raw streams, built once (written to a temporary name, then renamed)."""
    sub = _raw_submission(reg, sid)
    out = derived_folder(reg, sid) / "recording.rrd"
    if out.is_file():
        return out
    from haptify.formats.storage import open_session
    from haptify.pipeline.results import ResultsFile
    from haptify_tools.viewer.save import build

    with _derive_lock:
        if not out.is_file():
            tmp = out.with_name(f".recording-{uuid.uuid4().hex}.rrd")
            try:
                build(open_session(reg.session_folder(sid)), tmp, results=ResultsFile.model_validate(sub["results"]))
                os.replace(tmp, out)
            finally:
                tmp.unlink(missing_ok=True)
    return out


def report_figures(reg, submissions: list[dict]) -> dict[str, list[str]]:
    """PNG names of the reports already drawn, by submission id (the device page shows them inline)."""
    out = {}
    for s in submissions:
        folder = report_folder(reg, s["id"])
        if folder.is_dir():
            out[s["id"]] = sorted(p.name for p in folder.glob("*.png"))
    return out


@router.get("/submissions/{sid}/report/{name}", name="page_report")
def page_report(sid: str, name: str, request: Request) -> Response:
    """A file of the submission's ``haptify report`` (``index.html``, figures, sounds), drawn on first request."""
    reg = api_read.reads(request).reg
    try:
        if not REPORT_FILE.match(name):
            raise fail(
                Code.NOT_FOUND,
                f"{name!r} is not a file of a report",
                pointer="/name",
                expected="index.html or a figure",
                found=name,
            )
        path = ensure_report(reg, sid) / name
        if not path.is_file():
            raise fail(
                Code.NOT_FOUND,
                f"the report of {sid} has no file {name!r}",
                pointer="/name",
                expected="index.html or a figure",
                found=name,
            )
    except HaptifyError as err:
        return _error_page(request, err)
    return FileResponse(path)


@router.get("/submissions/{sid}/recording.rrd", name="page_recording")
def page_recording(sid: str, request: Request) -> Response:
    """The submission's recording for the viewer: open it with ``rerun FILE.rrd``."""
    try:
        path = ensure_recording(api_read.reads(request).reg, sid)
    except HaptifyError as err:
        return _error_page(request, err)
    return FileResponse(path, media_type="application/octet-stream", filename=f"{sid}.rrd")


@router.get("/challenges/{cid}", name="page_challenge", response_class=HTMLResponse)
def page_challenge(cid: str, request: Request) -> HTMLResponse:
    """A conformance challenge (spec §17.8): its cases while open; once answered, the implementation, the
    verdict and each case's expected and found value."""
    from haptify_tools.registry import challenge

    try:
        record = challenge.record(api_read.reads(request).reg, cid)
    except HaptifyError as err:
        return _error_page(request, err)
    return _render(request, "challenge.html", c=record)


def register(app: FastAPI) -> None:
    """Add the web pages, the read-side JSON endpoints and the stylesheet to the registry app."""
    app.include_router(api_read.router)
    app.include_router(router)
    app.mount("/static", StaticFiles(directory=str(_HERE / "static")), name="registry_static")
