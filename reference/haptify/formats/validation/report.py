"""The validation report (spec §4.6): the findings of one session folder, grouped by trial and file,
its exit code, and the machine-readable model of ``validation-report.schema.json``."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from haptify.codes import Code
from haptify.errors import Finding
from haptify.formats.storage import MANIFEST
from haptify.versions import PACKAGE_VERSION, SPEC_VERSION

EXIT_VALID, EXIT_INVALID, EXIT_CANNOT_RUN = 0, 1, 2


@dataclass
class ReportItem:
    """A finding and the trial it belongs to (None for session-level findings)."""

    finding: Finding
    trial: str | None = None


@dataclass
class ValidationReport:
    """Everything validation found in one session folder (spec §4.6)."""

    session: str
    items: list[ReportItem] = field(default_factory=list)
    streams_checked: int = 0

    @property
    def findings(self) -> list[Finding]:
        return [i.finding for i in self.items]

    @property
    def codes(self) -> list[str]:
        """The distinct codes found, sorted."""
        return sorted({f.code for f in self.findings})

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.is_error]

    @property
    def warnings(self) -> list[Finding]:
        return [f for f in self.findings if not f.is_error]

    @property
    def valid(self) -> bool:
        """True when no finding is an error (warnings allowed)."""
        return not self.errors

    @property
    def exit_code(self) -> int:
        """0 valid, 1 invalid, 2 validation could not run (no session folder, internal error) — spec §4.6."""
        if any(f.code in (Code.SESSION_NOT_FOUND, Code.INTERNAL_ERROR) for f in self.findings):
            return EXIT_CANNOT_RUN
        return EXIT_VALID if self.valid else EXIT_INVALID

    def groups(self) -> list[tuple[str | None, str, list[Finding]]]:
        """Findings grouped as ``(trial, file, findings)``: session-level first, then trial by trial."""
        order: dict[tuple[str | None, str], list[Finding]] = {}
        for item in self.items:
            order.setdefault((item.trial, item.finding.file or MANIFEST), []).append(item.finding)
        trial_rank = {t: n for n, t in enumerate(dict.fromkeys(i.trial for i in self.items))}
        keys = sorted(order, key=lambda k: (k[0] is not None, trial_rank[k[0]], k[1] != MANIFEST))
        return [(trial, file, order[(trial, file)]) for trial, file in keys]

    def to_model(self) -> "ValidationReportModel":
        """The machine-readable report (``validation-report.schema.json``)."""
        return ValidationReportModel(
            spec_version=SPEC_VERSION,
            haptify_version=PACKAGE_VERSION,
            session=self.session,
            valid=self.valid,
            exit_code=self.exit_code,
            errors=len(self.errors),
            warnings=len(self.warnings),
            streams_checked=self.streams_checked,
            findings=[FindingModel(trial=i.trial, **jsonable(i.finding.to_dict())) for i in self.items],
        )


class FindingModel(BaseModel):
    """One finding of a validation report (spec §4.6)."""

    model_config = ConfigDict(extra="forbid")

    code: str = Field(pattern=r"^[EW][0-9]{3}$", description="Stable code from codes.json.")
    name: str = Field(description="The code's short name, e.g. 'time-not-increasing'.")
    severity: Literal["error", "warning"]
    message: str
    hint: str
    spec_section: str = Field(description="The spec section the rule comes from, e.g. '2.6'.")
    trial: str | None = Field(None, description="The trial the finding belongs to; absent for session-level findings.")
    file: str | None = Field(None, description="Path of the file, relative to the session folder.")
    pointer: str | None = Field(None, description="JSON pointer (RFC 6901) into that file when it is JSON.")
    column: str | None = Field(None, description="The stream column concerned.")
    time_range: list[float] | None = Field(
        None, min_length=2, max_length=2, description="First and last affected sample time, s."
    )
    expected: Any = None
    found: Any = None


class ValidationReportModel(BaseModel):
    """The ``--json`` output of ``haptify validate`` (spec §4.6)."""

    model_config = ConfigDict(extra="forbid")

    spec_version: Literal[SPEC_VERSION]  # type: ignore[valid-type]
    haptify_version: str
    session: str = Field(description="The session folder as given on the command line.")
    valid: bool = Field(description="True when no finding is an error.")
    exit_code: Literal[0, 1, 2]
    errors: int = Field(ge=0)
    warnings: int = Field(ge=0)
    streams_checked: int = Field(ge=0)
    findings: list[FindingModel] = Field(description="Every finding, grouped: session-level first, then by trial and file.")


def jsonable(value: Any) -> Any:
    """A JSON-safe copy: numpy scalars to Python, tuples to lists, non-finite floats to strings."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return str(value)


def short(value: Any) -> Any:
    """A short printable stand-in for a found value (containers summarised, long text cut)."""
    if isinstance(value, dict):
        return "<object>"
    if isinstance(value, list):
        return f"<array of {len(value)}>"
    if isinstance(value, str) and len(value) > 80:
        return value[:77] + "..."
    return value
