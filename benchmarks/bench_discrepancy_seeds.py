"""How often the discrepancy workflow names a hidden effect first, over seeds (issue 8: ≥ 90 % of seeds,
parameter within 15 %, held-out gap shrinking ≥ 50 %).

For every covered library effect: ``SEEDS`` sessions (own examiner paths and rig noise each), the effect
hidden with a random plausible value drawn from the seed, the workflow started from the ``touch`` preset
without it. Prints, per effect, the share of seeds where it was named first, the share within 15 % and
the share whose held-out gap shrank by half — as it is, and above the floor (the gap the true twin
itself leaves, :func:`~haptify_tools.discrepancy.floor.gap_above_floor`: an effect smaller than the
path's floor cannot halve the raw gap) — and the worst relative error. ``python
benchmarks/bench_discrepancy_seeds.py [SEEDS [EFFECT,…]]`` (default 10 seeds, every effect: about 8 minutes —
2–4 s a seed, 10–14 s for the local-dynamic effects — before the floor's six replays of issue 20).

The verdict cases of issue 20 (:data:`VERDICT_CASES`; pass their names as EFFECT): per seed, does the workflow reach
the right verdict — the Touch's per-drive Coulomb torques ×3 named per drive within 2 % and "explained"; a cogging
force 0.2 N · sin(2πx / 5 mm) outside the library "unexplained residual" with its period within 10 % and amplitude
within 20 %; a force 20 N·s²/m² · |v|² "unexplained residual" following a velocity state; a 4 s null session naming
nothing and reading "no discrepancy".
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from haptify.storage import open_session
from haptify_tools.discrepancy import workspace as ws
from haptify_tools.discrepancy.data import load_measured, simulate_all
from haptify_tools.discrepancy.floor import gap_above_floor, heldout_gap
from haptify_tools.discrepancy.outside import Cogging, SpeedSquared, with_field
from haptify_tools.discrepancy.workflow import assess, run_discrepancy
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


def _coulomb_x3_truth():
    return set_param(preset("touch"), "friction.coulomb.torque_Nm",
                     [3 * v for v in preset("touch").effects.friction_coulomb.torque_Nm])


def _coulomb_x3(result) -> bool:
    truth = _coulomb_x3_truth().effects.friction_coulomb.torque_Nm
    a = result.accepted[0] if result.accepted else None
    return (a is not None and a.effect_id == "friction.coulomb" and a.per_drive is not None
            and bool(np.allclose(a.per_drive, truth, rtol=0.02)) and result.verdict == "explained")


def _cogging(result) -> bool:
    top = result.residual.states[0]
    return (result.verdict == "unexplained residual" and result.residual.follows == "x" and top.kind == "periodic"
            and abs(top.period / 0.005 - 1) < 0.10 and abs(top.amplitude_N / 0.2 - 1) < 0.20)


def _speed(result) -> bool:
    return result.verdict == "unexplained residual" and result.residual.follows in ("speed", "vx", "vy", "vz")


def _null(result) -> bool:
    return not result.accepted and result.verdict == "no discrepancy"


#: case → (truth twin, start twin, force outside the library or None, protocol, seconds, passes(result))
VERDICT_CASES = {
    "coulomb-per-drive-x3": (_coulomb_x3_truth, lambda: disable(_coulomb_x3_truth(), "friction.coulomb"), None,
                             "free_space", 16.0, _coulomb_x3),
    "cogging": (lambda: preset("touch"), lambda: preset("touch"), Cogging(0.2, 0.005), "free_space", 16.0, _cogging),
    "speed-squared": (lambda: preset("touch"), lambda: preset("touch"), SpeedSquared(20.0), "free_space", 16.0, _speed),
    "null-short": (lambda: preset("touch"), lambda: preset("touch"), None, "free_space", 4.0, _null),
}


def verdict_case(name: str, seed: int, folder: Path) -> bool:
    """Does the workflow reach the case's right verdict on this seed (module docstring)?"""
    truth, start, field, protocol, seconds, passes = VERDICT_CASES[name]
    opt = SimulationOptions(protocols=(protocol, "rig.handle_calibration"), reps=1, seed=seed,
                            durations={protocol: seconds, "rig.handle_calibration": 12.0}, rig_trials=False, workers=1)
    trials = load_measured(open_session(simulate_dossier(truth(), folder / f"{name}-{seed}", opt).session))
    result, _ = assess(start(), trials if field is None else with_field(trials, field), {protocol: seconds}, workers=0)
    return passes(result)


def main() -> int:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    effects = sys.argv[2].split(",") if len(sys.argv) > 2 else [*CASES, *VERDICT_CASES]
    verdicts = [e for e in effects if e in VERDICT_CASES]
    effects = [e for e in effects if e not in VERDICT_CASES]
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
        for name in verdicts:
            t0 = time.perf_counter()
            ok = sum(verdict_case(name, s, Path(tmp)) for s in range(seeds))
            print(f"{name:28s} right verdict {ok:3d}/{seeds:<3d} {(time.perf_counter() - t0) / seeds:6.1f} s/seed", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
