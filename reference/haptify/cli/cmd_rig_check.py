"""``haptify rig-check SESSION [--json]``: the rig against the paper's requirements (spec §14.8).

One line per check — PASS, FAIL, WARN (an advisory shortfall the paper's own rig shares) or SKIP (the
session lacks the trial or description the check needs). Exit 1 when any check FAILs, else 0.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from haptify.metrics.rig_checks import check_rig
from haptify.pipeline.compute import ComputeContext
from haptify.pipeline.gate import require_valid_session

if TYPE_CHECKING:
    from haptify.cli.ui import UI, Subcommands


def register(sub: Subcommands) -> None:
    """Add the ``rig-check`` sub-command (spec §14.8)."""
    p = sub.add_parser("rig-check", help="check the rig against the paper's requirements (Table I, Appendix)")
    p.add_argument("session", type=Path)
    p.set_defaults(func=run)


def run(args: argparse.Namespace, ui: UI) -> int:
    """Print (or emit as JSON) one line per rig check; exit 1 when any check FAILs (spec §14.8)."""
    session, _ = require_valid_session(args.session)
    checks = check_rig(ComputeContext(session=session))
    failed = [c for c in checks if c.status == "FAIL"]
    if ui.json_mode:
        ui.emit_json({"session_id": session.session_id, "ok": not failed, "checks": [c.to_dict() for c in checks]})
    else:
        for c in checks:
            line = f"{c.status:4s}  {c.name}: {c.value if c.value is not None else '-'}  (required {c.requirement})"
            if c.detail:
                line += f"  [{c.detail}]"
            ui.say(line)
        ui.say(
            f"{len(checks) - len(failed)} of {len(checks)} checks did not fail" + (f"; {len(failed)} FAILED" if failed else "")
        )
    return 1 if failed else 0
