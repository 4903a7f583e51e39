"""``haptify batch compute SESSION… -o OUT [--metrics ID,…] [--params FILE] [--workers N | --scheduler ADDRESS]``:
many sessions computed at once on a Dask cluster (spec §15.4, §17.9).

Each session is one task doing exactly what ``haptify compute SESSION -o OUT/<name>/results.json`` does
(:func:`haptify.cli.cmd_compute.compute_folder`): the session passes the gate, its metrics are computed, the
rest of it is validated; ``OUT/<name>/results.json`` is written atomically, or for a refused session the
findings document of §16.4.1 as ``OUT/<name>/findings.json``. ``<name>`` is the session folder's name, so
each session has its own output folder. On a cluster of several machines the session folders and ``OUT``
must be at the same paths on every worker (a shared file system).

Plugin of the ``haptify.commands`` entry-point group: ``batch = "haptify_tools.cmd_batch:register"``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify_tools.cluster import add_executor_options, dask_client, describe, each_completed, worker_name

RESULTS = "results.json"
FINDINGS = "findings.json"


def register(sub) -> None:
    """Add ``haptify batch compute`` (spec §15.4, §17.9)."""
    p = sub.add_parser("batch", help="run a command on many sessions at once, on a Dask cluster")
    bsub = p.add_subparsers(dest="batch_command", metavar="ACTION", required=True)
    c = bsub.add_parser(
        "compute",
        help="`haptify compute` for many sessions, each into its own output folder",
        description="Compute every session given, one Dask task each; OUT/<session folder name>/ gets "
        "results.json, or findings.json when the session is refused.",
    )
    c.add_argument("sessions", nargs="+", type=Path, metavar="SESSION")
    c.add_argument("-o", "--out", type=Path, required=True, help="output folder (one sub-folder per session)")
    c.add_argument("--metrics", help="comma-separated metric ids (default: all)")
    c.add_argument("--params", type=Path, metavar="FILE", help="case parameters for every session (as `haptify compute`)")
    add_executor_options(c)
    c.set_defaults(func=run_compute)


def output_folders(sessions: list[Path], out: Path) -> dict[Path, Path]:
    """Each session's output folder ``OUT/<its folder name>``; E903 when two sessions share a name."""
    folders: dict[Path, Path] = {}
    seen: dict[str, Path] = {}
    for session in sessions:
        name = session.resolve().name
        if name in seen:
            raise fail(
                Code.USAGE,
                f"two sessions are named {name!r}; their outputs would share OUT/{name}",
                expected="session folders with different names",
                found=[str(seen[name]), str(session)],
            )
        seen[name] = session
        folders[session] = out / name
    return folders


def compute_one(session: str, folder: str, wanted: list[str] | None, parameters: dict[str, Any]) -> dict:
    """Task: ``haptify compute`` of one session into ``folder`` (results.json or findings.json, atomically)."""
    from haptify.cli.cmd_compute import compute_folder, write_findings
    from haptify.formats.storage import atomic_write_text

    t0 = time.perf_counter()
    target = Path(folder)
    target.mkdir(parents=True, exist_ok=True)
    try:
        results = compute_folder(Path(session), wanted, parameters)
    except HaptifyError as err:
        (target / RESULTS).unlink(missing_ok=True)
        write_findings(target / FINDINGS, err.findings)
        return {
            "session": session,
            "status": "refused",
            "codes": sorted({f.code for f in err.findings}),
            "worker": worker_name(),
            "seconds": time.perf_counter() - t0,
        }
    (target / FINDINGS).unlink(missing_ok=True)
    atomic_write_text(target / RESULTS, results.model_dump_json(indent=2) + "\n")
    return {
        "session": session,
        "status": "computed",
        "metrics": len(results.metrics),
        "unavailable": len(results.unavailable),
        "worker": worker_name(),
        "seconds": time.perf_counter() - t0,
    }


def batch_compute(
    sessions: list[Path],
    out: Path,
    client=None,
    wanted: list[str] | None = None,
    parameters: dict[str, Any] | None = None,
    progress=None,
) -> list[dict]:
    """:func:`compute_one` for every session on ``client``'s cluster (serially when None); one entry per
    session in the order given, a task that failed after its retries as ``status: error``."""
    folders = output_folders(sessions, out)
    jobs = [
        (f"compute-{i}-{folders[s].name}", (str(s.resolve()), str(folders[s].resolve()), wanted, parameters or {}))
        for i, s in enumerate(sessions)
    ]
    done: dict[str, dict] = {}
    for d in each_completed(client, compute_one, jobs):
        done[d.key] = d.value if d.error is None else {"status": "error", "error": f"{type(d.error).__name__}: {d.error}"}
        if progress:
            progress(1)
    return [{**done[key], "session": str(s), "out": str(folders[s])} for (key, _), s in zip(jobs, sessions)]


def run_compute(args, ui) -> int:
    """Run ``haptify batch compute``: exit 0 when every session was computed, 1 when one was refused or failed."""
    from haptify.cli.cmd_compute import _wanted_metrics, case_parameters

    wanted, parameters = _wanted_metrics(args.metrics), case_parameters(args.params)
    output_folders(args.sessions, args.out)
    with (
        dask_client(args.scheduler, args.workers) as client,
        ui.progress("computing sessions", total=len(args.sessions)) as advance,
    ):
        entries = batch_compute(args.sessions, args.out, client, wanted, parameters, advance)
    ui.emit_json({"executor": describe(args.scheduler, args.workers), "sessions": entries})
    for e in entries:
        if e["status"] == "computed":
            ui.say(f"{e['session']}: {e['metrics']} metrics ({e['unavailable']} not computable) → {e['out']}/{RESULTS}")
        elif e["status"] == "refused":
            ui.say(f"{e['session']}: refused ({', '.join(e['codes'])}) → {e['out']}/{FINDINGS}")
        else:
            ui.warn(f"{e['session']}: not computed: {e['error']}")
    counts = {k: sum(e["status"] == k for e in entries) for k in ("computed", "refused", "error")}
    ui.say(
        f"{counts['computed']} computed, {counts['refused']} refused, {counts['error']} failed ({describe(args.scheduler, args.workers)})"
    )
    return 0 if counts["computed"] == len(entries) else 1
