"""The haptify command (spec §0.5): versions, JSON, exit codes, no tracebacks."""

from __future__ import annotations

import json
import subprocess
import sys

from haptify.cli.main import main
from haptify.versions import PACKAGE_VERSION, SCHEMA_VERSION, SPEC_VERSION


def test_version_human_and_json(capsys):
    assert main(["--version"]) == 0
    assert f"haptify {PACKAGE_VERSION} (spec {SPEC_VERSION}" in capsys.readouterr().out
    assert main(["--json", "--version"]) == 0
    assert json.loads(capsys.readouterr().out) == {"package": PACKAGE_VERSION, "spec": SPEC_VERSION, "schema": SCHEMA_VERSION}


def test_unknown_command_and_no_command_exit_2(capsys):
    assert main(["frobnicate"]) == 2
    assert main([]) == 2
    capsys.readouterr()


def test_console_script_runs_without_traceback():
    proc = subprocess.run([sys.executable, "-m", "haptify.cli.main", "--help"], capture_output=True, text=True)
    assert proc.returncode == 0
    assert "COMMAND" in proc.stdout and "Traceback" not in proc.stderr


def test_compute_with_an_empty_metric_list_is_a_usage_error(example_session, capsys):
    assert main(["--json", "compute", str(example_session), "--metrics", ","]) == 2
    assert json.loads(capsys.readouterr().out)["findings"][0]["code"] == "E903"


def test_every_command_a_hint_names_exists():
    """A hint that sends the user to a command that does not exist is a dead end (spec §0.4)."""
    import re

    from haptify.cli.main import command_names
    from haptify.errors import catalogue
    from haptify_conform.cli import build_parser as conform_parser

    commands = set(command_names())
    conform_options = {o for a in conform_parser()._actions for o in a.option_strings}
    named = []
    for code, entry in catalogue().items():
        for word in re.findall(r"\bhaptify ([a-z][a-z-]*)", entry["hint"]):
            named.append((code, word, word in commands))
        for option in re.findall(r"\bhaptify-conform (--[a-z-]+)", entry["hint"]):
            named.append((code, option, option in conform_options))
    assert named and [n for n in named if not n[2]] == []
