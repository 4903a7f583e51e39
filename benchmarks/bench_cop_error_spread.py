"""Spread of ``rig.cop_error`` about its known answer over drawn registry-challenge rig sessions: the figure
behind the metric's tolerance budget (``haptify_tools.tolerance_budgets``; spec §14.5, §17.8).

Each session is the registry challenge's rig family (``haptify_tools.registry.challenge_sessions.rig``)
drawn from its own seed: three placements of a weight whose marker sits a drawn offset (0–15 mm) from each
load point, 5 mN noise on every plate channel. The reference computes ``rig.cop_error`` (``compute_session``);
the answer known by construction is the mean of the offsets' lengths. Reported: the deviations' sd and
largest magnitude, and how many sd the budget allows (target: at least 5, so that the reference does not fail
its own challenge by chance).

``python benchmarks/bench_cop_error_spread.py [SESSIONS]`` (default 300: about a minute on 2 cores).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from figures import report
from haptify.formats.storage import open_session
from haptify.pipeline.compute import compute_session
from haptify_tools.registry.challenge_sessions import rig
from haptify_tools.tolerance_budgets import budget_for

METRIC = "rig.cop_error"
MIN_SD_IN_BUDGET = 5.0


def deviation(seed: int, root: Path) -> float:
    """Computed minus known ``rig.cop_error`` (m) of the challenge rig session drawn from ``seed``."""
    folder = root / f"s{seed}"
    truths = rig(np.random.default_rng(seed), folder, f"conf-cop-{seed}")
    expected = next(value for metric, value, _, _ in truths if metric == METRIC)
    (result,) = [m for m in compute_session(open_session(folder), metrics=[METRIC]).metrics if m.id == METRIC]
    return float(result.value) - float(expected)


def main(sessions: int) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        d = np.array([deviation(seed, Path(tmp)) for seed in range(sessions)])
    (term,) = budget_for(f"{METRIC}.spread")
    sd, worst = float(d.std(ddof=1)), float(np.abs(d).max())
    print(f"{METRIC} over {sessions} drawn challenge rig sessions: mean deviation {d.mean():.2e} m, sd {sd:.2e} m, "
          f"largest |deviation| {worst:.2e} m; budget {term.abs:g} m = {term.abs / sd:.1f} sd")
    report(f"{METRIC}: deviation from the known answer, {sessions} drawn registry-challenge rig sessions",
           f"budget ≥ {MIN_SD_IN_BUDGET:g} sd and above the largest deviation",
           f"sd {sd:.2e} m, largest {worst:.2e} m", f"budget {term.abs:g} m", term.abs / sd,
           term.abs / sd >= MIN_SD_IN_BUDGET and term.abs > worst)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 300)
