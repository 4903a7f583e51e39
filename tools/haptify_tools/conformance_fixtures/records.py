"""The records of the conformance suite's metric cases (spec §16.2): a :class:`Fixture` (folder name, writer,
cases) and :func:`case`, one case with its tolerance summed from its budget."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from haptify.versions import SPEC_VERSION
from haptify_tools.tolerance_budgets import budget_record

FIXTURE_DIR = "conformance"


@dataclass
class Fixture:
    """One fixture: its folder name, the function that writes it, and the cases that run on it."""

    name: str
    build: Callable[[Path], None]
    cases: list[dict] = field(default_factory=list)


def case(
    cid: str,
    metric: str,
    section: str,
    fixture: str,
    value: Any,
    unit: str,
    kind: str,
    note: str,
    description: str,
    parameters: dict | None = None,
    level: str = "MUST",
    quantity: str = "value",
) -> dict:
    """A metric case (spec §16.2) whose tolerance is the sum of its budget (:mod:`haptify_tools.tolerance_budgets`);
    ``quantity`` u, U or k judges the metric's uncertainty record instead of its value (§19.4)."""
    value = [float(v) for v in value] if isinstance(value, (list, tuple, np.ndarray)) else float(value)
    budget = budget_record(cid)
    head = {"id": cid, "metric": metric} | ({"quantity": quantity} if quantity != "value" else {})
    return {
        **head,
        "spec_section": section,
        "level": level,
        "fixture": f"{FIXTURE_DIR}/{fixture}",
        "parameters": parameters or {},
        "expected": {"value": value, "unit": unit},
        "tolerance": {"abs": math.fsum(t["abs"] for t in budget), "rel": math.fsum(t["rel"] for t in budget)},
        "provenance": {"kind": kind, "note": note, "budget": budget},
        "spec_versions": [SPEC_VERSION],
        "description": description,
    }
