"""Speed of the whole conformance suite against the reference over JSON lines (spec chapter 16, issue 6).

Target: every case of ``conformance/cases`` through ``haptify-conform --jsonl`` in < 60 s on the 2-core
machine. Prints the wall time, the CPU time of the runner and the reference process, and the slowest cases.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 60.0


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="bench-conformance-") as tmp:
        report = Path(tmp) / "report.json"
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "haptify_conform.cli", "--jsonl", f"{sys.executable} -m haptify.conform_adapter",
                               "--json-report", str(report), "--quiet"], capture_output=True, text=True)
        wall = time.perf_counter() - start
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        data = json.loads(report.read_text())
    summary = data["summary"]
    print(proc.stdout.strip())
    print(f"conformance suite over --jsonl: {wall:.1f} s wall (target < {TARGET_S:.0f} s), "
          f"{usage.ru_utime + usage.ru_stime:.1f} s CPU (runner + reference), {summary['total']} cases, "
          f"{summary['passed']} passed")
    slow = sorted(data["cases"], key=lambda c: -c["duration_s"])[:5]
    print("slowest cases: " + ", ".join(f"{c['case_id']} {c['duration_s']:.2f} s" for c in slow))
    return 0 if proc.returncode == 0 and wall < TARGET_S else 1


if __name__ == "__main__":
    sys.exit(main())
