"""Cost of the measurement uncertainty of a whole dossier (issue 23; spec §19.5: at most 3× the plain compute).

Simulates the ``touch`` preset's demo dossier once (every protocol × 3 repetitions plus the rig trials,
seed 1; simulation not counted), or takes ``--session PATH``. Then, from a cold context each time:
``compute_session`` alone (plain), and ``compute_session`` followed by ``haptify.metrics.uncertainty.attach`` on
the same context (what ``haptify compute --uncertainty`` does). Best of ``--repeat`` runs, wall and CPU.

    python benchmarks/bench_uncertainty_cost.py [--repeat 2] [--session PATH]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from bench_workspace import best
from figures import report
from haptify.pipeline.compute import ComputeContext, compute_session
from haptify.formats.storage import open_session

LIMIT = 3.0  # total cost with uncertainty / plain cost (spec §19.5)


def run(path: Path, repeat: int) -> None:
    plain_wall, plain_cpu, _ = best(repeat, lambda: compute_session(open_session(path)))

    def with_uncertainty():
        ctx = ComputeContext(session=open_session(path))
        return compute_session(ctx.session, ctx=ctx, uncertainty=True)

    wall, cpu, results = best(repeat, with_uncertainty)
    records = [m for m in results.metrics if m.uncertainty is not None]
    mc = [m for m in records if m.uncertainty.mc_draws]
    print(f"plain compute_session: {plain_wall:.2f} s wall, {plain_cpu:.2f} s CPU; with --uncertainty: {wall:.2f} s wall, "
          f"{cpu:.2f} s CPU ({len(records)} metrics with u, {len(mc)} by Monte Carlo, {mc[0].uncertainty.mc_draws if mc else 0} draws)")
    for m in records:
        u = m.uncertainty
        print(f"  {m.id:32s} U = {u.U} (k = {u.k:.3g}, ν_eff = {u.dof_eff if u.dof_eff is None else round(u.dof_eff, 1)}) "
              + ", ".join(f"{b.source} {b.contribution if isinstance(b.contribution, list) else round(b.contribution, 6)}" for b in u.budget))
    ratio = cpu / plain_cpu
    report("whole dossier with uncertainty / plain compute (CPU)", f"≤ {LIMIT:g}×", f"{cpu:.2f} s CPU",
           f"plain {plain_cpu:.2f} s CPU", ratio, ratio <= LIMIT)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--session", type=Path, help="an existing dossier (default: simulate the demo's)")
    args = ap.parse_args()
    if args.session:
        run(args.session, args.repeat)
        return
    from haptify_tools.twin.model import preset
    from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        res = simulate_dossier(preset("touch"), Path(tmp) / "dossier", SimulationOptions(seed=1))
        print(f"(simulated {len(res.trials)} trials, {res.recorded_s:.0f} s of recording, in {time.perf_counter() - t0:.0f} s)")
        run(res.session, args.repeat)


if __name__ == "__main__":
    main()
