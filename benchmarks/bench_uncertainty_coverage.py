"""Are the reported uncertainties honest? A coverage study with the device twin (issue 23; spec chapter 19).

Simulates ``--sessions`` independent short sessions of the ``touch`` preset (seed = session number: the
examiner's paths, every sensor's noise, the rig's biases and plate errors drawn afresh): the plate bias and
handle calibration trials, then ``--reps`` trials of each device protocol of :data:`STUDIES` (workspace,
free space, frictionless surface, stiffness) at the lengths of :data:`DURATIONS` (``--duration NAME=S``
overrides one). Each session is computed by the reference with ``uncertainty=True``.

The truth of a metric is its measurand (§19 preamble): the value of the same protocol on a perfect rig —
the reference's own per-trial computation (one :class:`Study` per group of metrics names it) on the twin's
true signals (truth.npz: the hand's pose, the force on it as the reference defines it — the connector's
inertial force included, spec §6.1 —, the force on the plate, a perfect accelerometer's reading), at the
samples the measurement used, over the trials it used — and its expectation over the examiner's
repetitions, the mean over every such trial of every session (its own standard error is printed). A session
covers a metric when |value − truth| ≤ U. Target: 95 % ± 3 % for every metric that reports an uncertainty
(a metric whose method is ``none`` is shown, from rows of runs before it became so, but not reported as a
figure).

Rows are appended to ``--out`` (JSON lines) as sessions finish, so an interrupted run keeps what it did
and ``--sessions N`` resumes it; ``--summarise`` only reads that file. ``--protocols stiffness`` simulates
sessions of those protocols only (after a change to their metrics); per metric and seed the last row that
measured it counts, so such a run supersedes the earlier rows of its metrics and keeps the others. Without ``--sessions`` (as
``benchmarks/run.py`` runs it) the script summarises the rows ``--out`` holds, and simulates 200 sessions
only when it holds none: the figures say how many sessions they rest on.

    python benchmarks/bench_uncertainty_coverage.py [--sessions 200] [--reps 3] [--duration free_space=15] [--workers 2] [--protocols P …] [--out FILE] [--summarise]
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from figures import report
from haptify.metrics import stiffness, surface, workspace
from haptify.pipeline.compute import ComputeContext, compute_session
from haptify.errors import HaptifyError
from haptify.metrics.free_space import (FORCE_IDS, PLATE_ID, SPEED_IDS, magnitude_stats, plate_force_about_weight, plate_force_samples,
                                speed_samples)
from haptify.pipeline.repetitions import definition_of
from haptify.processing.preprocessing import lowpass_resample, mocap_track, process_mocap, resample_track, sp
from haptify.processing.signals import handle_signals
from haptify.formats.storage import open_session
from haptify.metrics.uncertainty import method_of
from haptify.metrics.vibration import GROUPS, combine

TARGET, BAND = 0.95, 0.03
#: Trial lengths (s): free space as the first study; surface and stiffness long enough for several
#: contacts and presses (spec §12–13), the workspace sweep at the protocol's (and the twin's) 75 s: the
#: perfect-rig volume depends on the sweep's length (+0.3 % from 40 s to 75 s), so the measurand is the
#: protocol's.
DURATIONS = {"free_space": 15.0, "frictionless_surface": 12.0, "stiffness": 15.0, "workspace": 75.0,
             "rig.handle_calibration": 30.0, "rig.plate_bias": 5.0}
RIG_TRIALS = ("rig.plate_bias", "rig.handle_calibration")


def true_force(truth, trial_id: str, grid: np.ndarray) -> np.ndarray:
    """The true hand force as the reference defines it — the device's force less the connector's inertial
    force ``m a_c``, which the calibration keeps (spec §6.1) — low-passed onto ``grid`` as the measured one
    is (spec §7.2), N, W."""
    force = truth[f"{trial_id}/force_W"].astype(float) - truth[f"{trial_id}/connector_inertia_W"].astype(float)
    return lowpass_resample(truth[f"{trial_id}/t"], force, grid, float(sp("wrench_cutoff_hz")))


def true_plate_force(truth, trial_id: str, grid: np.ndarray) -> np.ndarray:
    """The true force on the plate low-passed onto ``grid`` as the measured one is (spec §9.3), N, W."""
    return lowpass_resample(truth[f"{trial_id}/t"], truth[f"{trial_id}/base_force_W"].astype(float), grid, float(sp("wrench_cutoff_hz")))


def true_pose(truth, trial_id: str, times: np.ndarray):
    """The true hand pose processed as motion capture is (spec §7.4) and resampled at ``times`` (s)."""
    return resample_track(process_mocap(truth[f"{trial_id}/t"], truth[f"{trial_id}/position_W"].astype(float),
                                        truth[f"{trial_id}/quaternion_W"].astype(float)), times)


def hand_force_truth(ctx, truth, trial_id: str) -> tuple:
    """free_space.force_* (spec §9.2) of the true hand force at the samples with a usable measured force."""
    hs = handle_signals(ctx, trial_id)
    ok = hs.valid & np.all(np.isfinite(hs.force), axis=1)
    s = magnitude_stats(true_force(truth, trial_id, hs.t[ok]))
    return s["mean"], s["sd"], s["min"], s["max"]


def speed_truth(ctx, truth, trial_id: str) -> tuple:
    """free_space.speed_mean and angular_speed_mean (spec §9.4) of the true pose at the mocap samples each
    measured value averaged (the angular one: those settled past the segments' edges; NaN when none)."""
    track = mocap_track(ctx, trial_id)
    used, settled = speed_samples(track)
    pose = true_pose(truth, trial_id, track.t[used])
    spin = (float(np.nanmean(np.linalg.norm(true_pose(truth, trial_id, track.t[settled]).angular_velocity, axis=1)))
            if settled.any() else math.nan)
    return float(np.nanmean(np.linalg.norm(pose.velocity, axis=1))), spin


def plate_truth(ctx, truth, trial_id: str) -> tuple:
    """free_space.plate_force_mean (spec §9.3) of the true force on the plate on the measurement's grid."""
    grid, _ = plate_force_samples(ctx, trial_id)
    return (float(np.linalg.norm(plate_force_about_weight(true_plate_force(truth, trial_id, grid)), axis=1).mean()),)


def vibration_truth(ctx, truth, trial_id: str) -> tuple:
    """RMS and centroid (spec §10) of what a perfect accelerometer reads (no bias, noise, clipping or
    quantisation; the table's floor vibration is motion, so it is in)."""
    v = combine(truth[f"{trial_id}/accel_t"], truth[f"{trial_id}/accel_A"].astype(float), trial_id)
    return v.rms, v.centroid


def surface_truth(ctx, truth, trial_id: str) -> tuple:
    """surface.planar_force_mean / sd (spec §12.3) of the true hand force at the guarded contact samples."""
    cs = surface.contact_signals(ctx, trial_id)
    s = surface.planar_stats(true_force(truth, trial_id, cs.t[cs.used]), cs.normal)
    return s["mean"], s["sd"]


def stiffness_truth(ctx, truth, trial_id: str) -> tuple:
    """stiffness.* (spec §13.3–13.5): the trial's fit of the true normal force on the true penetration, with
    the contact and validity the measurement read."""
    cs = surface.contact_signals(ctx, trial_id)
    penetration = (cs.plane_point - true_pose(truth, trial_id, cs.t).position) @ cs.normal
    fit = stiffness.fit_stiffness(cs.t, penetration, true_force(truth, trial_id, cs.t) @ cs.normal, cs.contact, trial_id, cs.valid)
    return fit.stiffness, 100.0 * fit.stiffness / cs.stiffness_N_per_m, fit.peak_force


def workspace_truth(ctx, truth, trial_id: str) -> tuple:
    """workspace.measured_volume, volume_ratio, coverage (spec §8.7) of the twin's true gimbal positions at
    every row of the trial: the sweep as a perfect rig records it (no occlusion, no noise), the measurand of
    §19's preamble (benchmarks/RESULTS.md, "What makes the workspace metrics' lower tail?")."""
    solid = workspace.volume_solid(truth[f"{trial_id}/position_W"].astype(float))
    placement = ctx.session.manifest.device_placement
    model = ctx.cached(("workspace_model",), lambda: workspace.modeled_solid(ctx.session.device().kinematics, placement.position,
                                                                           placement.quaternion))
    return solid.volume, solid.volume / model.volume, workspace.overlap_volume(solid, model) / model.volume


@dataclass(frozen=True)
class Study:
    """Metrics whose truth one function gives per trial of ``protocol`` (values in the order of ``ids``)."""

    protocol: str
    ids: tuple[str, ...]
    truth: Callable


STUDIES = (
    Study("free_space", FORCE_IDS, hand_force_truth),
    Study("free_space", SPEED_IDS, speed_truth),
    Study("free_space", (PLATE_ID,), plate_truth),
    Study("free_space", GROUPS["free_space"], vibration_truth),
    Study("frictionless_surface", surface.IDS, surface_truth),
    Study("stiffness", stiffness.IDS, stiffness_truth),
    Study("workspace", ("workspace.measured_volume", "workspace.volume_ratio", "workspace.coverage"), workspace_truth),
)
METRICS = tuple(m for s in STUDIES for m in s.ids)


PROTOCOLS = tuple(dict.fromkeys(s.protocol for s in STUDIES))


def one_session(seed: int, reps: int, durations: dict[str, float], tmp: Path, protocols: tuple[str, ...] = PROTOCOLS) -> dict:
    """Simulate, compute and compare one session of ``protocols`` (module docstring)."""
    from haptify_tools.twin.model import preset
    from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

    studies = [s for s in STUDIES if s.protocol in protocols]
    opt = SimulationOptions(protocols=RIG_TRIALS + protocols, reps=reps, seed=seed, rig_trials=False,
                            durations=durations, workers=1)
    res = simulate_dossier(preset("touch"), tmp / f"s{seed}", opt, overwrite=True)
    ctx = ComputeContext(session=open_session(res.session))
    results = compute_session(ctx.session, [m for s in studies for m in s.ids], ctx=ctx, uncertainty=True)
    truth = np.load(res.truth_npz)
    per_trial: dict[str, dict[str, float]] = {}
    for study in studies:
        for trial in ctx.session.trials_of(study.protocol):
            try:
                per_trial.setdefault(trial.id, {}).update(zip(study.ids, map(float, study.truth(ctx, truth, trial.id))))
            except HaptifyError as exc:  # e.g. no press qualifies on the true signals: recorded, not fatal
                per_trial.setdefault(trial.id, {})[f"error:{study.ids[0]}"] = repr(exc)
    row = {"seed": seed, "protocols": list(protocols), "truth_per_trial": per_trial, "metrics": {}}
    for m in results.metrics:
        if m.uncertainty is not None:
            row["metrics"][m.id] = {"value": m.value, "u": m.uncertainty.u, "U": m.uncertainty.U, "k": m.uncertainty.k,
                                    "trials": m.trials, "per_repetition": m.per_repetition,
                                    "budget": {b.source: b.contribution for b in m.uncertainty.budget},
                                    "bias": m.uncertainty.bias.estimate if m.uncertainty.bias else None,
                                    "missing": m.uncertainty.sources_missing}
    shutil.rmtree(tmp / f"s{seed}", ignore_errors=True)
    return row


def _one(job: tuple) -> dict:
    return one_session(*job)


def used_truths(rows: list[dict], metric_id: str) -> np.ndarray:
    """The per-trial truths of ``metric_id`` over the trials its measured values rest on (a trial the
    computation left out, e.g. a workspace sweep that did not close, §8.7, is no sample of its measurand)."""
    return np.array([r["truth_per_trial"][tid][metric_id] for r in rows if metric_id in r["metrics"]
                     for tid in r["metrics"][metric_id]["trials"] if metric_id in r["truth_per_trial"].get(tid, {})])


def own_error(rows: list[dict], metric_id: str) -> float:
    """Mean over trials of (measured per-trial value − that trial's own truth), over the mean u: the
    measurement's bias with the examiner's variation taken out."""
    got = [(r["metrics"][metric_id], r["truth_per_trial"]) for r in rows if "per_repetition" in r["metrics"].get(metric_id, {})]
    err = [v - tt[tid][metric_id] for g, tt in got for tid, v in zip(g["trials"], g["per_repetition"]) if metric_id in tt.get(tid, {})]
    return float(np.mean(err) / np.mean([g["u"] for g, _ in got])) if err else math.nan


def resampled_type_a_coverage(per_trial: np.ndarray, reps: int, draws: int = 20000) -> float:
    """Coverage of the Type A interval alone (mean ± t_{0.975}(n − 1)·s/√n, §19.2) for sessions of ``reps``
    trials drawn with replacement from the pooled per-trial truths: what the examiner's own distribution
    allows with no measurement error at all (95 % when it is normal)."""
    from scipy.stats import t as student

    rng = np.random.default_rng(0)
    x = rng.choice(per_trial, size=(draws, reps))
    half = student.ppf(0.975, reps - 1) * x.std(axis=1, ddof=1) / math.sqrt(reps)
    return float(np.mean(np.abs(x.mean(axis=1) - per_trial.mean()) <= half))


def latest_rows(rows: list[dict], metric_id: str) -> list[dict]:
    """Per seed, the last row that measured ``metric_id``: a run of some protocols only (``--protocols``)
    supersedes the earlier rows of those metrics and leaves the others' rows standing."""
    return list({r["seed"]: r for r in rows if metric_id in r["metrics"]}.values())


def summarise(all_rows: list[dict]) -> None:
    print(f"{len({r['seed'] for r in all_rows})} seeds, {len(all_rows)} session rows")
    print("| metric | truth (mean over trials ± its SE) | sessions | inside U | coverage | mean k | mean (value − truth) / mean u "
          "| mean (trial value − its own truth) / mean u | Type A alone on resampled truths |")
    print("|---|---|---|---|---|---|---|---|---|")
    for mid in METRICS:
        rows = latest_rows(all_rows, mid)
        per_trial = used_truths(rows, mid)
        got = [r["metrics"][mid] for r in rows if mid in r["metrics"]]
        if not got or len(per_trial) < 2:
            continue
        truth, se = per_trial.mean(), per_trial.std(ddof=1) / math.sqrt(len(per_trial))
        inside = [abs(g["value"] - truth) <= g["U"] for g in got]
        bias = np.mean([g["value"] - truth for g in got]) / np.mean([g["u"] for g in got])
        cov = float(np.mean(inside))
        dropped = method_of(mid).method == "none"  # rows measured before the method became none (spec §19.1)
        unit = definition_of(mid.split(".")[0], mid).unit
        print(f"| `{mid}`{' (method now none)' if dropped else ''} | {truth:.5g} ± {se:.2g} {unit} | {len(got)} | {sum(inside)} | "
              f"**{cov:.1%}** | {np.mean([g['k'] for g in got]):.3g} | {bias:+.3f} | {own_error(rows, mid):+.3f} | "
              f"{resampled_type_a_coverage(per_trial, max(len(g['trials']) for g in got)):.1%} |")
        if dropped:
            continue
        report(f"coverage of U (k≈t, p = 95 %) for {mid}, {len(got)} twin sessions", f"{TARGET:.0%} ± {BAND:.0%}",
               f"{cov:.1%}", "", cov, abs(cov - TARGET) <= BAND)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sessions", type=int, default=None, help="simulate up to this many (default: 200 when --out holds no rows)")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--duration", action="append", default=[], metavar="NAME=S",
                    help=f"a trial's length in s (default {DURATIONS})")
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "haptify-uncertainty-coverage-families.jsonl")
    ap.add_argument("--workers", type=int, default=2, help="sessions simulated at once (processes)")
    ap.add_argument("--summarise", action="store_true", help="only summarise the rows already in --out")
    ap.add_argument("--protocols", nargs="+", choices=PROTOCOLS, default=list(PROTOCOLS),
                    help="simulate only these device protocols (and the rig trials); their rows supersede earlier ones")
    args = ap.parse_args()
    durations = DURATIONS | {k: float(v) for k, v in (d.split("=", 1) for d in args.duration)}
    rows = [json.loads(line) for line in args.out.read_text().splitlines()] if args.out.is_file() else []
    if args.sessions is None and rows:
        args.summarise = True
    if not args.summarise:
        protocols = tuple(args.protocols)
        done = {r["seed"] for r in rows if tuple(r.get("protocols", PROTOCOLS)) == protocols}
        clock = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp, multiprocessing.get_context("fork").Pool(args.workers) as pool:
            remaining = [(seed, args.reps, durations, Path(tmp), protocols) for seed in range(args.sessions or 200) if seed not in done]
            for row in pool.imap_unordered(_one, remaining):
                with args.out.open("a") as fh:
                    fh.write(json.dumps(row) + "\n")
                rows.append(row)
                print(f"session {row['seed']}: {time.perf_counter() - clock:.0f} s", flush=True)
    summarise(rows)


if __name__ == "__main__":
    main()
