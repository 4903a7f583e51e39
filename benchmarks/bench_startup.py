"""Start-up of the command line (issue 21, item 1): how long the ``haptify`` entry point takes before it does
any work, beside a bare interpreter's start measured in the same run.

Each command runs ``--repeat`` times as a fresh process (the venv's console script, as a user types it); the
figure is the best wall time (the least disturbed run on a shared machine) with the best process CPU time, which
load disturbs less. A command that imports a
sub-command's heavy modules (rerun, fastapi, matplotlib, numba, the discrepancy workflow) to build its parser
shows here as hundreds of milliseconds; ``tests/test_gate.py`` guards the imports themselves.

    python benchmarks/bench_startup.py [--repeat 7]
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
from pathlib import Path

from figures import report

TARGETS = (("haptify --version", ["--version"], 0.3), ("haptify validate --help", ["validate", "--help"], 0.5))


def best_run(argv: list[str], repeat: int) -> tuple[float, float]:
    """The shortest wall time and the shortest process CPU time (user + system), s, of ``repeat`` runs of
    ``argv`` as a fresh process (output discarded)."""
    wall = cpu = float("inf")
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = min(wall, time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = min(cpu, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    haptify = str(Path(sys.executable).with_name("haptify"))
    bare, bare_cpu = best_run([sys.executable, "-c", "pass"], args.repeat)
    print(f"bare interpreter (python -c pass): {bare:.3f} s wall, {bare_cpu:.3f} s CPU, best of {args.repeat}")
    for name, argv, limit in TARGETS:
        wall, cpu = best_run([haptify, *argv], args.repeat)
        print(f"{name}: {wall:.3f} s wall, {cpu:.3f} s CPU, best of {args.repeat} (target ≤ {limit} s wall)")
        report(f"start-up: `{name}` (ratio: CPU against the bare interpreter's)", f"≤ {limit} s wall",
               f"{wall:.3f} s wall, {cpu:.3f} s CPU", f"python -c pass {bare:.3f} s wall, {bare_cpu:.3f} s CPU",
               cpu / bare_cpu, wall <= limit)


if __name__ == "__main__":
    main()
