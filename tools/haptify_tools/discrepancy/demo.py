"""``make demo``: the discrepancy workflow on a ``touch`` session with hidden series elasticity and Coulomb
friction (discrepancy README, demo). Call :func:`demo`; it prints the effects named and the gap before and after."""

from __future__ import annotations

import tempfile
from pathlib import Path

from haptify_tools.twin.model import disable, preset, set_param
from haptify_tools.twin.dossier_plan import SimulationOptions
from haptify_tools.twin.simulate import simulate_dossier

#: Hidden truth of the demo: the touch preset with these two values; the twin starts without both effects.
DEMO_TRUTH = {"drive.series_elasticity.stiffness_Nm_per_rad": 9.0, "friction.coulomb.torque_Nm": 0.04}
DEMO_DURATIONS = {"free_space": 12.0, "stiffness": 12.0, "rig.handle_calibration": 12.0}


def demo_session(folder: Path, seed: int = 0) -> Path:
    """Simulate the demo's measured session (free-space and stiffness trials, hidden effects) into ``folder`` (discrepancy README, demo)."""
    truth = preset("touch")
    for key, value in DEMO_TRUTH.items():
        truth = set_param(truth, key, value)
    opts = SimulationOptions(
        protocols=("free_space", "stiffness", "rig.handle_calibration"),
        reps=1,
        seed=seed,
        durations=DEMO_DURATIONS,
        rig_trials=False,
        workers=1,
    )
    return simulate_dossier(truth, folder / "measured", opts).session


def demo(out: str | Path | None = None, print_fn=print) -> dict:
    """Run the demo; writes the workflow's outputs into ``out`` (default: a temporary folder) (discrepancy README, demo)."""
    from haptify_tools.discrepancy.workflow import run_discrepancy

    with tempfile.TemporaryDirectory() as tmp:
        session = demo_session(Path(tmp))
        start = disable(disable(preset("touch"), "drive.series_elasticity"), "friction.coulomb")
        print_fn("hidden: " + ", ".join(f"{k} = {v}" for k, v in DEMO_TRUTH.items()) + "; the twin starts without both")
        result, _ = run_discrepancy(
            session, start, out, overwrite=True, log=lambda m: print_fn("  " + m), report=out is not None, workers=0
        )
    for a in result.accepted:
        se = f" ± {a.stderr:.2g}" if a.stderr is not None else ""
        print_fn(
            f"named #{a.order}: {a.effect_id} {a.parameter} = {a.value:.4g}{se} {a.unit} "
            f"(ΔBIC {a.delta_bic:.0f}, explains {100 * a.share_explained:.0f} % of the held-out residual)"
        )
    print_fn(f"verdict: {result.verdict}; {result.gap_summary()}")
    for b in result.benchmark_gaps:
        print_fn(
            f"  {b.metric} ({b.trial_id}): measured {b.measured:.4g} {b.unit}, twin before {b.twin_before:.4g}, "
            f"after {b.twin_after:.4g}"
        )
    return result.model_dump(mode="json")


if __name__ == "__main__":
    demo()
