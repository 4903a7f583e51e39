"""The one rule of every generator in this folder: write the files, or ``--check`` that they are current."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Callable


def generator_main(
    argv: list[str] | None, description: str, module: str, what: str, targets: Callable[[], dict[Path, str]]
) -> int:
    """Compare every ``path → text`` of ``targets()`` with the file; write the stale ones, or with
    ``--check`` list them and return 1 (so a test fails when a committed file drifts from its source)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--check", action="store_true", help=f"exit 1 when a committed {what} is stale")
    args = parser.parse_args(argv)
    stale = [path for path, text in targets().items() if (path.read_text(encoding="utf-8") if path.exists() else None) != text]
    if args.check:
        if stale:
            print(f"stale {what} (run python -m {module}):", *map(str, stale), sep="\n  ")
            return 1
        return 0
    generated = targets()
    for path in stale:
        path.write_text(generated[path], encoding="utf-8")
    print(f"wrote {len(stale)} {what}")
    return 0
