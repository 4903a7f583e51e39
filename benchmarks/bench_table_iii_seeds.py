"""The device twin's presets against the paper's Table III over seeds (issue 20, item 4): every row within
±20 % of the paper and in the paper's order between the two devices on 10 seeds out of 10, and the modelled
workspace volumes within 3 % (tools/haptify_tools/twin/TWIN.md says which paper value each preset parameter
is fitted to; the twin is a tool, the spec has no chapter on it).

Per preset (``touch``, ``touch-x``) and seed: a dossier of the protocols Table III needs, 3 repetitions at
the simulator's default durations, with the rig trials (``simulate_dossier``), computed by the reference
(``compute_session``) for the rows of ``schemas/1.0/paper-values.json`` plus ``workspace.modeled_volume``.
Per row: the paper's value, min / median / max over the seeds, the worst relative deviation, the seeds
within the tolerance and the seeds on which the two devices are in the paper's order.

``python benchmarks/bench_table_iii_seeds.py [SEEDS [PROCESSES]]`` (default 10 seeds from 1, 2 processes, each
simulating and computing one dossier at a time: about 1–2 min of CPU per preset and seed).
"""

from __future__ import annotations

import sys
from concurrent.futures import ProcessPoolExecutor
import tempfile
import time
from pathlib import Path

import numpy as np

from figures import report
from haptify import schemas
from haptify.pipeline.compute import compute_session
from haptify.formats.storage import open_session
from haptify_tools.twin.model import TwinFile, preset
from haptify_tools.twin.simulate import DEVICE_PROTOCOLS, SimulationOptions, simulate_dossier

PRESETS = {"Touch": "touch", "Touch X": "touch-x"}
ROW_TOLERANCE, MODELED_TOLERANCE = 20.0, 3.0   # %, issue 20 item 4
MODELED = "workspace.modeled_volume"


def paper_rows() -> list[dict]:
    """Table III's rows (metric, label, per-device values, tolerance in %) and the modelled volume, which the
    paper gives in its text (§VI-A) and whose tolerance is tighter."""
    paper = schemas.load("paper-values.json")
    rows = [dict(r, tolerance=ROW_TOLERANCE) for r in paper["rows"]]
    rows.append({"metric": MODELED, "label": "Modeled workspace volume", "values": paper["other"][MODELED],
                 "tolerance": MODELED_TOLERANCE})
    return rows


def table_iii_values(twin: TwinFile, seed: int, metrics: list[str], workers: int = 1) -> dict[str, float]:
    """The scalar values of ``metrics`` that the reference computes from a 3-repetition dossier of ``twin``
    simulated with ``seed`` (every device protocol and the rig trials, in a temporary folder removed after);
    NaN for a metric it cannot compute."""
    opt = SimulationOptions(protocols=DEVICE_PROTOCOLS, reps=3, seed=seed, workers=workers)
    with tempfile.TemporaryDirectory(prefix="bench-table-iii-") as tmp:
        session = open_session(simulate_dossier(twin, Path(tmp) / "dossier", opt).session)
        res = compute_session(session, metrics)
    return {m: (float(r.value) if (r := res.get(m)) is not None and not isinstance(r.value, list) else float("nan"))
            for m in metrics}


def deviation(value: float, paper: float) -> float:
    """Relative deviation from the paper, %."""
    return 100.0 * (value / paper - 1.0)


def summarise(row: dict, values: dict[str, np.ndarray]) -> dict:
    """One row's spread over the seeds: per device min / median / max, the worst deviation (%), the seeds
    within the row's tolerance, and the seeds on which the devices are in the paper's order."""
    out: dict = {"ordered": int(np.sum((values["Touch"] > values["Touch X"]) == (row["values"]["Touch"] > row["values"]["Touch X"])))}
    for device, v in values.items():
        dev = deviation(v, row["values"][device])
        out[device] = {"min": float(np.min(v)), "median": float(np.median(v)), "max": float(np.max(v)),
                       "worst": float(dev[np.nanargmax(np.abs(dev))]) if np.any(np.isfinite(dev)) else float("nan"),
                       "within": int(np.sum(np.abs(dev) <= row["tolerance"]))}
    return out


def main() -> int:
    seeds = list(range(1, 1 + (int(sys.argv[1]) if len(sys.argv) > 1 else 10)))
    processes = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    rows = paper_rows()
    metrics = [r["metric"] for r in rows]
    values = {device: {m: np.full(len(seeds), np.nan) for m in metrics} for device in PRESETS}
    t0 = time.perf_counter()
    jobs = [(i, seed, device) for i, seed in enumerate(seeds) for device in PRESETS]
    with ProcessPoolExecutor(processes) as pool:
        futures = [pool.submit(table_iii_values, preset(PRESETS[device]), seed, metrics)
                   for _, seed, device in jobs]
        for (i, seed, device), future in zip(jobs, futures):
            got = future.result()
            for m in metrics:
                values[device][m][i] = got[m]
            print(f"seed {seed} {device}: " + ", ".join(f"{m} {got[m]:.5g}" for m in metrics), flush=True)
    minutes = (time.perf_counter() - t0) / 60.0
    n = len(seeds)
    print(f"\n{n} seeds × {len(PRESETS)} presets in {minutes:.1f} min")
    print("| row | device | paper | min | median | max | worst deviation | seeds within | ordered |")
    print("|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        s = summarise(row, {d: values[d][row["metric"]] for d in PRESETS})
        for device in PRESETS:
            d = s[device]
            print(f"| {row['label']} | {device} | {row['values'][device]:.5g} | {d['min']:.5g} | {d['median']:.5g} | "
                  f"{d['max']:.5g} | {d['worst']:+.1f} % | {d['within']}/{n} (±{row['tolerance']:g} %) | {s['ordered']}/{n} |")
            report(f"{row['label']}, {device} ({row['metric']}), seeds 1–{n}",
                   f"within ±{row['tolerance']:g} % of the paper's {row['values'][device]:.5g} and in its order, {n}/{n} seeds",
                   f"min {d['min']:.4g}, median {d['median']:.4g}, max {d['max']:.4g} (worst {d['worst']:+.1f} %); "
                   f"within {d['within']}/{n}, ordered {s['ordered']}/{n}",
                   holds=d["within"] == n and s["ordered"] == n)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
