"""Protocol self-test (spec §16.4.3): does an implementation speak the protocol, before any case runs?"""

from __future__ import annotations

import tempfile
from pathlib import Path

from haptify_conform.adapters import Adapter, JsonlAdapter
from haptify_conform.cases import Case, Expected, Provenance

PROBE = Case(
    id="self-test.missing-session",
    metric="validate",
    spec_section="16.4",
    level="MUST",
    fixture="-",
    expected=Expected(codes=["E101"]),
    provenance=Provenance(kind="spec", note="protocol probe"),
    spec_versions=["1.0"],
    description="a session folder that does not exist must be rejected with E101",
)


def self_test(adapter: Adapter) -> tuple[bool, list[str]]:
    """Run the protocol probes; returns (all passed, readable PASS/FAIL lines).
    The ``--self-test`` of spec §16.4.3."""
    lines: list[str] = []

    def check(ok: bool, what: str) -> bool:
        lines.append(f"{'PASS' if ok else 'FAIL'} {what}")
        return ok

    results = []
    with tempfile.TemporaryDirectory() as tmp:
        missing = Path(tmp) / "no-such-session"
        answer = adapter.run(PROBE, missing)
        results.append(
            check(answer.kind != "error", f"answers a request ({answer.kind}{': ' + answer.message if answer.message else ''})")
        )
        codes = {str(f.get("code")) for f in answer.payload or [] if isinstance(f, dict)} if answer.kind == "rejected" else set()
        results.append(check("E101" in codes, f"rejects a missing session with E101 (found {sorted(codes)})"))
        if isinstance(adapter, JsonlAdapter) and adapter.proc is not None:
            results.append(check(adapter.implementation.get("name") is not None, "handshake names the implementation"))
            try:
                reply = adapter.request({"op": "no-such-op"})
                results.append(
                    check(reply.get("status") == "error", "answers an unknown op with status 'error' and the same seq")
                )
            except (TimeoutError, RuntimeError) as exc:
                results.append(check(False, f"answers an unknown op ({exc})"))
    adapter.close()
    return all(results), lines
