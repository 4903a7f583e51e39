"""Conformance cases as data (spec §16.2): the case model, loading and selection."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

SUITE_ROOT = Path(__file__).resolve().parents[1]  # conformance/ of a source checkout
REPO_ROOT = SUITE_ROOT.parent
SUITE_ENV = "HAPTIFY_CONFORMANCE_SUITE"


@dataclass(frozen=True)
class Suite:
    """Where a run finds the suite's data (spec §16.1): ``cases_root/cases/*.json`` and ``repo/fixtures/``."""

    cases_root: Path
    repo: Path


def find_suite(option: Path | None = None, environ: Mapping[str, str] | None = None) -> Suite:
    """The suite named by ``--suite DIR``, else by ``$HAPTIFY_CONFORMANCE_SUITE``, else the source checkout
    this package lies in (spec §16.1). DIR is a checkout of the standard (or its suite archive, unpacked):
    it holds ``conformance/cases/`` and ``fixtures/``. Raises ValueError saying where it looked."""
    env: Mapping[str, str] = os.environ if environ is None else environ
    named = option or (Path(env[SUITE_ENV]) if env.get(SUITE_ENV) else None)
    candidates = [named] if named is not None else [REPO_ROOT]
    for root in candidates:
        if (root / "conformance" / "cases").is_dir() and (root / "fixtures").is_dir():
            return Suite(cases_root=root / "conformance", repo=root)
    where = f"{str(named)!r}" if named is not None else f"the installed package's checkout ({str(REPO_ROOT)!r})"
    raise ValueError(
        f"no conformance suite in {where}: expected conformance/cases/ and fixtures/ there; "
        f"pass --suite DIR or set {SUITE_ENV} to a checkout of the Haptify standard"
    )


class Tolerance(BaseModel):
    """A case passes when ``|actual − expected| ≤ abs + rel·|expected|`` for every component; abs in the metric's unit, rel dimensionless (spec §16.2)."""

    model_config = ConfigDict(extra="forbid")
    abs: float = Field(ge=0, description="Absolute part, in the metric's unit.")
    rel: float = Field(ge=0, description="Relative part (dimensionless).")


class Expected(BaseModel):
    """The expected answer: a value with its unit, or error codes (negative cases), or validity (spec §16.2, §16.3)."""

    model_config = ConfigDict(extra="forbid")
    value: float | list[float] | None = None
    unit: str | None = None
    codes: list[str] | None = Field(None, description="Codes the implementation must report (negative cases).")
    valid: bool | None = Field(None, description="For 'validate' cases on valid sessions: must be accepted.")


class BudgetTerm(BaseModel):
    """One source of allowed difference from the expected value: abs in the metric's unit, rel dimensionless (spec §16.2)."""

    model_config = ConfigDict(extra="forbid")
    source: str
    abs: float = Field(0.0, ge=0)
    rel: float = Field(0.0, ge=0)


class Provenance(BaseModel):
    """How a case's expected value is known: analytic, generated from a known model, paper or spec, with a note
    and, for a metric case, the budget its tolerance is the sum of (spec §16.2, §16.7, §16.8.1)."""

    model_config = ConfigDict(extra="forbid")
    kind: Literal["analytic", "generated", "paper", "spec"]
    note: str
    budget: list[BudgetTerm] | None = Field(
        None, description="Sources of allowed difference; the tolerance must not exceed their sum."
    )


class Case(BaseModel):
    """One conformance case (spec §16.2; ``conformance-cases.schema.json`` is generated from the case-file model)."""

    model_config = ConfigDict(extra="forbid")
    id: str = Field(pattern=r"^[a-z0-9][a-z0-9._-]*$", description="Permanent; never reused for another case.")
    metric: str = Field(description="A metric id from schemas/<v>/metrics, or 'validate'.")
    quantity: Literal["value", "u", "U", "k"] = Field(
        "value",
        description="What of the metric record is judged: its value, or u, U or k of its uncertainty record "
        '(spec §19.4; the case\'s parameters then ask for it: {"uncertainty": true}).',
    )
    spec_section: str
    level: Literal["MUST", "SHOULD"]
    requirements: list[str] = Field(
        default_factory=list,
        description="Ids of the requirements the case tests "
        "(schemas/<v>/requirements.json, or R<section>-<code> for a validation code; spec §16.7).",
    )
    fixture: str = Field(description="Session folder, relative to the repository's fixtures/ folder.")
    parameters: dict[str, Any] = Field(default_factory=dict)
    expected: Expected
    tolerance: Tolerance | None = None
    provenance: Provenance
    spec_versions: list[str] = Field(min_length=1)
    description: str


class CaseFile(BaseModel):
    """One case file ``conformance/cases/<name>.json``: a description and its cases (spec §16.1, §16.8.1)."""

    model_config = ConfigDict(extra="forbid")
    description: str
    cases: list[Case]


def case_files(root: Path = SUITE_ROOT) -> list[Path]:
    """The suite's case files ``cases/*.json``, sorted by name (spec §16.1)."""
    return sorted((root / "cases").glob("*.json"))


@lru_cache(maxsize=4)
def _load(root: Path) -> tuple[Case, ...]:
    out: list[Case] = []
    for path in case_files(root):
        data = json.loads(path.read_text(encoding="utf-8"))
        try:
            out.extend(CaseFile.model_validate(data).cases)
        except ValidationError as exc:
            raise ValueError(f"{path}: {exc}") from None
    return tuple(out)


def load_cases(root: Path = SUITE_ROOT) -> list[Case]:
    """Every case of the suite, in file order (``conformance/cases/*.json``, spec §16.1–16.2)."""
    return list(_load(root))


def select(
    cases: list[Case], *, level: str | None = None, metrics: set[str] | None = None, spec_version: str | None = None
) -> list[Case]:
    """Cases filtered by ``--level``, ``--metric`` and spec version; the suite itself never skips."""
    out = []
    for c in cases:
        if level == "MUST" and c.level != "MUST":
            continue
        if metrics and c.metric not in metrics:
            continue
        if spec_version and spec_version not in c.spec_versions:
            continue
        out.append(c)
    return out


def fixture_path(case: Case, repo: Path = REPO_ROOT) -> Path:
    """The session folder a case runs on: ``fixtures/<case.fixture>`` under ``repo`` (spec §16.1)."""
    return repo / "fixtures" / case.fixture
