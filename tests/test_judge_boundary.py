"""The judge stands alone (spec §16.1): the conformance package imports neither the reference (``haptify``)
nor the tools (``haptify_tools``); it reads the standard as data (``haptify_schemas``, the case files and the
fixtures). The reference reaches the judge only through its own adapter entry point."""

from __future__ import annotations

import ast
import json
import subprocess
import sys

import pytest
from conftest import REPO

JUDGE = REPO / "conformance" / "haptify_conform"
FORBIDDEN = ("haptify", "haptify_tools", "haptify_mutants")


def imported_packages(source: str) -> set[str]:
    """The top-level packages a module imports, anywhere in it (function-level imports included)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_the_import_check_sees_every_kind_of_import():
    source = (
        "import haptify.formats.storage\nfrom haptify_tools import twin\ndef f():\n    from haptify.pipeline.compute import x\n"
    )
    assert imported_packages(source) == {"haptify", "haptify_tools"}
    assert imported_packages("from . import cases\nimport haptify_schemas\n") == {"haptify_schemas"}


@pytest.mark.parametrize("module", sorted(p.name for p in JUDGE.glob("*.py")))
def test_no_judge_module_imports_the_reference_or_the_tools(module):
    found = imported_packages((JUDGE / module).read_text(encoding="utf-8")) & set(FORBIDDEN)
    assert not found, f"haptify_conform/{module} imports {sorted(found)}"


def test_linting_the_suite_loads_nothing_of_the_reference_or_the_tools():
    """Run the linter and the CLI's parser in a fresh interpreter, then list what got imported."""
    probe = (
        "import sys, json\n"
        "from haptify_conform import cli\n"
        "from haptify_conform.lint import lint\n"
        "cli.build_parser()\n"
        "problems = lint()\n"
        f"bad = sorted(m for m in sys.modules if m.split('.')[0] in {FORBIDDEN!r})\n"
        "print(json.dumps({'problems': problems, 'bad': bad}))\n"
    )
    proc = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=REPO)
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["problems"] == []
    assert out["bad"] == []
