"""Workspace volume operator speed (issue 4; spec §8.4): 10⁶ boundary points in under 2 s.

Times the operator on 10⁶ points sampled on the boundary of the Touch's modeled workspace (faces of the
joint-limit box through eq. 4, the examiner's sweep of paper §IV-A), and the modeled workspace itself
(§8.3: joint-space sampling + operator), best of ``--repeat`` runs, wall and CPU time.

    python benchmarks/bench_workspace.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from haptify.processing.kinematics import configurations_from_unit, forward_positions
from haptify.formats.session_format import Device
from haptify.metrics.workspace import modeled_solid, volume_solid
from haptify_tools.example_session import TOUCH_DEVICE


def best(repeat: int, fn):
    """Run ``fn`` ``repeat`` times: (wall s, CPU s, result) of the fastest run (wall clock)."""
    runs = []
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        out = fn()
        runs.append((time.perf_counter() - w, time.process_time() - c, out))
    return min(runs, key=lambda r: r[0])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    kin = Device.model_validate(TOUCH_DEVICE).kinematics
    rng = np.random.default_rng(0)
    n = 1_000_000
    s = rng.random((int(n * 1.02), 3))
    s[np.arange(len(s)), rng.integers(0, 3, len(s))] = rng.integers(0, 2, len(s))
    q = configurations_from_unit(kin, s)
    pts = forward_positions(kin, q[~np.isnan(q).any(axis=1)])[:n]
    wall, cpu, solid = best(args.repeat, lambda: volume_solid(pts))
    print(f"volume operator, {len(pts):,} boundary points (Touch): {wall:.2f} s wall, {cpu:.2f} s CPU "
          f"(target < 2 s); V = {solid.volume * 1e6:.0f} cm³, closed = {solid.closed}")
    wall, cpu, model = best(args.repeat, lambda: modeled_solid(kin))
    print(f"modeled workspace (sampling + operator, Touch): {wall:.2f} s wall, {cpu:.2f} s CPU; "
          f"V = {model.volume * 1e6:.0f} cm³ (paper 13 223 cm³)")


if __name__ == "__main__":
    main()
