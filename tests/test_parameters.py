"""Typed family parameters (spec §0.3): each family's parameters load once, at import, into the owning
module's ``PARAMETERS``, checked against the definition file; a file whose keys or value types differ from
the declared model stops with E905 naming the file, the key, what was expected and what was found."""

from __future__ import annotations

import ast
import importlib
import json
from pathlib import Path
from typing import Literal

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import haptify_schemas
from haptify.errors import HaptifyError
from haptify.metrics import uncertainty
from haptify.metrics.metric_definitions import FamilyParameters, all_families, family, load_parameters, validate_parameters

REPO = Path(__file__).resolve().parents[1]

#: family → the module that declares and loads its parameters
OWNERS = {
    "calibration": "haptify.processing.calibration",
    "dynamics": "haptify.dynamics.parameter_file",
    "free_space": "haptify.metrics.free_space",
    "rig": "haptify.processing.force_plate",
    "signals": "haptify.processing.preprocessing",
    "stiffness": "haptify.metrics.stiffness",
    "surface": "haptify.metrics.surface",
    "vibration": "haptify.metrics.vibration",
    "workspace": "haptify.metrics.volume_operator",
}


def test_every_defined_family_has_one_owner():
    assert sorted(f.family for f in all_families()) == sorted(OWNERS)


@pytest.mark.parametrize("name", sorted(OWNERS))
def test_each_family_loads_into_its_owners_parameters_with_the_definition_files_values(name):
    params = importlib.import_module(OWNERS[name]).PARAMETERS
    assert isinstance(params, FamilyParameters)
    assert params.model_dump(mode="json") == {k: p.value for k, p in family(name).parameters.items()}


def test_uncertainty_parameters_are_the_values_of_uncertainty_json():
    expected = {k: p["value"] for k, p in haptify_schemas.load("uncertainty.json")["parameters"].items()}
    assert uncertainty.PARAMETERS.model_dump(mode="json") == expected


def test_parameters_are_frozen():
    from haptify.metrics import vibration

    with pytest.raises(Exception, match="frozen"):
        vibration.PARAMETERS.edge_trim_s = 0.0  # type: ignore[misc]


def _modified_vibration(tmp_path: Path, change) -> Path:
    """A copy of vibration.json with its parameter values changed by ``change(values)``."""
    doc = json.loads((REPO / "schemas" / haptify_schemas.SPEC_VERSION / "metrics" / "vibration.json").read_text())
    values = {k: p["value"] for k, p in doc["parameters"].items()}
    change(values)
    doc["parameters"] = {k: {"value": v, "unit": "1", "description": "-"} for k, v in values.items()}
    path = tmp_path / "vibration.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def _only_finding(path: Path):
    from haptify.metrics.vibration import VibrationParameters

    with pytest.raises(HaptifyError) as exc:
        load_parameters(path, VibrationParameters)
    assert exc.value.code == "E905"
    (finding,) = exc.value.findings
    assert finding.file == str(path)
    return finding


def test_the_shipped_file_loads_through_a_path_as_through_the_family_name(tmp_path):
    from haptify.metrics import vibration

    assert load_parameters(_modified_vibration(tmp_path, lambda v: None), vibration.VibrationParameters) == vibration.PARAMETERS


def test_a_key_the_model_lacks_is_named(tmp_path):
    f = _only_finding(_modified_vibration(tmp_path, lambda v: v.update(lowpass_cutoff_hz=5.0)))
    assert "lowpass_cutoff_hz" in f.message and f.pointer == "/parameters/lowpass_cutoff_hz/value"
    assert "no parameter 'lowpass_cutoff_hz'" in f.expected and "edge_trim_s" in f.expected and f.found == 5.0


def test_a_key_the_file_lacks_is_named(tmp_path):
    f = _only_finding(_modified_vibration(tmp_path, lambda v: v.pop("edge_trim_s")))
    assert "edge_trim_s" in f.message and f.pointer == "/parameters/edge_trim_s"
    assert f.expected == "float" and f.found == "no such parameter"


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        ("edge_trim_s", "0.5", "float"),  # a string is no number
        ("highpass_order", 4.0, "int"),  # a number with a fraction part's notation is no integer
        ("highpass_order", True, "int"),  # nor is a boolean
        ("highpass_cutoff_hz", [10.0], "float"),
    ],
)
def test_a_value_of_the_wrong_type_is_named(tmp_path, key, value, expected):
    f = _only_finding(_modified_vibration(tmp_path, lambda v: v.update({key: value})))
    assert key in f.message and f.pointer == f"/parameters/{key}/value"
    assert f.expected == expected and f.found == value


def test_an_integer_is_taken_where_a_number_is_declared(tmp_path):
    from haptify.metrics.vibration import VibrationParameters

    p = load_parameters(_modified_vibration(tmp_path, lambda v: v.update(edge_trim_s=1)), VibrationParameters)
    assert p.edge_trim_s == 1.0 and isinstance(p.edge_trim_s, float)


def test_every_problem_is_one_finding(tmp_path):
    from haptify.metrics.vibration import VibrationParameters

    path = _modified_vibration(tmp_path, lambda v: (v.pop("min_duration_s"), v.update(highpass_order="4", extra=1)))
    with pytest.raises(HaptifyError) as exc:
        load_parameters(path, VibrationParameters)
    assert sorted(f.pointer for f in exc.value.findings) == [
        "/parameters/extra/value",
        "/parameters/highpass_order/value",
        "/parameters/min_duration_s",
    ]


def test_uncertainty_json_goes_through_the_same_check():
    defs = uncertainty.definitions()
    params = {k: p for k, p in defs.parameters.items() if k != "mc_seed"}
    with pytest.raises(HaptifyError) as exc:
        validate_parameters(params, uncertainty.UncertaintyParameters, "uncertainty.json")
    (finding,) = exc.value.findings
    assert finding.code == "E905" and finding.file == "uncertainty.json" and "mc_seed" in finding.message
    assert finding.expected == "int"


class _Toy(FamilyParameters):
    rate_hz: float
    order: int
    band_hz: tuple[float, float]
    mode: Literal["fast", "exact"]
    enabled: bool


_FINITE = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(
    rate=_FINITE,
    order=st.integers(-(2**53), 2**53),
    band=st.tuples(_FINITE, _FINITE),
    mode=st.sampled_from(["fast", "exact"]),
    enabled=st.booleans(),
)
def test_any_valid_value_set_round_trips(rate, order, band, mode, enabled):
    values = {"rate_hz": rate, "order": order, "band_hz": list(band), "mode": mode, "enabled": enabled}
    doc = {
        "family": "toy",
        "version": "1.0.0",
        "spec_section": "99",
        "parameters": {k: {"value": v, "unit": "1", "description": "-"} for k, v in values.items()},
    }
    assert load_parameters(doc, _Toy).model_dump(mode="json") == values


@settings(max_examples=40, deadline=None)
@given(value=st.one_of(st.text(), st.booleans(), st.floats(allow_nan=False, allow_infinity=False), st.none()))
def test_an_integer_parameter_takes_nothing_but_an_integer(value):
    doc = {
        "family": "toy",
        "version": "1.0.0",
        "spec_section": "99",
        "parameters": {
            k: {"value": v, "unit": "1", "description": "-"}
            for k, v in {"rate_hz": 1.0, "order": value, "band_hz": [0.0, 1.0], "mode": "fast", "enabled": False}.items()
        },
    }
    with pytest.raises(HaptifyError) as exc:
        load_parameters(doc, _Toy)
    assert [f.pointer for f in exc.value.findings] == ["/parameters/order/value"]


def _imports_of_parameters(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [
        f"{path.relative_to(REPO)}:{node.lineno}"
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and any(a.name == "PARAMETERS" for a in node.names)
    ]


def test_parameters_are_read_through_the_owning_module_never_bound_by_name():
    """``from haptify.metrics.vibration import PARAMETERS`` would keep the object of import time: a patch of the owner's
    attribute (the mutants', a test's) would not reach that reader."""
    files = [*(REPO / "reference").rglob("*.py"), *(REPO / "tools").rglob("*.py"), *(REPO / "conformance").rglob("*.py")]
    assert [hit for f in files for hit in _imports_of_parameters(f)] == []
