"""``haptify view``: inspect a session, its results and a simulated counterpart in rerun (design §1).

``--save out.rrd`` writes a recording without any display; ``--web`` serves rerun's built-in web
viewer on 127.0.0.1 only (the ``rerun`` CLI with ``--bind 127.0.0.1``; rerun's Python serve
functions would listen on every interface); with neither, the native viewer is started when a
display exists, and otherwise the command says how to use ``--save`` or ``--web``.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.storage import MANIFEST
from haptify.pipeline.gate import CheckedSession, open_checked_session
from haptify.pipeline.results import load_results
from haptify_tools.viewer.plan import DEFAULT_DERIVED, DERIVED_MODES
from haptify_tools.viewer.save import build

LOOPBACK = "127.0.0.1"
DEFAULT_WEB_PORT = 9090  # rerun's own default web-viewer port
SERVE_TIMEOUT_S = 20.0  # how long to wait for the web viewer to answer
STOP_TIMEOUT_S = 5.0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``view`` sub-command (entry point ``view = "haptify_tools.viewer.cmd_view:register"``)."""
    p = subparsers.add_parser(
        "view",
        help="inspect a session in 3-D and in time (rerun viewer)",
        description="Show a session, its results and optionally a simulated counterpart in the rerun viewer.",
    )
    p.add_argument("session", metavar="SESSION", help="session folder (or a 'haptify simulate' output folder)")
    p.add_argument("--trial", metavar="ID", help="show only this trial")
    p.add_argument("--results", metavar="RESULTS", help="results.json whose metrics are shown as a table")
    p.add_argument(
        "--compare",
        metavar="OTHER",
        help="a second session (e.g. simulated, or a 'haptify simulate' output folder) overlaid on the first",
    )
    p.add_argument("--save", metavar="OUT.rrd", help="write the recording to this .rrd file (no display needed)")
    p.add_argument(
        "--derived",
        choices=DERIVED_MODES,
        default=DEFAULT_DERIVED,
        help="derived signals (calibrated hand force, plate force/COP, DFT321, contact, force arrows, workspace "
        "meshes): off = raw streams only (default), compact = float32 at most 100 Hz, full = every sample",
    )
    p.add_argument("--web", action="store_true", help=f"serve rerun's web viewer on {LOOPBACK} only")
    p.add_argument("--port", type=int, metavar="N", help=f"HTTP port of the web viewer (with --web; default {DEFAULT_WEB_PORT})")
    p.set_defaults(func=run)


def display_available() -> bool:
    """True when a native window can open: macOS/Windows, or DISPLAY / WAYLAND_DISPLAY set."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def rerun_command(*args: str) -> list[str]:
    """The rerun CLI of this Python environment (``python -m rerun``) with ``args``."""
    return [sys.executable, "-m", "rerun", *args]


def free_port() -> int:
    """A currently free TCP port on the loopback interface."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((LOOPBACK, 0))
        return int(s.getsockname()[1])


def web_url(web_port: int, grpc_port: int) -> str:
    """The address that opens the web viewer connected to the served recording."""
    proxy = f"rerun+http://{LOOPBACK}:{grpc_port}/proxy"
    return f"http://{LOOPBACK}:{web_port}/?url={urllib.parse.quote(proxy, safe='')}"


def _interrupt(signum: int, frame: object) -> None:
    """SIGTERM while serving: leave as Ctrl-C does, so the viewer process group is stopped, never orphaned."""
    raise KeyboardInterrupt


def _signal_group(pid: int, sig: int) -> bool:
    """Send ``sig`` to the process group ``pid`` (a viewer started here); False when the group is gone."""
    try:
        os.killpg(pid, sig)
        return True
    except (ProcessLookupError, PermissionError):
        return False


@dataclass
class WebViewer:
    """A rerun web viewer serving one .rrd on 127.0.0.1, started by :func:`serve_web`."""

    proc: subprocess.Popen
    url: str
    web_port: int
    log: IO[bytes]  # the viewer's stderr (a file, so a long session can never block on a full pipe)

    def log_tail(self, limit: int = 400) -> str:
        self.log.seek(0)
        return self.log.read().decode(errors="replace").strip()[-limit:]

    def wait_until_serving(self, timeout_s: float = SERVE_TIMEOUT_S) -> None:
        """Poll the HTTP root until it answers 200; E904 (after stopping) when it dies or time runs out."""
        deadline = time.monotonic() + timeout_s
        root = f"http://{LOOPBACK}:{self.web_port}/"
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                code, tail = self.proc.returncode, self.log_tail()
                self.stop()
                raise fail(
                    Code.VIEWER_UNAVAILABLE,
                    f"the rerun web viewer exited with code {code}: {tail}",
                    expected=f"a web viewer on {root}",
                    found=f"exit code {code}",
                )
            try:
                with urllib.request.urlopen(root, timeout=1.0) as resp:
                    if resp.status == 200:
                        return
            except (urllib.error.URLError, ConnectionError, TimeoutError):
                pass
            time.sleep(0.1)
        self.stop()
        raise fail(
            Code.VIEWER_UNAVAILABLE,
            f"the rerun web viewer did not answer on {root} within {timeout_s:g} s",
            expected=f"HTTP 200 from {root}",
            found="no answer",
        )

    def stop(self) -> None:
        """Stop the ``python -m rerun`` wrapper AND the rerun binary it runs.

        The viewer runs in its own session (process group): the group gets SIGTERM, then SIGKILL after
        a grace period. On Windows the wrapper is terminated.
        """
        if os.name != "posix":
            if self.proc.poll() is None:
                self.proc.terminate()
        else:
            _signal_group(self.proc.pid, signal.SIGTERM)
            deadline = time.monotonic() + STOP_TIMEOUT_S
            while _signal_group(self.proc.pid, 0) and time.monotonic() < deadline:
                self.proc.poll()  # reap the wrapper so the group can disappear
                time.sleep(0.05)
            _signal_group(self.proc.pid, signal.SIGKILL)
        self.proc.wait(timeout=STOP_TIMEOUT_S)
        self.log.close()


def serve_web(rrd: str | os.PathLike, web_port: int, grpc_port: int | None = None) -> WebViewer:
    """Start the rerun CLI serving ``rrd`` to its built-in web viewer, listening on 127.0.0.1 only."""
    grpc_port = grpc_port or free_port()
    log = tempfile.TemporaryFile()
    proc = subprocess.Popen(
        rerun_command(str(rrd), "--serve-web", "--bind", LOOPBACK, "--web-viewer-port", str(web_port), "--port", str(grpc_port)),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=log,
        start_new_session=True,
    )
    return WebViewer(proc, web_url(web_port, grpc_port), web_port, log)


def open_session_or_dossier(path: str) -> CheckedSession:
    """Open a session folder, or the ``session/`` inside a folder written by ``haptify simulate``, through the
    validation gate (spec §4.8): each stream is validated as the recording reads it (one read), and
    :meth:`CheckedSession.finish` runs before the recording is renamed into place, so an invalid session
    is refused before anything is drawn or saved."""
    root = Path(path)
    if not (root / MANIFEST).is_file() and (root / "session" / MANIFEST).is_file():
        root = root / "session"
    return open_checked_session(root)


def run(args: argparse.Namespace, ui) -> int:
    """Build the recording, then save, serve or show it."""
    if args.port is not None and not args.web:
        raise fail(Code.USAGE, "--port is only meaningful with --web", expected="--web --port N", found=f"--port {args.port}")
    if args.port is not None and not 0 < args.port < 65536:
        raise fail(Code.USAGE, f"--port {args.port} is not a TCP port", expected="1..65535", found=args.port)
    if not (args.save or args.web or display_available()):
        ui.warn(
            "No display here (neither DISPLAY nor WAYLAND_DISPLAY is set), so the native viewer cannot open.\n"
            f"  haptify view {args.session} --save out.rrd     writes a recording to open elsewhere (rerun out.rrd)\n"
            f"  haptify view {args.session} --web [--port N]   serves the web viewer on http://{LOOPBACK}:N"
        )
        ui.emit_json({"ok": False, "reason": "no display; use --save or --web"})
        return 2
    session = open_session_or_dossier(args.session)
    other = open_session_or_dossier(args.compare) if args.compare else None
    results = load_results(args.results) if args.results else None
    with tempfile.TemporaryDirectory(prefix="haptify-view-") as tmp:
        out = Path(args.save) if args.save else Path(tmp) / f"{session.session_id}.rrd"
        try:
            plan = build(
                session,
                out,
                trial_id=args.trial,
                results=results,
                other=other,
                derived=args.derived,
                before_commit=lambda: [s.finish() for s in (session, other) if s is not None],
            )
        except OSError as exc:
            raise fail(Code.OUTPUT_NOT_WRITABLE, f"cannot write {str(out)!r}: {exc.strerror or exc}", file=str(out)) from None
        summary = {
            "ok": True,
            "rrd": str(out) if args.save else None,
            "trials": [tp.trial.id for tp in plan.trials],
            "entities": len(plan.entries),
            "rows": sum(e.rows for e in plan.entries),
        }
        if args.save:
            ui.say(f"wrote {out} ({len(plan.trials)} trial(s), {summary['entities']} entities); open it with: rerun {out}")
        if args.web:
            port = args.port or DEFAULT_WEB_PORT
            viewer = serve_web(out, port)
            previous = signal.signal(signal.SIGTERM, _interrupt)  # `kill` stops the viewer as Ctrl-C does
            interrupted = False
            try:
                viewer.wait_until_serving()
                summary["url"] = viewer.url
                ui.emit_json(summary)
                ui.say(f"web viewer: {viewer.url}\n(serving on {LOOPBACK} only; Ctrl-C stops it)")
                viewer.proc.wait()
            except KeyboardInterrupt:
                interrupted = True
            finally:  # the viewer is stopped before anything else is written (an output that blocks cannot orphan it)
                signal.signal(signal.SIGTERM, previous)
                viewer.stop()
            if interrupted:
                ui.say("stopped the web viewer")
            return 0
        if args.save:
            ui.emit_json(summary)
            return 0
        ui.say(f"opening the rerun viewer on {session.session_id} …")
        ui.emit_json(summary)
        return subprocess.call(rerun_command(str(out)))
