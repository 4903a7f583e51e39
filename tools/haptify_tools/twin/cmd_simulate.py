"""``haptify simulate`` and ``haptify twin export``: the device twin on the command line (TWIN.md).

Two plugins of the ``haptify.commands`` entry-point group:

- ``simulate = "haptify_tools.twin.cmd_simulate:register_simulate"``
- ``twin = "haptify_tools.twin.cmd_simulate:register_twin"``
"""

from __future__ import annotations

import argparse
from pathlib import Path

from haptify.codes import Code
from haptify.errors import fail

from haptify_tools.twin.model import EFFECT_IDS, PRESETS, TwinFile, disable, load_twin, preset, set_param, write_twin
from haptify_tools.twin.dossier_plan import DEFAULT_DURATIONS, SimulationOptions, name_number, parse_protocols, plan
from haptify_tools.twin.simulate import simulate_dossier
from haptify_tools.twin.rig import RigConfig
from haptify_tools.twin.round_robin import SPREADS, parse_spreads, simulate_round_robin, trial_count


def _add_twin_source(p: argparse.ArgumentParser, required: bool = True) -> None:
    src = p.add_mutually_exclusive_group(required=required)
    src.add_argument("--preset", choices=PRESETS, help="a built-in device twin")
    src.add_argument("--twin", metavar="TWIN.json", help="a twin file (haptify twin export writes one)")
    p.add_argument(
        "--disable",
        metavar="EFFECT",
        action="append",
        default=[],
        help="switch an effect off (repeatable); effects: " + ", ".join(EFFECT_IDS),
    )
    p.add_argument(
        "--set",
        metavar="EFFECT.PARAM=VALUE",
        action="append",
        default=[],
        dest="set_params",
        help="change one parameter (repeatable), e.g. friction.coulomb.torque_Nm=0.02 or "
        "drive.torque_saturation.max_torque_Nm[1]=0.4; VALUE is JSON",
    )


def twin_from_args(args: argparse.Namespace) -> TwinFile:
    """The twin named by ``--preset``/``--twin`` with every ``--disable`` and ``--set`` applied (E801/E802/E903)."""
    twin = preset(args.preset) if args.preset else load_twin(args.twin)
    for effect in args.disable:
        twin = disable(twin, effect)
    for item in args.set_params:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise fail(Code.USAGE, f"--set expects EFFECT.PARAM=VALUE, got {item!r}", expected="EFFECT.PARAM=VALUE", found=item)
        twin = set_param(twin, key.strip(), value)
    return twin


def _durations(items: list[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items:
        name, seconds = name_number(item)
        if name not in DEFAULT_DURATIONS or not seconds > 0:
            raise fail(
                Code.USAGE,
                f"--duration expects NAME=SECONDS with a known protocol and a positive time, got {item!r}",
                expected=sorted(DEFAULT_DURATIONS),
                found=item,
            )
        out[name] = seconds
    return out


# --- haptify simulate --------------------------------------------------------------------------


def register_simulate(subparsers) -> None:
    """Add ``haptify simulate`` (tools, not the standard; TWIN.md)."""
    p = subparsers.add_parser(
        "simulate",
        help="simulate a benchmarking dossier of a device twin into a standard session",
        description="Simulate every protocol (× repetitions) and the rig's calibration trials "
        "into ONE standard session OUT/session, with the ground truth in "
        "OUT/truth.json and OUT/truth.npz beside it. Deterministic for a seed.",
    )
    _add_twin_source(p)
    p.add_argument(
        "--protocol",
        default="all",
        metavar="all|NAME[,NAME...]",
        help="device protocols (workspace, free_space, local_dynamic, figure_eight, frictionless_surface, "
        "stiffness) and/or rig trials (rig.*); default all",
    )
    p.add_argument("--reps", type=int, default=3, help="repetitions of each device protocol (default 3)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("-o", "--out", required=True, metavar="DIR", help="output folder (holds session/, truth.json, truth.npz)")
    p.add_argument("--overwrite", action="store_true", help="replace DIR if it exists")
    p.add_argument("--no-rig-trials", action="store_true", help="leave out the rig calibration trials not named in --protocol")
    p.add_argument(
        "--clock-offsets",
        action="store_true",
        help="give the accelerometer and motion capture their own clocks (clock_offset records in the session)",
    )
    p.add_argument("--duration", action="append", default=[], metavar="NAME=SECONDS", help="override a trial duration")
    p.add_argument("--workers", type=int, default=0, help="parallel processes (default: one per CPU, at most 4)")
    p.add_argument("--format", choices=("parquet", "csv"), default="parquet", help="stream file format")
    p.add_argument(
        "--compact",
        action="store_true",
        help="Parquet: store the sensor columns as float32 (every simulated sensor is far coarser; spec §3.2.1)",
    )
    p.add_argument(
        "--lab-variation",
        type=int,
        default=0,
        metavar="N",
        help="a round robin: N virtual labs (own rig, own examiner, drawn from --seed) each measure the twin "
        "--reps times; writes OUT/lab-01/ … and OUT/labs.json (what each lab's rig was)",
    )
    p.add_argument(
        "--lab-spread",
        action="append",
        default=[],
        metavar="NAME=SD",
        help="how far the labs differ (repeatable; with --lab-variation): "
        + "; ".join(f"{k} (default {s.default:g})" for k, s in SPREADS.items()),
    )
    p.set_defaults(func=run_simulate)


def run_simulate(args: argparse.Namespace, ui) -> int:
    """Run ``haptify simulate``; exit 0 when the dossier was written."""
    if args.reps < 1:
        raise fail(Code.USAGE, "--reps must be at least 1", expected=">= 1", found=args.reps)
    if args.lab_variation < 0 or args.lab_variation == 1 or (args.lab_spread and not args.lab_variation):
        raise fail(
            Code.USAGE,
            "--lab-variation needs at least two labs (and --lab-spread needs --lab-variation)",
            expected="--lab-variation N, N ≥ 2",
            found=args.lab_variation,
        )
    spreads = parse_spreads(args.lab_spread)
    twin = twin_from_args(args)
    options = SimulationOptions(
        protocols=parse_protocols(args.protocol),
        reps=args.reps,
        seed=args.seed,
        rig_trials=not args.no_rig_trials,
        durations=_durations(args.duration),
        rig=RigConfig(clock_offsets=args.clock_offsets),
        workers=args.workers,
        fmt=args.format,
        compact=args.compact,
    )
    if args.lab_variation:
        return _run_round_robin(twin, options, args, spreads, ui)
    total = len(plan(options))
    with ui.progress(f"simulating {twin.name}", total) as advance:
        result = simulate_dossier(twin, Path(args.out), options, overwrite=args.overwrite, advance=advance)
    ui.say(
        f"wrote {result.session} ({len(result.trials)} trials, {result.recorded_s / 60:.1f} min recorded); "
        f"truth in {result.truth_json.name} and {result.truth_npz.name}"
    )
    ui.emit_json(
        {
            "ok": True,
            "session": str(result.session),
            "truth": str(result.truth_json),
            "arrays": str(result.truth_npz),
            "trials": result.trials,
            "recorded_s": result.recorded_s,
        }
    )
    return 0


def _run_round_robin(twin: TwinFile, options: SimulationOptions, args: argparse.Namespace, spreads: dict[str, float], ui) -> int:
    with ui.progress(
        f"round robin of {twin.name}: {args.lab_variation} labs", trial_count(options, args.lab_variation)
    ) as advance:
        result = simulate_round_robin(
            twin, Path(args.out), options, args.lab_variation, spreads, overwrite=args.overwrite, advance=advance
        )
    ui.say(
        f"wrote {len(result.sessions)} lab sessions under {result.out_dir} and what each lab's rig was in {result.labs_json.name}"
    )
    ui.emit_json(
        {
            "ok": True,
            "labs": str(result.labs_json),
            "sessions": {k: str(v) for k, v in result.sessions.items()},
            "spreads": spreads,
        }
    )
    return 0


# --- haptify twin export -----------------------------------------------------------------------


def register_twin(subparsers) -> None:
    """Add ``haptify twin export`` (TWIN.md)."""
    p = subparsers.add_parser("twin", help="device twin files", description="Work with device twin files.")
    sub = p.add_subparsers(dest="twin_command", metavar="ACTION", required=True)
    e = sub.add_parser("export", help="write a preset (optionally modified) as a twin file")
    _add_twin_source(e)
    e.add_argument("-o", "--out", required=True, metavar="TWIN.json", help="file to write")
    e.add_argument("--overwrite", action="store_true", help="replace the file if it exists")
    e.set_defaults(func=run_twin_export)


def run_twin_export(args: argparse.Namespace, ui) -> int:
    """Run ``haptify twin export``: the twin with its edits, written atomically."""
    out = Path(args.out)
    if out.exists() and not args.overwrite:
        raise fail(Code.OUTPUT_EXISTS, f"{str(out)!r} already exists", file=str(out))
    twin = twin_from_args(args)
    write_twin(twin, out)
    off = [e for e in EFFECT_IDS if not twin.on(e)]
    ui.say(f"wrote {out} ({twin.name}; effects off: {', '.join(off) or 'none'})")
    ui.emit_json({"ok": True, "twin": str(out), "disabled": off})
    return 0
