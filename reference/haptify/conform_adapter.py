"""The reference implementation behind the conformance protocol (spec §16.4).

``analyse(session, metric, parameters)`` validates the session and, when it is valid, computes the
asked-for metric with the reference; it is what ``--python haptify.conform_adapter:analyse`` calls.
``python -m haptify.conform_adapter`` serves the JSON-lines protocol; with arguments
``SESSION OUT [METRIC [PARAMS]]`` it behaves as a ``--cmd`` program and writes its answer to OUT.

Work shared by the cases of one fixture (the modeled workspace, a fitted dynamic model, calibrated
signals) is kept in a per-session :class:`~haptify.pipeline.compute.ComputeContext`, keyed by the session folder,
the manifest's checksum and the case parameters, for the few most recent sessions.
"""

from __future__ import annotations

import json
import sys
from collections import OrderedDict
from pathlib import Path
from typing import Any

from haptify.errors import HaptifyError
from haptify.formats.storage import MANIFEST, atomic_write_text, open_session, sha256_file
from haptify.formats.validation import validate_session
from haptify.pipeline.compute import ComputeContext, compute_session
from haptify.versions import PACKAGE_VERSION

IMPLEMENTATION = {"name": "haptify-reference", "version": PACKAGE_VERSION}
CONTEXTS_KEPT = 4
_contexts: OrderedDict[tuple[str, str, str], ComputeContext] = OrderedDict()


def _context(session: str, parameters: dict[str, Any], cache: bool) -> ComputeContext:
    folder = open_session(session)
    if not cache:
        return ComputeContext(session=folder, parameters=dict(parameters))
    key = (str(Path(session).resolve()), sha256_file(folder.root / MANIFEST), json.dumps(parameters, sort_keys=True))
    if key not in _contexts:
        _contexts[key] = ComputeContext(session=folder, parameters=dict(parameters))
        while len(_contexts) > CONTEXTS_KEPT:
            _contexts.popitem(last=False)
    _contexts.move_to_end(key)
    ctx = _contexts[key]
    ctx.warnings = []
    out: ComputeContext = ctx
    return out


def analyse(session: str, metric: str = "", parameters: dict[str, Any] | None = None, *, cache: bool = True) -> dict[str, Any]:
    """A results document, or ``{"findings": [...]}`` when the session is rejected (or ``metric == "validate"``).

    ``parameters`` are the case's (spec §16.2); ``{"model": "<file in the session>"}`` makes the dynamics
    metrics use that parameter file instead of fitting (§11.3, §16.2). ``cache=False`` computes afresh.
    """
    parameters = parameters or {}
    report = validate_session(Path(session))
    findings = [f.to_dict() for f in report.findings]
    if not report.valid or metric == "validate":
        return {"findings": findings}
    try:
        ctx = _context(session, parameters, cache)
        results = compute_session(ctx.session, [metric] if metric else None, ctx=ctx)
    except HaptifyError as err:
        return {"findings": [f.to_dict() for f in err.findings]}
    return results.model_dump(mode="json")


def main(argv: list[str] | None = None) -> int:
    """The reference as a conformance implementation: ``SESSION OUT [METRIC [PARAMS.json]]`` (spec §16.4.1),
    or no arguments to serve JSON lines on stdin/stdout (spec §16.4.2)."""
    from haptify_conform.adapters import serve_jsonl

    argv = sys.argv[1:] if argv is None else argv
    if len(argv) in (2, 3, 4):  # SESSION OUT [METRIC [PARAMS.json]]: the --cmd form (spec §16.4.1)
        metric = argv[2] if len(argv) > 2 else ""
        params = json.loads(Path(argv[3]).read_text(encoding="utf-8")) if len(argv) > 3 else {}
        atomic_write_text(Path(argv[1]), json.dumps(analyse(argv[0], metric, params)) + "\n")
        return 0
    return serve_jsonl(analyse, IMPLEMENTATION)


if __name__ == "__main__":
    sys.exit(main())
