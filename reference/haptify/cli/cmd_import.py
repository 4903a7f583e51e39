"""``haptify import [c3d|tsv|motive|nexus|csv] FILE -o SESSION [--map MAP.json]`` (spec §5.8).

Without a format word (or with ``auto``) a motion-capture file's format is recognised from its content.

With ``--map`` the map supplies every fact the source does not hold; the options below override the
map's fields (one map, many files). Without a map (C3D only) the options must supply them: ``--device``,
``--lab``, ``--examiner``, ``--date``, ``--placement`` and ``--powered``; the file's markers (and its
first force platform) become an ``other`` trial labelled with the file's name. ``--append`` adds the
file as one more trial of an existing session, whose facts fill what the map and options leave out.
``--list`` describes a C3D file (labels, units, rates, platforms) without writing anything.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.importers import (
    MOCAP_SOURCES,
    Destination,
    ImportResult,
    LoadedMap,
    Recording,
    detect_format,
    import_c3d,
    import_csv,
    import_export,
    load_map,
    read_c3d,
    read_export,
)
from haptify.formats.validation import validate_session

if TYPE_CHECKING:
    from haptify.cli.ui import UI, Advance, Subcommands

# option name -> the map field it fills (for the error that lists what is missing without a map)
_OPTION_OF_FIELD = {
    "/session/date": "--date",
    "/session/lab": "--lab",
    "/session/examiner": "--examiner",
    "/session/device": "--device",
    "/session/device_placement": "--placement",
    "/trial/powered": "--powered",
    "/session": "--device, --lab, --examiner, --date, --placement",
    "/trial": "--powered",
}


def register(sub: Subcommands) -> None:
    """Add ``import c3d`` and ``import csv`` with their options (spec §5.8)."""
    p = sub.add_parser("import", help="import a C3D file or a CSV log as a session", description=__doc__.splitlines()[0])
    kinds = p.add_subparsers(dest="import_kind", metavar="FORMAT", required=True)
    for fmt, text in FORMATS.items():
        q = kinds.add_parser(fmt, help=f"import {text}")
        q.add_argument("file", type=Path, help="the source file")
        q.add_argument("-o", "--output", type=Path, help="the session folder to create")
        q.add_argument(
            "--map", type=Path, help="import map (JSON; import-map.schema.json)" + (" — required" if fmt == "csv" else "")
        )
        q.add_argument(
            "--suggest-map",
            action="store_true",
            help="print a map guessed from the file's labels, bodies, platforms or columns (placeholders for the facts it cannot hold) and what it could not place; write nothing",
        )
        q.add_argument("--overwrite", action="store_true", help="replace an existing session folder")
        q.add_argument(
            "--append",
            action="store_true",
            help="add the file as one more trial of the existing session SESSION (its facts need not be repeated)",
        )
        g = q.add_argument_group("session facts (override the map; required for a motion-capture file without --map)")
        g.add_argument("--device", type=Path, help="device description (device.json), copied into the session")
        g.add_argument("--lab", help="pseudonymous lab id")
        g.add_argument("--examiner", help="pseudonymous examiner id")
        g.add_argument("--date", help="recording date, YYYY-MM-DD")
        g.add_argument(
            "--placement", help="device frame in W: 'x,y,z' in m, optionally ',qw,qx,qy,qz' (default orientation: aligned with W)"
        )
        g.add_argument("--powered", choices=["yes", "no"], help="was the device powered during the trial")
        g.add_argument("--session-id", help="session id (default: the file's name)")
        g.add_argument("--trial-id", help="trial id (default: the file's name)")
        g.add_argument("--repetition", type=int, help="repetition number of the trial")
        if fmt != "csv":
            g.add_argument("--plate", help="force platform that defines W: a number, or 'none' (default: 1 when present)")
            q.add_argument(
                "--list", action="store_true", help="describe the file (labels, bodies, units, rates, platforms) and exit"
            )
        q.set_defaults(func=run)


FORMATS = {
    "c3d": "a C3D motion-capture file (Vicon, Qualisys, OptiTrack, markerless, …)",
    "tsv": "a Qualisys Track Manager TSV export (3-D markers and 6DOF bodies)",
    "motive": "an OptiTrack Motive CSV export (markers and rigid bodies)",
    "nexus": "a Vicon Nexus CSV export (trajectories, model outputs, segments, devices)",
    "auto": "a motion-capture file of any of the formats above, recognised from its content (the default: `haptify import FILE`)",
    "csv": "a column-mapped CSV log (ATI F/T log, CHAI3D log, …)",
}


def implicit_format(argv: list[str]) -> list[str]:
    """``haptify import FILE …`` without a format word means ``haptify import auto FILE …`` (spec §5.8):
    the word after ``import`` is a format when it names one, an option when it starts with ``-``, and
    otherwise the file, recognised by its content."""
    if "import" not in argv:
        return argv
    k = argv.index("import") + 1
    if k < len(argv) and argv[k] not in FORMATS and not argv[k].startswith("-"):
        return [*argv[:k], "auto", *argv[k:]]
    return argv


def _format_of(args: argparse.Namespace) -> str:
    """The source format: the sub-command's, or for ``auto`` the one the file's content shows (§5.8)."""
    if args.import_kind != "auto":
        return str(args.import_kind)
    fmt = detect_format(args.file)
    if fmt is None:
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE,
            f"{str(args.file)!r} is none of the motion-capture formats {list(MOCAP_SOURCES)}",
            file=str(args.file),
            expected=list(MOCAP_SOURCES),
            found=None,
        )
    return fmt


def _read(fmt: str, path: Path) -> Recording:
    if fmt == "c3d":
        return read_c3d(path)
    return read_export(fmt, path)


def _placement(text: str) -> dict[str, list[float]]:
    try:
        vals = [float(v) for v in text.replace(" ", ",").split(",") if v]
    except ValueError:
        vals = []
    if len(vals) not in (3, 7):
        raise fail(Code.USAGE, "--placement takes 'x,y,z' or 'x,y,z,qw,qx,qy,qz'", expected="3 or 7 numbers", found=text)
    return {"position": vals[:3], "quaternion": vals[3:] if len(vals) == 7 else [1.0, 0.0, 0.0, 0.0]}


def overrides_from(args: argparse.Namespace) -> dict[str, Any]:
    """The map fields the command-line options set (spec §5.8)."""
    session: dict[str, Any] = {}
    trial: dict[str, Any] = {}
    if args.device is not None:
        session["device"] = {"file": str(args.device.resolve())}
    for opt, key in (("lab", "lab"), ("examiner", "examiner")):
        if getattr(args, opt) is not None:
            session[key] = {"id": getattr(args, opt)}
    if args.date is not None:
        session["date"] = args.date
    if args.placement is not None:
        session["device_placement"] = _placement(args.placement)
    if args.session_id is not None:
        session["session_id"] = args.session_id
    if args.powered is not None:
        trial["powered"] = args.powered == "yes"
    if args.trial_id is not None:
        trial["id"] = args.trial_id
    if args.repetition is not None:
        trial["repetition"] = args.repetition
    out: dict[str, Any] = {}
    if session:
        out["session"] = session
    if trial or args.map is None:
        out["trial"] = trial
    plate = getattr(args, "plate", None)
    if plate is not None:
        out["force_plate"] = "none" if plate == "none" else (int(plate) if plate.isdigit() else plate)
    return out


def _load(args: argparse.Namespace, fmt: str, facts: dict[str, Any] | None) -> LoadedMap:
    try:
        return load_map(args.map, fmt, overrides_from(args), facts)
    except HaptifyError as err:
        if args.map is not None:
            raise
        missing = sorted(
            {_OPTION_OF_FIELD.get(f.pointer or "", f.pointer or "") for f in err.findings if "missing" in (f.expected, f.found)}
        )
        if missing:
            raise fail(
                Code.USAGE, "without --map, give the session facts on the command line", expected=missing, found="missing"
            ) from None
        raise fail(Code.USAGE, "; ".join(f"{f.pointer}: {f.message}" for f in err.findings), found="invalid option") from None


def _suggest(fmt: str, args: argparse.Namespace, ui: UI) -> int:
    """``--suggest-map`` (spec §5.11): the guessed map on stdout, what it could not place on stderr."""
    import json

    from haptify.formats.suggest_map import suggest_csv_map, suggest_recording_map

    if fmt == "csv":
        if not args.file.is_file():
            raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{str(args.file)!r} does not exist or is not a file", file=str(args.file))
        m, unplaced = suggest_csv_map(args.file)
    else:
        m, unplaced = suggest_recording_map(_read(fmt, args.file))
    if ui.json_mode:
        ui.emit_json({"map": m, "unplaced": unplaced})
        return 0
    print(json.dumps(m, indent=2, ensure_ascii=False))
    for note in unplaced:
        ui.warn(f"not placed: {note}")
    return 0


def _importer(fmt: str, advance: Advance) -> Callable[[Path, Destination, LoadedMap], ImportResult]:
    """The import function of ``fmt``, reporting a streamed file's frames to ``advance`` (§5.5.1)."""
    if fmt == "csv":
        return import_csv
    seen = [0]

    def progress(done: int, total: int) -> None:
        advance(done - seen[0], total=total)
        seen[0] = done

    if fmt == "c3d":
        return lambda path, dest, loaded: import_c3d(path, dest, loaded, progress=progress)
    return lambda path, dest, loaded: import_export(fmt, path, dest, loaded, progress=progress)


def run(args: argparse.Namespace, ui: UI) -> int:
    """Import (or ``--list``) one source file; exit 0 valid, 1 imported but invalid (spec §5.8)."""
    fmt = _format_of(args)
    if args.suggest_map:
        return _suggest(fmt, args, ui)
    if fmt == "csv" and args.map is None:
        raise fail(
            Code.USAGE,
            "haptify import csv needs --map MAP.json (--suggest-map prints one to start from)",
            expected="--map MAP.json",
            found=None,
        )
    if fmt != "csv" and args.list:
        summary = _read(fmt, args.file).summary()
        if ui.json_mode:
            ui.emit_json(summary)
        else:
            mk, an = summary["markers"], summary["analog"]
            ui.say(f"{summary['file']} ({summary['manufacturer'] or 'unknown system'})")
            ui.say(f"markers: {mk['count']} at {mk['rate_hz']:g} Hz, {mk['frames']} frames, units {mk['units']}")
            ui.say("  " + ", ".join(mk["labels"]))
            if summary["bodies"]["count"]:
                ui.say(f"6-DoF bodies: {summary['bodies']['count']}")
                ui.say("  " + ", ".join(summary["bodies"]["labels"]))
            ui.say(f"analog: {an['count']} channels at {an['rate_hz']:g} Hz, {an['samples']} samples")
            ui.say("  " + ", ".join(f"{c['label']} [{c['unit']}]" for c in an["channels"]))
            for p in summary["force_platforms"]:
                ui.say(
                    f"force platform {p['number']}: type {p['type']}, channels "
                    + (", ".join(p["channels"]) or "none")
                    + (" (calibration matrix)" if p["calibrated"] else "")
                )
            for w in summary["warnings"]:
                ui.warn(f"{w['code']} warning: {w['message']}")
        return 0
    if args.output is None:
        raise fail(Code.USAGE, f"haptify import {fmt} needs -o SESSION", expected="-o SESSION", found=None)
    dest = Destination.of(args.output, overwrite=args.overwrite, append=args.append)
    loaded = _load(args, fmt, dest.session_facts())
    with ui.progress(f"importing {args.file.name}", total=None) as advance:
        result = _importer(fmt, advance)(args.file, dest, loaded)
        report = validate_session(result.session)
    if ui.json_mode:
        ui.emit_json(
            {**result.to_dict(), "validation": {"valid": report.valid, "findings": [f.to_dict() for f in report.findings]}}
        )
        return report.exit_code
    ui.say(f"wrote {result.session} (session {result.session_id}, trial {result.trial_id})")
    for s in result.streams:
        ui.say(f"  {s['kind']:16s} {s['rows']:8d} rows at {s['rate_hz']:g} Hz, {s['columns']} columns")
    ui.say(f"  {result.world_frame}")
    for w in result.warnings:
        ui.warn(str(w))
    for f in report.findings:
        ui.warn(str(f))
    ui.say(
        "the session validates" + (f" ({len(report.warnings)} warnings)" if report.warnings else "")
        if report.valid
        else "the session does NOT validate (see above)"
    )
    return report.exit_code
