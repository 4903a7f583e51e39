"""Machine-readable metric definitions (spec §0.3 and every metric chapter).

Each metric family (one spec chapter, e.g. vibration) has one definition file
``schemas/<v>/metrics/<family>.json``: the family's parameters (filter orders, cut-offs, windows,
constants) and its metrics (id, unit, inputs). The reference reads every parameter from there and the
spec's parameter tables are generated from the same files, so prose and code cannot drift.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from haptify import schemas


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


def param(family_name: str, key: str) -> Any:
    """The value of parameter ``key`` of family ``family_name`` (units as its definition says; spec §0.3)."""
    return family(family_name).parameters[key].value


def all_families() -> list[MetricFamily]:
    """Every definition file shipped with this spec version."""
    return [family(n[:-5]) for n in schemas.list_dir("metrics")]
