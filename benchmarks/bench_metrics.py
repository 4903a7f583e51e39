"""Benchmark-metric speed on a full simulated dossier (issue 4; spec chapters 8–10, 12, 13 and §15.4).

Simulates the ``touch`` preset's full dossier once with the device twin (every protocol × 3 repetitions
plus the rig trials; simulation time not counted), then times from a cold start (fresh context, nothing
cached): ``compute_session`` for the whole session (every family — target < 10 s), and each of the five
benchmark families of this issue on its own. Best of ``--repeat`` runs; wall and CPU time.

    python benchmarks/bench_metrics.py [--repeat 2] [--preset touch]
"""

from __future__ import annotations

import argparse
import importlib
import tempfile
import time
from pathlib import Path

from bench_workspace import best
from haptify.pipeline.compute import ComputeContext, compute_session
from haptify.formats.storage import open_session

FAMILIES = ("workspace", "free_space", "vibration", "surface", "stiffness")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--preset", default="touch")
    args = ap.parse_args()
    from haptify_tools.twin.model import preset
    from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        res = simulate_dossier(preset(args.preset), Path(tmp) / "dossier", SimulationOptions(seed=1))
        print(f"(simulated {len(res.trials)} trials, {res.recorded_s:.0f} s of recording, in {time.perf_counter() - t0:.0f} s)")
        path = res.session
        wall, cpu, results = best(args.repeat, lambda: compute_session(open_session(path)))
        print(f"whole dossier, compute_session (every family): {wall:.2f} s wall, {cpu:.2f} s CPU (target < 10 s); "
              f"{len(results.metrics)} metrics, {len(results.unavailable)} unavailable")
        for fam in FAMILIES:
            module = importlib.import_module(f"haptify.metrics.{fam}")
            wall, cpu, out = best(args.repeat, lambda: module.compute(ComputeContext(session=open_session(path))))
            print(f"  {fam}: {wall:.2f} s wall, {cpu:.2f} s CPU ({len(out)} records)")


if __name__ == "__main__":
    main()
