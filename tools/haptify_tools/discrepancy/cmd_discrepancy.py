"""``haptify discrepancy``: where twin and measurement disagree, the missing effect, the gap before/after (discrepancy README).

Plugin of the ``haptify.commands`` entry-point group:
``discrepancy = "haptify_tools.discrepancy.cmd_discrepancy:register"``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from haptify.codes import Code
from haptify.errors import fail

from haptify_tools.cluster import dask_client
from haptify_tools.discrepancy.workflow import run_discrepancy
from haptify_tools.twin.model import load_twin


def register(subparsers) -> None:
    """Add ``haptify discrepancy`` (discrepancy README, command line)."""
    p = subparsers.add_parser(
        "discrepancy",
        help="find where a device twin and a measured session disagree and name the missing effect",
        description="Re-simulate every force trial of the measured session with the twin along the measured hand "
        "path, localise and rank the disagreement, name missing effects from the library of the twin's "
        "effect ids (held-out blocks, BIC, F test), write the updated twin OUT/twin.json, "
        "OUT/discrepancy.json and OUT/report.html.",
    )
    p.add_argument("--session", required=True, metavar="MEASURED", help="the measured session folder")
    p.add_argument("--twin", required=True, metavar="TWIN.json", help="the twin to start from")
    p.add_argument("-o", "--out", required=True, metavar="OUT", help="output folder")
    p.add_argument("--max-effects", type=int, default=5, metavar="N", help="accept at most N effects (default 5)")
    p.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    p.add_argument("--no-overlay", action="store_true", help="do not write OUT/overlay.rrd (the viewer recording)")
    p.add_argument(
        "--workers", type=int, default=0, help="processes fitting candidates in parallel (default: one per CPU, at most 4)"
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the candidates' simulations on an existing Dask cluster instead, e.g. tcp://host:8786",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace, ui) -> int:
    """Run ``haptify discrepancy`` (discrepancy README, command line); exit 0 when the outputs were written (whatever the verdict)."""
    if args.max_effects < 0:
        raise fail(Code.USAGE, "--max-effects must be at least 0", expected=">= 0", found=args.max_effects)
    out = Path(args.out)
    if out.exists() and not args.overwrite:
        raise fail(Code.OUTPUT_EXISTS, f"{str(out)!r} already exists", file=str(out))
    twin = load_twin(args.twin)
    with dask_client(getattr(args, "scheduler", None), 0) as client:
        result, _ = run_discrepancy(
            args.session,
            twin,
            out,
            max_effects=args.max_effects,
            overwrite=args.overwrite,
            log=ui.say,
            workers=args.workers,
            overlay=not args.no_overlay,
            client=client,
        )
    named = ", ".join(f"{a.effect_id} {a.parameter}={a.value:.4g} {a.unit}" for a in result.accepted) or "none"
    ui.say(f"{result.verdict}: effects named: {named}; {result.gap_summary()}; wrote {out}")
    ui.emit_json(
        {
            "ok": True,
            "out": str(out),
            "verdict": result.verdict,
            "accepted": [a.model_dump(mode="json") for a in result.accepted],
            "heldout_gap_before_N": result.heldout_gap_before_N,
            "heldout_gap_after_N": result.heldout_gap_after_N,
            "floor_N": result.floor_N,
        }
    )
    return 0
