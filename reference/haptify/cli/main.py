"""The ``haptify`` command (spec §0.5): sub-commands are plugins registered under the entry-point
group ``haptify.commands``; each plugin's ``register(subparsers)`` adds its parser and sets
``func(args, ui) -> int``.

Exit codes: 0 success (valid), 1 the input is invalid or a check failed, 2 the command could not run.
No traceback ever reaches the user: coded errors print as findings, anything else as E999.
"""

from __future__ import annotations

import argparse
import sys
from importlib.metadata import entry_points
from typing import TYPE_CHECKING

from haptify.cli.ui import UI as UI
from haptify.codes import Code
from haptify.errors import Finding, HaptifyError
from haptify.versions import PACKAGE_VERSION, SCHEMA_VERSION, SPEC_VERSION

if TYPE_CHECKING:
    from haptify.cli.ui import Subcommands

EXIT_OK, EXIT_INVALID, EXIT_CANNOT_RUN = 0, 1, 2


GLOBAL_FLAGS = {"--json": "json", "--quiet": "quiet", "-q": "quiet"}  # accepted before or after the sub-command


def command_names() -> list[str]:
    """The sub-commands, from the entry-point metadata alone (nothing is imported)."""
    return sorted({ep.name for ep in entry_points(group="haptify.commands")})


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``haptify`` parser: ``--version``, ``--json``, ``--quiet`` and the plugin sub-commands (spec §0.5).

    Only ``command``'s plugin is imported and registered; the others are listed by name from the
    entry-point metadata, so starting the command costs only what the command itself needs.
    """
    parser = argparse.ArgumentParser(
        prog="haptify",
        description="Haptify: benchmark grounded force-feedback haptic devices from external measurements.",
        epilog="Run 'haptify COMMAND --help' for a command's options.",
    )
    parser.add_argument("--version", action="store_true", help="print package, spec and schema versions")
    parser.add_argument("--json", action="store_true", help="machine-readable output on stdout (also after COMMAND)")
    parser.add_argument("--quiet", "-q", action="store_true", help="print only errors (also after COMMAND)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for ep in sorted(entry_points(group="haptify.commands"), key=lambda e: e.name):
        if ep.name != command:
            sub.add_parser(ep.name, help="", add_help=False)
            continue
        try:
            register = ep.load()
        except Exception as exc:  # a broken plugin must not take the other commands down
            _register_broken(sub, ep.name, ep.value, exc)
            continue
        register(sub)
    return parser


def split_global_flags(argv: list[str]) -> tuple[list[str], dict[str, bool], str | None]:
    """``argv`` without the global flags, the flags found (anywhere before ``--``), and the sub-command
    named (the first argument that is one), spec §0.5."""
    names = set(command_names())
    rest: list[str] = []
    flags = {"json": False, "quiet": False}
    command = None
    for k, arg in enumerate(argv):
        if arg == "--":
            rest.extend(argv[k:])
            break
        if arg in GLOBAL_FLAGS:
            flags[GLOBAL_FLAGS[arg]] = True
            continue
        if command is None and arg in names:
            command = arg
        rest.append(arg)
    return rest, flags, command


def _register_broken(sub: Subcommands, name: str, target: str, exc: Exception) -> None:
    """Keep a plugin that failed to import visible: calling it reports E999 with the cause."""

    def run(args: argparse.Namespace, ui: UI) -> int:
        raise HaptifyError(
            Finding(Code.INTERNAL_ERROR, f"the '{name}' command ({target}) failed to load: {type(exc).__name__}: {exc}")
        )

    parser = sub.add_parser(name, help=f"(unavailable: {type(exc).__name__})", add_help=False)
    parser.add_argument("rest", nargs="*")
    parser.set_defaults(func=run)


def _print_findings(ui: UI, findings: list[Finding]) -> None:
    if ui.json_mode:
        ui.emit_json({"ok": False, "findings": [f.to_dict() for f in findings]})
    else:
        for f in findings:
            print(str(f), file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``haptify`` console script; returns the process exit code.
    0, 1 or 2 as spec §0.5 defines."""
    argv, flags, command = split_global_flags(sys.argv[1:] if argv is None else list(argv))
    if command == "import":  # the format word is optional (spec §5.8)
        from haptify.cli.cmd_import import implicit_format

        argv = implicit_format(argv)
    parser = build_parser(command)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse already printed usage or --help
        return EXIT_OK if exc.code == 0 else EXIT_CANNOT_RUN
    ui = UI(json_mode=flags["json"] or args.json, quiet=flags["quiet"] or args.quiet)
    if args.version:
        versions = {"package": PACKAGE_VERSION, "spec": SPEC_VERSION, "schema": SCHEMA_VERSION}
        if ui.json_mode:
            ui.emit_json(versions)
        else:
            print(f"haptify {PACKAGE_VERSION} (spec {SPEC_VERSION}, schemas {SCHEMA_VERSION})")
        return EXIT_OK
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_CANNOT_RUN
    try:
        return int(args.func(args, ui))
    except HaptifyError as err:  # exit 1 when the input was refused (spec §4.8), else 2
        _print_findings(ui, err.findings)
        return err.exit_code
    except BrokenPipeError:  # e.g. `haptify … | head`: the reader left; not an error of ours
        sys.stderr.close()
        return EXIT_OK
    except KeyboardInterrupt:
        ui.warn("interrupted; nothing half-written was left behind")
        return EXIT_CANNOT_RUN
    except Exception as exc:  # the last guard: report, never a traceback
        _print_findings(ui, [Finding(Code.INTERNAL_ERROR, f"{type(exc).__name__}: {exc}")])
        return EXIT_CANNOT_RUN


if __name__ == "__main__":
    sys.exit(main())
