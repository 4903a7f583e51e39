"""``haptify validate SESSION [--json]`` (spec §4.6): check a session folder and report every finding.

Human output groups the findings by trial and file; ``--json`` prints a
:class:`~haptify.formats.validation.report.ValidationReportModel` (``validation-report.schema.json``). Exit code 0 when
the session is valid (warnings allowed), 1 when it is invalid, 2 when validation could not run.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from haptify.cli.ui import UI, Subcommands

    # the validator (numpy, pandas, Arrow) is imported when the command runs, not for --help
    from haptify.formats.validation import ValidationReport


def register(subparsers: Subcommands) -> None:
    """Add the ``validate`` sub-command (entry point ``validate = "haptify.cli.cmd_validate:register"``).
    Spec §4.6."""
    parser = subparsers.add_parser(
        "validate",
        help="check a session folder against the Haptify spec",
        description="Check a session folder (session.json and its stream files) against the Haptify spec and "
        "report every problem, grouped by trial and file. Exit code: 0 valid (warnings allowed), "
        "1 invalid, 2 could not run. --json (before or after the sub-command) prints the report as JSON "
        "(validation-report.schema.json).",
    )
    parser.add_argument("session", metavar="SESSION", help="the session folder")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace, ui: UI) -> int:
    """Validate ``args.session``; print the report; return the exit code (spec §4.6)."""
    from haptify.formats.validation import SessionValidator

    validator = SessionValidator(args.session)
    validator.check_manifest()
    with ui.progress(f"validating {validator.stream_count} streams", total=validator.stream_count) as advance:
        validator.check_streams(advance)
    report = validator.finish()
    if ui.json_mode:
        ui.emit_json(report.to_model().model_dump(mode="json", exclude_none=True))
    else:
        for line in render_text(report, errors_only=ui.quiet):
            print(line)
    return report.exit_code


def render_text(report: ValidationReport, errors_only: bool = False) -> list[str]:
    """The human report: one heading per trial and file, then the findings, then a summary line.
    Spec §4.6."""
    lines: list[str] = []
    last_trial: object = object()
    for trial, file, findings in report.groups():
        shown = [f for f in findings if f.is_error or not errors_only]
        if not shown:
            continue
        if trial != last_trial:
            if lines:
                lines.append("")
            lines.append(f"trial {trial}" if trial is not None else "session")
            last_trial = trial
        lines.append(f"  {file}")
        for f in shown:
            lines.extend("    " + part for part in str(f).splitlines())
    if not errors_only:
        verdict = {0: "valid", 1: "INVALID", 2: "could not be validated"}[report.exit_code]
        summary = (
            f"{report.session}: {verdict} — {len(report.errors)} error(s), {len(report.warnings)} warning(s), "
            f"{report.streams_checked} stream(s) checked"
        )
        lines.extend(["", summary] if lines else [summary])
    return lines
