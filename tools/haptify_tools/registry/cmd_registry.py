"""``haptify registry serve [--db URL] [--data DIR] [--host 127.0.0.1] [--port 8080]``,
``haptify registry token create --lab LAB [--scope submit|admin] [--rate N]`` (spec §17.6, §17.7) and
``haptify registry reverify [--since-version V] [--resume RUN] [--workers N | --scheduler ADDRESS]`` (spec §17.9)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from haptify.codes import Code
from haptify.errors import fail
from haptify_tools.cluster import add_executor_options, dask_client, describe
from haptify_tools.registry.bundle import Limits
from haptify_tools.registry.records import DEFAULT_RATE_PER_MINUTE, SCOPES, Settings
from haptify_tools.registry.service import Registry

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
    serve.add_argument(
        "--max-archive-mib", type=int, default=limits.max_archive_bytes >> 20, help="largest upload accepted (MiB)"
    )
    serve.add_argument(
        "--max-unpacked-mib", type=int, default=limits.max_unpacked_bytes >> 20, help="most bytes a bundle may unpack to (MiB)"
    )
    serve.add_argument(
        "--worker-memory-mib",
        type=int,
        default=limits.worker_memory_bytes >> 20,
        help="address space of the worker that unpacks and re-computes a bundle (MiB)",
    )
    serve.add_argument(
        "--worker-seconds",
        type=float,
        default=limits.worker_seconds,
        help="time the worker may take for each step of checking a bundle (s)",
    )
    serve.add_argument(
        "--upload-ttl-hours",
        type=float,
        default=Settings.upload_ttl_s / 3600,
        help="a resumable upload without a chunk for this long expires and is deleted (h)",
    )
    serve.set_defaults(func=run_serve)
    token = rsub.add_parser("token", help="API tokens")
    tsub = token.add_subparsers(dest="token_command", metavar="ACTION", required=True)
    create = tsub.add_parser("create", help="create a token for a lab (printed once; stored only as its sha256)")
    _store_options(create)
    create.add_argument("--lab", required=True, help="the lab id (as in the sessions' lab.id)")
    create.add_argument("--scope", choices=SCOPES, default="submit")
    create.add_argument("--rate", type=int, default=DEFAULT_RATE_PER_MINUTE, help="requests per minute allowed")
    create.set_defaults(func=run_token_create)
    reverify = rsub.add_parser(
        "reverify",
        help="re-compute every stored submission with raw streams with the installed "
        "reference, on a Dask cluster; record the new values beside the old",
    )
    _store_options(reverify)
    reverify.add_argument(
        "--storage", metavar="LOCATION", help="the data folder as the workers see it (default: --data; spec §17.9)"
    )
    reverify.add_argument(
        "--since-version", metavar="V", help="only submissions no reference of version V or later has re-verified yet"
    )
    reverify.add_argument("--resume", metavar="RUN", help="finish the run RUN (skips the submissions it has recorded)")
    add_executor_options(reverify)
    reverify.set_defaults(func=run_reverify_command)


def _settings(args) -> Settings:
    limits = Limits()
    if hasattr(args, "worker_seconds"):
        limits = replace(
            limits,
            max_archive_bytes=args.max_archive_mib << 20,
            max_unpacked_bytes=args.max_unpacked_mib << 20,
            worker_memory_bytes=args.worker_memory_mib << 20,
            worker_seconds=args.worker_seconds,
        )
    ttl = {"upload_ttl_s": args.upload_ttl_hours * 3600} if hasattr(args, "upload_ttl_hours") else {}
    return Settings(data_dir=args.data, db_url=args.db, verify_raw=not getattr(args, "no_verify", False), limits=limits, **ttl)


def run_serve(args, ui) -> int:
    """Serve the registry (JSON API, web pages) on ``--host``/``--port`` until interrupted (spec §17.7)."""
    import uvicorn

    from haptify_tools.registry.app import create_app

    app = create_app(_settings(args))
    swept = app.state.swept
    ui.say(
        f"registry on http://{args.host}:{args.port} (API docs /docs); database {app.state.registry.engine.dialect.name}; "
        f"start-up sweep removed {swept['tmp']} temporary and {swept['orphans']} orphan file(s)"
    )
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


def run_reverify_command(args, ui) -> int:
    """Start (or ``--resume``) a re-verification run and print its summary (spec §17.9). Exit 1 when a
    submission could not be re-verified for a reason that is not its own (resume the run to retry it)."""
    from haptify_tools.registry.reverify import load_run, run_reverify, start_run
    from haptify_tools.registry.storage import open_store

    if args.resume and args.since_version:
        raise fail(
            Code.USAGE,
            "--since-version chooses the submissions of a new run; a resumed run keeps its own",
            expected="--resume RUN or --since-version V",
            found="both",
        )
    settings = _settings(args)
    store = open_store(args.storage or str(settings.data_dir))
    registry = Registry(settings, lock=False)
    try:
        executor = describe(args.scheduler, args.workers)
        with dask_client(args.scheduler, args.workers) as client:  # E980 before a run is recorded
            run = load_run(registry.engine, args.resume or start_run(registry.engine, executor, args.since_version))
            run_id = run.id
            ui.say(f"re-verification run {run_id} ({executor})")
            with ui.progress("re-verifying", total=len(json.loads(run.planned_json))) as advance:
                summary = run_reverify(registry.engine, store, run_id, client, limits=settings.limits, progress=advance)
    finally:
        registry.close()
    ui.emit_json(summary.to_dict())
    for line in summary_lines(summary):
        ui.say(line)
    for sid, why in sorted(summary.errors.items()):
        ui.warn(f"{sid}: not re-verified ({why}); `haptify registry reverify --resume {run_id}` retries it")
    return 0 if summary.complete else 1


def summary_lines(summary) -> list[str]:
    """The human summary of a run: totals, then one line per metric, verification changes and the moved."""
    s = summary.submissions
    lines = [
        f"run {summary.run_id} (reference {summary.reference_version}): {summary.recorded}/{summary.planned} recorded "
        f"({summary.computed_now} now, {summary.skipped} before) in {summary.seconds:.1f} s; "
        f"changed {s['changed']}, unchanged {s['unchanged']}, failed {s['failed']}"
    ]
    for metric, counts in summary.metrics.items():
        lines.append(f"  {metric:36s} " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    for transition, n in summary.transitions.items():
        lines.append(f"  verification {transition}: {n}")
    for sid, metrics in summary.changed.items():
        lines.append(f"  W982 {sid}: moved beyond tolerance: {', '.join(metrics)}")
    for sid, codes in summary.failed.items():
        lines.append(f"  {sid}: the reference refuses it now ({', '.join(codes)})")
    return lines
