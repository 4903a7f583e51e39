"""``haptify report SESSION -o DIR [--results results.json] [--wav-scale A] [--overwrite]`` (spec §15.6)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

from haptify.codes import Code
from haptify.errors import fail
from haptify.pipeline.compute import ComputeContext, compute_session
from haptify.pipeline.families import family_modules
from haptify.pipeline.gate import as_result_warnings, require_valid_session
from haptify.pipeline.results import load_results
from haptify.report.document import write_report

if TYPE_CHECKING:
    from haptify.cli.ui import UI, Subcommands


def register(sub: Subcommands) -> None:
    """Add the ``report`` sub-command; ``--wav-scale`` in m/s² (spec §15.6)."""
    p = sub.add_parser("report", help="an HTML report with figures and vibration sounds")
    p.add_argument("session", type=Path)
    p.add_argument("-o", "--output", type=Path, required=True, help="report folder to create")
    p.add_argument("--results", type=Path, help="use these results instead of computing them")
    p.add_argument(
        "--wav-scale",
        type=float,
        help="divide vibration audio by this (m/s^2), as the paper did, "
        "to compare devices; default: this session's largest amplitude",
    )
    p.add_argument("--overwrite", action="store_true")
    p.add_argument(
        "--uncertainty",
        action="store_true",
        help="compute each metric's uncertainty too (spec chapter 19; results given with --results keep theirs)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace, ui: UI) -> int:
    """Compute (or read) the results and write the report folder (spec §15.6)."""
    if args.wav_scale is not None and not (math.isfinite(args.wav_scale) and args.wav_scale > 0):
        # 0 silently meant "the default", a negative scale inverted the audio and NaN wrote NaN samples
        raise fail(Code.USAGE, "--wav-scale must be a positive amplitude in m/s^2", expected="> 0", found=args.wav_scale)
    session, validation_warnings = require_valid_session(args.session)
    ctx = ComputeContext(session=session)
    if args.results:
        results = load_results(args.results)
        if results.session_id != session.session_id:
            raise fail(
                Code.USAGE,
                "the results belong to another session",
                file=str(args.results),
                expected=session.session_id,
                found=results.session_id,
            )
    else:
        with ui.progress("computing metrics", total=len(family_modules())) as advance:
            results = compute_session(session, progress=advance, ctx=ctx, uncertainty=args.uncertainty)
        results.warnings = as_result_warnings(validation_warnings) + results.warnings
    out = write_report(ctx, results, args.output, wav_scale=args.wav_scale, overwrite=args.overwrite)
    ui.say(f"wrote {out / 'index.html'}")
    ui.emit_json({"report": str(out / "index.html")})
    return 0
