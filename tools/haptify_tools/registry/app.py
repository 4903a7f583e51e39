"""The registry's HTTP service (spec §17.5): a FastAPI app with a JSON API and OpenAPI docs at ``/docs``.

``create_app(settings)`` opens (and migrates) the database, sweeps what an interrupted submission left,
and returns the app. ``app.state.registry`` is the :class:`~haptify_tools.registry.service.Registry`;
the web pages are added by :func:`haptify_tools.registry.web.register` when that module exists, so the
pages and the API share one process, one database and one set of queries.

Every refusal is a JSON body ``{"status": "refused", "findings": [...]}`` whose findings carry a code
from ``codes.json``, the field (``file`` and ``pointer``), ``expected`` and ``found``.
"""

from __future__ import annotations

import importlib
import logging
from contextlib import asynccontextmanager
from dataclasses import asdict, replace
from typing import Any

from fastapi import FastAPI, Header, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, PlainTextResponse, Response
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError
from haptify.pipeline import compare
from haptify.versions import PACKAGE_VERSION, SPEC_VERSION
from haptify_tools.registry import challenge
from haptify_tools.registry.api_read import not_counted_notes, reads
from haptify_tools.registry.records import Settings
from haptify_tools.registry.service import Registry
from haptify_tools.registry.uploads import Uploads

API = "/api/v1"
VERIFICATION_FILTER = "^(all|verified|disagreeing|unverified)$"  # lists: one verification state, or all (spec §17.3.1)
RANKED_FILTER = "^(verified|all)$"  # aggregates and rankings: verified results only (default), or all
log = logging.getLogger("haptify.registry")

STATUS: dict[str, int] = {
    Code.BUNDLE_TOO_LARGE: 413,
    Code.TOKEN_INVALID: 401,
    Code.TOKEN_SCOPE: 403,
    Code.RATE_LIMITED: 429,
    Code.NOT_FOUND: 404,
    Code.SUPERSEDE_CONFLICT: 409,
    Code.REQUEST_INVALID: 400,
    Code.LAB_MISMATCH: 403,
    Code.REGISTRY_UNAVAILABLE: 503,
    Code.CHALLENGE_CLOSED: 410,
    Code.INTERNAL_ERROR: 500,
}


def http_status(err: HaptifyError) -> int:
    """The HTTP status of a refusal: by its first code; content problems are 422.
    The mapping of spec §17.5.1."""
    return STATUS.get(err.findings[0].code, 422)


def refusal(err: HaptifyError) -> JSONResponse:
    """The refusal ``{"status": "refused", "findings": [...]}``, its HTTP status, ``Retry-After`` (s); spec §17.5.1."""
    headers = {}
    wait = getattr(err, "retry_after", None)
    if wait is not None:
        headers["Retry-After"] = str(max(1, int(wait + 0.999)))
    return JSONResponse(
        {"status": "refused", "findings": [f.to_dict() for f in err.findings]}, status_code=http_status(err), headers=headers
    )


def log_refusal(request: Request, err: HaptifyError) -> None:
    """Every refusal is logged on the server with its codes, method, path and client (spec §17.5.1)."""
    client = request.client.host if request.client else "-"
    log.warning(
        "refused %s %s from %s: %s",
        request.method,
        request.url.path,
        client,
        "; ".join(f"{f.code} {f.message}" for f in err.findings[:5]),
    )


class WithdrawBody(BaseModel):
    """The body of ``POST /api/v1/submissions/{id}/withdraw``: a non-empty ``reason`` (spec §17.5)."""

    model_config = ConfigDict(extra="forbid")
    reason: str = Field(min_length=1, max_length=2000, description="Why the submission is withdrawn (kept with the record).")


class TokenBody(BaseModel):
    """The body of ``POST /api/v1/tokens``: lab, scope and rate limit in requests per minute (spec §17.6)."""

    model_config = ConfigDict(extra="forbid")
    lab: str
    scope: str = "submit"
    rate_per_minute: int | None = Field(default=None, ge=1, le=100_000)


CSP_PAGES = (
    "default-src 'none'; img-src 'self' data:; media-src 'self'; style-src 'self' 'unsafe-inline'; "
    "font-src 'self'; connect-src 'self'; form-action 'self'; base-uri 'none'; frame-ancestors 'none'"
)
# Swagger UI and ReDoc (/docs, /redoc) are FastAPI's pages: their script and style come from its CDN.
CSP_API_DOCS = (
    "default-src 'none'; script-src 'unsafe-inline' https://cdn.jsdelivr.net; "
    "style-src 'unsafe-inline' https://cdn.jsdelivr.net https://fonts.googleapis.com; font-src https://fonts.gstatic.com; "
    "img-src 'self' data: https://fastapi.tiangolo.com https://cdn.redoc.ly; connect-src 'self'; worker-src blob:; "
    "base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
)
API_DOCS_PATHS = ("/docs", "/docs/oauth2-redirect", "/redoc")


def security_headers(path: str) -> list[tuple[bytes, bytes]]:
    """The headers every response carries (spec §17.4.1): a Content-Security-Policy without scripts on the
    registry's own pages and ``frame-ancestors 'none'`` everywhere, ``X-Content-Type-Options: nosniff``,
    ``X-Frame-Options: DENY`` and ``Referrer-Policy: no-referrer``."""
    csp = CSP_API_DOCS if path in API_DOCS_PATHS else CSP_PAGES
    return [
        (b"content-security-policy", csp.encode()),
        (b"x-content-type-options", b"nosniff"),
        (b"x-frame-options", b"DENY"),
        (b"referrer-policy", b"no-referrer"),
    ]


class SecurityHeaders:
    """ASGI middleware adding :func:`security_headers` to every HTTP response (pages, API, files, errors).

    :func:`create_app` puts it outside Starlette's ``ServerErrorMiddleware``, so the 500 of an unhandled
    exception carries the headers too (a middleware added with ``add_middleware`` sits inside it)."""

    def __init__(self, app) -> None:
        self.app = app

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        extra = security_headers(scope.get("path", ""))

        async def send_with_headers(message) -> None:
            if message["type"] == "http.response.start":
                names = {k.lower() for k, _ in message.get("headers", [])}
                message = {**message, "headers": [*message.get("headers", []), *(h for h in extra if h[0] not in names)]}
            await send(message)

        await self.app(scope, receive, send_with_headers)


class _RegistryApp(FastAPI):
    """The FastAPI app with :class:`SecurityHeaders` outermost, outside ``ServerErrorMiddleware``: 500s get the
    headers too."""

    def build_middleware_stack(self) -> ASGIApp:
        return SecurityHeaders(super().build_middleware_stack())


def create_app(settings: Settings | None = None, *, registry: Registry | None = None) -> FastAPI:
    """The registry app for ``settings`` (spec §17.5); migrations and the orphan sweep run here, at start-up.
    The routes are registered by concern, in this order: errors, service, submission intake, submission
    records, admin and limits, conformance challenges, labs and devices, then the web pages."""
    reg = registry or Registry(settings or Settings())
    swept = reg.sweep()

    @asynccontextmanager
    async def lifespan(_app: FastAPI):
        yield
        reg.close()

    app = _RegistryApp(
        title="Haptify results registry",
        version=PACKAGE_VERSION,
        lifespan=lifespan,
        description="Labs submit verified device results; everyone compares devices (Haptify spec chapter 17).",
    )
    app.state.registry = reg
    app.state.swept = swept
    _register_error_handlers(app)
    _register_health(app, reg)
    _register_intake(app, reg)
    _register_submission_records(app, reg)
    _register_admin(app, reg)
    _register_conformance(app, reg)
    _register_devices(app, reg)
    _add_web(app)
    return app


def _register_error_handlers(app: FastAPI) -> None:
    """Coded refusals (``HaptifyError``, invalid requests E975, HTTP errors E973/E975) and the E999 of an
    unhandled exception, each a JSON body with findings (spec §17.5.1)."""

    @app.exception_handler(HaptifyError)
    async def _coded(request: Request, err: HaptifyError) -> JSONResponse:
        log_refusal(request, err)
        return refusal(err)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        findings = [
            Finding(
                Code.REQUEST_INVALID,
                e.get("msg", "invalid"),
                file=str(e.get("loc", ["request"])[0]),
                pointer="/" + "/".join(str(p) for p in e.get("loc", [])[1:]),
                expected=e.get("type"),
                found=_short(e.get("input")),
            )
            for e in exc.errors()
        ]
        err = HaptifyError(*(findings or [Finding(Code.REQUEST_INVALID, "invalid request")]))
        log_refusal(request, err)
        return refusal(err)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        err = HaptifyError(Finding(Code.NOT_FOUND if exc.status_code == 404 else Code.REQUEST_INVALID, str(exc.detail)))
        log_refusal(request, err)
        return JSONResponse(
            {"status": "refused", "findings": [f.to_dict() for f in err.findings]},
            status_code=exc.status_code,
            headers=getattr(exc, "headers", None),
        )

    @app.exception_handler(Exception)
    async def _internal(request: Request, exc: Exception) -> JSONResponse:
        log.error(
            "error %s %s from %s: E999 %s: %s",
            request.method,
            request.url.path,
            request.client.host if request.client else "-",
            type(exc).__name__,
            exc,
            exc_info=exc,
        )
        return JSONResponse(
            {"status": "error", "findings": [Finding(Code.INTERNAL_ERROR, f"{type(exc).__name__}: {exc}").to_dict()]},
            status_code=500,
        )


def _register_health(app: FastAPI, reg: Registry) -> None:
    """``GET /health``: liveness, versions and the start-up sweep (spec §17.5)."""

    @app.get(f"{API}/health", tags=["service"])
    def health() -> dict:
        """Liveness, versions and what the start-up sweep removed."""
        return {
            "ok": True,
            "version": PACKAGE_VERSION,
            "spec_versions": [SPEC_VERSION],
            "database": reg.engine.dialect.name,
            "swept": app.state.swept,
        }


def _register_intake(app: FastAPI, reg: Registry) -> None:
    """Submission intake (spec §17.2, §17.5.2): ``POST /submissions`` with the bundle as the body, and the
    resumable uploads (open, append, state, submit); the uploads left by a restart are resumed or expired here."""

    @app.post(
        f"{API}/submissions",
        tags=["submissions"],
        status_code=201,
        openapi_extra={
            "requestBody": {"required": True, "content": {"application/gzip": {"schema": {"type": "string", "format": "binary"}}}}
        },
    )
    async def submit(
        request: Request,
        response: Response,
        dry_run: bool = Query(False, description="check only; store nothing"),
        authorization: str | None = Header(None),
    ) -> dict:
        """Submit a bundle (the request body is the ``.tar.gz``; spec §17.2). 201 accepted, 200 duplicate or dry run."""
        caller = await run_in_threadpool(reg.authenticate, authorization, "submit")
        declared = request.headers.get("content-length")
        limit = reg.settings.limits.max_archive_bytes
        if declared and declared.isdigit() and int(declared) > limit:
            raise HaptifyError(
                Finding(
                    Code.BUNDLE_TOO_LARGE,
                    "the bundle archive is larger than the registry accepts",
                    file="<upload>",
                    expected=f"≤ {limit} bytes",
                    found=f"{declared} bytes",
                )
            )
        upload = await reg.receive(request.stream())
        outcome = await run_in_threadpool(reg.submit, upload, caller, dry_run=dry_run)
        if outcome.status != "accepted":
            response.status_code = 200
        return outcome.to_dict()

    uploads = Uploads(reg.data / "uploads", reg.tmp, reg.settings.limits.max_archive_bytes, reg.settings.upload_ttl_s)
    app.state.swept.update(uploads_resumed=uploads.resumed, uploads_expired=uploads.expired)

    @app.post(f"{API}/uploads", tags=["submissions"], status_code=201)
    def open_upload(upload_length: str | None = Header(None), authorization: str | None = Header(None)) -> dict:
        """Open a resumable upload of ``Upload-Length`` bytes (spec §17.5.2); send it with PATCH in chunks."""
        caller = reg.authenticate(authorization, "submit")
        return uploads.open(caller.token_id, upload_length).state()

    @app.patch(f"{API}/uploads/{{uid}}", tags=["submissions"])
    async def append_upload(
        uid: str, request: Request, upload_offset: str | None = Header(None), authorization: str | None = Header(None)
    ) -> dict:
        """Append the body at ``Upload-Offset`` (the bytes received so far); a body cut short keeps what arrived."""
        caller = await run_in_threadpool(reg.authenticate, authorization, "submit")
        return (await uploads.append(uid, caller.token_id, upload_offset, request.stream())).state()

    @app.get(f"{API}/uploads/{{uid}}", tags=["submissions"])
    def upload_state(uid: str, authorization: str | None = Header(None)) -> dict:
        """How far an upload got: resume with PATCH at ``offset``."""
        caller = reg.authenticate(authorization, "submit", rate_limit=False)
        return uploads.get(uid, caller.token_id).state()

    @app.post(f"{API}/uploads/{{uid}}/submit", tags=["submissions"], status_code=201)
    def submit_upload(
        uid: str,
        response: Response,
        dry_run: bool = Query(False, description="check only; store nothing"),
        authorization: str | None = Header(None),
    ) -> dict:
        """Submit a complete upload: the same checks and answers as ``POST /submissions`` (spec §17.3)."""
        caller = reg.authenticate(authorization, "submit")
        outcome = reg.submit(uploads.take(uid, caller.token_id), caller, dry_run=dry_run)
        if outcome.status != "accepted":
            response.status_code = 200
        return outcome.to_dict()


def _register_submission_records(app: FastAPI, reg: Registry) -> None:
    """Submission records (spec §17.3, §17.5): list, one submission, its archive, withdrawal."""

    @app.get(f"{API}/submissions", tags=["submissions"])
    def list_submissions(
        lab: str | None = None,
        device: str | None = None,
        state: str = Query("all", pattern="^(all|current|superseded|withdrawn)$"),
        verification: str = Query("all", pattern=VERIFICATION_FILTER),
        limit: int = Query(100, ge=1, le=1000),
        offset: int = Query(0, ge=0),
    ) -> list[dict]:
        """Submissions, newest first; ``state`` current, superseded, withdrawn or all; ``verification``
        verified, disagreeing, unverified or all (spec §17.3.1)."""
        return reg.submissions(lab=lab, device=device, state=state, verification=verification, limit=limit, offset=offset)

    @app.get(f"{API}/submissions/{{sid}}", tags=["submissions"])
    def get_submission(sid: str, request: Request) -> dict:
        """One submission: state, verification per metric, results and bundle manifest."""
        return reads(request).get(("submission", sid), lambda: reg.submission(sid))

    @app.get(f"{API}/submissions/{{sid}}/bundle", tags=["submissions"], response_class=FileResponse)
    def get_bundle(sid: str) -> FileResponse:
        """The submitted archive, byte for byte."""
        return FileResponse(reg.archive(sid), media_type="application/gzip", filename=f"{sid}.tar.gz")

    @app.post(f"{API}/submissions/{{sid}}/withdraw", tags=["submissions"])
    def withdraw(sid: str, body: WithdrawBody, authorization: str | None = Header(None)) -> dict:
        """Withdraw a submission with a reason (own lab with a submit token, any with admin); the record stays."""
        caller = reg.authenticate(authorization, "submit")
        return reg.withdraw(sid, body.reason, caller)


def _register_admin(app: FastAPI, reg: Registry) -> None:
    """Lab tokens (admin only; spec §17.6) and the registry's published limits (spec §17.4)."""

    @app.post(f"{API}/tokens", tags=["service"], status_code=201)
    def create_token(body: TokenBody, authorization: str | None = Header(None)) -> dict:
        """Create a lab token (admin only). The token is shown once; the registry keeps only its sha256."""
        reg.authenticate(authorization, "admin")
        return {"lab": body.lab, "scope": body.scope, "token": reg.create_token(body.lab, body.scope, body.rate_per_minute)}

    @app.get(f"{API}/limits", tags=["service"])
    def limits() -> dict:
        """What this registry accepts (spec §17.4, §17.4.1): a client checks its bundle against these before sending."""
        return {
            **asdict(reg.settings.limits),
            "challenge_ttl_s": reg.settings.challenge_ttl_s,
            "upload_ttl_s": reg.settings.upload_ttl_s,
        }


def _register_conformance(app: FastAPI, reg: Registry) -> None:
    """Conformance challenges (spec §17.8): issue, read, sessions archive, answer; the implementations list."""

    @app.post(f"{API}/challenges", tags=["conformance"], status_code=201)
    def create_challenge(authorization: str | None = Header(None)) -> dict:
        """Issue a conformance challenge to the token's lab (spec §17.8): fresh known-answer sessions from a
        secret seed; the answers stay on the registry. Answer it before ``expires_at``."""
        return challenge.issue(reg, reg.authenticate(authorization, "submit"))

    @app.get(f"{API}/challenges/{{cid}}", tags=["conformance"])
    def get_challenge(cid: str) -> dict:
        """A challenge: its cases (no answers) while open; once answered, the verdict and every case's figures."""
        return challenge.record(reg, cid)

    @app.get(f"{API}/challenges/{{cid}}/sessions.tar.gz", tags=["conformance"], response_class=FileResponse)
    def get_challenge_sessions(cid: str) -> FileResponse:
        """The challenge's session folders (while it is open)."""
        return FileResponse(
            challenge.sessions_archive(reg, cid), media_type="application/gzip", filename=f"challenge-{cid}.tar.gz"
        )

    @app.post(f"{API}/challenges/{{cid}}/answers", tags=["conformance"])
    def answer_challenge(cid: str, body: challenge.Answers, authorization: str | None = Header(None)) -> dict:
        """Answer a challenge once: the registry judges every case against its secret answers and records
        that the implementation and version passed or failed (spec §17.8)."""
        return challenge.answer(reg, cid, reg.authenticate(authorization, "submit"), body)

    @app.get(f"{API}/implementations", tags=["conformance"])
    def implementations() -> list[dict]:
        """Implementations and versions with answered challenges: passed, failed, latest passed challenge."""
        return challenge.implementations(reg)


def _register_devices(app: FastAPI, reg: Registry) -> None:
    """Labs and devices (spec §17.5, §15.5): lab records, device aggregates, comparison table, CSV export."""

    @app.get(f"{API}/labs", tags=["labs"])
    def labs() -> list[dict]:
        return reg.labs()

    @app.get(f"{API}/labs/{{lab_id}}", tags=["labs"])
    def lab(lab_id: str) -> dict:
        return reg.lab(lab_id)

    @app.get(f"{API}/devices", tags=["devices"])
    def devices(request: Request) -> list[dict]:
        return reads(request).devices()

    @app.get(f"{API}/devices/{{slug}}", tags=["devices"])
    def device(slug: str, request: Request, verification: str = Query("verified", pattern=RANKED_FILTER)) -> dict:
        """A device's aggregated results: per metric mean and spread over labs and repetitions (spec §17.5),
        of its verified current submissions (``verification=all``: of all of them); the others are listed
        in ``not_counted`` with their state.

        Records are append-only, so answers are cached until a submission or withdrawal is added."""
        return reads(request).device_results(slug, verification)

    @app.get(f"{API}/compare", tags=["devices"])
    def compare_devices(
        request: Request,
        devices: str = Query(..., description="comma-separated device slugs"),
        format: str = Query("json", pattern="^(json|csv|md|html)$"),
        paper: bool = False,
        verification: str = Query("verified", pattern=RANKED_FILTER),
    ) -> Any:
        """The paper's Table III for any number of devices (``haptify.pipeline.compare``; spec §15.5), from their
        verified current submissions (``verification=all``: from all); a note counts those left out."""
        slugs = [s for s in devices.split(",") if s]
        if not slugs:
            raise HaptifyError(
                Finding(
                    Code.REQUEST_INVALID,
                    "no device given",
                    file="query",
                    pointer="/devices",
                    expected="slug,slug,…",
                    found=devices,
                )
            )
        cache = reads(request)
        table = compare.build_table(cache.comparison(tuple(slugs), verification), with_paper=paper)
        apart = {slug: cache.device_results(slug, verification)["not_counted"] for slug in slugs}
        table.notes.extend(not_counted_notes(apart))
        if format == "csv":
            return PlainTextResponse(compare.to_csv(neutralised(table)), media_type="text/csv")
        if format == "md":
            return PlainTextResponse(compare.to_markdown(table), media_type="text/markdown")
        if format == "html":
            return Response(compare.to_html(table), media_type="text/html")
        return {
            "devices": slugs,
            "verification": verification,
            "header": table.header,
            "rows": table.rows,
            "notes": table.notes,
            "not_counted": apart,
        }

    @app.get(f"{API}/export.csv", tags=["devices"], response_class=PlainTextResponse)
    def export_csv(
        device: str | None = None,
        state: str = Query("current", pattern="^(all|current|superseded|withdrawn)$"),
        verification: str = Query("all", pattern=VERIFICATION_FILTER),
    ) -> Response:
        """Every metric of every submission (filtered by state and verification state), one row each, as
        CSV; the ``verification`` column carries each submission's state (spec §17.3.1)."""
        return PlainTextResponse(
            to_csv(reg.export_rows(device=device, state=state, verification=verification)), media_type="text/csv"
        )


EXPORT_COLUMNS = [
    "submission",
    "state",
    "verification",
    "lab",
    "device",
    "manufacturer",
    "model",
    "serial",
    "implementation",
    "metric",
    "value",
    "unit",
    "n",
    "sd",
    "received_at",
]


def to_csv(rows: list[dict]) -> str:
    """The export rows as CSV with a header line (values of vector metrics as JSON lists).
    ``GET /export.csv`` of spec §17.5.1."""
    import csv
    import io

    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=EXPORT_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: csv_cell(v) for k, v in row.items()} for row in rows)
    return buf.getvalue()


FORMULA_LEAD = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value: Any) -> Any:
    """A CSV cell that no spreadsheet runs as a formula (spec §17.4.1): text starting with ``=``, ``+``,
    ``-``, ``@``, a tab or a carriage return gets a leading ``'``, unless the whole text is a number
    (``-1.5`` stays a number). Non-text values pass unchanged."""
    if not isinstance(value, str) or not value.startswith(FORMULA_LEAD):
        return value
    try:
        float(value)
        return value
    except ValueError:
        return "'" + value


def neutralised(table: compare.Table) -> compare.Table:
    """The comparison table with every header and body cell passed through :func:`csv_cell`."""
    return replace(table, header=[csv_cell(h) for h in table.header], rows=[[csv_cell(c) for c in row] for row in table.rows])


def _short(value: Any) -> Any:
    if isinstance(value, (dict, list)):
        return f"<{type(value).__name__}>"
    if isinstance(value, (bytes, str)) and len(value) > 200:
        return value[:200]
    return value


def _add_web(app: FastAPI) -> None:
    """Mount the web pages (``haptify_tools.registry.web.register(app)``) when that module is present."""
    try:
        web = importlib.import_module("haptify_tools.registry.web")
    except ModuleNotFoundError as exc:
        if exc.name != "haptify_tools.registry.web":
            raise
        return
    web.register(app)


__all__ = ["create_app", "Settings"]
