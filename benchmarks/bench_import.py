"""Import speed (spec chapter 5): a 140 s ATI-style F/T log at 1 kHz, a 140 s accelerometer log at 2 kHz
in g, and the two real C3D recordings (when ../shared is present). Issue 2 sets no import target;
these figures show that importing stays well below the time of the recording it imports.

Large C3D files (spec §5.5.1, issue 19): a C3D of ``--big-mb`` MB (default 1200: 40 markers at 100 Hz,
32 analog channels at 1 kHz, six of them a type-2 force platform) is written to a temporary folder by
``haptify_tools.c3d_variants.grow_c3d`` and deleted afterwards. Each measurement runs in its own process
(wall time and peak RSS from ``getrusage``): the streamed import (markers, the platform's plate_wrench,
a trigger) of the large file and of a ``--small-mb`` slice, the whole-file import of the slice, and
ezc3d's own read of the slice (``ezc3d.c3d``, under an address-space limit: it holds every frame as C++
objects). Issue 19's target: a 2 GB file must not need 2 GB of RAM.

Then the commands a user runs on the large file (spec §4.4, §5.5.1): ``haptify import c3d`` (the streamed
import and the validation of the session it wrote) and ``haptify validate`` on that session — each stream
read in chunks — against the same validation with every stream read whole (as before chunking; the gate
still reads whole the streams it computes from).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from figures import report
from haptify.formats.importers import import_c3d, import_csv

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


MARKERS, CHANNELS, PER_FRAME = 40, 32, 10
FRAME_BYTES = 4 * (4 * MARKERS + CHANNELS * PER_FRAME)


def big_c3d(path: Path, megabytes: float) -> Path:
    """A C3D of about ``megabytes`` MB (10⁶ B): markers on slow circles (mm), 26 noise channels and a
    type-2 platform under a swaying 700 N load (N, N·mm)."""
    from haptify_tools.c3d_variants import PLATFORM_UNITS, C3DSpec, Platform, grow_c3d, rectangle_corners

    frames = int(megabytes * 1e6 // FRAME_BYTES)
    labels = [f"M{i:02d}" for i in range(MARKERS)]
    template = C3DSpec(labels=labels, points=np.zeros((2, MARKERS, 3)), analog_rate=100.0 * PER_FRAME,
                       analog_labels=["Trigger", *[f"EMG{i}" for i in range(25)], *[f"F{a}" for a in ("x", "y", "z", "mx", "my", "mz")]],
                       analog_units=["V"] * 26 + PLATFORM_UNITS[2], analogs=np.zeros((CHANNELS, 2 * PER_FRAME)),
                       platforms=[Platform(2, rectangle_corners([0.0, 0.0, 0.0], 600.0, 400.0), np.array([0.0, 0.0, -40.0]),
                                           list(range(27, 33)))])
    phase = np.arange(MARKERS)[None, :] * 0.3

    def fill(at: int, n: int):
        t = (at + np.arange(n))[:, None] / 100.0
        pts = np.stack([300 * np.cos(t + phase), 300 * np.sin(t + phase), 100 + 0 * t + phase], axis=2)
        k = (at * PER_FRAME + np.arange(n * PER_FRAME)) / (100.0 * PER_FRAME)
        rng = np.random.default_rng(at)
        sway = 20 * np.sin(2 * np.pi * 0.5 * k)
        plate = np.vstack([0 * k, 0 * k, 700 + 0 * k, -700 * sway, 700 * sway, 0 * k])  # 700 N at (sway, sway) mm
        return pts, np.vstack([5.0 * (np.sin(k) > 0), rng.normal(size=(25, k.size)), plate])

    return grow_c3d(path, template, frames, fill)


CHILD = {
    "ezc3d": "import ezc3d; c = ezc3d.c3d({path!r}); n = c['data']['points'].shape[2]",
    "import": ("from haptify.formats.importers import import_c3d; "
               "import_c3d({path!r}, {out!r}, {map!r}, overwrite=True, stream={stream})"),
    "haptify import": ("from haptify.cli import main as cli; "
                       "assert cli.main(['--quiet', 'import', 'c3d', {path!r}, '--map', {map!r}, '-o', {out!r}, '--overwrite']) == 0"),
    "haptify validate": "from haptify.cli import main as cli; assert cli.main(['--quiet', 'validate', {out!r}]) == 0",
    "validate whole": ("from haptify.formats.validation import SessionValidator; v = SessionValidator({out!r}); v.check_manifest(); "
                       "[v.check_stream(e, keep=True) for e in v.entries]; assert v.report.valid"),
}


def measure(kind: str, path: Path, tmp: Path, stream: bool = True, limit_gb: float = 12.0) -> dict:
    """Wall time and peak RSS of one measurement in its own process (RLIMIT_AS = ``limit_gb``)."""
    code = CHILD[kind].format(path=str(path), out=str(tmp / "session"), map=str(tmp / "big.json"), stream=stream)
    probe = ("import resource, time, json\n"
             f"resource.setrlimit(resource.RLIMIT_AS, ({int(limit_gb * 2**30)}, {int(limit_gb * 2**30)}))\n"
             "t0 = time.perf_counter()\n"
             "try:\n"
             f"    exec({code!r})\n"
             "    ok = True\n"
             "except MemoryError:\n"
             "    ok = False\n"
             "print(json.dumps({'s': time.perf_counter() - t0, 'ok': ok, "
             "'rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))\n")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return {**json.loads(out.stdout.strip().splitlines()[-1]), "mb": path.stat().st_size / 1e6}


def big_files(tmp: Path, big_mb: float, small_mb: float) -> None:
    """The large-file figures (issue 19): streamed import speed and memory against ezc3d's own read."""
    from haptify_tools.example_session import TOUCH_DEVICE

    m = {"source": "c3d", "session": {"date": "2026-11-25", "lab": {"id": "bench"}, "examiner": {"id": "bench"},
                                      "device": TOUCH_DEVICE, "device_placement": {"position": [0, 0, 0], "quaternion": [1, 0, 0, 0]}},
         "trial": {"powered": False}, "platform_wrench": {},
         "streams": {"sync": {"columns": {"trigger": {"source": "Trigger", "threshold": 2.5}}}}}
    (tmp / "big.json").write_text(json.dumps(m))
    small = big_c3d(tmp / "small.c3d", small_mb)
    runs = {"ezc3d read (slice)": measure("ezc3d", small, tmp),
            "whole-file import (slice)": measure("import", small, tmp, stream=False),
            "streamed import (slice)": measure("import", small, tmp)}
    small.unlink()
    big = big_c3d(tmp / "big.c3d", big_mb)
    runs["streamed import (large)"] = measure("import", big, tmp)
    runs["haptify import, with validation (large)"] = measure("haptify import", big, tmp)
    runs["haptify validate, streams in chunks (large)"] = measure("haptify validate", big, tmp)
    runs["validation, streams read whole (large)"] = measure("validate whole", big, tmp)
    session_mb = sum(f.stat().st_size for f in (tmp / "session").rglob("*") if f.is_file()) / 1e6
    big.unlink()
    for name, r in runs.items():
        speed = r["mb"] / r["s"]
        print(f"{name}: {r['mb']:.0f} MB in {r['s']:.1f} s = {speed:.1f} MB/s, peak RSS {r['rss_mb']:.0f} MB"
              + ("" if r["ok"] else " (ran out of its address-space limit)"))
    ez, slice_, large = runs["ezc3d read (slice)"], runs["streamed import (slice)"], runs["streamed import (large)"]
    ratio = (slice_["mb"] / slice_["s"]) / (ez["mb"] / ez["s"])
    report(f"streamed C3D import speed, {slice_['mb']:.0f} MB file", "faster than ezc3d's own read",
           f"{slice_['mb'] / slice_['s']:.1f} MB/s", f"ezc3d.c3d {ez['mb'] / ez['s']:.1f} MB/s", ratio, ratio > 1)
    report(f"streamed C3D import peak RSS, {large['mb']:.0f} MB file", "below the file's size (issue 19)",
           f"{large['rss_mb']:.0f} MB at {large['mb'] / large['s']:.1f} MB/s",
           f"ezc3d.c3d {ez['rss_mb']:.0f} MB for {ez['mb']:.0f} MB", large["rss_mb"] / large["mb"],
           large["rss_mb"] < large["mb"])
    cli_import, cli_validate = runs["haptify import, with validation (large)"], runs["haptify validate, streams in chunks (large)"]
    whole = runs["validation, streams read whole (large)"]
    print(f"the imported session: {session_mb:.0f} MB of Parquet; validating it: {cli_validate['s']:.1f} s in chunks, "
          f"{whole['s']:.1f} s with every stream read whole")
    report(f"haptify import (with validation) peak RSS, {large['mb']:.0f} MB C3D", "below the file's size (issue 19)",
           f"{cli_import['rss_mb']:.0f} MB in {cli_import['s']:.1f} s", f"import alone {large['rss_mb']:.0f} MB",
           cli_import["rss_mb"] / large["mb"], cli_import["rss_mb"] < large["mb"])
    report(f"haptify validate peak RSS, session of a {large['mb']:.0f} MB C3D", "below the file's size (issue 19)",
           f"{cli_validate['rss_mb']:.0f} MB in {cli_validate['s']:.1f} s",
           f"streams read whole {whole['rss_mb']:.0f} MB in {whole['s']:.1f} s", cli_validate["rss_mb"] / large["mb"],
           cli_validate["rss_mb"] < large["mb"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--big-mb", type=float, default=1200.0, help="size of the large C3D file, MB")
    parser.add_argument("--small-mb", type=float, default=150.0, help="size of the slice ezc3d reads whole, MB")
    args = parser.parse_args()
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
        big_files(tmp, args.big_mb, args.small_mb)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
