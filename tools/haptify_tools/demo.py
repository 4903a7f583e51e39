"""``make demo``: the main job on built-in data, through the same commands a lab uses.

Simulates a full benchmarking dossier (every protocol, three repetitions, the rig's calibration trials)
of the paper's two devices with the device twin, validates both sessions, computes every metric, lays
the results out as the paper's Table III beside the published values, writes an HTML report with
figures and sounds per device, saves a viewer recording, and runs the discrepancy workflow on a session
with hidden effects. Everything goes to ``--out``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from haptify.cli.main import main as haptify
from haptify_tools.discrepancy.demo import demo as discrepancy_demo

DEVICES = (("touch", 1), ("touch-x", 2))  # preset and seed


def step(title: str, argv: list[str]) -> None:
    """Run one ``haptify`` command, stopping the demo when it fails."""
    print(f"\n== {title}\n$ haptify {' '.join(argv)}", flush=True)
    start = time.perf_counter()
    code = haptify(argv)
    if code != 0:
        print(f"demo stopped: 'haptify {argv[0]}' exited {code}", file=sys.stderr)
        raise SystemExit(code)
    print(f"   ({time.perf_counter() - start:.1f} s)", flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("demo-out"))
    args = parser.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    results = []
    for preset, seed in DEVICES:
        folder = out / preset
        step(
            f"simulate the {preset} dossier (device twin + virtual rig)",
            [
                "simulate",
                "--preset",
                preset,
                "--protocol",
                "all",
                "--reps",
                "3",
                "--seed",
                str(seed),
                "--compact",
                "-o",
                str(folder),
                "--overwrite",
            ],
        )
        step(f"validate the {preset} session", ["validate", str(folder / "session")])
        result = out / f"{preset}.results.json"
        step(f"compute every benchmark of the {preset}", ["compute", str(folder / "session"), "-o", str(result)])
        step(
            f"report for the {preset}",
            ["report", str(folder / "session"), "--results", str(result), "-o", str(out / f"{preset}-report"), "--overwrite"],
        )
        results.append(str(result))
    for fmt in ("csv", "html", "md"):
        step(f"Table III as {fmt}", ["compare", *results, "--paper", "--format", fmt, "-o", str(out / f"table.{fmt}")])
    print("\n" + (out / "table.md").read_text(encoding="utf-8"))
    rrd = out / "touch-stiffness.rrd"
    step(
        "viewer recording of the Touch's stiffness trial",
        ["view", str(out / "touch" / "session"), "--trial", "stiffness-1", "--results", results[0], "--save", str(rrd)],
    )
    print(
        "\n== the discrepancy workflow: a touch session with hidden series elasticity and Coulomb friction, "
        "the twin started without both",
        flush=True,
    )
    start = time.perf_counter()
    discrepancy_demo(out / "discrepancy")
    print(f"   ({time.perf_counter() - start:.1f} s)")
    print(
        f"\nDone. Everything is in {out}/:\n"
        f"  table.md / table.csv / table.html — the benchmark table beside the paper's Table III\n"
        f"  touch-report/index.html, touch-x-report/index.html — figures, every metric, vibration sounds\n"
        f"  discrepancy/ — the named effects, twin.json, report.html, overlay.rrd\n"
        f"  {rrd.name} — open with  .venv/bin/rerun {rrd}  (or: .venv/bin/haptify view {out}/touch/session --web)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
