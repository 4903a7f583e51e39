"""Speed of the device twin's physics (issue 3): passive inverse dynamics and the 1 kHz active loop.

Prints seconds of compute per second of recorded time for each preset, and the twin-physics share of a
full dossier (3 repetitions of the free-space, local-dynamic and figure-eight trials passive, and of the
frictionless-surface and stiffness trials active, at the simulator's default durations). The dossier as
a whole (examiner, rig, writing) must stay under 60 s on a 2-core machine; this script measures only the
physics part so the two can be budgeted separately.
"""

from __future__ import annotations

import time

import numpy as np

from haptify_tools.twin import examiner as ex
from haptify_tools.twin.model import preset
from haptify_tools.twin.physics import simulate_active, simulate_passive
from haptify_tools.twin.simulate import DEFAULT_DURATIONS, RENDER_STIFFNESS_N_PER_M

PASSIVE = ("free_space", "local_dynamic", "figure_eight")
ACTIVE = ("frictionless_surface", "stiffness")
REPS = 3


def _best_of(fn, repeat: int = 3) -> float:
    """Best CPU time (``time.process_time``) of ``repeat`` runs, s: on a shared machine the wall clock
    also counts the time other processes hold the cores."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def main() -> None:
    print("bench_twin_physics: CPU time of the twin's physics (best of 3, single thread)")
    for name in ("touch", "touch-x"):
        tw = preset(name)
        reach = ex.reach_from_twin(tw)
        centre = reach.centre()
        surface = {"surface_point_m": centre.tolist(), "surface_normal": [0.0, 0.0, 1.0],
                   "stiffness_N_per_m": RENDER_STIFFNESS_N_PER_M, "loop_rate_hz": 1000.0}
        rng = np.random.default_rng(0)
        trajs = {
            "free_space": ex.free_space_wander(rng, reach, DEFAULT_DURATIONS["free_space"]),
            "local_dynamic": ex.local_oscillations(rng, reach, DEFAULT_DURATIONS["local_dynamic"]),
            "figure_eight": ex.figure_eight(rng, reach, DEFAULT_DURATIONS["figure_eight"]),
            "frictionless_surface": ex.surface_circles(rng, reach, centre[2], DEFAULT_DURATIONS["frictionless_surface"]),
            "stiffness": ex.surface_presses(rng, reach, centre[2], DEFAULT_DURATIONS["stiffness"]),
        }
        total = 0.0
        recorded = 0.0
        for proto, tr in trajs.items():
            step = int(round(tr.rate_hz / 1000.0))
            t, p, q = tr.t[::step], tr.position_W[::step], tr.quaternion_W[::step]
            if proto in ACTIVE:
                secs = _best_of(lambda: simulate_active(tw, t, p, q, surface))
            else:
                secs = _best_of(lambda: simulate_passive(tw, t, p, q))
            dur = DEFAULT_DURATIONS[proto]
            total += REPS * secs
            recorded += REPS * dur
            kind = "active " if proto in ACTIVE else "passive"
            print(f"  {name:8s} {kind} {proto:21s} {dur:6.1f} s recorded: {secs:6.3f} s  ({secs / dur * 1000:6.2f} ms per s)")
        print(f"  {name:8s} physics of a {REPS}-repetition dossier ({recorded / 60:.1f} min recorded): {total:.2f} s "
              f"(target: the whole dossier < 60 s)")


if __name__ == "__main__":
    main()
