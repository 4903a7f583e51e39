"""Preprocessing speed (issue 4; spec chapters 6, 7, 14): the share of the "full dossier in < 10 s" target
spent turning raw streams into calibrated signals.

Times, on the 140 s local-dynamic session of ``bench_io.py`` (plus a handle_gravity record):
``handle_signals`` at 100 Hz (§7.5), ``handle_accel_native`` (§7.6) and ``plate_signals`` (§14.1), each
from a cold start; and the calibration fit of eqs. 1–3 on a 24 s calibration trial's worth of samples
(§6.2–6.3). A full dossier (paper: five experiments × three repetitions) preprocesses about fifteen such
trials, most of them shorter.

    python benchmarks/bench_preprocessing.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from bench_import import best_of
from bench_io import build
from haptify.processing import calibration, force_plate, signals
from haptify.formats.conventions import STANDARD_GRAVITY
from haptify.formats.storage import atomic_write_json, open_session

RECORD = {"kind": "handle_gravity", "id": "bench", "force_bias_N": [0.1, -0.2, 0.3], "connector_mass_kg": 0.05,
          "connector_com_m": [0.0, 0.0, 0.02], "torque_bias_Nm": [0.0, 0.0, 0.0], "accel_bias_m_per_s2": [0.0, 0.0, 0.0],
          "gravity_m_per_s2": STANDARD_GRAVITY}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = build(Path(tmp))
        manifest = json.loads((path / "session.json").read_text())
        manifest["calibration"] = [RECORD]
        atomic_write_json(path / "session.json", manifest)
        trial = "local_dynamic-1"
        s_hs = best_of(args.repeat, lambda: signals.handle_signals(open_session(path), trial))
        s_acc = best_of(args.repeat, lambda: signals.handle_accel_native(open_session(path), trial))
        rec = {"kind": "plate_bias", "id": "pb", "bias": [0.0] * 24}
        manifest["calibration"].append(rec)
        atomic_write_json(path / "session.json", manifest)
        s_plate = best_of(args.repeat, lambda: force_plate.plate_signals(open_session(path), trial))
    rng = np.random.default_rng(0)
    n = 2400  # 24 s at the 100 Hz fit rate
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    force = 0.3 + 0.5 * u + rng.normal(0, 0.004, (n, 3))
    torque = 0.01 + np.cross([0.0, 0.0, 0.02], 0.5 * u) + rng.normal(0, 1e-4, (n, 3))
    accel = 0.1 - 9.81 * u + rng.normal(0, 0.05, (n, 3))
    s_fit = best_of(args.repeat, lambda: calibration.fit_from_samples(force, torque, accel))
    print(f"handle_signals, 140 s trial at 100 Hz: {s_hs:.3f} s (share of the < 10 s dossier target)")
    print(f"handle_accel_native, 140 s at 2 kHz: {s_acc:.3f} s")
    print(f"plate_signals, 140 s at 1 kHz: {s_plate:.3f} s")
    print(f"calibration fit (eqs. 1-3), 2400 samples: {s_fit:.3f} s")


if __name__ == "__main__":
    main()
