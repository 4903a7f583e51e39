"""Code says what it does and where in the spec, not which work item asked for it: no tracker reference
(``issue 8``, ``issues 6 and 16``, ``Issue 20, item 5``) in the sources of the reference, the conformance
package, the mutant set or the tools. Where a docstring pointed at a work item it now names the spec section,
the design brief's section, TWIN.md or the discrepancy README; history lives in the CHANGELOG and git, measured
figures in benchmarks/RESULTS.md."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

REPO = Path(__file__).resolve().parents[1]
#: the source trees checked (benchmark scripts may name the targets of their work item; tests are not scanned)
SCANNED = ("reference", "conformance/haptify_conform", "conformance/mutants", "tools")
WORK_ITEM = re.compile(r"issues? \d+", re.IGNORECASE)


def _sources() -> list[Path]:
    """Every .py file of the scanned trees, outside hidden folders and byte-code caches."""
    out = []
    for root in SCANNED:
        for path in sorted((REPO / root).rglob("*.py")):
            rel = path.relative_to(REPO)
            if not any(part.startswith(".") or part == "__pycache__" for part in rel.parts):
                out.append(path)
    return out


def work_item_references(text: str) -> list[tuple[int, str]]:
    """``(line number, line)`` of every line of ``text`` that names a work item."""
    return [(n, line.strip()) for n, line in enumerate(text.splitlines(), 1) if WORK_ITEM.search(line)]


@pytest.mark.parametrize(
    "text, found",
    [
        ('"""The discrepancy workflow (issue 8)."""', True),
        ("# (issue 3; TWIN.md, Effects)", True),
        ("spec chapter 16, issues 6 and 16", True),
        ("Issue 20, item 5: a null session", True),
        ("ISSUES 21", True),
        ("return challenge.issue(reg, caller)", False),
        ("the issue's type-3 file", False),
        ("def issue(reg, caller) -> dict:", False),
        ("spec §16.8.3 (the mutant set)", False),
        ("issue-8 or #8", False),
    ],
)
def test_the_pattern_finds_tracker_numbers_and_nothing_else(text, found):
    assert bool(work_item_references(text)) is found


@given(
    st.sampled_from(["issue", "issues", "Issue", "ISSUES", "iSsUe"]),
    st.integers(0, 10**6),
    st.text(alphabet="abc ,;:(", max_size=8),
    st.text(alphabet="abc ,;:)", max_size=8),
)
def test_any_tracker_number_in_any_case_is_found_on_its_line(word, number, before, after):
    text = f"first line\n{before}{word} {number}{after}\nlast line"
    assert [n for n, _ in work_item_references(text)] == [2]


def test_the_scan_sees_the_source_trees():
    files = {p.relative_to(REPO).as_posix() for p in _sources()}
    for expected in (
        "reference/haptify/metrics/vibration.py",
        "conformance/haptify_conform/coverage.py",
        "conformance/mutants/run.py",
        "tools/haptify_tools/discrepancy/floor.py",
    ):
        assert expected in files


def test_no_work_item_reference_in_the_sources():
    hits = []
    for path in _sources():
        rel = path.relative_to(REPO).as_posix()
        hits += [f"{rel}:{n}: {line}" for n, line in work_item_references(path.read_text(encoding="utf-8"))]
    assert not hits, (
        "name the spec / design / README section instead of the work item (history: CHANGELOG; "
        "figures: benchmarks/RESULTS.md):\n" + "\n".join(hits)
    )
