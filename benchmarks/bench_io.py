"""Validate and load every stream of a 140 s session in under 1 s (issue 2; spec chapters 3–4).

The session is what the paper's local-dynamic trial produces (paper §V-C: ~140 s): handle_wrench and
plate_wrench at 1 kHz, handle_accel at 2 kHz, handle_pose and a 20-marker markers stream at 100 Hz
(with 2 % occlusion), noisy signals so the Parquet files are as large as real ones. It is written once
to a temporary folder (not timed); then ``validate_session`` plus reading every stream is timed.

    python benchmarks/bench_io.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from haptify.formats.storage import SessionWriter, open_session
from haptify.formats.validation import validate_session
from haptify_tools.example_session import example_writer

DURATION_S = 140.0
N_MARKERS = 20
TARGET_S = 1.0


def build(folder: Path, seed: int = 0) -> Path:
    """Write the 140 s benchmark session into ``folder / 'session'``."""
    rng = np.random.default_rng(seed)
    base = example_writer().manifest
    markers = [f"m{k:02d}" for k in range(N_MARKERS)]
    rig = {**base["rig"], "motion_capture": {"system": "Vicon", "rate_hz": 100.0, "markers": markers,
                                             "rigid_bodies": [{"name": "handle", "markers": markers[:3]}]}}
    w = SessionWriter(manifest={**base, "session_id": "bench-140s", "rig": rig})
    w.add_trial("local_dynamic-1", "local_dynamic", powered=False)

    def grid(rate: float) -> np.ndarray:
        return np.arange(int(DURATION_S * rate)) / rate

    t1k, t2k, t100 = grid(1000.0), grid(2000.0), grid(100.0)
    osc = lambda t, f: np.sin(2 * np.pi * f * t)  # noqa: E731
    wrench = {"t": t1k, **{c: 0.5 * osc(t1k, 2.0 + k) + 0.02 * rng.standard_normal(t1k.size)
                          for k, c in enumerate(["fx", "fy", "fz", "tx", "ty", "tz"])}}
    w.add_stream("local_dynamic-1", "handle_wrench", wrench, rate_hz=1000)
    accel = {"t": t2k, "ax": 0.3 * rng.standard_normal(t2k.size), "ay": 0.3 * rng.standard_normal(t2k.size),
             "az": 9.81 + 0.3 * rng.standard_normal(t2k.size)}
    w.add_stream("local_dynamic-1", "handle_accel", accel, rate_hz=2000)
    plate = {"t": t1k}
    for i in range(1, 5):
        for k, c in enumerate(["fx", "fy", "fz", "tx", "ty", "tz"]):
            plate[f"c{i}_{c}"] = (-4.6 if c == "fz" else 0.0) + 0.05 * osc(t1k, 1.0 + k) + 0.01 * rng.standard_normal(t1k.size)
    w.add_stream("local_dynamic-1", "plate_wrench", plate, rate_hz=1000)
    ang = 0.3 * osc(t100, 0.7)
    pose = {"t": t100, "px": 0.05 * osc(t100, 1.5), "py": 0.05 * osc(t100, 1.1), "pz": 0.1 + 0.03 * osc(t100, 0.9),
            "qw": np.cos(ang / 2), "qx": np.zeros_like(t100), "qy": np.sin(ang / 2), "qz": np.zeros_like(t100)}
    w.add_stream("local_dynamic-1", "handle_pose", pose, rate_hz=100)
    cols = {"t": t100}
    for k, m in enumerate(markers):
        occluded = rng.random(t100.size) < 0.02
        for axis in "xyz":
            v = 0.01 * k + 0.05 * osc(t100, 0.5 + 0.1 * k) + 0.0005 * rng.standard_normal(t100.size)
            cols[f"{m}_{axis}"] = np.where(occluded, np.nan, v)
    w.add_stream("local_dynamic-1", "markers", cols, rate_hz=100, entities=markers)
    return w.write(folder / "session")


def validate_and_load(session: Path) -> tuple[float, float, int, float]:
    """Wall seconds to validate, to load every stream, the number of values loaded, and the CPU seconds of both."""
    c0 = time.process_time()
    t0 = time.perf_counter()
    report = validate_session(session)
    t1 = time.perf_counter()
    if not report.valid:
        raise SystemExit("benchmark session is invalid:\n" + "\n".join(str(f) for f in report.errors))
    s = open_session(session)
    samples = 0
    for trial in s.trials:
        for stream in trial.streams:
            samples += s.read_stream(stream).size
    t2 = time.perf_counter()
    return t1 - t0, t2 - t1, samples, time.process_time() - c0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        session = build(Path(tmp))
        size = sum(p.stat().st_size for p in session.rglob("*") if p.is_file())
        runs = [validate_and_load(session) for _ in range(args.repeat)]
    totals = [v + r for v, r, _, _ in runs]
    med = statistics.median(totals)
    print(f"session: {DURATION_S:.0f} s, 5 streams, {runs[0][2]} values, {size / 2**20:.1f} MiB on disk; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"validate: {statistics.median(r[0] for r in runs):.3f} s (median of {args.repeat})")
    print(f"load every stream: {statistics.median(r[1] for r in runs):.3f} s (median of {args.repeat})")
    print(f"validate + load: {med:.3f} s median, {min(totals):.3f} s best, {max(totals):.3f} s worst wall; "
          f"{statistics.median(r[3] for r in runs):.3f} s CPU (target < {TARGET_S:g} s)")
    return 0 if med < TARGET_S else 1


if __name__ == "__main__":
    sys.exit(main())
