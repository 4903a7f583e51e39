"""What one submission costs the registry (spec §17.3): packing, and accepting a bundle with and without raw
streams (with raw streams the registry validates the session and re-computes every submitted metric).

The analytic example session (one free-space trial, 4 streams) with the reference's results for five
metrics; ``Registry.submit`` is called directly (no HTTP), best of 3 each on fresh registries. No target:
the figures say what a lab waits for beyond the upload itself.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the registry tests' builders (example session, passing report)

from _registry_fixtures import bundle_for, example_session, passing_report, write_results  # noqa: E402

from haptify_tools.registry.service import Caller, Registry, Settings  # noqa: E402

REPEATS = 3


def best(fn) -> float:
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="bench-registry-verify-") as tmp:
        root = Path(tmp)
        session = example_session(root / "session")
        results = write_results(session, root / "results.json")
        report = passing_report(root / "conformance.json", json.loads(results.read_text())["implementation"])
        counter = iter(range(1_000_000))

        def pack(raw: bool) -> Path:
            return bundle_for(session, results, report, root / f"b{next(counter)}.tar.gz", include_raw=raw)[0]

        def submit(raw: bool) -> float:
            """Seconds of one Registry.submit on a fresh registry (its creation and the packing not counted)."""
            archive = pack(raw)
            reg = Registry(Settings(data_dir=root / f"reg{next(counter)}"), lock=False)
            try:
                reg.create_token("lab-example")
                t0 = time.perf_counter()
                outcome = reg.submit(archive, Caller(1, "lab-example", "submit"))
                elapsed = time.perf_counter() - t0
            finally:
                reg.close()
            expected = "verified" if raw else "unverified"
            if outcome.verification["status"] != expected:
                raise SystemExit(f"unexpected verification {outcome.verification['status']!r}")
            return elapsed

        pack_raw = best(lambda: pack(True))
        size = pack(True).stat().st_size
        no_raw = min(submit(False) for _ in range(REPEATS))
        raw = min(submit(True) for _ in range(REPEATS))
        print(f"pack with raw streams: {pack_raw * 1000:.0f} ms ({size / 1024:.0f} KiB archive)")
        print(f"accept without raw streams (unpack, checks, store): {no_raw * 1000:.0f} ms")
        print(f"accept with raw streams (+ validation and re-computation of 5 metrics): {raw * 1000:.0f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
