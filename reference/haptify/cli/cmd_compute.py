"""``haptify compute SESSION [-o results.json] [--metrics ID,…] [--params FILE] [--uncertainty]`` (spec §15.4, §19.5).

The session passes the validation gate first (§4.8): a session that does not validate gets no results
file; with ``-o`` the findings document of §16.4.1 is written there instead and the exit status is 1,
so the command is itself a conformance ``--cmd`` implementation.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail
from haptify.formats.storage import atomic_write_text, parse_json_file
from haptify.pipeline.compute import ComputeContext, compute_session
from haptify.pipeline.families import family_modules
from haptify.pipeline.gate import CheckedSession, SessionRefused, as_result_warnings, open_checked_session
from haptify.pipeline.results import ResultsFile

if TYPE_CHECKING:
    from haptify.cli.ui import UI, Subcommands


def register(sub: Subcommands) -> None:
    """Add the ``compute`` sub-command (spec §15.4)."""
    p = sub.add_parser(
        "compute",
        help="compute every metric the session's trials allow",
        description="Validate the session (refused sessions exit 1 with the validator's codes) and compute "
        "every metric its trials allow.",
    )
    p.add_argument("session", type=Path)
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        help="results file (default SESSION/../<id>.results.json); a refused session writes "
        '{"findings": [...]} here (spec §16.4.1)',
    )
    p.add_argument("--metrics", help="comma-separated metric ids (default: all)")
    p.add_argument(
        "--params",
        type=Path,
        metavar="FILE",
        help='case parameters, a JSON object (spec §16.2), e.g. {"model": "<model file in the session>"}',
    )
    p.add_argument(
        "--uncertainty",
        action="store_true",
        help="add each metric's measurement uncertainty: u, U = k·u at 95 %%, the budget (spec chapter 19)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace, ui: UI) -> int:
    """Validate, compute and write ``results.json`` atomically (spec §15.4, §4.8, §3.6)."""
    try:
        wanted = _wanted_metrics(args.metrics)
        parameters = case_parameters(args.params)
        results = compute_folder(args.session, wanted, parameters, ui, uncertainty=args.uncertainty)
    except HaptifyError as err:
        if args.output is not None:
            write_findings(args.output, err.findings)
        raise
    out = args.output or args.session.parent / f"{results.session_id}.results.json"
    atomic_write_text(out, results.model_dump_json(indent=2) + "\n")
    if ui.json_mode:
        ui.emit_json(results.model_dump(mode="json"))
        return 0
    for m in results.metrics:
        value = m.value if isinstance(m.value, list) else f"{m.value:.6g}"
        spread = f" ± {_fmt(m.uncertainty.U)} (k={m.uncertainty.k:.3g})" if m.uncertainty else ""
        ui.say(f"{m.id:36s} {value}{spread} {m.unit}  (n={m.n})")
    for u in results.unavailable:
        ui.say(f"{u.id:36s} not computed: {u.code} {u.reason}")
    for w in results.warnings:
        ui.warn(f"{w.code} warning: {w.message}")
    ui.say(f"wrote {out}")
    return 0


def _fmt(v: Any) -> str:
    return f"[{', '.join(f'{x:.3g}' for x in v)}]" if isinstance(v, list) else f"{v:.3g}"


def _wanted_metrics(text: str | None) -> list[str] | None:
    if text is None:
        return None
    wanted = [m.strip() for m in text.split(",") if m.strip()]
    if not wanted:
        raise fail(Code.USAGE, "--metrics names no metric id", expected="ID[,ID…]", found=text)
    return wanted


def case_parameters(path: Path | None) -> dict[str, Any]:
    """The case parameters of spec §16.2 from a JSON file: an object (E903 otherwise)."""
    if path is None:
        return {}
    if not path.is_file():
        raise fail(Code.USAGE, f"--params file {str(path)!r} does not exist", file=str(path), expected="a JSON file", found=None)
    params = parse_json_file(path, Code.USAGE, str(path))
    if not isinstance(params, dict):
        raise fail(
            Code.USAGE,
            f"--params file {str(path)!r} is not a JSON object",
            file=str(path),
            expected="a JSON object",
            found=type(params).__name__,
        )
    return params


def compute_folder(
    path: Path,
    wanted: list[str] | None = None,
    parameters: dict[str, Any] | None = None,
    ui: UI | None = None,
    uncertainty: bool = False,
) -> ResultsFile:
    """What ``haptify compute`` computes for the session folder ``path``: the session through the gate, every
    (or every ``wanted``) metric (with its uncertainty, chapter 19, when asked), then the rest of its validation
    (spec §15.4, §4.8); ``ui`` shows progress."""
    from haptify.cli.ui import UI

    return _compute_checked(open_checked_session(path), wanted, parameters or {}, ui or UI(quiet=True), uncertainty)


def _compute_checked(
    session: CheckedSession, wanted: list[str] | None, parameters: dict[str, Any], ui: UI, uncertainty: bool = False
) -> ResultsFile:
    """Compute on a gated session, then finish its validation (spec §4.8): the streams no metric read
    are checked too, so a result exists only for a session that validates whole. A coded failure of the
    computation is reported as the session's refusal when the session turns out invalid."""
    ctx = ComputeContext(session=session, parameters=parameters, keep=False)
    with ui.progress("computing metrics", total=len(family_modules()) + 1) as advance:
        try:
            results = compute_session(session, wanted, progress=advance, ctx=ctx, uncertainty=uncertainty)
        except SessionRefused:
            raise  # it carries the whole folder's validation report already (gate.refusal)
        except HaptifyError:
            session.finish()
            raise
        validation_warnings = session.finish()
        advance(1)
    results.warnings = as_result_warnings(validation_warnings) + results.warnings
    return results


def write_findings(path: Path, findings: list[Finding]) -> None:
    """The findings document of spec §16.4.1, written atomically."""
    atomic_write_text(path, json.dumps({"findings": [f.to_dict() for f in findings]}, indent=2) + "\n")
