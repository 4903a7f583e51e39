"""``haptify-conform``: run an implementation against the Haptify conformance suite (spec chapter 16).

Exit codes: 0 the implementation conforms (every selected case passed, or was skip-listed where §16 allows a
skip), 1 it does not, 2 the run could not start (bad arguments, unreadable skip list, no suite found, no case
selected, an implementation that cannot be started).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from haptify_schemas import SPEC_VERSION
from haptify_conform.adapters import Adapter, CannotStart, CmdAdapter, JsonlAdapter, PythonAdapter
from haptify_conform.cases import SUITE_ENV, find_suite, load_cases, select
from haptify_conform.coverage import coverage_table, suite_coverage
from haptify_conform.lint import lint
from haptify_conform.report import build_report, header, to_junit, to_table, write_report
from haptify_conform.runner import load_skips, run_cases
from haptify_conform.selftest import self_test


def build_parser() -> argparse.ArgumentParser:
    """The ``haptify-conform`` options: adapters (spec §16.4), selection, timeouts (§16.5), reports (§16.6)."""
    p = argparse.ArgumentParser(
        prog="haptify-conform", description="Check an implementation against the Haptify conformance suite."
    )
    how = p.add_mutually_exclusive_group()
    how.add_argument("--cmd", help='a command per case, e.g. "mytool {session} {out}" (also {metric} {case} {params})')
    how.add_argument("--jsonl", help="a program speaking the JSON-lines protocol on stdin/stdout")
    how.add_argument("--python", help="an in-process implementation, module:function(session, metric, parameters)")
    how.add_argument("--lint", action="store_true", help="check the suite itself and exit")
    p.add_argument("--self-test", action="store_true", help="only check that the implementation speaks the protocol")
    p.add_argument("--level", choices=["MUST", "SHOULD"], help="MUST: only the MUST cases")
    p.add_argument("--metric", action="append", help="only cases of this metric id (repeatable; 'validate' for negative cases)")
    p.add_argument("--skip-file", type=Path, help='the implementation\'s skip list: {"skips": {"case id": "reason"}}')
    p.add_argument("--timeout", type=float, default=120.0, help="seconds per case (default 120)")
    p.add_argument("--max-restarts", type=int, default=3, help="restarts of a crashed --jsonl process (default 3)")
    p.add_argument("--json-report", type=Path, help="write the JSON report here")
    p.add_argument("--junit", type=Path, help="write a JUnit XML report here")
    p.add_argument("--quiet", action="store_true", help="print only the summary line")
    p.add_argument(
        "--challenge",
        metavar="URL",
        help="instead of the suite, answer a fresh challenge of the results registry at URL (spec §17.8)",
    )
    p.add_argument("--token", help="the registry API token for --challenge (default: $HAPTIFY_TOKEN)")
    p.add_argument(
        "--suite",
        type=Path,
        metavar="DIR",
        help=f"a checkout of the standard holding conformance/cases/ and fixtures/ (default: ${SUITE_ENV}, "
        "else the checkout this package was installed from)",
    )
    return p


def make_adapter(args: argparse.Namespace) -> Adapter:
    """The adapter the arguments name: ``--cmd``, ``--jsonl`` or ``--python`` (spec §16.4)."""
    if args.cmd:
        return CmdAdapter(args.cmd, args.timeout)
    if args.jsonl:
        return JsonlAdapter(args.jsonl, args.timeout, args.max_restarts)
    return PythonAdapter(args.python)


def main(argv: list[str] | None = None) -> int:
    """Run the suite, the linter or the self-test; exit 0, 1 or 2 as spec §16.6 says."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return 0 if exc.code == 0 else 2
    if args.lint:
        try:
            suite = find_suite(args.suite)
        except ValueError as exc:
            print(f"haptify-conform: {exc}", file=sys.stderr)
            return 2
        problems = lint(suite.cases_root, suite.repo)
        if not args.quiet:
            try:
                print(coverage_table(suite_coverage(suite.cases_root)))
            except ValueError:  # an invalid case file: the problems below say which
                pass
        for line in problems:
            print(line)
        print(f"suite lint: {len(problems)} problem(s)")
        return 1 if problems else 0
    if not (args.cmd or args.jsonl or args.python):
        parser.print_usage(sys.stderr)
        print("haptify-conform: give --cmd, --jsonl or --python", file=sys.stderr)
        return 2
    if args.challenge:
        return run_challenge_command(args)
    try:  # the suite first: a missing or broken suite means the run cannot start (exit 2, spec §16.6)
        suite = find_suite(args.suite)
        cases = select(
            load_cases(suite.cases_root),
            level=args.level,
            metrics=set(args.metric) if args.metric else None,
            spec_version=SPEC_VERSION,
        )
        if not cases:
            raise ValueError(f"no case of {str(suite.cases_root / 'cases')!r} is selected: nothing would be judged")
        adapter = make_adapter(args)
        skips = load_skips(args.skip_file)
    except (ValueError, OSError, ImportError, AttributeError, json.JSONDecodeError) as exc:
        print(f"haptify-conform: {exc}", file=sys.stderr)
        return 2
    if args.self_test:
        ok, lines = self_test(adapter)
        print("\n".join(lines))
        return 0 if ok else 1
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    try:
        verdicts = run_cases(cases, adapter, skips, repo=suite.repo)
    except CannotStart as exc:  # the implementation never ran: no verdict would mean anything (spec §16.6)
        print(f"haptify-conform: {exc}", file=sys.stderr)
        return 2
    implementation = getattr(adapter, "implementation", {}) or {"command": args.cmd or args.jsonl or args.python}
    report = build_report(header(adapter.name, implementation, started), verdicts)
    if args.json_report:
        write_report(args.json_report, report.model_dump_json(indent=2) + "\n")
    if args.junit:
        write_report(args.junit, to_junit(report))
    text = to_table(report)
    print(text.splitlines()[-1] if args.quiet else text, end="\n" if args.quiet else "")
    return 0 if report.summary.conforms else 1


def run_challenge_command(args: argparse.Namespace) -> int:
    """``--challenge URL``: answer a registry's challenge with the implementation; 0 passed, 1 failed, 2 not run."""
    import os

    from haptify_conform.challenge import ChallengeError, run_challenge, summary

    token = args.token or os.environ.get("HAPTIFY_TOKEN")
    if not token:
        print("haptify-conform: --challenge needs --token (or $HAPTIFY_TOKEN)", file=sys.stderr)
        return 2
    try:
        record = run_challenge(args.challenge, token, make_adapter(args))
    except (ChallengeError, CannotStart, ValueError, OSError, ImportError, AttributeError) as exc:
        print(f"haptify-conform: {exc}", file=sys.stderr)
        return 2
    if args.json_report:
        write_report(args.json_report, json.dumps(record, indent=2) + "\n")
    print(summary(record).splitlines()[-1] if args.quiet else summary(record))
    return 0 if record["result"]["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
