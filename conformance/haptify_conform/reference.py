"""The reference implementation behind the conformance protocol (spec §16.4).

``analyse(session, metric, parameters)`` validates the session and, when it is valid, computes the
asked-for metric with the reference; it is what ``--python haptify_conform.reference:analyse`` calls.
``python -m haptify_conform.reference`` serves the JSON-lines protocol; with two arguments
(``SESSION OUT``) it behaves as a ``--cmd`` program and writes its answer to OUT.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from haptify.compute import compute_session
from haptify.errors import HaptifyError
from haptify.storage import atomic_write_text, open_session
from haptify.validation import validate_session
from haptify.versions import PACKAGE_VERSION

IMPLEMENTATION = {"name": "haptify-reference", "version": PACKAGE_VERSION}


def analyse(session: str, metric: str = "", parameters: dict | None = None) -> dict:
    """A results document, or ``{"findings": [...]}`` when the session is rejected."""
    report = validate_session(Path(session))
    findings = [f.to_dict() for f in report.findings]
    if not report.valid or metric == "validate":
        return {"findings": findings}
    try:
        results = compute_session(open_session(session), [metric] if metric else None)
    except HaptifyError as err:
        return {"findings": [f.to_dict() for f in err.findings]}
    return results.model_dump(mode="json")


def main(argv: list[str] | None = None) -> int:
    from haptify_conform.adapters import serve_jsonl

    argv = sys.argv[1:] if argv is None else argv
    if len(argv) == 2:
        atomic_write_text(Path(argv[1]), json.dumps(analyse(argv[0])) + "\n")
        return 0
    return serve_jsonl(analyse, IMPLEMENTATION)


if __name__ == "__main__":
    sys.exit(main())
