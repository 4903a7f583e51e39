"""``haptify compute SESSION [-o results.json] [--metrics ID,…]`` (spec §15.4)."""

from __future__ import annotations

from pathlib import Path

from haptify.compute import compute_session, family_modules
from haptify.errors import fail
from haptify.storage import atomic_write_text, open_session


def register(sub) -> None:
    """Add the ``compute`` sub-command (spec §15.4)."""
    p = sub.add_parser("compute", help="compute every metric the session's trials allow")
    p.add_argument("session", type=Path)
    p.add_argument("-o", "--output", type=Path, help="results file (default SESSION/../<id>.results.json)")
    p.add_argument("--metrics", help="comma-separated metric ids (default: all)")
    p.set_defaults(func=run)


def run(args, ui) -> int:
    """Compute the session's metrics and write ``results.json`` atomically (spec §15.4, §3.6)."""
    session = open_session(args.session)
    wanted = None
    if args.metrics is not None:
        wanted = [m.strip() for m in args.metrics.split(",") if m.strip()]
        if not wanted:
            raise fail("E903", "--metrics names no metric id", expected="ID[,ID…]", found=args.metrics)
    out = args.output or args.session.parent / f"{session.session_id}.results.json"
    with ui.progress("computing metrics", total=len(family_modules())) as advance:
        results = compute_session(session, wanted, progress=advance)
    atomic_write_text(out, results.model_dump_json(indent=2) + "\n")
    if ui.json_mode:
        ui.emit_json(results.model_dump(mode="json"))
        return 0
    for m in results.metrics:
        value = m.value if isinstance(m.value, list) else f"{m.value:.6g}"
        ui.say(f"{m.id:36s} {value} {m.unit}  (n={m.n})")
    for u in results.unavailable:
        ui.say(f"{u.id:36s} not computed: {u.code} {u.reason}")
    for w in results.warnings:
        ui.warn(f"{w.code} warning: {w.message}")
    ui.say(f"wrote {out}")
    return 0
