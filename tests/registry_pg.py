"""A throwaway PostgreSQL server for the registry tests (issue 9: "tests run against a real PostgreSQL").

``start_postgres()`` runs ``initdb`` into a fresh temporary folder, starts ``postgres`` listening on
127.0.0.1 only (a free port) and on a Unix socket inside that folder, and returns a :class:`PgServer`
whose ``database()`` creates a fresh empty database and returns its SQLAlchemy URL. ``stop()`` shuts
the server down (fast mode) and removes the folder. The pytest fixture ``postgres_server`` (session
scope) wraps it and skips with a clear message when no PostgreSQL binaries are found or the server
cannot start; use it from a test module with ``from registry_pg import postgres_server  # noqa: F401``.

PostgreSQL refuses to run as root: when the tests run as root the server runs as the ``postgres``
system user (or ``nobody``), which then owns the temporary folder.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import pytest

LOOPBACK = "127.0.0.1"
START_TIMEOUT_S = 30


class PostgresUnavailable(RuntimeError):
    """PostgreSQL cannot be started here (no binaries, no unprivileged user, initdb or start failed)."""


def find_binaries() -> Path:
    """The folder holding ``initdb``, ``pg_ctl`` and ``postgres`` (PATH, /usr/local/bin, Debian's layout)."""
    candidates = []
    on_path = shutil.which("initdb")
    if on_path:
        candidates.append(Path(on_path).parent)
    candidates.append(Path("/usr/local/bin"))
    candidates += [Path(p) for p in sorted(glob.glob("/usr/lib/postgresql/*/bin"), reverse=True)]
    for folder in candidates:
        if all((folder / b).is_file() for b in ("initdb", "pg_ctl", "postgres")):
            return folder
    raise PostgresUnavailable("no PostgreSQL server binaries (initdb, pg_ctl, postgres) on PATH, in /usr/local/bin "
                              "or /usr/lib/postgresql/*/bin — install the postgresql package to run these tests")


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((LOOPBACK, 0))
        return s.getsockname()[1]


def _server_user() -> pwd.struct_passwd | None:
    """None when we are not root; else an unprivileged account to run the server as."""
    if os.geteuid() != 0:
        return None
    for name in ("postgres", "nobody"):
        try:
            return pwd.getpwnam(name)
        except KeyError:
            continue
    raise PostgresUnavailable("running as root and there is no 'postgres' or 'nobody' user to run PostgreSQL as")


@dataclass
class PgServer:
    """A running throwaway server: ``folder`` (data, socket, log), ``port`` on 127.0.0.1."""

    folder: Path
    port: int
    bindir: Path
    user: pwd.struct_passwd | None
    superuser: str = "haptify"
    _databases: list[str] = field(default_factory=list)

    def _run(self, *argv: str, timeout: float = START_TIMEOUT_S) -> subprocess.CompletedProcess:
        kwargs = {}
        if self.user is not None:
            kwargs = {"user": self.user.pw_uid, "group": self.user.pw_gid, "extra_groups": []}
        return subprocess.run(argv, capture_output=True, text=True, timeout=timeout, cwd=self.folder, **kwargs)

    def url(self, database: str = "postgres") -> str:
        """SQLAlchemy URL (psycopg 3 driver) of ``database`` over TCP on 127.0.0.1."""
        return f"postgresql+psycopg://{self.superuser}@{LOOPBACK}:{self.port}/{database}"

    def database(self) -> str:
        """Create a fresh empty database and return its SQLAlchemy URL."""
        import psycopg

        name = "t_" + uuid.uuid4().hex[:12]
        with psycopg.connect(host=LOOPBACK, port=self.port, user=self.superuser, dbname="postgres",
                             autocommit=True, connect_timeout=10) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        self._databases.append(name)
        return self.url(name)

    def stop(self) -> None:
        """Stop the server (fast shutdown, bounded) and remove its folder."""
        try:
            self._run(str(self.bindir / "pg_ctl"), "stop", "-D", str(self.folder / "data"), "-m", "fast", "-w",
                      "-t", str(START_TIMEOUT_S), timeout=START_TIMEOUT_S + 5)
        finally:
            shutil.rmtree(self.folder, ignore_errors=True)


def start_postgres() -> PgServer:
    """initdb a fresh cluster in a temporary folder and start it on 127.0.0.1:<free port> (trust auth, fsync off).

    Raises :class:`PostgresUnavailable` with the reason when it cannot.
    """
    bindir = find_binaries()
    user = _server_user()
    folder = Path(tempfile.mkdtemp(prefix="haptify-pg-"))
    if user is not None:
        os.chown(folder, user.pw_uid, user.pw_gid)
    server = PgServer(folder=folder, port=free_port(), bindir=bindir, user=user)
    try:
        init = server._run(str(bindir / "initdb"), "-D", str(folder / "data"), "-A", "trust", "-U", server.superuser,
                           "-E", "UTF8", "--no-sync", "--no-instructions")
        if init.returncode != 0:
            raise PostgresUnavailable(f"initdb failed: {init.stderr.strip()[-500:]}")
        opts = (f"-c listen_addresses={LOOPBACK} -p {server.port} -k {folder} -c fsync=off "
                "-c synchronous_commit=off -c full_page_writes=off -c max_connections=200")
        start = server._run(str(bindir / "pg_ctl"), "start", "-D", str(folder / "data"), "-l", str(folder / "log.txt"),
                            "-w", "-t", str(START_TIMEOUT_S), "-o", opts, timeout=START_TIMEOUT_S + 5)
        if start.returncode != 0:
            log = (folder / "log.txt").read_text(errors="replace")[-800:] if (folder / "log.txt").exists() else ""
            raise PostgresUnavailable(f"pg_ctl start failed: {start.stderr.strip()[-300:]} {log}")
    except (PostgresUnavailable, OSError, subprocess.TimeoutExpired) as exc:
        server.stop()
        if isinstance(exc, PostgresUnavailable):
            raise
        raise PostgresUnavailable(f"PostgreSQL could not start: {exc}") from exc
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:  # pg_ctl -w waited for the socket; also wait until TCP accepts
        try:
            with socket.create_connection((LOOPBACK, server.port), timeout=1):
                break
        except OSError:
            if time.monotonic() > deadline:
                server.stop()
                raise PostgresUnavailable(f"PostgreSQL did not accept TCP connections on {LOOPBACK}:{server.port}")
            time.sleep(0.1)
    return server


@pytest.fixture(scope="session")
def postgres_server():
    """A throwaway PostgreSQL server for the whole test session; skips with the reason when unavailable."""
    try:
        server = start_postgres()
    except PostgresUnavailable as exc:
        pytest.skip(f"PostgreSQL tests skipped: {exc}")
    try:
        yield server
    finally:
        server.stop()
