"""``haptify registry serve [--db URL] [--data DIR] [--host 127.0.0.1] [--port 8080]`` and
``haptify registry token create --lab LAB [--scope submit|admin] [--rate N]`` (spec §17.6, §17.7)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from haptify_tools.registry.bundle import Limits
from haptify_tools.registry.service import DEFAULT_RATE_PER_MINUTE, SCOPES, Registry, Settings

DEFAULT_DATA = Path("haptify-registry")


def _store_options(p) -> None:
    p.add_argument("--db", help="database URL (default: SQLite in the data folder); e.g. postgresql://user@host/db")
    p.add_argument("--data", type=Path, default=DEFAULT_DATA, help="data folder for archives (and the SQLite file)")


def register(sub) -> None:
    """Add ``registry serve`` (spec §17.7) and ``registry token create`` (spec §17.6)."""
    p = sub.add_parser("registry", help="run a results registry or manage its API tokens")
    rsub = p.add_subparsers(dest="registry_command", metavar="ACTION", required=True)
    serve = rsub.add_parser("serve", help="serve the registry (JSON API, OpenAPI docs at /docs, web pages)")
    _store_options(serve)
    serve.add_argument("--host", default="127.0.0.1")
    serve.add_argument("--port", type=int, default=8080)
    serve.add_argument("--no-verify", action="store_true", help="do not re-compute metrics of bundles with raw streams")
    limits = Limits()
    serve.add_argument("--max-archive-mib", type=int, default=limits.max_archive_bytes >> 20, help="largest upload accepted (MiB)")
    serve.add_argument("--max-unpacked-mib", type=int, default=limits.max_unpacked_bytes >> 20,
                       help="most bytes a bundle may unpack to (MiB)")
    serve.add_argument("--worker-memory-mib", type=int, default=limits.worker_memory_bytes >> 20,
                       help="address space of the worker that unpacks and re-computes a bundle (MiB)")
    serve.add_argument("--worker-seconds", type=float, default=limits.worker_seconds,
                       help="time the worker may take for each step of checking a bundle (s)")
    serve.add_argument("--upload-ttl-hours", type=float, default=Settings.upload_ttl_s / 3600,
                       help="a resumable upload without a chunk for this long expires and is deleted (h)")
    serve.set_defaults(func=run_serve)
    token = rsub.add_parser("token", help="API tokens")
    tsub = token.add_subparsers(dest="token_command", metavar="ACTION", required=True)
    create = tsub.add_parser("create", help="create a token for a lab (printed once; stored only as its sha256)")
    _store_options(create)
    create.add_argument("--lab", required=True, help="the lab id (as in the sessions' lab.id)")
    create.add_argument("--scope", choices=SCOPES, default="submit")
    create.add_argument("--rate", type=int, default=DEFAULT_RATE_PER_MINUTE, help="requests per minute allowed")
    create.set_defaults(func=run_token_create)


def _settings(args) -> Settings:
    limits = Limits()
    if hasattr(args, "worker_seconds"):
        limits = replace(limits, max_archive_bytes=args.max_archive_mib << 20, max_unpacked_bytes=args.max_unpacked_mib << 20,
                         worker_memory_bytes=args.worker_memory_mib << 20, worker_seconds=args.worker_seconds)
    ttl = {"upload_ttl_s": args.upload_ttl_hours * 3600} if hasattr(args, "upload_ttl_hours") else {}
    return Settings(data_dir=args.data, db_url=args.db, verify_raw=not getattr(args, "no_verify", False), limits=limits, **ttl)


def run_serve(args, ui) -> int:
    """Serve the registry (JSON API, web pages) on ``--host``/``--port`` until interrupted (spec §17.7)."""
    import uvicorn

    from haptify_tools.registry.app import create_app

    app = create_app(_settings(args))
    swept = app.state.swept
    ui.say(f"registry on http://{args.host}:{args.port} (API docs /docs); database {app.state.registry.engine.dialect.name}; "
           f"start-up sweep removed {swept['tmp']} temporary and {swept['orphans']} orphan file(s)")
    uvicorn.run(app, host=args.host, port=args.port, log_level="warning")
    return 0


def run_token_create(args, ui) -> int:
    """Create a lab token and print it once; only its sha256 is stored (spec §17.6)."""
    registry = Registry(_settings(args), lock=False)
    try:
        token = registry.create_token(args.lab, args.scope, args.rate)
    finally:
        registry.close()
    if ui.json_mode:
        ui.emit_json({"lab": args.lab, "scope": args.scope, "rate_per_minute": args.rate, "token": token})
    else:
        print(token)
        ui.warn(f"token for lab {args.lab} (scope {args.scope}); it is shown once and stored only as its sha256")
    return 0
