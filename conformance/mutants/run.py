"""``make mutants``: the whole conformance suite against every mutant of the catalogue (spec §16.8.3).

Every case file runs in-process (the reference's ``analyse`` with the mutant's patches applied for the whole
run, one compute context per session as the JSON-lines reference keeps them) in ``--workers`` processes. A
control run of the unpatched reference comes first: it must pass every case, or no verdict on a mutant means
anything (exit 2). The validation of a fixture (spec chapter 4: more than half of a run's time) is done once per
worker process and reused by every mutant that patches nothing in the ``haptify.formats.validation`` package: the fixtures do not
change between mutants, and no other mutant can change a validation report. A mutant is **caught** when at least one case fails. Per mutant the failing cases are
listed with their deviation in tolerances, ``max_i |value_i − expected_i| / (abs + rel·|expected_i|)``
(none when the value is missing, of the wrong shape or unit, or the session was rejected).

    python -m haptify_mutants.run [--workers 2] [--only NAME ...] [--out conformance/mutants/results.json]

Writes the machine-readable result (``results.json``: per mutant its section, rule, whether it was caught,
its failing cases and their ratios) and exits 0 when every mutant is caught, 1 when one escapes.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any, Callable
from unittest import mock

from haptify import conform_adapter as reference
from haptify.formats import validation
from haptify.formats.storage import atomic_write_text
from haptify_conform.adapters import PythonAdapter
from haptify_conform.cases import REPO_ROOT, SUITE_ROOT, Case, load_cases
from haptify_conform.coverage import cases_digest
from haptify_conform.judge import Verdict
from haptify_conform.runner import run_cases
from haptify_mutants.catalogue import BY_NAME, MUTANTS

RESULTS = REPO_ROOT / "conformance" / "mutants" / "results.json"
CONTROL = "(reference)"


def deviation_ratio(case: Case, verdict: Verdict) -> float | None:
    """``max_i |value_i − expected_i| / (abs + rel·|expected_i|)``: how many tolerances the value is off
    (spec §16.3); None when the verdict carries no comparable value."""
    expected, actual, tol = case.expected.value, verdict.actual, case.tolerance
    if expected is None or tol is None:
        return None
    exp = expected if isinstance(expected, list) else [expected]
    act = actual if isinstance(actual, list) else [actual]
    if len(exp) != len(act) or not all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in act):
        return None
    ratios = []
    for a, e in zip(act, exp):
        band = tol.abs + tol.rel * abs(e)
        d = abs(float(a) - e)
        ratios.append(d / band if band > 0 else (0.0 if d == 0 else math.inf))
    return max(ratios)


_VALIDATED: dict[str, Any] = {}  # fixture folder → its validation report, per worker process


def _validate_once(real: Callable) -> Callable:
    def validate_session(path: Path, *args: Any, **kw: Any) -> Any:
        key = str(Path(path).resolve())
        if args or kw:
            return real(path, *args, **kw)
        if key not in _VALIDATED:
            _VALIDATED[key] = real(path)
        return _VALIDATED[key]

    return validate_session


def _in_validation(module: str) -> bool:
    """True for ``haptify.formats.validation`` and its modules (``haptify.formats.validation.streams`` ...)."""
    return module == "haptify.formats.validation" or module.startswith("haptify.formats.validation.")


def run_one(name: str) -> dict[str, Any]:
    """Run every case against the mutant ``name`` (or the unpatched reference for :data:`CONTROL`)."""
    cases = {c.id: c for c in load_cases()}
    start = time.perf_counter()
    reference._contexts.clear()
    adapter = PythonAdapter("haptify.conform_adapter:analyse")
    with ExitStack() as stack:
        mutant = BY_NAME.get(name)
        if mutant is None or not any(_in_validation(getattr(p.owner, "__name__", "")) for p in mutant.patches):
            stack.enter_context(mock.patch.object(reference, "validate_session", _validate_once(validation.validate_session)))
        if mutant is not None:
            stack.enter_context(mutant.applied())
        verdicts = run_cases(list(cases.values()), adapter)
    reference._contexts.clear()
    failing = []
    for v in verdicts:
        if v.status in ("failed", "error"):
            ratio = deviation_ratio(cases[v.case_id], v)
            failing.append(
                {
                    "case": v.case_id,
                    "metric": v.metric,
                    "status": v.status,
                    "ratio": None if ratio is None else (ratio if math.isfinite(ratio) else "inf"),
                    "message": "" if ratio is not None else v.message[:300],
                }
            )
    failing.sort(key=lambda f: (f["ratio"] is None, -(math.inf if f["ratio"] == "inf" else (f["ratio"] or 0.0))))
    return {"name": name, "cases": len(verdicts), "failing": failing, "seconds": round(time.perf_counter() - start, 2)}


def _record(name: str, outcome: dict[str, Any]) -> dict[str, Any]:
    m = BY_NAME[name]
    return {
        "section": m.section,
        "requirement": m.requirement,
        "rule": m.rule,
        "wrong": m.wrong,
        "expected_metrics": list(m.metrics),
        "caught": bool(outcome["failing"]),
        "failing_cases": outcome["failing"],
        "seconds": outcome["seconds"],
    }


def _best(failing: list[dict]) -> str:
    if not failing:
        return ""
    f = failing[0]
    how = (
        f"{f['ratio']:.3g} × tolerance"
        if isinstance(f["ratio"], float)
        else ("∞ × tolerance" if f["ratio"] == "inf" else f"{f['status']}: {f['message'][:90]}")
    )
    return f"best {f['case']} ({how})"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="run only these mutants (the result file is not written)")
    parser.add_argument("--out", type=Path, default=RESULTS, help=f"result file (default {RESULTS.relative_to(REPO_ROOT)})")
    args = parser.parse_args(argv)
    names = args.only or [m.name for m in MUTANTS]
    unknown = sorted(set(names) - set(BY_NAME))
    if unknown:
        parser.error(f"unknown mutant(s) {unknown}")
    start = time.perf_counter()
    ctx = multiprocessing.get_context("fork")
    outcomes: dict[str, dict] = {}
    with ctx.Pool(args.workers, maxtasksperchild=None) as pool:
        for outcome in pool.imap_unordered(run_one, [CONTROL, *names]):
            outcomes[outcome["name"]] = outcome
            if outcome["name"] == CONTROL:
                continue
            verdict = "CAUGHT " if outcome["failing"] else "ESCAPED"
            print(
                f"{verdict} {outcome['name']:36s} §{BY_NAME[outcome['name']].section:7s} "
                f"{len(outcome['failing']):3d} failing  {_best(outcome['failing'])}  [{outcome['seconds']:.0f} s]",
                flush=True,
            )
    wall = time.perf_counter() - start
    control = outcomes[CONTROL]
    if control["failing"]:
        print(f"the unpatched reference fails {len(control['failing'])} case(s): {[f['case'] for f in control['failing']]}")
        return 2
    records = {n: _record(n, outcomes[n]) for n in names}
    caught = sum(r["caught"] for r in records.values())
    escaped = [n for n, r in records.items() if not r["caught"]]
    print(f"\nmutants caught: {caught}/{len(records)} ({control['cases']} cases each; {args.workers} workers; {wall:.0f} s wall)")
    if escaped:
        print("escaped: " + ", ".join(escaped))
    if not args.only:
        doc = {
            "$comment": "written by `make mutants` (python -m haptify_mutants.run); read by the suite's lint",
            "date": time.strftime("%Y-%m-%d", time.gmtime()),
            "workers": args.workers,
            "cpu_count": os.cpu_count(),
            "wall_s": round(wall, 1),
            "cases_digest": cases_digest(SUITE_ROOT),
            "cases": control["cases"],
            "caught": caught,
            "total": len(records),
            "escaped": escaped,
            "mutants": records,
        }
        atomic_write_text(args.out, json.dumps(doc, indent=1, ensure_ascii=False) + "\n")
    return 1 if escaped else 0


if __name__ == "__main__":
    sys.exit(main())
