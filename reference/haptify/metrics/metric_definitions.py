"""Machine-readable metric definitions (spec §0.3 and every metric chapter).

Each metric family (one spec chapter, e.g. vibration) has one definition file
``schemas/<v>/metrics/<family>.json``: the family's parameters (filter orders, cut-offs, windows,
constants) and its metrics (id, unit, inputs). The spec's parameter tables are generated from the same
files, so prose and code cannot drift. The module that owns a family declares its parameters as a
:class:`FamilyParameters` model and loads them once, at import, with :func:`load_parameters`: a definition
file whose keys or value types differ from the model stops the import with a coded error (E905).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from haptify import schemas
from haptify.codes import Code
from haptify.errors import Finding, HaptifyError


class Parameter(BaseModel):
    """One parameter of a metric family: its value, SI unit ('1' dimensionless) and meaning (spec §0.3)."""

    model_config = ConfigDict(extra="forbid")
    value: Any = Field(description="The value, in 'unit'.")
    unit: str = Field(description="SI unit, or '1' for dimensionless, or '' for names and flags.")
    description: str


class MetricDefinition(BaseModel):
    """One metric of a family: id, SI unit, shape, the protocols and streams it reads, how repetitions aggregate (spec §0.3, §15.2–15.3)."""

    model_config = ConfigDict(extra="forbid")
    id: str = Field(pattern=r"^[a-z_]+(\.[a-z0-9_]+)+$")
    title: str
    unit: str
    shape: str = Field(
        "scalar", pattern=r"^(scalar|vector3|vector6|table)$", description="scalar, or a per-axis vector, or a diagnostic table."
    )
    protocols: list[str] = Field(description="Trials whose data feed the metric.")
    inputs: list[str] = Field(description="Stream kinds (and calibration records) it reads.")
    aggregation: str = Field(description="How repetitions combine into the reported value.")
    paper: str | None = Field(None, description="Where the paper defines or reports it.")
    description: str


class MetricFamily(BaseModel):
    """One definition file: a spec chapter's parameters and metrics."""

    model_config = ConfigDict(extra="forbid")
    family: str = Field(pattern=r"^[a-z_]+$")
    version: str = Field(pattern=r"^\d+\.\d+\.\d+$", description="Definition version; bumps when a parameter changes.")
    spec_section: str
    parameters: dict[str, Parameter]
    metrics: list[MetricDefinition] = Field(default_factory=list)


@lru_cache(maxsize=None)
def family(name: str) -> MetricFamily:
    """The parsed definition file ``metrics/<name>.json`` (spec §0.3)."""
    return MetricFamily.model_validate(schemas.load(f"metrics/{name}.json"))


class FamilyParameters(BaseModel):
    """The base of a family's typed parameters (spec §0.3): one field per parameter of its definition file,
    named by the parameter's key, of the value's type, in the unit the definition file states."""

    model_config = ConfigDict(extra="forbid", frozen=True)


P = TypeVar("P", bound=FamilyParameters)


def _type_name(annotation: Any) -> str:
    """``float``, ``tuple[float, float]``, ``Literal['soft_l1', 'linear']``: a field's type as a reader writes it."""
    return annotation.__name__ if isinstance(annotation, type) else str(annotation).replace("typing.", "")


def validate_parameters(parameters: Mapping[str, Parameter], model: type[P], file: str) -> P:
    """The parameters of one definition file (``file``, named in errors) as ``model``.

    Values are checked as the JSON they are, strictly: an integer where ``model`` wants a number is taken,
    a number where it wants an integer, a string for a number or a boolean for an integer is not. A key
    the model lacks, a key the file lacks or a value of the wrong type raises :class:`HaptifyError` E905
    with one finding per key: the file, the key (``/parameters/<key>/value``), expected and found
    (spec §0.3).
    """
    values = {key: p.value for key, p in parameters.items()}
    try:
        return model.model_validate_json(json.dumps(values), strict=True)
    except ValidationError as exc:
        findings = []
        for key in dict.fromkeys(str(e["loc"][0]) for e in exc.errors()):
            field = model.model_fields.get(key)
            expected = (
                _type_name(field.annotation)
                if field is not None
                else f"no parameter {key!r} ({model.__name__} declares {sorted(model.model_fields)})"
            )
            found = values[key] if key in values else "no such parameter"
            findings.append(
                Finding(
                    Code.DEFINITION_PARAMETERS_INVALID,
                    f"{file}: parameter {key!r} does not match {model.__name__}",
                    file=file,
                    pointer=f"/parameters/{key}/value" if key in values else f"/parameters/{key}",
                    expected=expected,
                    found=found,
                )
            )
        raise HaptifyError(*findings) from None


def load_parameters(source: str | Path | Mapping[str, Any], model: type[P]) -> P:
    """A family's parameters, validated against ``model`` (:func:`validate_parameters`; spec §0.3).

    ``source`` is a family name (its shipped file ``metrics/<name>.json``), the path of a definition file,
    or a definition document already parsed. Each family's owning module calls this once, at import:
    ``PARAMETERS = load_parameters("vibration", VibrationParameters)``.
    """
    if isinstance(source, str):
        return validate_parameters(family(source).parameters, model, f"metrics/{source}.json")
    if isinstance(source, Path):
        document = MetricFamily.model_validate(json.loads(source.read_text(encoding="utf-8")))
        return validate_parameters(document.parameters, model, str(source))
    document = MetricFamily.model_validate(source)
    return validate_parameters(document.parameters, model, f"metrics/{document.family}.json")


def all_families() -> list[MetricFamily]:
    """Every definition file shipped with this spec version."""
    return [family(n[:-5]) for n in schemas.list_dir("metrics")]
