"""Coded findings and errors (spec chapter 4 and §0.4).

Every problem the reference reports carries a stable code from ``schemas/<v>/codes.json``, named in the
code by its :class:`~haptify.codes.Code` member (``Code.TIME_NOT_INCREASING``, never the bare ``"E203"``). A
:class:`Finding` is one problem in a report (validation collects many); :class:`HaptifyError` is
raised when a command cannot go on, and carries one or more findings. The CLI turns both into
readable lines or JSON and never shows a traceback.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from functools import lru_cache
from typing import Any

from haptify import schemas
from haptify.codes import Code


@lru_cache(maxsize=1)
def catalogue() -> dict[str, dict[str, Any]]:
    """The code catalogue ``schemas/1.0/codes.json``, keyed by code (``"E203"``; spec §0.4)."""
    return {c["code"]: c for c in schemas.load("codes.json")["codes"]}


@dataclass
class Finding:
    """One coded problem: what, where (file, JSON pointer or column and time range), expected vs found.
    Spec §0.4, §4.6."""

    code: str
    message: str
    file: str | None = None
    pointer: str | None = None
    column: str | None = None
    time_range: tuple[float, float] | None = None
    expected: Any = None
    found: Any = None
    severity: str = field(init=False)
    name: str = field(init=False)
    hint: str = field(init=False)
    spec_section: str = field(init=False)

    def __post_init__(self) -> None:
        self.code = str(self.code)  # a Code member is kept as its plain code, so reprs and pickles stay as before
        try:
            entry = catalogue()[self.code]
        except KeyError:  # a programming error: every code must be catalogued
            raise ValueError(f"finding code {self.code!r} is not in codes.json") from None
        self.severity = entry["severity"]
        self.name = entry["name"]
        self.hint = entry["hint"]
        self.spec_section = entry["spec_section"]

    @property
    def is_error(self) -> bool:
        return self.severity == "error"

    def location(self) -> str:
        """A short human location such as ``trials/t1/handle_wrench.parquet [fx] t=1.2–1.3 s``."""
        parts = [self.file or ""]
        if self.pointer:
            parts.append(f"#{self.pointer}")
        if self.column:
            parts.append(f" [{self.column}]")
        if self.time_range:
            parts.append(f" t={self.time_range[0]:.6g}–{self.time_range[1]:.6g} s")
        return "".join(parts).strip()

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if self.time_range is not None:
            d["time_range"] = list(self.time_range)
        return {k: v for k, v in d.items() if v is not None}

    def __str__(self) -> str:
        text = f"{self.code} {self.severity}: {self.message}"
        loc = self.location()
        if loc:
            text += f"\n    at {loc}"
        if self.expected is not None or self.found is not None:
            text += f"\n    expected {self.expected!r}, found {self.found!r}"
        text += f"\n    hint: {self.hint} (spec §{self.spec_section})"
        return text


class HaptifyError(Exception):
    """A coded failure that stops a command; holds the findings that explain it (spec §0.4).
    ``exit_code`` is the command's exit status (§0.5): 2, the command could not run."""

    exit_code = 2

    def __init__(self, *findings: Finding) -> None:
        if not findings:
            raise ValueError("HaptifyError needs at least one finding")
        self.findings = list(findings)
        super().__init__("\n".join(str(f) for f in findings))

    @property
    def code(self) -> str:
        return self.findings[0].code


def fail(code: Code, message: str, **where: Any) -> HaptifyError:
    """Build (not raise) a :class:`HaptifyError` with a single finding: ``raise fail(Code.STREAM_FILE_MISSING, ...)``.
    Spec §0.4."""
    return HaptifyError(Finding(code, message, **where))
