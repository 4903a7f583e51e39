"""Generate the JSON Schemas in ``schemas/<v>/`` from the pydantic models (spec §0.3).

The pydantic models in the reference are the single source; this tool writes their JSON Schemas
(draft 2020-12, ``$id`` carrying the spec version) and ``--check`` fails when a committed file is
stale. Run ``python -m haptify_tools.gen_schemas`` after changing a model.
"""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

from haptify.versions import SCHEMA_VERSION, SPEC_VERSION, schema_id
from haptify_tools.generated_files import generator_main

# schema name -> "module:Class"; the file is schemas/<spec>/<name>.schema.json, except for the tools' own
# files (OUTSIDE_THE_STANDARD).
MODELS: dict[str, str] = {
    "session": "haptify.formats.session_format:Session",
    "device": "haptify.formats.session_format:Device",
    "rig": "haptify.formats.session_format:Rig",
    "metric-definition": "haptify.metrics.metric_definitions:MetricFamily",
    "results": "haptify.pipeline.results:ResultsFile",
    "uncertainty-definitions": "haptify.metrics.uncertainty:UncertaintyDefinitions",
    "import-map": "haptify.formats.importers:ImportMap",
    "hw-model": "haptify.dynamics:HWModelFile",
    "validation-report": "haptify.formats.validation.report:ValidationReportModel",
    "bundle": "haptify.formats.bundle_format:Bundle",
    "conformance-cases": "haptify_conform.cases:CaseFile",
    "conform-report": "haptify_conform.report:ConformReport",
    "twin": "haptify_tools.twin.model:TwinFile",
    "discrepancy": "haptify_tools.discrepancy.model:DiscrepancyFile",
}

REPO = Path(__file__).resolve().parents[2]
SCHEMA_DIR = REPO / "schemas" / SPEC_VERSION
# Files of the tools are not part of the standard: their schemas live beside the tool.
OUTSIDE_THE_STANDARD = {
    "twin": REPO / "tools" / "haptify_tools" / "twin" / "twin.schema.json",
    "discrepancy": REPO / "tools" / "haptify_tools" / "discrepancy" / "discrepancy.schema.json",
}


def render(name: str, target: str) -> str:
    """The JSON text of schema ``name`` generated from ``target`` (``module:Class``)."""
    module_name, cls_name = target.split(":")
    model = getattr(importlib.import_module(module_name), cls_name)
    body = model.model_json_schema(mode="validation")
    doc = {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": schema_id(name),
        "x-haptify-schema-version": SCHEMA_VERSION,
    }
    doc.update(body)
    return json.dumps(doc, indent=2, ensure_ascii=False, sort_keys=False) + "\n"


def targets() -> dict[Path, str]:
    return {
        OUTSIDE_THE_STANDARD.get(name, SCHEMA_DIR / f"{name}.schema.json"): render(name, target)
        for name, target in MODELS.items()
    }


def main(argv: list[str] | None = None) -> int:
    return generator_main(argv, __doc__.splitlines()[0], "haptify_tools.gen_schemas", "schema(s)", targets)


if __name__ == "__main__":
    sys.exit(main())
