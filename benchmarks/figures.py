"""One line per benchmark figure that ``benchmarks/run.py`` collects into the generated results table.

A script calls :func:`report` for each target it measures; the line it prints starts with ``RESULT`` and
carries the figure as JSON (figure, target, measured, peer, ratio, holds), so no number is copied by hand
into benchmarks/RESULTS-table.md (issue 21, item 5).
"""

from __future__ import annotations

import json

PREFIX = "RESULT "


def report(figure: str, target: str, measured: str, peer: str = "", ratio: float | None = None,
           holds: bool | None = None) -> None:
    """Print one figure: what was measured against which target, the peer measured in the same run and
    the ratio that the target is stated in (``None`` where a target has no peer)."""
    print(PREFIX + json.dumps({"figure": figure, "target": target, "measured": measured, "peer": peer,
                               "ratio": None if ratio is None else round(float(ratio), 3), "holds": holds},
                              ensure_ascii=False), flush=True)
