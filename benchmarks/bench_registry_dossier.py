"""A standard dossier through the registry (issue 18): the demo's 3-repetition Touch dossier, simulated with
compact streams (spec §3.2.1), computed, and submitted with ``--include-raw`` to a local registry
(``haptify registry serve``) as a resumable chunked upload (§17.5.2); the registry unpacks and re-computes it
in its worker (§17.4.1).

Prints the stream and archive sizes, the time of each step, the verification state and the serving
process's peak resident memory (target: verified, server < 1 GiB). Takes about 3 minutes on 2 cores.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
from _registry_fixtures import free_port, passing_report, wait_http  # noqa: E402

HAPTIFY = [sys.executable, "-m", "haptify.cli.main"]


def timed(argv: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="bench-dossier-") as tmp:
        root = Path(tmp)
        session = root / "touch" / "session"
        sim = timed(HAPTIFY + ["simulate", "--preset", "touch", "--protocol", "all", "--reps", "3", "--seed", "1",
                               "--compact", "-o", str(root / "touch")])
        streams = sum(p.stat().st_size for p in session.rglob("*.parquet"))
        results = root / "results.json"
        compute = timed(HAPTIFY + ["--quiet", "compute", str(session), "-o", str(results)])
        report = passing_report(root / "conformance.json", json.loads(results.read_text())["implementation"])
        data = root / "data"
        lab = json.loads((session / "session.json").read_text())["lab"]["id"]
        token = subprocess.run(HAPTIFY + ["registry", "token", "create", "--data", str(data), "--lab", lab],
                               check=True, capture_output=True, text=True).stdout.strip()
        port = free_port()
        server = subprocess.Popen(HAPTIFY + ["registry", "serve", "--data", str(data), "--port", str(port)],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            wait_http(f"http://127.0.0.1:{port}/api/v1/health", timeout=60, alive=server)
            submit = timed(HAPTIFY + ["submit", str(session), "--results", str(results), "--conformance", str(report),
                                      "--include-raw", "--registry", f"http://127.0.0.1:{port}", "--token", token,
                                      "--keep", str(root / "bundle.tar.gz")])
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/v1/submissions") as r:
                subs = json.loads(r.read())
            with open(f"/proc/{server.pid}/status") as fh:
                peak = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmHWM:"))
        finally:
            server.terminate()
            server.wait(30)
        archive = (root / "bundle.tar.gz").stat().st_size
    print(f"simulate (compact): {sim:.1f} s; streams {streams / 1e6:.1f} MB")
    print(f"compute every metric: {compute:.1f} s")
    print(f"submit --include-raw (pack, chunked upload, unpack + re-compute in the worker): {submit:.1f} s; "
          f"archive {archive / 2**20:.1f} MiB")
    print(f"verification: {subs[0]['verification']} (target verified)")
    print(f"server peak RSS: {peak / 2**20:.0f} MiB (target < 1024 MiB)")
    return 0 if subs[0]["verification"] == "verified" and peak < 1 << 30 else 1


if __name__ == "__main__":
    sys.exit(main())
