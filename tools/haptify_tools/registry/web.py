"""Web pages of the registry, served by the same app as the API (issue 9).

* ``/`` — the devices (with check boxes to compare them) and the list of leaderboards;
* ``/leaderboard/{metric}`` — one metric's leaderboard (ranking rule from ``rankings.json``);
* ``/devices/{slug}`` — a device's metrics with their spread over labs and repetitions, its submissions,
  the figures of ``haptify report`` when a submission shipped them, and how to open its recording in
  the viewer;
* ``/compare?device=a&device=b…`` — the paper's Table III for the chosen devices
  (``haptify.compare.build_table`` / ``to_html``).

``install(app)`` adds these pages, the read-side JSON API (:mod:`haptify_tools.registry.api_read`) and
the stylesheet to a FastAPI app whose ``app.state.engine`` is the registry's database engine.
"""

from __future__ import annotations

from importlib import resources
from urllib.parse import urlencode

from fastapi import APIRouter, FastAPI, Query, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates

from haptify.compare import _fmt, to_html
from haptify.errors import HaptifyError
from haptify.versions import SPEC_VERSION
from haptify_tools.registry import api_read
from haptify_tools.registry.aggregate import comparison, leaderboard

_HERE = resources.files("haptify_tools.registry")
templates = Jinja2Templates(directory=str(_HERE / "templates"))
templates.env.filters["num"] = _fmt  # 5 significant digits, '—' for None (the comparison table's format)
templates.env.globals["spec_version"] = SPEC_VERSION

STATUS_OF_CODE = {"E973": 404, "E975": 400}

router = APIRouter(include_in_schema=False)


def _render(request: Request, name: str, status_code: int = 200, **context) -> HTMLResponse:
    return templates.TemplateResponse(request, name, context, status_code=status_code)


def _error_page(request: Request, exc: HaptifyError) -> HTMLResponse:
    f = exc.findings[0]
    status = STATUS_OF_CODE.get(f.code, 500)
    title = "Not found" if status == 404 else "Bad request" if status == 400 else "Error"
    return _render(request, "error.html", status_code=status, code=f.code, title=title, message=f.message)


def _metric_menu(snap: api_read.Snapshot) -> list[dict]:
    """Every scalar metric that some device has, in definition order, with its title and device count."""
    defs = api_read.metric_definitions()
    counts: dict[str, int] = {}
    for d in snap.devices.values():
        for mid in d.metrics:
            counts[mid] = counts.get(mid, 0) + 1
    order = {mid: i for i, mid in enumerate(defs)}
    ids = sorted(counts, key=lambda m: (order.get(m, len(order)), m))
    return [{"id": m, "title": defs[m].title if m in defs else m, "n_devices": counts[m]} for m in ids]


@router.get("/", name="page_index", response_class=HTMLResponse)
def page_index(request: Request) -> HTMLResponse:
    snap = api_read.read_model(request).snapshot()
    labs = {e.lab for e in snap.entries}
    return _render(request, "index.html", devices=list(snap.devices.values()), metrics=_metric_menu(snap),
                   n_labs=len(labs), n_submissions=len(snap.entries))


@router.get("/leaderboard", name="page_leaderboard_redirect")
def page_leaderboard_redirect(request: Request, metric: str | None = None) -> Response:
    """``/leaderboard?metric=ID`` (the metric picker) → ``/leaderboard/ID``; without a metric, the first one."""
    if metric is None:
        menu = _metric_menu(api_read.read_model(request).snapshot())
        if not menu:
            return RedirectResponse(request.url_for("page_index"), status_code=303)
        metric = menu[0]["id"]
    return RedirectResponse(request.url_for("page_leaderboard", metric_id=metric), status_code=303)


@router.get("/leaderboard/{metric_id}", name="page_leaderboard", response_class=HTMLResponse)
def page_leaderboard(metric_id: str, request: Request) -> HTMLResponse:
    snap = api_read.read_model(request).snapshot()
    defs = api_read.metric_definitions()
    menu = _metric_menu(snap)
    if metric_id not in defs and all(m["id"] != metric_id for m in menu):
        from haptify.errors import fail

        return _error_page(request, fail("E973", f"there is no metric '{metric_id}'", pointer="/metric",
                                         expected="a metric id such as vibration.rms", found=metric_id))
    rows, rule = leaderboard(metric_id, snap.devices)
    definition = defs.get(metric_id)
    unit = rows[0].metric.unit if rows else (definition.unit if definition else "")
    return _render(request, "leaderboard.html", metric_id=metric_id, title=definition.title if definition else metric_id,
                   description=definition.description if definition else "", unit=unit, rule=rule, rows=rows, metrics=menu)


@router.get("/devices/{slug}", name="page_device", response_class=HTMLResponse)
def page_device(slug: str, request: Request) -> HTMLResponse:
    snap = api_read.read_model(request).snapshot()
    try:
        device = api_read.device_or_404(snap, slug)
    except HaptifyError as exc:
        return _error_page(request, exc)
    defs = api_read.metric_definitions()
    order = {mid: i for i, mid in enumerate(defs)}
    metrics = sorted(device.metrics.values(), key=lambda m: (order.get(m.id, len(order)), m.id))
    vectors = [{"id": m.id, "submission": e.submission_id, "lab": e.lab, "unit": m.unit,
                "value": ", ".join(_fmt(v) for v in m.value)}
               for e in device.entries for m in e.results.metrics if isinstance(m.value, list)]
    return _render(request, "device.html", device=device, metrics=metrics, vectors=vectors,
                   titles={k: v.title for k, v in defs.items()})


@router.get("/compare", name="page_compare", response_class=HTMLResponse)
def page_compare(request: Request, device: list[str] = Query(default=[]), paper: bool = False) -> HTMLResponse:
    snap = api_read.read_model(request).snapshot()
    table_html = csv_url = json_url = None
    if device:
        try:
            chosen = api_read.chosen_devices(snap, device)
        except HaptifyError as exc:
            return _error_page(request, exc)
        table_html = to_html(comparison(chosen, with_paper=paper))
        query = urlencode([("device", d.slug) for d in chosen] + ([("paper", "true")] if paper else []))
        csv_url = f"{request.url_for('api_compare_csv')}?{query}"
        json_url = f"{request.url_for('api_compare')}?{query}"
    return _render(request, "compare.html", devices=list(snap.devices.values()), chosen_slugs=set(device),
                   with_paper=paper, table_html=table_html, csv_url=csv_url, json_url=json_url)


def install(app: FastAPI) -> None:
    """Add the read-side JSON API, the web pages and the stylesheet to the registry app."""
    app.include_router(api_read.router)
    app.include_router(router)
    app.mount("/static", StaticFiles(directory=str(_HERE / "static")), name="registry_static")
