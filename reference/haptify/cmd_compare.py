"""``haptify compare A/results.json B/results.json … [--paper] [--format md|csv|html] [-o FILE]`` (spec §15.5)."""

from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError

from haptify.compare import build_table, to_csv, to_html, to_markdown
from haptify.errors import HaptifyError, fail
from haptify.results import ResultsFile
from haptify.storage import atomic_write_text, parse_json_file, pydantic_findings

RENDERERS = {"md": to_markdown, "csv": to_csv, "html": to_html}


def register(sub) -> None:
    p = sub.add_parser("compare", help="lay out results of several devices side by side (the paper's Table III)")
    p.add_argument("results", nargs="+", type=Path, help="results.json files, one per device")
    p.add_argument("--paper", action="store_true", help="add the paper's published values")
    p.add_argument("--format", choices=sorted(RENDERERS), default="md")
    p.add_argument("-o", "--output", type=Path, help="write the table to this file instead of stdout")
    p.set_defaults(func=run)


def load_results(path: Path) -> ResultsFile:
    """Read and check a results.json (E103-style JSON errors as E104 findings naming the file)."""
    if not path.is_file():
        raise fail("E101", f"{str(path)!r} does not exist", file=str(path))
    data = parse_json_file(path, "E104", str(path))
    try:
        return ResultsFile.model_validate(data)
    except ValidationError as exc:
        raise HaptifyError(*pydantic_findings(exc, "E104", str(path))) from None


def run(args, ui) -> int:
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
