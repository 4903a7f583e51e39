"""How ``compute`` scales with the recorded length of a session (issue 21, item 3: "scaling with recorded
length stays sub-linear in fixed costs and linear in data").

Simulated Touch sessions of 1, 4 and 8 repetitions of every protocol (``haptify simulate --preset touch
--protocol all --reps N --seed 1``, as the demo's dossier) are computed through the gate exactly as
``bench_gate.py`` computes the demo dossier (:data:`COMPUTE_GATED`: process CPU time after the entry modules'
import, peak resident memory of the whole process), ``REPEATS`` times each, best CPU and highest peak kept.
The recorded length of a session is the sum over its trials of the trial's longest stream (rows / rate).

- CPU time, linear in the data: the cost of a further recorded minute does not grow with the recording —
  the marginal cost from 4 to 8 repetitions is at most :data:`MARGINAL_RATIO` times that from 1 to 4 (a cost
  growing as the square of the length would make it about 2.2 times; one process's CPU time for the same
  work spreads by about ±10 % on the shared 2-core VM, which moves this ratio by about ±0.25). The fixed part
  (imports, the device's modeled workspace; the intercept of the line through the sessions) and the cost per
  recorded minute are reported.
- Peak memory: sub-linear when the longest session's peak over the shortest's is below their length
  ratio (a trial's data is released once no family still to run reads it, spec §15.4).

``python benchmarks/bench_compute_scaling.py``.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench_gate import COMPUTE_GATED, PEAK_RSS_MIB, cpu_once
from figures import report
from haptify.formats.storage import open_session

REPETITIONS = (1, 4, 8)
REPEATS = 3
MARGINAL_RATIO = 1.5


def session_of(reps: int, tmp: Path) -> Path:
    """The session of a ``reps``-repetition Touch dossier simulated into ``tmp``."""
    out = tmp / f"touch-{reps}"
    subprocess.run([sys.executable, "-m", "haptify.cli.main", "simulate", "--preset", "touch", "--protocol", "all",
                    "--reps", str(reps), "--seed", "1", "-o", str(out)], check=True, capture_output=True)
    return out / "session"


def recorded_minutes(session: Path) -> float:
    """Σ over trials of the trial's longest stream, in minutes."""
    folder = open_session(session)
    return sum(max(s.rows / s.rate_hz for s in trial.streams) for trial in folder.trials) / 60.0


def main() -> int:
    minutes, cpu, rss = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for reps in REPETITIONS:
            session = session_of(reps, Path(tmp))
            runs = [cpu_once(COMPUTE_GATED, session) for _ in range(REPEATS)]
            minutes.append(recorded_minutes(session))
            cpu.append(min(runs))
            rss.append(max(PEAK_RSS_MIB[-REPEATS:]))
            print(f"{reps} repetition(s): {minutes[-1]:.1f} min recorded, compute {cpu[-1]:.2f} s CPU, peak {rss[-1]:.0f} MiB")
    length, seconds = np.array(minutes), np.array(cpu)
    rate, fixed = np.polyfit(length, seconds, 1)
    low, high = (float((seconds[i + 1] - seconds[i]) / (length[i + 1] - length[i])) for i in (0, 1))
    print(f"CPU ≈ {fixed:.2f} s + {rate:.3f} s per recorded minute; marginal cost {low:.3f} s/min from "
          f"{REPETITIONS[0]} to {REPETITIONS[1]} repetitions, {high:.3f} s/min from {REPETITIONS[1]} to {REPETITIONS[2]}")
    span = f"{length[0]:.1f} → {length[-1]:.1f} min recorded"
    report(f"compute with the gate vs recorded length ({', '.join(map(str, REPETITIONS))} repetitions of every "
           "protocol): CPU (ratio: marginal cost of the long step over the short)",
           f"linear in data: marginal cost per recorded minute, {REPETITIONS[1]} → {REPETITIONS[2]} repetitions, "
           f"≤ {MARGINAL_RATIO:g}× that of {REPETITIONS[0]} → {REPETITIONS[1]}",
           f"≈ {fixed:.2f} s fixed + {rate:.3f} s per recorded min ({span}; {', '.join(f'{c:.2f}' for c in cpu)} s); "
           f"marginal {low:.3f} then {high:.3f} s/min", "", high / low, holds=bool(high <= MARGINAL_RATIO * low))
    memory_ratio, length_ratio = rss[-1] / rss[0], length[-1] / length[0]
    report(f"compute with the gate vs recorded length ({', '.join(map(str, REPETITIONS))} repetitions): peak RSS "
           "(ratio: peak growth over length growth)",
           "sub-linear: longest / shortest peak below their length ratio",
           f"{', '.join(f'{r:.0f}' for r in rss)} MiB ({span})", "", memory_ratio / length_ratio,
           holds=bool(memory_ratio < length_ratio))
    return 0


if __name__ == "__main__":
    sys.exit(main())
