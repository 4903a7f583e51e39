"""Shared builders for the registry tests: sessions, results, conformance reports, bundles, hostile
archives, a registry app on SQLite or a throwaway PostgreSQL server."""

from __future__ import annotations

import contextlib
import gzip
import hashlib
import io
import json
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import pytest

from haptify.formats.storage import open_session
from haptify.pipeline.compute import compute_session
from haptify_conform.cases import load_cases, select
from haptify_conform.judge import Verdict
from haptify_conform.report import ConformReport, build_report, header
from haptify_tools.example_session import write_example
from haptify_tools.registry.bundle import build_bundle, pack

FAST_METRICS = [
    "free_space.speed_mean",
    "free_space.angular_speed_mean",
    "vibration.rms",
    "vibration.spectral_centroid",
    "workspace.spec_box_volume",
]


def _pg_bin() -> Path:
    """The folder of PostgreSQL's initdb and pg_ctl: /usr/local/bin, else Debian's /usr/lib/postgresql/<newest>/bin."""
    candidates = [Path("/usr/local/bin")] + sorted(
        Path("/usr/lib/postgresql").glob("*/bin"),
        key=lambda p: int(p.parent.name) if p.parent.name.isdigit() else 0,
        reverse=True,
    )
    return next((c for c in candidates if (c / "initdb").exists()), candidates[0])


PG_BIN = _pg_bin()


def skip_or_fail(reason: str) -> None:
    """Skip the test with ``reason``; under CI (``CI=true``, as ``.ci/run`` sets) a skip is a failure, so the
    PostgreSQL and browser tests cannot silently not run there."""
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"{reason} — CI=true: this test must run (.ci/run installs what it needs)")
    pytest.skip(reason)


def example_session(
    root: Path,
    lab: str = "lab-example",
    session_id: str = "example-0001",
    manufacturer: str | None = None,
    model: str | None = None,
) -> Path:
    """The analytic example session, optionally re-labelled (lab, id, device) by editing its manifest."""
    path = write_example(root)
    manifest = json.loads((path / "session.json").read_text())
    manifest["lab"]["id"] = lab
    manifest["session_id"] = session_id
    if manufacturer:
        manifest["device"]["manufacturer"] = manufacturer
    if model:
        manifest["device"]["model"] = model
    (path / "session.json").write_text(json.dumps(manifest, indent=2))
    return path


def write_results(session: Path, target: Path, *, metrics=FAST_METRICS, edit=None) -> Path:
    """results.json of the reference for ``session``; ``edit(dict)`` may change it before writing."""
    results = compute_session(open_session(session), metrics=metrics).model_dump(mode="json")
    if edit:
        edit(results)
    target.write_text(json.dumps(results, indent=2))
    return target


def passing_report(target: Path, implementation: dict, *, fail_case: str | None = None, spec_version: str = "1.0") -> Path:
    """A conformance report in which every case of the suite passed (or ``fail_case`` failed)."""
    verdicts = [
        Verdict(
            case_id=c.id,
            metric=c.metric,
            status="failed" if c.id == fail_case else "passed",
            message="",
            level=c.level,
            spec_section=c.spec_section,
            duration_s=0.01,
        )
        for c in select(load_cases(), spec_version="1.0")
    ]
    report = build_report(header("python", implementation, "2026-11-22T12:00:00Z"), verdicts)
    data = report.model_dump(mode="json")
    data["header"]["spec_version"] = spec_version
    ConformReport.model_validate(data)
    target.write_text(json.dumps(data, indent=2))
    return target


def bundle_for(session: Path, results: Path, conformance: Path | None, target: Path, **kw) -> tuple[Path, str]:
    """Pack a bundle; returns (archive, digest)."""
    bundle, files = build_bundle(session, results, conformance, **kw)
    digest = pack(bundle, files, target)
    return target, digest


def tar_gz(members: list[tuple[tarfile.TarInfo, bytes | None]]) -> bytes:
    """A .tar.gz from hand-made members (for hostile archives)."""
    buf = io.BytesIO()
    with (
        gzip.GzipFile(fileobj=buf, mode="wb", mtime=0) as gz,
        tarfile.open(fileobj=gz, mode="w", format=tarfile.PAX_FORMAT) as tar,
    ):
        for info, data in members:
            if data is not None:
                info.size = len(data)
                tar.addfile(info, io.BytesIO(data))
            else:
                tar.addfile(info)
    return buf.getvalue()


def member(name: str, kind: bytes = tarfile.REGTYPE, linkname: str = "") -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.type = kind
    info.linkname = linkname
    return info


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PostgresServer:
    """A throwaway PostgreSQL 15 server in a temporary folder on a loopback port (trust authentication)."""

    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="haptify-pg-"))
        self.port = free_port()
        self.prefix: list[str] = []
        if os.geteuid() == 0:  # initdb refuses to run as root: run the server as the 'postgres' user
            shutil.chown(self.root, "postgres", "postgres")
            self.prefix = ["runuser", "-u", "postgres", "--"]

    def _run(self, *cmd: str) -> None:
        subprocess.run([*self.prefix, *cmd], check=True, capture_output=True, timeout=60)

    def start(self) -> str:
        data = self.root / "data"
        self._run(str(PG_BIN / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres", "--no-sync")
        self._run(
            str(PG_BIN / "pg_ctl"),
            "-D",
            str(data),
            "-l",
            str(self.root / "log"),
            "-w",
            "-o",
            f"-p {self.port} -k {self.root} -c listen_addresses=127.0.0.1 -c fsync=off",
            "start",
        )
        return f"postgresql://postgres@127.0.0.1:{self.port}/postgres"

    def new_database(self, name: str) -> str:
        import psycopg

        with psycopg.connect(f"postgresql://postgres@127.0.0.1:{self.port}/postgres", autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return f"postgresql://postgres@127.0.0.1:{self.port}/{name}"

    def stop(self) -> None:
        try:
            self._run(str(PG_BIN / "pg_ctl"), "-D", str(self.root / "data"), "-m", "immediate", "stop")
        except Exception:
            pass
        shutil.rmtree(self.root, ignore_errors=True)


def postgres_or_skip() -> PostgresServer:
    """Start a PostgreSQL server, or skip the test with the reason (fail under CI)."""
    if not (PG_BIN / "initdb").exists():
        skip_or_fail(f"PostgreSQL not available: no initdb in {PG_BIN}")
    if os.geteuid() == 0 and shutil.which("runuser") is None:
        skip_or_fail("PostgreSQL cannot start: running as root without runuser")
    server = PostgresServer()
    try:
        server.start()
    except (subprocess.SubprocessError, OSError, KeyError, LookupError) as exc:
        server.stop()
        detail = getattr(exc, "stderr", b"") or b""
        skip_or_fail(f"PostgreSQL could not be started: {exc} {detail.decode(errors='replace')[:300]}")
    return server


@pytest.fixture(scope="module")
def pg_server():
    """A throwaway PostgreSQL server for the tests of one module (skipped without one; a failure under CI)."""
    server = postgres_or_skip()
    yield server
    server.stop()


def wait_http(url: str, timeout: float = 20.0, alive: subprocess.Popen | None = None) -> None:
    """Poll ``url`` until it answers 200; with ``alive``, fail at once (with its stderr) if that server process exits."""
    import urllib.request

    deadline = time.monotonic() + timeout
    while True:
        if alive is not None and alive.poll() is not None:
            err = alive.stderr.read().decode(errors="replace") if alive.stderr else ""
            raise RuntimeError(f"the server exited with {alive.returncode} before answering {url}: {err[-2000:]}")
        try:
            with urllib.request.urlopen(url, timeout=1):
                return
        except Exception:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


SERVE = (
    "import argparse, sys; from haptify.cli.main import UI; from haptify_tools.registry import cmd_registry; "
    "p = argparse.ArgumentParser(); cmd_registry.register(p.add_subparsers()); a = p.parse_args(sys.argv[1:]); "
    "sys.exit(a.func(a, UI(quiet=True)))"
)


def start(data: Path, db_url: str | None = None) -> tuple[subprocess.Popen, int]:
    """``haptify registry serve --data DATA [--db URL] --port PORT`` in a subprocess on a fresh port, once it answers.

    Every start takes a new port: a port given back by a killed server may be taken by a parallel test's
    server (another xdist worker) before the restart binds it."""
    port = free_port()
    db = ["--db", db_url] if db_url else []
    proc = subprocess.Popen(
        [sys.executable, "-c", SERVE, "registry", "serve", "--data", str(data), *db, "--port", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        wait_http(f"http://127.0.0.1:{port}/api/v1/health", alive=proc)
    except Exception:
        proc.kill()
        raise
    return proc, port


CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


@contextlib.contextmanager
def browser(profile: Path):
    """A page of the system's headless Chromium driven by Playwright (which downloads nothing: it runs
    ``/usr/bin/chromium``). Skipped without Chromium or Playwright — a failure under CI (:func:`skip_or_fail`)."""
    if not CHROMIUM.exists():
        skip_or_fail(f"browser test skipped: no system Chromium at {CHROMIUM} (install the 'chromium' package)")
    try:
        from playwright import sync_api
    except ImportError:
        skip_or_fail("browser test skipped: the playwright package is not installed")
    with sync_api.sync_playwright() as pw:
        ctx = pw.chromium.launch_persistent_context(
            str(profile), executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_FLAGS, timeout=30_000
        )
        try:
            page = ctx.new_page()
            page.set_default_timeout(15_000)
            yield page
        finally:
            ctx.close()
            shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture(scope="session")
def base(tmp_path_factory):
    root = tmp_path_factory.mktemp("api")
    session = example_session(root / "s-base", lab="lab-a", session_id="base")
    results = write_results(session, root / "results.json")
    impl = json.loads(results.read_text())["implementation"]
    report = passing_report(root / "conformance.json", impl)
    return root, session, results, report, impl


def variant(
    base,
    tmp: Path,
    name: str,
    *,
    lab: str = "lab-a",
    model: str | None = None,
    rms: list[float] | None = None,
    scale: float | None = None,
) -> tuple[Path, Path]:
    """A copy of the base session re-labelled (lab, device model) with results edited to known values.

    The results' manifest_sha256 follows the edited manifest, so the bundle is consistent (no raw streams)."""
    root, session, results, report, impl = base
    target = tmp / name
    shutil.copytree(session, target)
    manifest = json.loads((target / "session.json").read_text())
    manifest["lab"]["id"], manifest["session_id"] = lab, name
    if model:
        manifest["device"]["model"] = model
    (target / "session.json").write_text(json.dumps(manifest, indent=2))
    data = json.loads(results.read_text())
    data["session_id"] = name
    data["manifest_sha256"] = hashlib.sha256((target / "session.json").read_bytes()).hexdigest()
    if model:
        data["device"]["model"] = model
    for m in data["metrics"]:
        if rms is not None and m["id"] == "vibration.rms":
            m["per_repetition"], m["value"], m["n"] = rms, statistics.fmean(rms), len(rms)
            m["sd"] = statistics.stdev(rms) if len(rms) > 1 else None
            m["trials"] = [f"t{i}" for i in range(len(rms))]
        if scale is not None and m["id"] == "vibration.rms":
            m["value"] *= scale
            m["per_repetition"] = [v * scale for v in m["per_repetition"]]
    out = tmp / f"{name}.results.json"
    out.write_text(json.dumps(data))
    return target, out
