"""Speed of one full discrepancy run (issue 8): target < 60 s on the 2-core machine.

The measured dossier (not timed): the touch twin with hidden series elasticity and Coulomb friction, one
repetition of the free-space, local-dynamic, figure-eight, surface and stiffness protocols (durations
below) plus the handle calibration trial. Timed: ``run_discrepancy`` from the twin without both effects,
writing every output (twin.json, discrepancy.json, report.html with figures). Prints the wall time, the
effects named and the held-out gap before/after.
"""

from __future__ import annotations

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


def main() -> int:
    truth = preset("touch")
    for key, value in DEMO_TRUTH.items():
        truth = set_param(truth, key, value)
    protocols = ("free_space", "local_dynamic", "figure_eight", "frictionless_surface", "stiffness", "rig.handle_calibration")
    with tempfile.TemporaryDirectory(prefix="bench-discrepancy-") as tmp:
        opt = SimulationOptions(protocols=protocols, reps=1, seed=1, durations=DURATIONS, rig_trials=False)
        session = simulate_dossier(truth, Path(tmp) / "measured", opt).session
        start = disable(disable(preset("touch"), "drive.series_elasticity"), "friction.coulomb")
        t0 = time.perf_counter()
        result, _ = run_discrepancy(session, start, Path(tmp) / "out", workers=0)
        wall = time.perf_counter() - t0
    recorded = sum(v for k, v in DURATIONS.items() if not k.startswith("rig."))
    print(f"discrepancy run on a {recorded:.0f} s dossier (5 device trials): {wall:.1f} s wall (target < {TARGET_S:.0f} s)")
    for a in result.accepted:
        print(f"  named {a.effect_id} {a.parameter} = {a.value:.4g} {a.unit}")
    print(f"  verdict {result.verdict}; {result.gap_summary()}")
    return 0 if wall < TARGET_S else 1


if __name__ == "__main__":
    raise SystemExit(main())
