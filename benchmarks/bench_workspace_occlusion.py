"""What makes the workspace metrics' lower tail? Motion-capture occlusion, measured with the twin (issue 23;
spec §8.7, §19.8).

The coverage study (``bench_uncertainty_coverage.py``) found the measured workspace metrics covered by their
Type A interval in only 71.5–77 % of 200 sessions, and the per-trial truths it used strongly skewed. This
script separates the candidate causes on workspace-only sessions of the ``touch`` preset (seed = session
number, ``--reps`` sweeps each, every ``--duration``): for every trial it applies the volume operator
(§8.4) to

* ``meas``  — the trial's finite measured positions alone (:func:`haptify.metrics.workspace.measured_points`), as the
  reference computed it before the repair of §8.7;
* ``rep``   — the measured cloud with its occlusion gaps repaired from the other repetitions, as the reference
  computes it now (:func:`haptify.metrics.workspace.trial_solid`, spec §8.7);
* ``mask``  — the twin's true positions at the rows whose measured position is finite (the coverage study's
  truth until the repair): the examiner's sweep with the occlusion gaps cut out, no noise;
* ``all``   — the twin's true positions at every row: the sweep as a perfect rig records it, the measurand of
  spec §19 (preamble) and of the paper (§IV-A, §V-A: every point the end-effector reaches is recorded);

and records the occlusion gaps (length, the chord between the finite rows around them, the true path inside
them) and how far a gap filled by interpolation in time (linear as §7.4, or PCHIP) lies from the true path.
The summary prints, per duration: the spread of each per-trial variant, the volume lost to occlusion by
the longest gap, the fill errors by gap length, and the coverage of the Type A interval (§19.2) for
sessions of ``reps`` trials drawn from the pooled trials, for an estimator (``meas`` or ``all``) against a
truth (the mean of ``mask`` or of ``all``).

Rows go to ``--out`` (JSON lines, resumable); ``--summarise`` only reads them.

    python benchmarks/bench_workspace_occlusion.py [--sessions 40] [--reps 3] [--duration 40 --duration 75] [--workers 2] [--out FILE] [--summarise]
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import shutil
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.stats import skew
from scipy.stats import t as student

from haptify.metrics import workspace
from haptify.pipeline.compute import ComputeContext
from haptify.formats.storage import open_session

METRICS = {"ratio": "workspace.volume_ratio", "coverage": "workspace.coverage"}


def gaps_of(t: np.ndarray, measured: np.ndarray, true: np.ndarray) -> list[dict]:
    """Every interior occlusion gap of a trial: rows ``i < j`` finite with only non-finite rows between.
    Duration ``t_j − t_i`` (s), chord ``|p_j − p_i|`` and the true path inside (m), and the largest distance
    (m) of a fill in time from the true positions: linear (as spec §7.4 bridges short gaps) and PCHIP."""
    finite = np.all(np.isfinite(measured), axis=1)
    idx = np.flatnonzero(finite)
    pchip = PchipInterpolator(t[finite], measured[finite], axis=0) if len(idx) > 1 else None
    out = []
    for i, j in zip(idx[:-1], idx[1:]):
        if j - i < 2:
            continue
        mid = np.arange(i + 1, j)
        s = ((t[mid] - t[i]) / (t[j] - t[i]))[:, None]
        linear = measured[i] + s * (measured[j] - measured[i])
        out.append({"duration_s": float(t[j] - t[i]), "chord_m": float(np.linalg.norm(measured[j] - measured[i])),
                    "path_m": float(np.linalg.norm(np.diff(true[i:j + 1], axis=0), axis=1).sum()),
                    "fill_linear_m": float(np.linalg.norm(linear - true[mid], axis=1).max()),
                    "fill_pchip_m": float(np.linalg.norm(pchip(t[mid]) - true[mid], axis=1).max())})
    return out


def one_session(seed: int, reps: int, duration: float, tmp: Path) -> list[dict]:
    """Simulate one workspace-only session and measure every trial (module docstring)."""
    from haptify_tools.twin.model import preset
    from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

    opt = SimulationOptions(protocols=("workspace",), reps=reps, seed=seed, rig_trials=False,
                            durations={"workspace": duration}, workers=1)
    res = simulate_dossier(preset("touch"), tmp / f"s{seed}-{duration:g}", opt, overwrite=True)
    ctx = ComputeContext(session=open_session(res.session))
    truth = np.load(res.truth_npz)
    placement = ctx.session.manifest.device_placement
    model = workspace.modeled_solid(ctx.session.device().kinematics, placement.position, placement.quaternion)
    ctx.cached(("workspace_model",), lambda: model)
    rows = []
    trials = [t.id for t in ctx.session.trials_of("workspace")]
    for tid in trials:
        pose = ctx.session.read(tid, "handle_pose")
        measured = pose[["px", "py", "pz"]].to_numpy(float)
        true = truth[f"{tid}/position_W"].astype(float)
        finite = np.all(np.isfinite(measured), axis=1)
        row = {"seed": seed, "duration_s": duration, "trial": tid, "rows": len(measured),
               "occluded_rows": int((~finite).sum()),
               "gaps": gaps_of(pose["t"].to_numpy(float), measured, true)}
        repaired = workspace.trial_solid(ctx, trials, tid)
        row["repair_points"] = repaired.repair_points
        for name, solid in (("meas", workspace.volume_solid(measured[finite])), ("rep", repaired),
                            ("mask", workspace.volume_solid(true[finite])), ("all", workspace.volume_solid(true))):
            row[name] = {"volume": solid.volume, "ratio": solid.volume / model.volume,
                         "coverage": workspace.overlap_volume(solid, model) / model.volume, "closed": solid.closed}
        rows.append(row)
    shutil.rmtree(tmp / f"s{seed}-{duration:g}", ignore_errors=True)
    return rows


def _one(job: tuple) -> list[dict]:
    return one_session(*job)


def interval_coverage(values: np.ndarray, truth: float, reps: int, draws: int = 40000) -> tuple[float, float]:
    """Share of sessions of ``reps`` trials drawn with replacement from ``values`` whose Type A interval
    (mean ± t_{0.975}(reps − 1)·s/√reps, spec §19.2) holds ``truth``, and the mean (mean − truth)/u."""
    x = np.random.default_rng(0).choice(values, size=(draws, reps))
    u = x.std(axis=1, ddof=1) / math.sqrt(reps)
    inside = np.abs(x.mean(axis=1) - truth) <= student.ppf(0.975, reps - 1) * u
    return float(inside.mean()), float(np.mean(x.mean(axis=1) - truth) / np.mean(u))


def longest(row: dict, key: str) -> float:
    return max((g[key] for g in row["gaps"]), default=0.0)


def summarise(rows: list[dict], reps: int) -> None:
    by_duration = defaultdict(list)
    for r in rows:
        by_duration[r["duration_s"]].append(r)
    for duration, rs in sorted(by_duration.items()):
        print(f"\n### {duration:g} s sweeps: {len({r['seed'] for r in rs})} sessions, {len(rs)} trials; occluded rows per trial "
              f"{np.mean([r['occluded_rows'] for r in rs]):.1f} of {np.mean([r['rows'] for r in rs]):.0f} (mean), "
              f"{np.mean([len(r['gaps']) for r in rs]):.1f} gaps")
        print("\n| per-trial volume ratio of | closed | median | IQR | 5th pct | min | sd | skew |\n|---|---|---|---|---|---|---|---|")
        for name in [n for n in ("meas", "rep", "mask", "all") if all(n in r for r in rs)]:
            x = np.array([r[name]["ratio"] for r in rs if r[name]["closed"]])
            print(f"| `{name}` | {len(x)}/{len(rs)} | {np.median(x):.4f} | {np.subtract(*np.percentile(x, [75, 25])):.4f} | "
                  f"{np.percentile(x, 5):.4f} | {x.min():.4f} | {x.std(ddof=1):.5f} | {skew(x):+.2f} |")
        closed = [r for r in rs if r["mask"]["closed"]]
        print("\n| longest gap's true path | trials | volume ratio lost to occlusion (`all` − `mask`): mean | max |\n|---|---|---|---|")
        for lo, hi in ((0.0, 0.01), (0.01, 0.03), (0.03, 0.06), (0.06, 0.10), (0.10, math.inf)):
            d = [r["all"]["ratio"] - r["mask"]["ratio"] for r in closed if lo <= longest(r, "path_m") < hi]
            if d:
                print(f"| {lo * 100:g}–{hi * 100:g} cm | {len(d)} | {np.mean(d):.5f} | {np.max(d):.5f} |")
        if all("rep" in r for r in rs):
            print("\n| per-trial error against the perfect rig (`x` − `all`) | mean | sd | 5th pct | 95th pct |\n|---|---|---|---|---|")
            for key in METRICS:
                for name in ("meas", "rep"):
                    d = np.array([r[name][key] - r["all"][key] for r in rs])
                    print(f"| `{name}`, {key} | {d.mean():+.5f} | {d.std(ddof=1):.5f} | {np.percentile(d, 5):+.5f} | {np.percentile(d, 95):+.5f} |")
            print(f"\nDonors taken per trial (§8.7): mean {np.mean([r['repair_points'] for r in rs]):.1f}, "
                  f"max {max(r['repair_points'] for r in rs)}.")
        opened = [f"{longest(r, 'path_m') * 100:.0f} cm" for r in rs if not r["mask"]["closed"]]
        print(f"\nSweeps that do not close (W410) without the occluded rows: {len(opened)} (longest gap's path {', '.join(opened) or '—'}); "
              f"with every true row: {sum(not r['all']['closed'] for r in rs)}.")
        gaps = [g for r in rs for g in r["gaps"]]
        print("\n| gap length | gaps | chord (median) | true path (median) | linear fill error: median / max | PCHIP fill error: median / max |\n|---|---|---|---|---|---|")
        for lo, hi in ((0.0, 0.06), (0.06, 0.1), (0.1, 0.2), (0.2, 0.4), (0.4, math.inf)):
            g = [x for x in gaps if lo < x["duration_s"] <= hi]
            if g:
                med = lambda k: np.median([x[k] for x in g]) * 1e3  # noqa: E731
                mx = lambda k: np.max([x[k] for x in g]) * 1e3  # noqa: E731
                print(f"| {lo:g}–{hi:g} s | {len(g)} | {med('chord_m'):.1f} mm | {med('path_m'):.1f} mm | {med('fill_linear_m'):.1f} / "
                      f"{mx('fill_linear_m'):.1f} mm | {med('fill_pchip_m'):.1f} / {mx('fill_pchip_m'):.1f} mm |")
        for key, label in METRICS.items():
            print(f"\n| `{label}`: estimator vs truth | Type A coverage, {reps} trials | mean (value − truth)/u | {reps + 2} trials | bias/u |\n|---|---|---|---|---|")
            pairs = (("meas", "mask"), ("mask", "mask"), ("meas", "all"), ("rep", "all"), ("all", "all"))
            for est, tru in [(e, t) for e, t in pairs if all(e in r for r in rs)]:
                values = np.array([r[est][key] for r in rs if r[est]["closed"]])
                truth = float(np.mean([r[tru][key] for r in rs if r[tru]["closed"]]))
                c, b = interval_coverage(values, truth, reps)
                c5, b5 = interval_coverage(values, truth, reps + 2)
                print(f"| `{est}` vs mean of `{tru}` | {c:.1%} | {b:+.2f} | {c5:.1%} | {b5:+.2f} |")
            clean = [r for r in rs if r["meas"]["closed"] and longest(r, "chord_m") <= 0.03]
            truth = float(np.mean([r["all"][key] for r in rs]))
            if len(clean) > 2:
                d = np.array([r["meas"][key] - r["all"][key] for r in clean])
                c, b = interval_coverage(np.array([r["meas"][key] for r in clean]), truth, reps)
                print(f"\nTrials whose longest gap's chord is ≤ 3 cm ({len(clean)} of {len(rs)}): `meas` − `all` = {d.mean():+.5f} "
                      f"(sd {d.std(ddof=1):.5f}); Type A coverage of the mean of `all` from {reps} of them {c:.1%} ({b:+.2f} u).")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sessions", type=int, default=40)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--duration", type=float, action="append", default=None, help="workspace sweep length in s (default 40 and 75)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "haptify-workspace-occlusion.jsonl")
    ap.add_argument("--summarise", action="store_true")
    args = ap.parse_args()
    durations = args.duration or [40.0, 75.0]
    rows = [json.loads(line) for line in args.out.read_text().splitlines()] if args.out.is_file() else []
    if not args.summarise:
        done = {(r["seed"], r["duration_s"]) for r in rows}
        clock = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp, multiprocessing.get_context("fork").Pool(args.workers) as pool:
            jobs = [(seed, args.reps, d, Path(tmp)) for d in durations for seed in range(args.sessions) if (seed, d) not in done]
            for session_rows in pool.imap_unordered(_one, jobs):
                with args.out.open("a") as fh:
                    fh.writelines(json.dumps(r) + "\n" for r in session_rows)
                rows += session_rows
                print(f"session {session_rows[0]['seed']} ({session_rows[0]['duration_s']:g} s): {time.perf_counter() - clock:.0f} s", flush=True)
    summarise(rows, args.reps)


if __name__ == "__main__":
    main()
