"""``haptify compare A/results.json B/results.json … [--paper] [--format md|csv|html] [-o FILE]`` (spec §15.5)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from haptify.formats.storage import atomic_write_text
from haptify.pipeline.compare import build_table, to_csv, to_html_document, to_markdown
from haptify.pipeline.results import load_results

if TYPE_CHECKING:
    from haptify.cli.ui import UI, Subcommands

RENDERERS = {"md": to_markdown, "csv": to_csv, "html": to_html_document}


def register(sub: Subcommands) -> None:
    """Add the ``compare`` sub-command (spec §15.5)."""
    p = sub.add_parser("compare", help="lay out results of several devices side by side (the paper's Table III)")
    p.add_argument("results", nargs="+", type=Path, help="results.json files, one per device")
    p.add_argument("--paper", action="store_true", help="add the paper's published values")
    p.add_argument("--format", choices=sorted(RENDERERS), default="md")
    p.add_argument("-o", "--output", type=Path, help="write the table to this file instead of stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, ui: UI) -> int:
    """Print, emit as JSON or write the Table III-style comparison of the results files (spec §15.5)."""
    table = build_table([load_results(p) for p in args.results], with_paper=args.paper)
    text = RENDERERS[args.format](table)
    if args.output:
        atomic_write_text(args.output, text)
        ui.say(f"wrote {args.output}")
    elif ui.json_mode:
        ui.emit_json({"header": table.header, "rows": table.rows, "notes": table.notes})
    else:
        print(text, end="")
    return 0
