"""The normative data: schemas are current, valid against their metaschema, tables are generated."""

from __future__ import annotations

import json

import jsonschema
import pytest
from conftest import REPO

from haptify import schemas
from haptify.metrics.metric_definitions import MetricFamily
from haptify.versions import SPEC_VERSION, schema_id
from haptify_tools import gen_docs, gen_schemas

SCHEMA_FILES = sorted((REPO / "schemas" / SPEC_VERSION).glob("*.schema.json"))


def test_committed_schemas_are_current():
    assert gen_schemas.main(["--check"]) == 0


def test_normative_schemas_come_from_the_reference_or_the_judge_never_from_the_tools():
    # spec §0.3: a schema of the standard (schemas/<v>/) is generated from a model of the reference, or of the
    # conformance package for the judge's own files; the tools' schemas live beside the tools
    for name, target in gen_schemas.MODELS.items():
        package = target.split(".")[0]
        if name in gen_schemas.OUTSIDE_THE_STANDARD:
            assert package == "haptify_tools", name
        else:
            assert package in ("haptify", "haptify_conform"), f"{name} is generated from {target}"


def test_spec_generated_tables_are_current():
    assert gen_docs.main(["--check"]) == 0


@pytest.mark.parametrize("path", SCHEMA_FILES, ids=lambda p: p.name)
def test_schema_is_valid_draft_2020_12_with_versioned_id(path):
    doc = json.loads(path.read_text())
    jsonschema.Draft202012Validator.check_schema(doc)
    assert doc["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert doc["$id"] == schema_id(path.name.removesuffix(".schema.json"))
    assert f"/{SPEC_VERSION}/" in doc["$id"]


def test_every_metric_definition_validates_and_ids_are_unique():
    ids = []
    for name in schemas.list_dir("metrics"):
        fam = MetricFamily.model_validate(schemas.load(f"metrics/{name}"))
        assert fam.family == name.removesuffix(".json")
        ids += [m.id for m in fam.metrics]
        for m in fam.metrics:
            assert m.id.split(".")[0] in (
                fam.family,
                "rig",
                "surface",
                "stiffness",
                "vibration",
                "workspace",
                "free_space",
                "dynamics",
            )
    assert len(ids) == len(set(ids))


def test_the_definition_files_name_no_code_and_every_family_with_metrics_has_its_module():
    """Spec §15.4: the standard's data says nothing of Python; the computing module of a family is the
    entry point of its id (group haptify.metric_families), and no entry point names an undefined family."""
    import importlib
    from importlib.metadata import entry_points

    from haptify.pipeline.families import FAMILY_ENTRY_POINTS, family_module

    families = {name.removesuffix(".json"): schemas.load(f"metrics/{name}") for name in schemas.list_dir("metrics")}
    assert all("module" not in data for data in families.values())
    named = {ep.name: ep.value for ep in entry_points(group=FAMILY_ENTRY_POINTS)}
    assert set(named) <= set(families)
    for family, data in families.items():
        if data["metrics"]:
            assert family in named, f"family {family!r} defines metrics but no module computes it"
            assert callable(importlib.import_module(named[family]).compute)
            assert {family_module(m["id"]) for m in data["metrics"]} == {named[family]}


def test_code_catalogue_is_unique_and_complete():
    codes = schemas.load("codes.json")["codes"]
    assert len({c["code"] for c in codes}) == len(codes)
    assert len({c["name"] for c in codes}) == len(codes)
    for c in codes:
        assert c["severity"] in ("error", "warning")
        assert c["code"][0] == {"error": "E", "warning": "W"}[c["severity"]]
        assert c["hint"] and c["title"] and c["spec_section"]


def test_stream_kinds_and_protocols_agree():
    kinds = schemas.load("stream-kinds.json")["kinds"]
    for name, proto in schemas.load("protocols.json")["protocols"].items():
        for k in proto["required"] + proto["recommended"]:
            assert k in kinds, (name, k)


def test_session_schema_accepts_what_the_model_accepts(example_session):
    doc = json.loads((example_session / "session.json").read_text())
    validator = jsonschema.Draft202012Validator(schemas.schema("session"))
    assert list(validator.iter_errors(doc)) == []
    doc["trials"][0]["protocol"] = "juggling"
    assert any(e.validator == "enum" or e.validator == "const" for e in validator.iter_errors(doc))
