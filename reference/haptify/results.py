"""The results file ``results.json`` and the metric-result records (spec chapter 15).

A family module (``haptify.vibration``, ``haptify.workspace``, …) computes its metrics into
:class:`MetricResult` records, or says with :class:`Unavailable` why it could not. ``haptify compute``
collects them into a :class:`ResultsFile`, whose JSON Schema (``results.schema.json``) is generated
from this model.
"""

from __future__ import annotations

import math
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, field_validator

from haptify.versions import SPEC_VERSION

Number = float
Value = float | list[float]


class MetricResult(BaseModel):
    """One metric's value (spec §15.2). ``value`` aggregates ``per_repetition`` as the definition says."""

    model_config = ConfigDict(extra="forbid")
    id: str = Field(pattern=r"^[a-z_]+(\.[a-z0-9_]+)+$")
    value: Value
    unit: str
    per_repetition: list[Value] = Field(default_factory=list, description="One value per repetition (trial), in trial order.")
    trials: list[str] = Field(default_factory=list, description="The trial ids the values come from.")
    n: int = Field(ge=0, description="Number of repetitions (or, for single-trial metrics, samples) behind the value.")
    sd: Value | None = Field(None, description="Standard deviation over repetitions (ddof = 1) when n ≥ 2.")
    diagnostics: dict[str, Any] = Field(default_factory=dict)
    definition_version: str
    warnings: list[str] = Field(default_factory=list, description="Codes of findings about this metric.")

    @field_validator("value", "per_repetition", "sd")
    @classmethod
    def _finite(cls, v: Any) -> Any:
        """No metric silently returns NaN (spec §15.2)."""
        flat = v if isinstance(v, list) else [v]
        for x in flat:
            for y in (x if isinstance(x, list) else [x]):
                if y is not None and not math.isfinite(y):
                    raise ValueError("metric values must be finite; report Unavailable instead")
        return v


class Unavailable(BaseModel):
    """A metric that could not be computed from this session, and why (spec §15.2)."""

    model_config = ConfigDict(extra="forbid")
    id: str
    code: str = Field(description="A code from codes.json that explains why (e.g. E302 when a stream is missing).")
    reason: str


class ResultWarning(BaseModel):
    """A coded finding raised while computing, optionally tied to a metric and a trial (spec §15.1)."""

    model_config = ConfigDict(extra="forbid")
    code: str
    message: str
    metric: str | None = None
    trial: str | None = None


class Implementation(BaseModel):
    """Name and version of the software that computed the results (spec §15.1)."""

    model_config = ConfigDict(extra="forbid")
    name: str
    version: str


class DeviceSummary(BaseModel):
    """Which device the results describe (copied from the session's device description; spec §15.1)."""

    model_config = ConfigDict(extra="forbid")
    manufacturer: str
    model: str
    serial: str | None = None

    @property
    def label(self) -> str:
        return f"{self.manufacturer} {self.model}" + (f" #{self.serial}" if self.serial else "")


class ResultsFile(BaseModel):
    """``results.json`` (spec §15.1)."""

    model_config = ConfigDict(extra="forbid")
    spec_version: str = SPEC_VERSION
    implementation: Implementation
    session_id: str
    device: DeviceSummary | None = None
    manifest_sha256: str = Field(pattern=r"^[0-9a-f]{64}$")
    metrics: list[MetricResult] = Field(default_factory=list)
    unavailable: list[Unavailable] = Field(default_factory=list)
    warnings: list[ResultWarning] = Field(default_factory=list)

    def get(self, metric_id: str) -> MetricResult | None:
        return next((m for m in self.metrics if m.id == metric_id), None)
