"""Import speed (spec chapter 5): a 140 s ATI-style F/T log at 1 kHz, a 140 s accelerometer log at 2 kHz
in g, and the two real C3D recordings (when ../shared is present). Issue 2 sets no import target;
these figures show that importing stays well below the time of the recording it imports.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from haptify.importers import import_c3d, import_csv

REPO = Path(__file__).resolve().parents[1]
FIX = REPO / "fixtures" / "import"
C3D = REPO.parent / "shared" / "data" / "c3d"
DURATION_S = 140.0


def best_of(n: int, fn) -> float:
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def write_log(path: Path, rate_hz: float, header: list[str], n_values: int, seed: int) -> int:
    rows = int(DURATION_S * rate_hz)
    rng = np.random.default_rng(seed)
    data = np.column_stack([np.arange(rows) * (1000.0 / rate_hz), rng.normal(size=(rows, n_values))])
    np.savetxt(path, data, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    return rows


def main() -> None:
    tmp = Path(tempfile.mkdtemp(prefix="bench-import-"))
    try:
        ati_map = json.loads((FIX / "ati-map.json").read_text())
        ati_map["csv"] = {"skip_rows": 0}
        ati_map["session"]["device"] = {"file": str(FIX / "touch-device.json")}
        (tmp / "ati.json").write_text(json.dumps(ati_map))
        rows = write_log(tmp / "ati.csv", 1000.0, ["Time (ms)", "Fx (N)", "Fy (N)", "Fz (N)", "Tx (N-mm)", "Ty (N-mm)",
                                                   "Tz (N-mm)"], 6, 1)
        secs = best_of(3, lambda: import_csv(tmp / "ati.csv", tmp / "s1", tmp / "ati.json", overwrite=True))
        print(f"ATI F/T log, 140 s at 1 kHz ({rows} rows, N and N-mm): {secs:.2f} s (no target)")

        acc_map = {**ati_map, "time": {"source": "t_ms", "unit": "ms"}, "streams": {"handle_accel": {
            "columns": {c: {"source": c, "unit": "g"} for c in ("ax", "ay", "az")}}}}
        (tmp / "acc.json").write_text(json.dumps(acc_map))
        rows = write_log(tmp / "acc.csv", 2000.0, ["t_ms", "ax", "ay", "az"], 3, 2)
        secs = best_of(3, lambda: import_csv(tmp / "acc.csv", tmp / "s2", tmp / "acc.json", overwrite=True))
        print(f"accelerometer log, 140 s at 2 kHz ({rows} rows, g): {secs:.2f} s (no target)")

        if C3D.is_dir():
            date = {"session": {"date": "2026-11-22"}}
            for name, mapping in (("Vicon.c3d", "vicon-map.json"), ("Qualisys.c3d", "qualisys-map.json")):
                secs = best_of(3, lambda: import_c3d(C3D / name, tmp / "c", FIX / mapping, overrides=date, overwrite=True))
                print(f"{name} with {mapping}: {secs:.2f} s (no target)")
        else:
            print(f"real C3D recordings skipped: {C3D} is absent")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
