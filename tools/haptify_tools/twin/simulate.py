"""Simulate a full benchmarking dossier into ONE standard session, with its ground truth beside it (design §4).

``simulate_dossier(twin, out_dir, options)`` runs the virtual examiner (:mod:`.examiner`) through every
requested protocol and repetition plus the rig's calibration trials, drives the twin's physics
(:mod:`.physics`: passive inverse dynamics or the active rendering loop), turns the true signals into
raw streams with the virtual rig (:mod:`.rig`) and writes:

- ``<out>/session/`` — a standard 1.0 session (spec chapters 2–3) written atomically by
  :class:`haptify.formats.storage.SessionWriter`; nothing in it reveals the truth;
- ``<out>/truth.json`` — every effect's parameters (the whole twin), the rig's noise levels, biases and
  geometry, every trial's examiner parameters and clock offsets;
- ``<out>/truth.npz`` — the true trajectories, joint and gimbal angles and wrenches per trial (1 kHz), the
  connector's inertial force ``m a_c`` (``connector_inertia_W``, which the reported hand force keeps, spec §6.1),
  a perfect accelerometer's reading (``accel_t``, ``accel_A``: the accelerometer's clock and frame).

Everything is a deterministic function of the twin, the options and the seed: each trial draws from
its own generator seeded by ``(seed, crc32(trial id))``, so a trial is identical whichever other
protocols are simulated with it.

The plan and its options are in :mod:`haptify_tools.twin.dossier_plan`, one trial's simulation in
:mod:`haptify_tools.twin.dossier_trials` (:class:`~haptify_tools.twin.dossier_trials.DossierSimulator`),
the output files' helpers in :mod:`haptify_tools.twin.truth_files`; this module runs the trials (in
parallel processes when asked) and writes the dossier.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.storage import SessionWriter, atomic_write_json
from haptify_tools.twin import plate_loads

# re-exported for the benchmark scripts (bench_twin_physics, bench_stiffness_spread, bench_table_iii_seeds)
from haptify_tools.twin.dossier_plan import DEFAULT_DURATIONS as DEFAULT_DURATIONS
from haptify_tools.twin.dossier_plan import DEVICE_PROTOCOLS as DEVICE_PROTOCOLS
from haptify_tools.twin.dossier_plan import RENDER_STIFFNESS_N_PER_M as RENDER_STIFFNESS_N_PER_M
from haptify_tools.twin.dossier_plan import PlannedTrial, SimulationOptions, plan, planned_duration
from haptify_tools.twin.dossier_trials import DossierSimulator, TrialOutput
from haptify_tools.twin.model import TwinFile, twin_to_dict
from haptify_tools.twin.truth_files import _jsonable, _truth_array, built_in_place, write_npz

# --- the dossier -----------------------------------------------------------------------------------


@dataclass
class DossierResult:
    """What :func:`simulate_dossier` wrote: folders and files, trial ids, recorded time and timings (s)."""

    out_dir: Path
    session: Path
    truth_json: Path
    truth_npz: Path
    trials: list[str]
    recorded_s: float
    timings_s: dict[str, float] = field(default_factory=dict)


def simulate_dossier(
    twin: TwinFile,
    out_dir: str | os.PathLike,
    options: SimulationOptions | None = None,
    *,
    overwrite: bool = False,
    advance: Callable[[int], object] | None = None,
) -> DossierResult:
    """Simulate every planned trial and write ``<out>/session``, ``<out>/truth.json`` and ``<out>/truth.npz``.

    ``advance(n)`` is called after each trial (for a progress bar). The output folder is built beside
    the target and renamed into place, so an interrupted run leaves nothing half-written (spec §3.6).
    E901 when ``out_dir`` exists and not ``overwrite``.
    """
    opt = options or SimulationOptions()
    out = Path(out_dir)
    if out.exists() and not overwrite:
        raise fail(Code.OUTPUT_EXISTS, f"{str(out)!r} already exists", file=str(out))
    sim = DossierSimulator(twin, opt)
    writer = SessionWriter(manifest=sim.manifest(), compact=opt.compact)
    trials_truth, arrays, clock_records = [], {}, []
    recorded = 0.0
    planned = plan(opt)
    clock0 = time.perf_counter()
    for p, res in zip(planned, _run_all(sim, planned, opt.workers)):
        writer.add_trial(
            p.trial_id,
            p.protocol,
            powered=res.powered,
            repetition=p.repetition,
            label=p.label,
            rendering=res.rendering,
            notes="simulated by the haptify device twin",
        )
        for kind, cols in res.streams.items():
            stream = writer.add_stream(
                p.trial_id, kind, cols, rate_hz=res.rates[kind], fmt=opt.fmt, entities=res.entities.get(kind)
            )
            off = res.truth.get("clock_offsets_s", {}).get(kind, 0.0)
            if off:
                clock_records.append(
                    {"kind": "clock_offset", "id": f"clock-{p.trial_id}-{kind}", "stream_file": stream["file"], "offset_s": off}
                )
        trials_truth.append(
            {
                "id": p.trial_id,
                "protocol": p.protocol,
                "label": p.label,
                "repetition": p.repetition,
                "t_start_s": p.t0,
                "t_end_s": res.end_time,
                **res.truth,
            }
        )
        for key, val in res.arrays.items():
            arrays[f"{p.trial_id}/{key}"] = _truth_array(key, val)
        recorded += res.end_time - p.t0
        if advance is not None:
            advance(1)
    timings = {"simulate": time.perf_counter() - clock0}
    if clock_records:
        writer.manifest = {**writer.manifest, "calibration": clock_records}
    truth = {
        "format": "haptify-twin-truth",
        "version": "1.0",
        "seed": opt.seed,
        "reps": opt.reps,
        "examiner": {"id": opt.examiner_id, "pace": opt.examiner_pace},
        "protocols": list(opt.protocols),
        "session_folder": "session",
        "twin": twin_to_dict(twin),
        "rig": {
            "config": opt.rig.to_dict(),
            "marker_layout_m": {k: v.tolist() for k, v in sim.layout.items()},
            "cop_marker_offsets_m": plate_loads.COP_MARKER_OFFSETS.tolist(),
            "plate_corner_positions_m": sim.plate_errors.positions.tolist(),
            "plate_corner_gains": sim.plate_errors.gains.tolist(),
        },
        "effective": {
            "handle_force_bias_N": sim.bias_f.tolist(),
            "handle_torque_bias_Nm": sim.bias_t.tolist(),
            "accel_bias_m_per_s2": sim.bias_a.tolist(),
            "plate_corner_force_bias_N": sim.bias_p.tolist(),
            "connector_mass_kg": sim.conn_m,
            "connector_com_m": sim.conn_r.tolist(),
            "rendering": sim.surface,
        },
        "trials": trials_truth,
        "arrays_file": "truth.npz",
        "arrays_note": "per trial '<trial id>/<name>': true signals at 1 kHz (workspace: 100 Hz; vibration_W_2kHz: "
        "2 kHz), SI units, W frame; float32 except the time base 't' (float64, session clock)",
    }
    with built_in_place(out) as build:
        from concurrent.futures import ThreadPoolExecutor

        clock0 = time.perf_counter()
        # Parquet and deflate both release the GIL: write the truth arrays while the session is written.
        with ThreadPoolExecutor(max_workers=1) as pool:
            npz = pool.submit(write_npz, build / "truth.npz", arrays)
            writer.write(build / "session")
            timings["write_session"] = time.perf_counter() - clock0
            npz.result()
        atomic_write_json(build / "truth.json", _jsonable(truth))
        timings["write_all"] = time.perf_counter() - clock0
    return DossierResult(
        out, out / "session", out / "truth.json", out / "truth.npz", [p.trial_id for p in planned], recorded, timings
    )


_WORKER: DossierSimulator | None = None


def _init_worker(twin: TwinFile, options: SimulationOptions) -> None:
    global _WORKER
    _WORKER = DossierSimulator(twin, options)


def _run_in_worker(p: PlannedTrial) -> TrialOutput:
    assert _WORKER is not None
    return _WORKER.run(p)


def _run_all(sim: DossierSimulator, planned: list[PlannedTrial], workers: int):
    """Trial outputs in plan order; with more than one worker the trials run in parallel processes.

    Results do not depend on the number of workers (every trial has its own seeded generators).
    """
    n = workers or min(4, os.cpu_count() or 1)
    n = min(n, len(planned))
    if n <= 1:
        for p in planned:
            yield sim.run(p)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    # longest trials first keeps both workers busy; results are yielded in plan order
    order = sorted(range(len(planned)), key=lambda i: -planned_duration(planned[i].name, sim.opt))
    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
    with ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_init_worker, initargs=(sim.twin, sim.opt)) as pool:
        futures = {i: pool.submit(_run_in_worker, planned[i]) for i in order}
        for i in range(len(planned)):
            yield futures[i].result()
