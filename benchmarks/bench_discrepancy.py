"""Speed of one full discrepancy run (issue 8): target < 60 s on the 2-core machine.

Two measured dossiers (not timed), both of the touch twin with hidden series elasticity and Coulomb friction:
a short one (one repetition of the free-space, local-dynamic, figure-eight, surface and stiffness protocols,
durations below, 130 s of device trials) and the simulator's default dossier (every protocol × 3 and the rig
trials: 13 min of force trials, 18.7 min recorded). Timed: ``run_discrepancy`` from the twin without both
effects, 2 worker processes, writing every output (twin.json, discrepancy.json, report.html with figures,
overlay.rrd). Prints the wall time, the effects named and the held-out gap before/after; the exit code
judges the default dossier. ``python benchmarks/bench_discrepancy.py [short|default]`` runs one of them.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from haptify_tools.discrepancy.demo import DEMO_TRUTH
from haptify_tools.discrepancy.workflow import run_discrepancy
from haptify_tools.twin.model import disable, preset, set_param
from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

TARGET_S = 60.0
DURATIONS = {"free_space": 40.0, "local_dynamic": 30.0, "figure_eight": 25.0, "frictionless_surface": 15.0,
             "stiffness": 20.0, "rig.handle_calibration": 20.0}


def run(name: str, options: SimulationOptions, folder: Path) -> float:
    """Simulate the measured dossier, time one full run on it and print what it named; returns the wall time, s."""
    truth = preset("touch")
    for key, value in DEMO_TRUTH.items():
        truth = set_param(truth, key, value)
    session = simulate_dossier(truth, folder / f"{name}-measured", options).session
    start = disable(disable(preset("touch"), "drive.series_elasticity"), "friction.coulomb")
    t0 = time.perf_counter()
    result, sel = run_discrepancy(session, start, folder / f"{name}-out", workers=0)
    wall = time.perf_counter() - t0
    recorded = sum(len(tr.t) / tr.rate_hz for tr in sel.rounds[0].design.trials)
    print(f"{name} dossier ({len(sel.rounds[0].design.trials)} force trials, {recorded:.0f} s): {wall:.1f} s wall "
          f"(target < {TARGET_S:.0f} s)")
    for a in result.accepted:
        print(f"  named {a.effect_id} {a.parameter} = {a.value:.4g} {a.unit}")
    print(f"  verdict {result.verdict}; {result.gap_summary()}", flush=True)
    return wall


def main() -> int:
    which = sys.argv[1:] or ["short", "default"]
    protocols = ("free_space", "local_dynamic", "figure_eight", "frictionless_surface", "stiffness", "rig.handle_calibration")
    cases = {"short": SimulationOptions(protocols=protocols, reps=1, seed=1, durations=DURATIONS, rig_trials=False),
             "default": SimulationOptions(seed=1)}
    walls = {}
    with tempfile.TemporaryDirectory(prefix="bench-discrepancy-") as tmp:
        for name in which:
            walls[name] = run(name, cases[name], Path(tmp))
    return 0 if walls.get("default", walls.get("short", 0.0)) < TARGET_S else 1


if __name__ == "__main__":
    raise SystemExit(main())
