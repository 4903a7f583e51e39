"""Codes as names (spec §0.4, §4.1): ``haptify.codes.Code`` is generated from ``schemas/1.0/codes.json`` and is
the only way the reference and the tools name a code.

A *bare code literal* is a string constant whose whole value matches ``^[EWI][0-9]{3}$``. It is allowed only in
the catalogue itself (``schemas/``), in the generated ``reference/haptify/codes.py``, in the tests, and in the
conformance judge (``conformance/haptify_conform``), which must not import the reference (§16.1) and treats codes
as the data of its cases. Docstrings, comments and the literal text of f-strings may mention a code in prose:
those are text, not values.
"""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pytest

from conftest import REPO
from haptify import schemas
from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail
from haptify_tools.gen_docs import CODES_MODULE, code_member, codes_module

CODE = re.compile(r"[EWI][0-9]{3}")
CHECKED = [REPO / "reference" / "haptify", REPO / "tools" / "haptify_tools"]


def bare_code_literals(source: str) -> list[tuple[int, str]]:
    """(line, code) of every string constant that is a whole code, leaving out docstrings and f-string text."""
    tree = ast.parse(source)
    text_nodes: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                text_nodes.add(id(body[0].value))
        elif isinstance(node, ast.JoinedStr):
            text_nodes |= {id(v) for v in node.values}
    return sorted(
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and CODE.fullmatch(node.value)
        and id(node) not in text_nodes
    )


def test_the_literal_check_tells_values_from_prose():
    source = (
        '"""Module docstring: E101."""\n'
        "def f(x):\n"
        '    """E102"""\n'
        '    y = f"{x}E103"  # E104 in a comment\n'
        '    raise fail("E105", f"see W401 and {x}")\n'
        "codes = {'W406': 1, 'I001': 2}\n"
        "ok = x in ('e101', 'E1010', 'X101')\n"
    )
    assert bare_code_literals(source) == [(5, "E105"), (6, "I001"), (6, "W406")]


def test_the_codes_module_is_current():
    """``python -m haptify_tools.gen_docs`` writes it; a drifted module fails here as in ``--check``."""
    assert CODES_MODULE.read_text(encoding="utf-8") == codes_module()


def test_every_code_of_the_catalogue_is_a_member_and_nothing_else():
    catalogue = schemas.load("codes.json")["codes"]
    assert {m.value: m.name for m in Code} == {c["code"]: code_member(c["name"]) for c in catalogue}
    assert len(Code) == len(catalogue)


def test_member_names_follow_the_catalogue_names():
    assert code_member("session-not-found") == "SESSION_NOT_FOUND"
    assert code_member("import-plate-geometry-meaningless") == "IMPORT_PLATE_GEOMETRY_MEANINGLESS"
    assert Code.SESSION_NOT_FOUND == "E101"
    assert Code.WORKSPACE_SHELL_OPEN == "W410"
    assert Code("E203") is Code.TIME_NOT_INCREASING


def test_a_member_formats_and_serialises_as_its_code():
    member = Code.STREAM_FILE_MISSING
    assert f"{member}" == str(member) == "{}".format(member) == "E110"
    assert json.dumps({"code": member, "codes": [member]}) == '{"code": "E110", "codes": ["E110"]}'
    assert {"E110": 1}[member] == 1 and sorted([Code.USAGE, "E101"]) == ["E101", "E903"]


def test_a_finding_keeps_the_plain_code():
    finding = Finding(Code.TIME_NOT_INCREASING, "t goes back", column="t")
    assert type(finding.code) is str and finding.code == "E203"
    assert finding.name == "time-not-increasing" and finding.severity == "error"
    assert repr(finding) == repr(Finding("E203", "t goes back", column="t"))
    assert finding.to_dict()["code"] == "E203"
    err = fail(Code.WORKSPACE_SHELL_OPEN, "open")
    assert isinstance(err, HaptifyError) and err.code == "W410" and str(err).startswith("W410 warning: open")


def _modules() -> list[Path]:
    return [p for root in CHECKED for p in sorted(root.rglob("*.py")) if p != CODES_MODULE]


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(REPO)))
def test_no_bare_code_literal_in_the_reference_or_the_tools(path):
    found = bare_code_literals(path.read_text(encoding="utf-8"))
    assert not found, f"{path.relative_to(REPO)}: name these codes with haptify.codes.Code: {found}"
