"""Coverage of the discrepancy workflow's estimates (issue 20, item 2; discrepancy README §3, uncertainty).

For each case: a hidden value drawn off the search grid (uniform over the range, from the case's seed), a session
simulated by the ``touch`` preset with it (own examiner path and rig noise per seed), the workflow's search for that one
effect started from the preset without it (:func:`~haptify_tools.discrepancy.identify.select_effects`, one library
entry). Prints per case the truth, the estimate, its 95 % block-bootstrap interval, whether the interval covers the
truth and the relative error; then the coverage (issue: ≥ 90 %) and the median relative error (issue: ≤ 1 %).
``python benchmarks/bench_discrepancy_coverage.py [CASES [EFFECT,…]]`` (default 30 cases per effect).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from haptify.formats.storage import open_session
from haptify_tools.discrepancy.data import load_measured
from haptify_tools.discrepancy.floor import replay_floors
from haptify_tools.discrepancy.identify import select_effects
from haptify_tools.discrepancy.library import candidate
from haptify_tools.discrepancy.workflow import replay_parameters
from haptify_tools.twin.model import disable, preset, set_param
from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

#: effect → (parameter, low, high, protocol, seconds): the hidden value is uniform in [low, high]
CASES = {
    "drive.series_elasticity": ("stiffness_Nm_per_rad", 6.0, 16.0, "stiffness", 12.0),
    "friction.coulomb": ("torque_Nm", 0.02, 0.06, "free_space", 16.0),
}


def one(effect: str, seed: int, folder: Path) -> tuple[float, float, float, float]:
    """(truth, estimate, 95 % interval low, high) for one case, printed as a line."""
    parameter, low, high, protocol, seconds = CASES[effect]
    value = float(np.random.default_rng(2000 + seed).uniform(low, high))
    truth = set_param(set_param(preset("touch"), f"{effect}.{parameter}", value), f"{effect}.enabled", True)
    opt = SimulationOptions(protocols=(protocol, "rig.handle_calibration"), reps=1, seed=300 + seed,
                            durations={protocol: seconds, "rig.handle_calibration": 12.0}, rig_trials=False, workers=1)
    trials = load_measured(open_session(simulate_dossier(truth, folder / f"{effect}-{seed}", opt).session))
    sel = select_effects(disable(preset("touch"), effect), trials, max_effects=1, library=(candidate(effect),))
    est = sel.rounds[0].fits[0].value
    lo, hi = -np.inf, np.inf
    if sel.accepted:
        lo, hi = replay_floors(sel.twin, {protocol: seconds}, params=replay_parameters(sel)).uncertainty(0)[1]
    print(f"{effect:24s} seed {seed:2d}: truth {value:.5g} estimate {est:.5g} 95 % [{lo:.5g}, {hi:.5g}] "
          f"{'covered' if lo <= value <= hi else 'MISSED '} error {100 * (est / value - 1):+.2f} %", flush=True)
    return value, est, lo, hi


def summary(effect: str, rows: np.ndarray, seconds: float) -> str:
    """Coverage, median and worst relative error, median interval width of ``rows`` (truth, estimate, low, high)."""
    covered = np.mean((rows[:, 2] <= rows[:, 0]) & (rows[:, 0] <= rows[:, 3]))
    err = np.abs(rows[:, 1] / rows[:, 0] - 1)
    width = np.median((rows[:, 3] - rows[:, 2]) / rows[:, 0])
    return (f"{effect}: coverage {100 * covered:.0f} % of {len(rows)}, median relative error {100 * np.median(err):.2f} %, "
            f"worst {100 * err.max():.2f} %, median interval width {100 * width:.2f} % of the value, {seconds:.1f} s a case")


def main(argv: list[str]) -> int:
    n = int(argv[0]) if argv else 30
    with tempfile.TemporaryDirectory(prefix="bench-discrepancy-coverage-") as tmp:
        for effect in (argv[1].split(",") if len(argv) > 1 else CASES):
            t0 = time.perf_counter()
            rows = np.array([one(effect, seed, Path(tmp)) for seed in range(n)])
            print(summary(effect, rows, (time.perf_counter() - t0) / n), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
