"""Run every benchmark script in this folder (``make bench``) and print its figures.

Each ``bench_*.py`` is a standalone script that measures one speed or memory target of an issue and
prints ``<figure>: <value> <unit> (target <target>)`` lines. Measured figures are recorded by hand, with
date, machine and command, in ``benchmarks/RESULTS.md``. ``python benchmarks/run.py [NAME …]`` runs only
the scripts whose names contain one of the NAMEs (``make bench`` runs them all).
"""

from __future__ import annotations

import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(names: list[str]) -> int:
    scripts = [s for s in sorted(HERE.glob("bench_*.py")) if not names or any(n in s.stem for n in names)]
    print(f"# Haptify benchmarks — {time.strftime('%Y-%m-%d %H:%M')} — {platform.node()}, "
          f"{platform.python_implementation()} {platform.python_version()}, {len(scripts)} scripts")
    failed = []
    for script in scripts:
        print(f"\n## {script.name}", flush=True)
        proc = subprocess.run([sys.executable, str(script)], cwd=HERE.parent)
        if proc.returncode != 0:
            failed.append(script.name)
    if failed:
        print("\nfailed:", ", ".join(failed))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
