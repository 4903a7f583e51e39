"""Hostile bundles are contained (spec §17.4, §17.4.1): sparse members are refused before a byte is
written, unpacking and re-computation run in a worker process with memory and time limits, CSV output
cannot carry spreadsheet formulas, every response carries the security headers, and what the registry
stores is readable by its own user only."""

from __future__ import annotations

import csv
import io
import json
import re
import signal
import stat
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import _worker_jobs as jobs
import numpy as np
import pytest
from _registry_fixtures import (  # noqa: F401  (base: fixture)
    base,
    bundle_for,
    member,
    passing_report,
    start,
    tar_gz,
    variant,
    write_results,
)
from fastapi.testclient import TestClient
from hypothesis import given
from hypothesis import strategies as st

from haptify.errors import HaptifyError
from haptify.formats.storage import sha256_file
from haptify.pipeline.compare import Table
from haptify_tools.example_session import example_writer
from haptify_tools.invalid_fixtures import session_edits
from haptify_tools.registry.app import EXPORT_COLUMNS, FORMULA_LEAD, create_app, csv_cell, neutralised
from haptify_tools.registry.bundle import Limits, unpack
from haptify_tools.registry.records import Settings
from haptify_tools.registry.worker import run_contained

NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")  # a signed number is data, not a formula

SPARSE_SIZE = 3_000_000_010  # what the archive claims the member expands to


def sparse_archive() -> bytes:
    """A 0.2 KB archive whose one member is a PAX sparse file of 3 GB: 10 data bytes after a 3 GB hole."""
    info = member("session/big.csv")
    info.pax_headers = {
        "GNU.sparse.map": f"{SPARSE_SIZE - 10},10",
        "GNU.sparse.size": str(SPARSE_SIZE),
        "GNU.sparse.numblocks": "1",
    }
    return tar_gz([(info, b"0123456789")])


def post(client, data: bytes, token: str):
    return client.post(
        "/api/v1/submissions", content=data, headers={"Authorization": f"Bearer {token}", "Content-Type": "application/gzip"}
    )


# --- sparse members ------------------------------------------------------------------------------


def test_a_sparse_member_is_refused_before_anything_is_written(tmp_path):
    archive = tmp_path / "sparse.tar.gz"
    archive.write_bytes(sparse_archive())
    assert archive.stat().st_size < 1024
    with pytest.raises(HaptifyError) as err:
        unpack(archive, tmp_path / "out")
    assert err.value.findings[0].code == "E962" and err.value.findings[0].found == "sparse file"
    written = sum(p.stat().st_size for p in (tmp_path / "out").rglob("*") if p.is_file())
    assert written == 0


# --- the worker process ----------------------------------------------------------------------------
WORKER = Limits(worker_memory_bytes=1536 << 20, worker_seconds=5.0)


def test_the_worker_returns_the_value_and_passes_coded_refusals_through():
    assert run_contained(jobs.allocate, 8 * 1000, limits=WORKER) == 1000.0
    with pytest.raises(HaptifyError) as err:
        run_contained(jobs.refuse, limits=WORKER)
    f = err.value.findings[0]
    assert (f.code, f.message, f.file, f.expected, f.found) == ("E962", "a coded refusal from the worker", "x", "y", "z")


@pytest.mark.parametrize(
    "fn, args, found",
    [
        (jobs.allocate, (4 << 30,), "MemoryError"),  # 4 GiB in one array, over the worker's 1.5 GiB address space
        (jobs.sleep, (30.0,), "time limit"),
        (jobs.kill_self, (), "SIGKILL"),
    ],
)
def test_a_worker_over_its_limits_fails_alone_with_E976(fn, args, found):
    t0 = time.monotonic()
    with pytest.raises(HaptifyError) as err:
        run_contained(fn, *args, limits=WORKER)
    assert err.value.findings[0].code == "E976" and err.value.findings[0].found == found
    assert time.monotonic() - t0 < WORKER.worker_seconds + 10
    assert run_contained(jobs.allocate, 8 * 10, limits=WORKER) == 10.0  # the next job runs as before


@pytest.mark.parametrize(
    "limits, codes, says",
    [
        # No time at all: the worker cannot even unpack, and is killed.
        (Limits(worker_seconds=0.001), ["E976"], "took longer than"),
        # An address space below what the worker already maps: the first new mapping (Arrow's, reading the
        # streams) fails, and the validator reports the stream as too large to check (E112, spec §4.6).
        (Limits(worker_memory_bytes=1 << 20), ["E966", "E112"], "MemoryError"),
    ],
)
def test_a_bundle_the_worker_cannot_check_within_its_limits_fails_alone(base, tmp_path, limits, codes, says, caplog):
    import logging

    root, session, results, report, impl = base
    archive, _ = bundle_for(session, results, report, tmp_path / "raw.tar.gz", include_raw=True)
    app = create_app(Settings(data_dir=tmp_path / "data", limits=limits))
    token = app.state.registry.create_token("lab-a")
    with TestClient(app) as client, caplog.at_level(logging.WARNING, logger="haptify.registry"):
        r = post(client, archive.read_bytes(), token)
        assert any("POST /api/v1/submissions" in m.getMessage() and codes[0] in m.getMessage() for m in caplog.records)
        found = [f["code"] for f in r.json()["findings"]]
        assert r.status_code == 422 and found[: len(codes)] == codes and says in json.dumps(r.json()), r.json()
        assert client.get("/api/v1/health").status_code == 200
        assert client.get("/api/v1/submissions").json() == []
        assert list((tmp_path / "data" / "tmp").iterdir()) == []


# --- the Done-when: hostile bundles against a live server -------------------------------------------

NUL_MIB = 64


def nul_csv_bundle(base, tmp_path: Path) -> Path:
    """A consistent bundle with raw CSV streams whose handle pose is 64 MiB of NUL bytes (manifest rows and
    sha256 follow it; the results' manifest_sha256 follows the manifest), plus 1 MiB of random bytes so
    that the archive's expansion stays under the 100× bomb limit and the CSV reaches the re-computation."""
    root, session, results, report, impl = base
    folder = example_writer(duration_s=0.5, fmt="csv").write(tmp_path / "nul")
    manifest = session_edits.manifest(folder)
    manifest["lab"]["id"], manifest["session_id"] = "lab-a", "nul-csv"
    session_edits.save_manifest(folder, manifest)
    res = write_results(folder, tmp_path / "nul-results.json", metrics=["free_space.speed_mean"])
    stream = session_edits.stream_of(manifest, "handle_pose")
    with open(folder / stream["file"], "wb") as fh:
        for _ in range(NUL_MIB):
            fh.write(b"\0" * 2**20)
    stream.update(rows=NUL_MIB * 2**20 // (32 * len(stream["columns"])), sha256=sha256_file(folder / stream["file"]))
    session_edits.save_manifest(folder, manifest)
    (folder / "noise.bin").write_bytes(np.random.default_rng(7).bytes(1 << 20))
    data = json.loads(res.read_text())
    data["manifest_sha256"] = sha256_file(folder / "session.json")
    res.write_text(json.dumps(data))
    rep = passing_report(tmp_path / "nul-conformance.json", data["implementation"])
    archive, _ = bundle_for(folder, res, rep, tmp_path / "nul.tar.gz", include_raw=True)
    return archive


def _http(url: str, data: bytes | None = None, token: str | None = None) -> tuple[int, dict]:
    headers = {"Content-Type": "application/gzip"} if data is not None else {}
    if token:
        headers["Authorization"] = f"Bearer {token}"
    req = urllib.request.Request(url, data=data, headers=headers, method="POST" if data is not None else "GET")
    try:
        with urllib.request.urlopen(req, timeout=300) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def _peak_rss_bytes(pid: int) -> int:
    with open(f"/proc/{pid}/status") as fh:
        return next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmHWM:"))


def test_the_sparse_and_the_nul_csv_bundles_are_refused_while_the_server_stays_small_and_serves(base, tmp_path):
    from haptify_tools.registry.service import Registry

    nul = nul_csv_bundle(base, tmp_path).read_bytes()
    data = tmp_path / "data"
    reg = Registry(Settings(data_dir=data))
    token = reg.create_token("lab-a")
    reg.close()
    proc, port = start(data)
    url = f"http://127.0.0.1:{port}/api/v1"
    health: list[int] = []
    stop = threading.Event()

    def poll() -> None:
        while not stop.is_set():
            health.append(_http(f"{url}/health")[0])
            time.sleep(0.05)

    poller = threading.Thread(target=poll)
    poller.start()
    try:
        sparse_status, sparse_body = _http(f"{url}/submissions", sparse_archive(), token)
        nul_status, nul_body = _http(f"{url}/submissions", nul, token)
    finally:
        stop.set()
        poller.join()
        peak = _peak_rss_bytes(proc.pid)
        proc.send_signal(signal.SIGINT)
        proc.wait(30)
    assert sparse_status == 422 and sparse_body["findings"][0]["code"] == "E962"
    codes = [f["code"] for f in nul_body["findings"]]
    assert nul_status == 422 and codes[0] == "E966" and ("E211" in codes or "E112" in codes), nul_body
    assert peak < 1 << 30, f"server peak RSS {peak / 2**20:.0f} MiB"
    assert len(health) >= 3 and set(health) == {200}
    assert not any((data / "tmp").iterdir())


# --- CSV formula neutralisation -----------------------------------------------------------------------


@given(st.text(max_size=40))
def test_no_csv_cell_starts_a_formula_unless_it_is_a_number(text):
    cell = csv_cell(text)
    if cell.startswith(FORMULA_LEAD):
        float(cell)  # only a number may start with '-' or '+'
        assert cell == text
    elif text.startswith(FORMULA_LEAD):
        assert cell == "'" + text


@pytest.mark.parametrize("number", ["-1.5", "+2", "-0.0001e-3", "-inf"])
def test_numbers_stay_numbers(number):
    assert csv_cell(number) == number and csv_cell(-1.5) == -1.5


def test_export_and_compare_csv_carry_no_formula(base, tmp_path):
    evil = '=HYPERLINK("http://x","y")'
    session, results = variant(base, tmp_path, "evil", model=evil)
    archive, _ = bundle_for(session, results, base[3], tmp_path / "evil.tar.gz")
    app = create_app(Settings(data_dir=tmp_path / "data"))
    token = app.state.registry.create_token("lab-a")
    with TestClient(app) as client:
        assert post(client, archive.read_bytes(), token).status_code == 201
        slug = client.get("/api/v1/devices").json()[0]["slug"]
        export = list(csv.reader(io.StringIO(client.get("/api/v1/export.csv").text)))
        table = list(csv.reader(io.StringIO(client.get(f"/api/v1/compare?devices={slug}&format=csv").text)))
    cells = [c for row in export + table for c in row]
    assert export[1][EXPORT_COLUMNS.index("model")] == "'" + evil and len(table) > 1
    assert not [c for c in cells if c.startswith(FORMULA_LEAD) and not NUMBER.fullmatch(c)]


def test_a_comparison_table_is_neutralised_cell_by_cell():
    table = Table(["Metric", "@SUM(A1)"], [["+cmd|' /C calc'!A0", "-1.5", "-1.5 ± 0.2"]], [])
    assert neutralised(table) == Table(["Metric", "'@SUM(A1)"], [["'+cmd|' /C calc'!A0", "-1.5", "'-1.5 ± 0.2"]], [])


# --- headers and file modes -------------------------------------------------------------------------


def test_every_response_carries_the_security_headers(base, tmp_path):
    app = create_app(Settings(data_dir=tmp_path / "data"))
    with TestClient(app) as client:
        for path in [
            "/",
            "/api/v1/health",
            "/api/v1/devices",
            "/api/v1/submissions/nothere",
            "/no/such/page",
            "/openapi.json",
            "/docs",
            "/api/v1/export.csv",
        ]:
            h = client.get(path).headers
            csp = h["content-security-policy"]
            assert "frame-ancestors 'none'" in csp and "default-src 'none'" in csp, path
            assert h["x-content-type-options"] == "nosniff" and h["referrer-policy"] == "no-referrer", path
        assert "script-src" not in client.get("/").headers["content-security-policy"]  # the pages run no script
    app.state.registry.close()


def assert_secured(response) -> None:
    h = response.headers
    assert "frame-ancestors 'none'" in h["content-security-policy"] and "default-src 'none'" in h["content-security-policy"]
    assert h["x-content-type-options"] == "nosniff" and h["referrer-policy"] == "no-referrer"


def test_error_responses_and_a_forced_500_carry_the_security_headers(tmp_path, monkeypatch, caplog):
    """4xx of every kind (coded refusal, unknown route, wrong method, invalid query) and the 500 of an
    unhandled exception carry the headers; the 500 is the coded E999 body and is logged with its code."""
    import logging

    app = create_app(Settings(data_dir=tmp_path / "data"))

    def broken() -> list:
        raise RuntimeError("forced failure")

    monkeypatch.setattr(app.state.registry, "labs", broken)
    with TestClient(app, raise_server_exceptions=False) as client, caplog.at_level(logging.WARNING, logger="haptify.registry"):
        for method, path, status in [
            ("POST", "/api/v1/submissions", 401),
            ("GET", "/no/such/page", 404),
            ("DELETE", "/api/v1/health", 405),
            ("GET", "/api/v1/submissions?limit=0", 400),
            ("GET", "/api/v1/submissions/nothere", 404),
        ]:
            r = client.request(method, path)
            assert r.status_code == status, (path, r.status_code)
            assert_secured(r)
        crashed = client.get("/api/v1/labs")
        assert crashed.status_code == 500 and crashed.json()["findings"][0]["code"] == "E999"
        assert_secured(crashed)
    app.state.registry.close()
    assert any("GET /api/v1/labs" in r.getMessage() and "E999" in r.getMessage() and r.exc_info for r in caplog.records)


def test_the_database_and_the_archives_are_the_service_users_only(base, tmp_path):
    root, session, results, report, impl = base
    archive, digest = bundle_for(session, results, report, tmp_path / "b.tar.gz")
    data = tmp_path / "data"
    app = create_app(Settings(data_dir=data))
    token = app.state.registry.create_token("lab-a")
    with TestClient(app) as client:
        assert post(client, archive.read_bytes(), token).status_code == 201
        stored = data / "bundles" / digest[:2] / f"{digest}.tar.gz"
        files = [data / "registry.sqlite3", stored] + [p for p in data.glob("registry.sqlite3-*")]
        assert len(files) >= 3  # the WAL files exist while the database is open
        for p in files:
            assert stat.S_IMODE(p.stat().st_mode) == 0o600, p
        for d in [data, data / "bundles", stored.parent, data / "tmp"]:
            assert stat.S_IMODE(d.stat().st_mode) == 0o700, d


def test_every_refusal_is_logged_with_its_code(tmp_path, caplog):
    """Each kind of refusal — a coded one, the framework's (validation, unknown route, wrong method), a size
    refusal before reading, an upload's, a challenge's, a page's and a hostile bundle refused by the worker —
    leaves one WARNING line with its method, path and code."""
    import logging

    app = create_app(Settings(data_dir=tmp_path / "data"))
    token = app.state.registry.create_token("lab-a")
    h = {"Authorization": f"Bearer {token}", "Content-Type": "application/gzip"}
    limit = app.state.registry.settings.limits.max_archive_bytes
    expected = [
        (("POST", "/api/v1/submissions", {"content": b"x", "headers": {"Content-Type": "application/gzip"}}), "E970"),
        (("GET", "/api/v1/submissions/nothere", {}), "E973"),
        (("GET", "/devices/nothere", {}), "E973"),
        (("GET", "/api/v1/submissions?limit=0", {}), "E975"),
        (("GET", "/no/such/route/at/all", {}), "E973"),
        (("DELETE", "/api/v1/health", {}), "E975"),
        (("POST", "/api/v1/submissions", {"content": b"x", "headers": {**h, "Content-Length": str(limit + 1)}}), "E960"),
        (("GET", "/api/v1/uploads/0123456789abcdef01234567", {"headers": h}), "E973"),
        (("POST", "/api/v1/uploads", {"headers": {**h, "Upload-Length": str(limit + 1)}}), "E960"),
        (("GET", "/api/v1/challenges/nothere", {}), "E973"),
        (("POST", "/api/v1/submissions", {"content": sparse_archive(), "headers": h}), "E962"),  # refused in the worker
    ]
    with TestClient(app) as client, caplog.at_level(logging.WARNING, logger="haptify.registry"):
        for (method, path, kwargs), code in expected:
            caplog.clear()
            response = client.request(method, path, **kwargs)
            assert response.status_code >= 400, path
            lines = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
            assert any(f"{method} {path.split('?')[0]}" in m and code in m for m in lines), (method, path, code, lines)
    app.state.registry.close()
