"""The two JSON Schema validators of spec §4.3.1 agree on what is valid: jsonschema-rs decides, and only an
instance it rejects is explained by ``jsonschema`` (haptify.formats.validation.schema). A disagreement would
either let an invalid manifest through (rs lenient) or report an error-free rejection (rs strict)."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haptify.codes import Code
from haptify.formats.validation.schema import detailed_validator, fast_validator, schema_findings

ROOT = Path(__file__).resolve().parents[1]


def _parsed(path: Path) -> Any:
    """A fixture's JSON document, or None for the fixtures of E102/E103 that are not JSON at all."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None


DOCUMENTS = {
    p: doc
    for p in sorted((ROOT / "fixtures").rglob("*.json"))
    if p.name in ("session.json", "device.json") and (doc := _parsed(p)) is not None
}
FIXTURE_FILES = list(DOCUMENTS)


def _schema_name(path: Path) -> str:
    return "device" if path.name == "device.json" else "session"


def _agree(instance: Any, name: str) -> tuple[bool, bool]:
    return fast_validator(name).is_valid(instance), not any(detailed_validator(name).iter_errors(instance))


def _non_finite(node: Any) -> bool:
    """Whether a JSON document holds NaN or ±Infinity (which Python's json module parses)."""
    if isinstance(node, float):
        return not math.isfinite(node)
    children = node.values() if isinstance(node, dict) else node if isinstance(node, list) else []
    return any(_non_finite(child) for child in children)


@pytest.mark.parametrize("path", FIXTURE_FILES, ids=lambda p: str(p.relative_to(ROOT / "fixtures")))
def test_validators_agree_on_every_fixture_manifest(path: Path) -> None:
    """Equal verdicts; a document with a non-finite number only the fast validator may reject."""
    instance = DOCUMENTS[path]
    fast, detailed = _agree(instance, _schema_name(path))
    assert fast == detailed or (not fast and _non_finite(instance))


def test_the_fixtures_hold_both_valid_and_invalid_manifests() -> None:
    verdicts = {_agree(DOCUMENTS[p], _schema_name(p))[1] for p in FIXTURE_FILES if p.parts[-3] == "invalid"}
    assert verdicts == {True, False}  # the invalid fixtures include schema violations and other faults


JSON_LEAF = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**20), 10**20),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(max_size=8),
)
JSON_VALUE = st.recursive(
    JSON_LEAF, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3), max_leaves=6
)


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every member path of a JSON document (object keys and array indices), the root excluded."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else []
    out: list[tuple[Any, ...]] = []
    for key, child in items:
        out.append((*prefix, key))
        out.extend(_paths(child, (*prefix, key)))
    return out


VALID_SESSION = json.loads((ROOT / "fixtures" / "valid" / "parquet-basic" / "session.json").read_text())
SESSION_PATHS = _paths(VALID_SESSION)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(path=st.sampled_from(SESSION_PATHS), value=JSON_VALUE, delete=st.booleans())
def test_validators_agree_on_a_valid_session_with_one_member_replaced_or_removed(
    path: tuple[Any, ...], value: Any, delete: bool
) -> None:
    instance = copy.deepcopy(VALID_SESSION)
    parent = instance
    for key in path[:-1]:
        parent = parent[key]
    if delete:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    fast, detailed = _agree(instance, "session")
    assert fast == detailed


def test_a_rejected_instance_is_explained_and_an_accepted_one_has_no_finding() -> None:
    assert schema_findings(VALID_SESSION, "session", Code.SCHEMA_VIOLATION, "session.json") == []
    broken = copy.deepcopy(VALID_SESSION)
    broken["trials"][0]["protocol"] = "juggling"
    (finding,) = schema_findings(broken, "session", Code.SCHEMA_VIOLATION, "session.json")
    assert finding.code == Code.PROTOCOL_UNKNOWN and finding.pointer == "/trials/0/protocol"


def test_a_nan_the_fast_validator_rejects_is_judged_by_the_detailed_one() -> None:
    """jsonschema-rs refuses NaN as a number; ``jsonschema`` (Python's float semantics) accepts it: the
    detailed validator's verdict stands, so NaN-bearing documents are judged as before (spec §4.3.2 checks
    non-finite values itself)."""
    instance = copy.deepcopy(VALID_SESSION)
    instance["trials"][0]["streams"][0]["rate_hz"] = float("nan")
    fast, detailed = _agree(instance, "session")
    assert not fast and detailed
    assert schema_findings(instance, "session", Code.SCHEMA_VIOLATION, "session.json") == []
