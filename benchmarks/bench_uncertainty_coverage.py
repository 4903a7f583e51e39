"""Are the reported uncertainties honest? A coverage study with the device twin (issue 23; spec chapter 19).

Simulates ``--sessions`` independent short sessions of the ``touch`` preset (seed = session number: the
examiner's paths, every sensor's noise, the rig's biases and plate errors drawn afresh): the handle
calibration trial and ``--reps`` free-space trials of ``--duration`` s. Each is computed by the reference
with ``uncertainty=True``. The truth of a metric is its measurand (§19 preamble): the value of the same
protocol on a perfect rig — the reference's own per-trial computation on the twin's true 1 kHz signals
(truth.npz: the hand's pose and the force on it), evaluated at the samples the measurement used — and
its expectation over the examiner's repetitions, the mean over every trial of every session (its own
standard error is printed). A session covers a metric when |value − truth| ≤ U. Target: 95 % ± 3 % for
every metric that reports an uncertainty (a metric whose method is ``none`` is shown, from rows of runs
before it became so, but not reported as a figure).

Rows are appended to ``--out`` (JSON lines) as sessions finish, so an interrupted run keeps what it did;
``--summarise`` only reads that file.

    python benchmarks/bench_uncertainty_coverage.py [--sessions 200] [--reps 3] [--duration 15] [--workers 2] [--out FILE] [--summarise]
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import tempfile
import time
from pathlib import Path

import numpy as np

from figures import report
from haptify.compute import ComputeContext, compute_session
from haptify.free_space import FORCE_IDS, SPEED_IDS, hand_force_samples, speeds
from haptify.signals import handle_signals, lowpass_resample, mocap_track, process_mocap, resample_track, sp
from haptify.storage import open_session
from haptify.uncertainty import method_of

METRICS = FORCE_IDS + SPEED_IDS
TARGET, BAND = 0.95, 0.03


def true_trial_values(ctx, truth: np.lib.npyio.NpzFile, trial_id: str) -> dict[str, float]:
    """Per-trial values of :data:`METRICS` on the twin's true signals, at the samples the measurement used."""
    t = truth[f"{trial_id}/t"]
    hs = handle_signals(ctx, trial_id)
    ok = hs.valid & np.all(np.isfinite(hs.force), axis=1)
    grid = hs.t[ok]
    force = lowpass_resample(t, truth[f"{trial_id}/force_W"].astype(float), grid, float(sp("wrench_cutoff_hz")))
    mag = np.linalg.norm(force, axis=1)
    track = mocap_track(ctx, trial_id)
    used = track.valid & np.all(np.isfinite(track.velocity), axis=1) & np.all(np.isfinite(track.angular_velocity), axis=1)
    true_track = resample_track(process_mocap(t, truth[f"{trial_id}/position_W"].astype(float),
                                              truth[f"{trial_id}/quaternion_W"].astype(float)), track.t[used])
    return {"free_space.force_mean": float(mag.mean()), "free_space.force_sd": float(mag.std(ddof=1)),
            "free_space.force_min": float(mag.min()), "free_space.force_max": float(mag.max()),
            "free_space.speed_mean": float(np.nanmean(np.linalg.norm(true_track.velocity, axis=1))),
            "free_space.angular_speed_mean": float(np.nanmean(np.linalg.norm(true_track.angular_velocity, axis=1)))}


def one_session(seed: int, reps: int, duration: float, tmp: Path) -> dict:
    """Simulate, compute and compare one session (module docstring)."""
    from haptify_tools.twin.model import preset
    from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

    opt = SimulationOptions(protocols=("rig.handle_calibration", "free_space"), reps=reps, seed=seed, rig_trials=False,
                            durations={"free_space": duration}, workers=1)
    res = simulate_dossier(preset("touch"), tmp / f"s{seed}", opt, overwrite=True)
    ctx = ComputeContext(session=open_session(res.session))
    results = compute_session(ctx.session, list(METRICS), ctx=ctx, uncertainty=True)
    truth = np.load(res.truth_npz)
    trials = [t.id for t in ctx.session.trials_of("free_space")]
    row = {"seed": seed, "truth_per_trial": {tid: true_trial_values(ctx, truth, tid) for tid in trials}, "metrics": {}}
    for m in results.metrics:
        if m.uncertainty is not None:
            row["metrics"][m.id] = {"value": m.value, "u": m.uncertainty.u, "U": m.uncertainty.U, "k": m.uncertainty.k,
                                    "trials": m.trials, "missing": m.uncertainty.sources_missing}
    return row


def _one(job: tuple) -> dict:
    return one_session(*job)


def summarise(rows: list[dict]) -> None:
    print(f"{len(rows)} sessions")
    print("| metric | truth (mean over trials ± its SE) | sessions | inside U | coverage | mean k | mean (value − truth) / mean u |")
    print("|---|---|---|---|---|---|---|")
    for mid in METRICS:
        per_trial = np.array([tv[mid] for r in rows for tv in r["truth_per_trial"].values()])
        truth, se = per_trial.mean(), per_trial.std(ddof=1) / math.sqrt(len(per_trial))
        got = [r["metrics"][mid] for r in rows if mid in r["metrics"]]
        if not got:
            continue
        inside = [abs(g["value"] - truth) <= g["U"] for g in got]
        bias = np.mean([g["value"] - truth for g in got]) / np.mean([g["u"] for g in got])
        cov = float(np.mean(inside))
        dropped = method_of(mid).method == "none"  # rows measured before the method became none (spec §19.1)
        print(f"| `{mid}`{' (method now none)' if dropped else ''} | {truth:.5g} ± {se:.2g} | {len(got)} | {sum(inside)} | "
              f"**{cov:.1%}** | {np.mean([g['k'] for g in got]):.3g} | {bias:+.3f} |")
        if dropped:
            continue
        report(f"coverage of U (k≈t, p = 95 %) for {mid}, {len(got)} twin sessions", f"{TARGET:.0%} ± {BAND:.0%}",
               f"{cov:.1%}", "", cov, abs(cov - TARGET) <= BAND)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sessions", type=int, default=200)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--duration", type=float, default=15.0, help="free-space trial length, s")
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "haptify-uncertainty-coverage.jsonl")
    ap.add_argument("--workers", type=int, default=2, help="sessions simulated at once (processes)")
    ap.add_argument("--summarise", action="store_true", help="only summarise the rows already in --out")
    args = ap.parse_args()
    rows = [json.loads(line) for line in args.out.read_text().splitlines()] if args.out.is_file() else []
    if not args.summarise:
        done = {r["seed"] for r in rows}
        clock = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp, multiprocessing.get_context("fork").Pool(args.workers) as pool:
            todo = [(seed, args.reps, args.duration, Path(tmp)) for seed in range(args.sessions) if seed not in done]
            for row in pool.imap_unordered(_one, todo):
                with args.out.open("a") as fh:
                    fh.write(json.dumps(row) + "\n")
                rows.append(row)
                print(f"session {row['seed']}: {time.perf_counter() - clock:.0f} s", flush=True)
    summarise(rows)


if __name__ == "__main__":
    main()
