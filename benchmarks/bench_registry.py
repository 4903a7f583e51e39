"""Registry load test (issue 9): 200 concurrent submissions and 10 000 reads against the SQLite default.

The registry runs as ``haptify_tools.registry.app.create_app`` under uvicorn in a subprocess on
127.0.0.1 (a port the OS picks; loopback only), with its embedded default database (SQLite in a fresh
data folder). The script

1. packs 200 distinct valid bundles (the example session re-labelled per bundle: 4 labs, 5 device
   models, results with distinct values; one passing conformance report) with the core's packer;
2. uploads all 200 at once from 200 threads (``haptify submit``'s ``post_bundle``), then re-sends
   20 of them at once (they must come back as duplicates with the same id);
3. checks that no record was lost or duplicated: the API lists exactly the 200 expected ids, the
   database holds 200 submission rows with 200 distinct digests, and the data folder holds 200
   archives and no temporary file;
4. makes 10 000 reads from 4 client threads (keep-alive connections), a fixed mix of the JSON API and the web
   pages, and reports p50/p99 latency and the submission rate.

Everything is bounded: the server must start within 60 s, each phase has a deadline, and the server
is stopped (SIGTERM, then SIGKILL after 20 s) in every case. Exit status 1 when a check fails.
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the registry tests' bundle builders (example session, passing report)

from _registry_fixtures import example_session, passing_report  # noqa: E402

from haptify.metrics.metric_definitions import family  # noqa: E402
from haptify.pipeline.results import DeviceSummary, Implementation, MetricResult, ResultsFile  # noqa: E402
from haptify.formats.storage import sha256_file  # noqa: E402
from haptify.versions import PACKAGE_VERSION  # noqa: E402
from haptify.formats.bundle_format import submission_id  # noqa: E402
from haptify_tools.registry.bundle import build_bundle, pack  # noqa: E402
from haptify_tools.registry.cmd_submit import post_bundle  # noqa: E402

LOOPBACK = "127.0.0.1"
N_SUBMISSIONS = 200
N_DUPLICATES = 20
N_READS = 10_000
READ_THREADS = 4
TARGET_P99_MS = 50.0
LABS = ["lab-a", "lab-b", "lab-c", "lab-d"]
MODELS = [
    ("3D Systems", "Touch"),
    ("3D Systems", "Touch X"),
    ("Novint", "Falcon"),
    ("Force Dimension", "omega.6"),
    ("Haption", "Virtuose 6D"),
]
SERVER = """
import sys, uvicorn
from pathlib import Path
from haptify_tools.registry.app import create_app
from haptify_tools.registry.service import Settings
app = create_app(Settings(data_dir=Path(sys.argv[1])))
config = uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning", access_log=False)
server = uvicorn.Server(config)
import threading, time
def announce():
    while not server.started:
        time.sleep(0.02)
    print(server.servers[0].sockets[0].getsockname()[1], flush=True)
threading.Thread(target=announce, daemon=True).start()
server.run()
"""


def make_bundles(root: Path, n: int) -> list[tuple[str, Path, str]]:
    """``n`` distinct bundles ``(lab, archive, submission id)`` from one re-labelled example session."""
    impl = Implementation(name="haptify-reference", version=PACKAGE_VERSION)
    root.mkdir(parents=True, exist_ok=True)
    report = passing_report(root / "conformance.json", impl.model_dump())
    versions = {f: family(f).version for f in ("vibration", "workspace", "free_space")}
    out = []
    for i in range(n):
        lab = LABS[i % len(LABS)]
        manufacturer, model = MODELS[i % len(MODELS)]
        session = example_session(
            root / f"s{i:03d}", lab=lab, session_id=f"bench-{i:03d}", manufacturer=manufacturer, model=model
        )
        reps = [0.03 + 0.01 * (i % len(MODELS)) + 1e-5 * i, 0.031 + 0.01 * (i % len(MODELS)) + 1e-5 * i]
        results = ResultsFile(
            implementation=impl,
            session_id=f"bench-{i:03d}",
            device=DeviceSummary(manufacturer=manufacturer, model=model),
            manifest_sha256=sha256_file(session / "session.json"),
            metrics=[
                MetricResult(
                    id="vibration.rms",
                    value=statistics.fmean(reps),
                    per_repetition=reps,
                    n=2,
                    sd=statistics.stdev(reps),
                    unit="m/s^2",
                    definition_version=versions["vibration"],
                ),
                MetricResult(
                    id="workspace.measured_volume",
                    value=0.01 + 1e-6 * i,
                    unit="m^3",
                    n=1,
                    definition_version=versions["workspace"],
                ),
                MetricResult(
                    id="free_space.force_mean", value=0.5 + 0.001 * i, unit="N", n=1, definition_version=versions["free_space"]
                ),
            ],
        )
        (root / f"r{i:03d}.json").write_text(results.model_dump_json())
        bundle, files = build_bundle(session, root / f"r{i:03d}.json", report)
        digest = pack(bundle, files, root / f"b{i:03d}.tar.gz")
        out.append((lab, root / f"b{i:03d}.tar.gz", submission_id(digest)))
    return out


def start_server(data: Path) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(
        [sys.executable, "-c", SERVER, str(data)], stdout=subprocess.PIPE, text=True, cwd=REPO, start_new_session=True
    )
    port_line: list[str] = []
    reader = threading.Thread(target=lambda: port_line.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(60)
    if not port_line or not port_line[0].strip().isdigit():
        stop_server(proc)
        raise SystemExit("the registry did not start within 60 s")
    return proc, f"http://{LOOPBACK}:{int(port_line[0])}"


def stop_server(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)


def submit_all(
    base: str, tokens: dict[str, str], bundles: list[tuple[str, Path, str]], deadline_s: float
) -> tuple[list[dict], float]:
    """Upload every bundle at once (one thread each, released together); returns outcomes and wall time."""
    barrier = threading.Barrier(len(bundles))

    def one(item):
        lab, archive, _ = item
        barrier.wait(timeout=deadline_s)
        return post_bundle(base, tokens[lab], archive)

    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=len(bundles)) as pool:
        outcomes = list(pool.map(one, bundles, timeout=deadline_s))
    return outcomes, time.perf_counter() - t0


READ_KINDS = [
    "GET /api/v1/devices/{slug}",
    "GET /api/v1/submissions/{id}",
    "GET /api/v1/leaderboard/{metric}",
    "page /devices/{slug}",
    "page /leaderboard/{metric}",
    "page /compare (2 devices)",
    "GET /api/v1/devices",
    "page / (index)",
]


def read_paths(ids: list[str], n: int) -> list[tuple[str, str]]:
    """The read mix ``(kind, path)``: the JSON API and the pages in turn, cycling over devices and submissions."""
    slugs = ["3d-systems-touch", "3d-systems-touch-x", "novint-falcon", "force-dimension-omega-6", "haption-virtuose-6d"]
    paths = []
    for i in range(n):
        slug, sid = slugs[i % len(slugs)], ids[i % len(ids)]
        paths.append(
            (
                READ_KINDS[i % 8],
                [
                    f"/api/v1/devices/{slug}",
                    f"/api/v1/submissions/{sid}",
                    "/api/v1/leaderboard/vibration.rms",
                    f"/devices/{slug}",
                    "/leaderboard/vibration.rms",
                    f"/compare?device={slug}&device=3d-systems-touch",
                    "/api/v1/devices",
                    "/",
                ][i % 8],
            )
        )
    return paths


def read_all(base: str, paths: list[tuple[str, str]], deadline_s: float, n_threads: int):
    """Every read from ``n_threads`` clients (one keep-alive ``http.client`` connection each, the lightest client);
    returns (latencies in s, latencies by kind, wall time)."""
    import http.client
    from urllib.parse import urlsplit

    host, port = urlsplit(base).hostname, urlsplit(base).port
    latencies: list[float] = [0.0] * len(paths)
    errors: list[str] = []
    t_end = time.monotonic() + deadline_s

    def worker(k: int) -> None:
        conn = http.client.HTTPConnection(host, port, timeout=30)
        try:
            for j in range(k, len(paths), n_threads):
                if time.monotonic() > t_end:
                    errors.append("deadline")
                    return
                t0 = time.perf_counter()
                conn.request("GET", paths[j][1])
                response = conn.getresponse()
                response_body = response.read()
                latencies[j] = time.perf_counter() - t0
                if response.status != 200 or not response_body:
                    errors.append(f"{paths[j][1]} → {response.status}")
        finally:
            conn.close()

    t0 = time.perf_counter()
    threads = [threading.Thread(target=worker, args=(k,)) for k in range(n_threads)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    wall = time.perf_counter() - t0
    if errors:
        raise SystemExit(f"{len(errors)} read(s) failed, e.g. {errors[:3]}")
    by_kind: dict[str, list[float]] = {}
    for (kind, _), lat in zip(paths, latencies):
        by_kind.setdefault(kind, []).append(lat)
    return latencies, by_kind, wall


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (Linux /proc), in seconds."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100 * (len(ordered) - 1))))] * 1000


def check_records(data: Path, expected: set[str], api: list[dict]) -> list[str]:
    """No lost or duplicated record: API list, database rows and archives all match the expected ids."""
    import sqlalchemy as sa

    problems = []
    listed = [s["id"] for s in api]
    if sorted(listed) != sorted(expected):
        problems.append(f"API lists {len(listed)} ids ({len(set(listed))} distinct), expected {len(expected)}")
    engine = sa.create_engine(f"sqlite:///{data / 'registry.sqlite3'}")
    with engine.connect() as conn:
        rows, digests = conn.execute(sa.text("SELECT count(*), count(DISTINCT digest) FROM submissions")).one()
        ids = {r[0] for r in conn.execute(sa.text("SELECT id FROM submissions"))}
    engine.dispose()
    if rows != len(expected) or digests != len(expected) or ids != expected:
        problems.append(f"database: {rows} rows, {digests} distinct digests, ids match: {ids == expected}")
    archives = [p for p in (data / "bundles").rglob("*") if p.is_file()] if (data / "bundles").exists() else []
    if len(archives) != len(expected):
        problems.append(f"data folder: {len(archives)} archives, expected {len(expected)}")
    leftovers = [p for p in (data / "tmp").rglob("*") if p.is_file()] if (data / "tmp").exists() else []
    if leftovers:
        problems.append(f"{len(leftovers)} temporary file(s) left: {leftovers[:3]}")
    return problems


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--submissions", type=int, default=N_SUBMISSIONS)
    ap.add_argument("--reads", type=int, default=N_READS)
    ap.add_argument("--threads", type=int, default=READ_THREADS, help="concurrent reading clients")
    args = ap.parse_args()
    from haptify_tools.registry.service import Registry, Settings

    with tempfile.TemporaryDirectory(prefix="bench-registry-") as tmp:
        root = Path(tmp)
        t0 = time.perf_counter()
        bundles = make_bundles(root / "bundles", args.submissions)
        print(
            f"packed {len(bundles)} distinct bundles in {time.perf_counter() - t0:.1f} s "
            f"({statistics.fmean(b.stat().st_size for _, b, _ in bundles) / 1024:.1f} KiB each)",
            flush=True,
        )
        data = root / "registry"
        reg = Registry(Settings(data_dir=data), lock=False)
        tokens = {lab: reg.create_token(lab, rate_per_minute=1_000_000) for lab in LABS}
        reg.close()
        proc, base = start_server(data)
        try:
            outcomes, wall = submit_all(base, tokens, bundles, deadline_s=600)
            statuses = [o["status"] for o in outcomes]
            expected = {sid for _, _, sid in bundles}
            got = [o["id"] for o in outcomes]
            print(
                f"submissions: {len(bundles)} concurrent in {wall:.1f} s = {len(bundles) / wall:.1f} submissions/s; "
                f"statuses {dict((s, statuses.count(s)) for s in set(statuses))}",
                flush=True,
            )
            dup_outcomes, _ = submit_all(base, tokens, bundles[:N_DUPLICATES], deadline_s=120)
            dup_ok = (
                all(o["status"] == "duplicate" for o in dup_outcomes) and [o["id"] for o in dup_outcomes] == got[:N_DUPLICATES]
            )
            print(f"re-sent {N_DUPLICATES} bundles at once: all duplicates with their first id: {dup_ok}")
            import httpx

            api = httpx.get(f"{base}/api/v1/submissions", params={"limit": 1000}, timeout=60).json()
            problems = check_records(data, expected, api)
            if sorted(got) != sorted(expected) or set(statuses) != {"accepted"}:
                problems.append("not every submission was accepted under its own id")
            if not dup_ok:
                problems.append("a re-sent bundle was not answered as a duplicate of its first id")
            print(f"records: {len(expected)} expected; lost or duplicated: {'none' if not problems else problems}", flush=True)

            paths = read_paths(sorted(expected), args.reads)
            for _, p in set(paths):  # warm-up: one read of each path (first-use imports, template compilation)
                httpx.get(base + p, timeout=60)
            cpu0 = cpu_seconds(proc.pid)
            latencies, by_kind, rwall = read_all(base, paths, deadline_s=600, n_threads=args.threads)
            server_cpu = cpu_seconds(proc.pid) - cpu0
            p50, p99 = pct(latencies, 50), pct(latencies, 99)
            print(
                f"reads: {len(latencies)} from {args.threads} threads in {rwall:.1f} s ({len(latencies) / rwall:.0f}/s); "
                f"p50 {p50:.1f} ms, p99 {p99:.1f} ms (target p99 < {TARGET_P99_MS:g} ms: {'met' if p99 < TARGET_P99_MS else 'NOT met'})"
            )
            print(
                f"server CPU time per read: {server_cpu / len(latencies) * 1000:.2f} ms (all kinds; the service time without queueing)"
            )
            for kind, lats in sorted(by_kind.items()):
                print(f"  {kind:34} n={len(lats):5d}  p50 {pct(lats, 50):6.1f} ms  p99 {pct(lats, 99):6.1f} ms")
            print(f"load average after the run: {os.getloadavg()[0]:.1f}")
        finally:
            stop_server(proc)
        return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
