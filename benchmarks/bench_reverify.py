"""Registry-wide re-verification at scale (issue 24, spec §17.9): a synthetic registry of ≥ 500 small
submissions with raw streams, re-verified serially, on a Dask LocalCluster of 2 worker processes, and on a
scheduler plus 2 workers started as separate commands (``python -m dask scheduler`` / ``python -m dask worker
tcp://…``, as on a cluster of machines); every run's records must equal the serial run's.

The submissions: ``SESSIONS`` short sessions simulated by the twin (``touch`` preset, one 3 s free-space trial,
no rig trials, compact Parquet — about 0.5 MB each) with the reference's results for five metrics; each is
registered ``VARIANTS`` times with different metadata (lab, session id, device serial), so the registry holds
``SESSIONS × VARIANTS`` distinct bundles (distinct digests) but only ``SESSIONS`` distinct stream sets:
simulating 500 sessions would take longer than the three runs together. The registry accepts them with
re-computation switched off (``verify_raw=False``, as ``registry serve --no-verify``), so the serial run is the
first re-computation of each; the two cluster runs then compare with it (all must be ``unchanged``).

Figures: submissions per second of each run (wall, tasks ready to run: the LocalCluster's start is reported
apart), the parallel efficiency of the 2-worker runs and the projection to 10 000 standard dossiers on M
machines. Usage: ``.venv/bin/python benchmarks/bench_reverify.py [--variants N]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the registry tests' builders and the separately started cluster

if __name__ == "__main__":  # not again in each registry worker: the forkserver re-imports this file as __mp_main__
    from _dask_cluster import separate_cluster
    from _registry_fixtures import bundle_for, passing_report
    from figures import report

    from haptify.pipeline.compute import compute_session
    from haptify.formats.storage import open_session, sha256_file
    from haptify_tools.cluster import dask_client
    from haptify_tools.registry.reverify import record_values, run_reverify, start_run
    from haptify_tools.registry.service import Caller, Registry, Settings
    from haptify_tools.registry.storage import LocalFolderStore
    from haptify_tools.twin.model import preset
    from haptify_tools.twin.simulate import SimulationOptions, simulate_dossier

SESSIONS = 8
VARIANTS = 63  # 8 × 63 = 504 submissions
METRICS = ["free_space.speed_mean", "free_space.angular_speed_mean", "vibration.rms", "vibration.spectral_centroid",
           "workspace.spec_box_volume"]
LABS = 6
DOSSIER_CPU_S = (10.0, 40.0)  # one standard dossier's re-computation: the estimate; compute of the demo dossier (issue 18)
MACHINES = (1, 4, 16, 64)
CORES_PER_MACHINE = 2


def simulate(root: Path) -> list[Path]:
    """The ``SESSIONS`` simulated sessions (one 3 s free-space trial each)."""
    out = []
    for seed in range(1, SESSIONS + 1):
        opt = SimulationOptions(protocols=("free_space",), reps=1, seed=seed, durations={"free_space": 3.0}, workers=1,
                                rig_trials=False, compact=True, session_id=f"sim-{seed}")
        out.append(simulate_dossier(preset("touch"), root / f"sim-{seed}", opt).session)
    return out


def relabel(session: Path, results: dict, target: Path, lab: str, sid: str, serial: str) -> tuple[Path, Path]:
    """A copy of ``session`` with another lab, session id and device serial, and its results following it."""
    shutil.copytree(session, target)
    manifest = json.loads((target / "session.json").read_text())
    manifest["lab"]["id"], manifest["session_id"] = lab, sid
    if isinstance(manifest["device"], dict) and "manufacturer" in manifest["device"]:
        manifest["device"]["serial"] = serial
    (target / "session.json").write_text(json.dumps(manifest, indent=2))
    data = dict(results, session_id=sid, manifest_sha256=sha256_file(target / "session.json"))
    if data.get("device"):
        data["device"] = dict(data["device"], serial=serial)
    out = target.parent / f"{sid}.results.json"
    out.write_text(json.dumps(data))
    return target, out


def build_registry(root: Path, sessions: list[Path], variants: int) -> Path:
    """The registry data folder with ``len(sessions) × variants`` submissions with raw streams."""
    data = root / "registry"
    registry = Registry(Settings(data_dir=data, verify_raw=False), lock=False)
    tokens = {}
    try:
        for i in range(LABS):
            registry.create_token(f"lab-{i}")
            tokens[f"lab-{i}"] = i + 1
        conformance = None
        work = root / "variants"
        for k, session in enumerate(sessions):
            results = compute_session(open_session(session), metrics=METRICS).model_dump(mode="json")
            if conformance is None:
                conformance = passing_report(root / "conformance.json", results["implementation"])
            for v in range(variants):
                lab, sid = f"lab-{v % LABS}", f"sim-{k}-{v}"
                s, r = relabel(session, results, work / sid / "session", lab, sid, f"SN-{k}-{v}")
                archive, _ = bundle_for(s, r, conformance if k == v == 0 else None, work / f"{sid}.tar.gz", include_raw=True)
                registry.submit(archive, Caller(tokens[lab], lab, "submit"))
                shutil.rmtree(work / sid)  # the upload itself is consumed by submit
    finally:
        registry.close()
    return data


def timed_run(registry: Registry, store, label: str, client) -> tuple[str, float]:
    run = start_run(registry.engine, label)
    t0 = time.perf_counter()
    summary = run_reverify(registry.engine, store, run, client)
    seconds = time.perf_counter() - t0
    if not summary.complete or summary.errors:
        raise SystemExit(f"{label}: incomplete run {summary.to_dict()}")
    print(f"{label}: {summary.recorded} records in {seconds:.1f} s ({summary.recorded / seconds:.2f}/s); "
          f"changed {summary.submissions['changed']}, unchanged {summary.submissions['unchanged']}, "
          f"failed {summary.submissions['failed']}; first {sum(m['first'] for m in summary.metrics.values())} metric values",
          flush=True)
    return run, seconds


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", type=int, default=VARIANTS)
    args = parser.parse_args()
    load = os.getloadavg()
    print(f"# bench_reverify: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {platform.node()}, "
          f"{os.cpu_count()} cores, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}", flush=True)
    with tempfile.TemporaryDirectory(prefix="bench-reverify-") as tmp:
        root = Path(tmp)
        t0 = time.perf_counter()
        sessions = simulate(root / "sim")
        t_sim = time.perf_counter() - t0
        t0 = time.perf_counter()
        data = build_registry(root, sessions, args.variants)
        n = len(sessions) * args.variants
        print(f"simulated {len(sessions)} sessions in {t_sim:.1f} s; registered {n} submissions in "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
        registry = Registry(Settings(data_dir=data), lock=False)
        store = LocalFolderStore(str(data))
        try:
            serial_run, t_serial = timed_run(registry, store, "serial", None)
            serial = record_values(registry.engine, serial_run)
            t0 = time.perf_counter()
            with dask_client(workers=2) as client:
                t_start = time.perf_counter() - t0
                local_run, t_local = timed_run(registry, store, "LocalCluster, 2 workers", client)
            t0 = time.perf_counter()
            with separate_cluster(2, root / "logs") as cluster:
                from distributed import Client

                t_cluster_start = time.perf_counter() - t0
                with Client(cluster.address) as client:
                    sep_run, t_sep = timed_run(registry, store, f"scheduler + 2 workers as commands ({cluster.address})", client)
            same = {label: record_values(registry.engine, run) == serial
                    for label, run in (("local", local_run), ("separate", sep_run))}
        finally:
            registry.close()
    print(f"LocalCluster start {t_start:.1f} s; scheduler + 2 workers start {t_cluster_start:.1f} s; "
          f"records identical to serial: {same}", flush=True)
    if not all(same.values()):
        raise SystemExit("a cluster run's records differ from the serial run's")
    rate = {k: n / t for k, t in (("serial", t_serial), ("local", t_local), ("separate", t_sep))}
    per_task = t_serial / n
    eff = {k: rate[k] / rate["serial"] / 2 for k in ("local", "separate")}
    report("reverify serial (≥500 small submissions)", "—", f"{rate['serial']:.2f} submissions/s ({n} in {t_serial:.0f} s)")
    report("reverify LocalCluster 2 workers", "identical to serial", f"{rate['local']:.2f} submissions/s, efficiency "
           f"{eff['local']:.2f}", ratio=rate["local"] / rate["serial"], holds=same["local"])
    report("reverify scheduler + 2 workers as commands", "identical to serial",
           f"{rate['separate']:.2f} submissions/s, efficiency {eff['separate']:.2f}", ratio=rate["separate"] / rate["serial"],
           holds=same["separate"])
    e = min(eff.values())
    for cpu in DOSSIER_CPU_S:
        hours = {m: 10_000 * (cpu + per_task) / (m * CORES_PER_MACHINE * e) / 3600 for m in MACHINES}
        print(f"projection, 10 000 dossiers of {cpu:.0f} s CPU (+ {per_task:.2f} s per task measured here), "
              f"{CORES_PER_MACHINE} workers per machine, efficiency {e:.2f}: "
              + ", ".join(f"{m} machine{'s' if m > 1 else ''} {h:.1f} h" for m, h in hours.items()), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
