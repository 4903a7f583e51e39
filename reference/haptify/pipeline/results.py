"""The results file ``results.json`` and the metric-result records (spec chapter 15).

A family module (``haptify.metrics.vibration``, ``haptify.metrics.workspace``, …) computes its metrics into
:class:`MetricResult` records, or says with :class:`Unavailable` why it could not. ``haptify compute``
collects them into a :class:`ResultsFile`, whose JSON Schema (``results.schema.json``) is generated
from this model.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from haptify.codes import Code
from haptify.versions import SPEC_VERSION

Number = float
Value = float | list[float]


class BudgetTerm(BaseModel):
    """One line of an uncertainty budget (spec §19.4): a source, its type, the standard uncertainty of the
    input quantity, the sensitivity of the metric to it and its contribution to the metric's u."""

    model_config = ConfigDict(extra="forbid")
    source: str = Field(description="A source id of uncertainty.json (e.g. repeatability, handle_force_calibration).")
    type: Literal["A", "B"] = Field(description="GUM evaluation type: A from the repetitions, B from other knowledge.")
    distribution: Literal["t", "normal", "rectangular"]
    u_input: Value = Field(description="Standard uncertainty of the input quantity, in 'unit'.")
    unit: str = Field(description="Unit of u_input.")
    sensitivity: Value = Field(description="|∂metric/∂input| (metric unit per input unit); 1 for repeatability.")
    contribution: Value = Field(description="Contribution to the metric's standard uncertainty, in the metric's unit.")
    dof: float | None = Field(None, gt=0, description="Degrees of freedom of the contribution; absent: infinite.")


class UncorrectedBias(BaseModel):
    """A systematic effect the value keeps (spec §19.3): the value reads off the measurand by about
    ``estimate``, whose magnitude U includes (GUM F.2.4.5)."""

    model_config = ConfigDict(extra="forbid")
    source: str = Field(description="A bias id of uncertainty.json (noise_maximum, mocap_noise).")
    estimate: float = Field(
        description="How far the value reads above (positive) or below (negative) the measurand, in the metric's unit."
    )
    u_input: float = Field(
        ge=0,
        description="The input the estimate rests on (noise_maximum: the force noise's sd; mocap_noise: the track's noise sd), in 'unit'.",
    )
    unit: str = Field(description="Unit of u_input.")


class MetricUncertainty(BaseModel):
    """A metric's measurement uncertainty (spec §19.4): u, U = k·u at the coverage probability, the
    effective degrees of freedom (Welch–Satterthwaite) and the budget."""

    model_config = ConfigDict(extra="forbid")
    method: Literal["type_a", "type_a_mc"] = Field(
        description="type_a: repetitions only; type_a_mc: plus Monte Carlo Type B (§19.3)."
    )
    u: Value = Field(description="Combined standard uncertainty, in the metric's unit (per component for a vector).")
    U: Value = Field(description="Expanded uncertainty k·u, plus |bias.estimate| when a bias is named.")
    k: float = Field(gt=0, description="Coverage factor: Student's t at dof_eff for the coverage probability.")
    coverage_probability: float = Field(gt=0, lt=1)
    dof_eff: float | None = Field(None, gt=0, description="Effective degrees of freedom (GUM G.4); absent: infinite.")
    budget: list[BudgetTerm]
    mc_draws: int | None = Field(None, ge=2, description="Monte Carlo draws behind the Type B terms.")
    bias: UncorrectedBias | None = Field(
        None, description="A systematic effect the value keeps, its magnitude included in U (§19.3)."
    )
    sources_missing: list[str] = Field(
        default_factory=list,
        description="Type B sources of the method this session's rig figures could not give (left out of u).",
    )

    @field_validator("u", "U")
    @classmethod
    def _finite(cls, v: Any) -> Any:
        for x in v if isinstance(v, list) else [v]:
            if not math.isfinite(x) or x < 0:
                raise ValueError("uncertainties are finite and non-negative")
        return v


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
    uncertainty: MetricUncertainty | None = Field(
        None, description="Measurement uncertainty (spec chapter 19), with `haptify compute --uncertainty`."
    )

    @field_validator("value", "per_repetition", "sd")
    @classmethod
    def _finite(cls, v: Any) -> Any:
        """No metric silently returns NaN (spec §15.2)."""
        flat = v if isinstance(v, list) else [v]
        for x in flat:
            for y in x if isinstance(x, list) else [x]:
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


def load_results(path: str | os.PathLike[str]) -> ResultsFile:
    """Read and check a results file (spec §15.1) — the one reader of ``compare``, ``report`` and ``view``:
    E903 when the path names no file, E104 naming the file and every invalid field."""
    from haptify.errors import fail
    from haptify.formats.storage import read_json_model

    path = Path(path)
    if not path.is_file():
        raise fail(Code.USAGE, f"results file {str(path)!r} does not exist", file=str(path))
    return read_json_model(path, ResultsFile, Code.SCHEMA_VIOLATION)
