"""How often the discrepancy workflow names a hidden effect first, over seeds (issue 8: ≥ 90 % of seeds,
parameter within 15 %, held-out gap shrinking ≥ 50 %).

For every covered library effect: ``SEEDS`` sessions (own examiner paths and rig noise each), the effect
hidden with a random plausible value drawn from the seed, the workflow started from the ``touch`` preset
without it. Prints, per effect, the share of seeds where it was named first, the share within 15 % and
the share whose held-out gap shrank by half — as it is, and above the floor (the gap the true twin
itself leaves, :func:`~haptify_tools.discrepancy.floor.gap_above_floor`: an effect smaller than the
path's floor cannot halve the raw gap) — and the worst relative error. ``python
benchmarks/bench_discrepancy_seeds.py [SEEDS [EFFECT,…]]`` (default 10 seeds, every effect: about 8 minutes —
2–4 s a seed, 10–14 s for the local-dynamic effects).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from haptify_tools.discrepancy import workspace as ws
from haptify_tools.discrepancy.data import simulate_all
from haptify_tools.discrepancy.floor import gap_above_floor, heldout_gap
from haptify_tools.discrepancy.workflow import run_discrepancy
from haptify_tools.twin.model import disable, preset, set_param
from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

DURATIONS = {"free_space": 16.0, "figure_eight": 16.0, "stiffness": 12.0, "workspace": 60.0, "rig.handle_calibration": 12.0}
#: effect → (parameter, low, high, protocols): the hidden value is uniform in [low, high]
CASES = {
    "gravity": ("g_m_per_s2", 9.0, 10.5, ("free_space",)),
    "friction.coulomb": ("torque_Nm", 0.02, 0.06, ("free_space",)),
    "friction.viscous": ("damping_Nms_per_rad", 0.005, 0.02, ("figure_eight",)),
    "kinematics.link_length": ("delta_a_m", 0.003, 0.01, ("free_space",)),
    "handle.connector_mass": ("mass_kg", 0.02, 0.06, ("local_dynamic",)),
    "inertia": ("rotor_inertia_kg_m2", 0.5e-6, 2e-6, ("local_dynamic",)),
    # ½–1½ × the preset's 0.07
    "friction.stribeck": ("excess_torque_Nm", 0.035, 0.105, ("free_space",)),
    "kinematics.base_collision": ("base_top_m", 0.075, 0.125, ("workspace",)),
    "drive.torque_saturation": ("max_torque_Nm", 0.12, 0.22, ("stiffness",)),
    "drive.force_cutoff": ("trip_force_N", 1.5, 2.5, ("stiffness",)),
    "drive.series_elasticity": ("stiffness_Nm_per_rad", 6.0, 16.0, ("stiffness",)),
    "drive.backlash": ("width_rad", 0.003, 0.008, ("frictionless_surface",)),   # torque reversals in contact
}


def truth_of(effect: str, parameter: str, value: float):
    """The touch preset with ``effect`` on and its parameter at ``value``."""
    if effect == ws.EFFECT_ID:
        return ws.apply(preset("touch"), value)
    return set_param(set_param(preset("touch"), f"{effect}.{parameter}", value), f"{effect}.enabled", True)


def one(effect: str, seed: int, folder: Path) -> tuple[bool, float, float, float]:
    """(named first?, relative error, held-out gap ratio after/before, the same above the true twin's floor)
    for one seed. The floor is the held-out gap of the twin that generated the session (known here)."""
    parameter, low, high, protocols = CASES[effect]
    value = float(np.random.default_rng(1000 + seed).uniform(low, high))
    rig = () if protocols == ("workspace",) else ("rig.handle_calibration",)
    opt = SimulationOptions(protocols=(*protocols, *rig), reps=1, seed=seed, durations=DURATIONS, rig_trials=False,
                            workers=1)
    truth = truth_of(effect, parameter, value)
    session = simulate_dossier(truth, folder / f"{effect}-{seed}", opt).session
    result, sel = run_discrepancy(session, disable(preset("touch"), effect), None, max_effects=1, workers=0)
    if not result.accepted or result.accepted[0].effect_id != effect:
        return False, float("nan"), float("nan"), float("nan")
    if effect == ws.EFFECT_ID:
        g = result.workspace_gaps[0]
        ratio = above = g.rms_after_m / g.rms_before_m
    else:
        before, after = result.heldout_gap_before_N, result.heldout_gap_after_N
        trials = sel.rounds[0].design.trials
        floor = heldout_gap(trials, simulate_all(truth, trials))
        ratio = after / before
        above = gap_above_floor(after, floor) / max(gap_above_floor(before, floor), 1e-12)
    return True, abs(result.accepted[0].value - value) / value, ratio, above


def main() -> int:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    effects = sys.argv[2].split(",") if len(sys.argv) > 2 else list(CASES)
    print(f"{'effect':28s} named-first  within-15%  gap-halved  above-floor-halved  worst-error  s/seed")
    with tempfile.TemporaryDirectory(prefix="bench-discrepancy-seeds-") as tmp:
        for effect in effects:
            t0 = time.perf_counter()
            rows = [one(effect, s, Path(tmp)) for s in range(seeds)]
            named = [r for r in rows if r[0]]
            within = sum(1 for r in named if r[1] < 0.15)
            halved = sum(1 for r in named if r[2] <= 0.5)
            above = sum(1 for r in named if r[3] <= 0.5)
            worst = max((r[1] for r in named), default=float("nan"))
            print(f"{effect:28s} {len(named):5d}/{seeds:<5d} {within:5d}/{seeds:<5d} {halved:5d}/{seeds:<5d} "
                  f"{above:9d}/{seeds:<9d} {worst:10.3f}  {(time.perf_counter() - t0) / seeds:6.1f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
