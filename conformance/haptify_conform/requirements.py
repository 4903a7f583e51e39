"""Requirement ids (spec §16.7): the normative statements a conformance case tests.

Two kinds, both normative data under ``schemas/<version>/``:

* **value requirements** — ``requirements.json``: a computational choice of chapters 1 and 6–15 (a filter,
  an axis combination, an aggregation…) with the metrics whose value it decides;
* **verdict requirements** — the validation codes of ``codes.json`` (chapters 1–4): a session showing
  what the code describes MUST be reported with it. Their id is ``R<section>-<code>``.

A case lists the ids of the requirements it tests: the value requirements that decide its metric, or, for a
``validate`` case, the verdict requirements of the codes it expects.
"""

from __future__ import annotations

from dataclasses import dataclass
from fnmatch import fnmatchcase
from functools import lru_cache
from typing import Any

import haptify_schemas as schemas

#: Chapters whose codes are validation verdicts (conventions, session format, storage, validation).
VERDICT_CHAPTERS = ("1", "2", "3", "4")


@dataclass(frozen=True)
class Requirement:
    """One normative statement: stable id, spec section, RFC 2119 level, text; ``metrics`` are the metric-id
    patterns whose value it decides (value requirements), ``code`` the code it demands (verdicts)."""

    id: str
    section: str
    level: str
    statement: str
    metrics: tuple[str, ...] = ()
    code: str | None = None

    @property
    def kind(self) -> str:
        return "verdict" if self.code else "value"

    def decides(self, metric: str) -> bool:
        """Whether this requirement decides the value of ``metric``."""
        return any(fnmatchcase(metric, pattern) for pattern in self.metrics)


@lru_cache(maxsize=1)
def _data() -> dict[str, Any]:
    data: dict[str, Any] = schemas.load("requirements.json")
    return data


def verdict_exemptions() -> dict[str, str]:
    """Validation codes that no fixture can show, each with the reason (``requirements.json``)."""
    return dict(_data().get("verdict_exemptions", {}))


@lru_cache(maxsize=1)
def all_requirements() -> tuple[Requirement, ...]:
    """Every requirement of the spec version, value requirements first, in data order."""
    value = [Requirement(r["id"], r["section"], r["level"], r["statement"], tuple(r["metrics"])) for r in _data()["requirements"]]
    exempt = verdict_exemptions()
    verdict = [
        Requirement(
            f"R{c['spec_section']}-{c['code']}",
            c["spec_section"],
            "MUST",
            f"{c['title']}: reported as {c['code']} ({c['severity']}).",
            code=c["code"],
        )
        for c in schemas.load("codes.json")["codes"]
        if c["spec_section"].split(".")[0] in VERDICT_CHAPTERS and c["code"] not in exempt
    ]
    return tuple(value + verdict)


@lru_cache(maxsize=1)
def by_id() -> dict[str, Requirement]:
    """Every requirement by its id."""
    return {r.id: r for r in all_requirements()}


def requirements_for_case(metric: str, codes: list[str] | None = None, quantity: str = "value") -> list[str]:
    """The ids a case of ``metric`` tests: for ``validate`` cases the verdicts of its expected ``codes``,
    otherwise every value requirement that decides the metric — and, for a case on ``u``, ``U`` or ``k`` of
    its uncertainty (spec §19.4), those whose patterns name ``<metric>:<quantity>`` (e.g. ``*:k``)."""
    if metric == "validate":
        wanted = set(codes or ())
        return [r.id for r in all_requirements() if r.code in wanted]
    decides = [r for r in all_requirements() if r.kind == "value" and r.decides(metric)]
    if quantity != "value":
        decides += [r for r in all_requirements() if r.kind == "value" and r.decides(f"{metric}:{quantity}")]
    seen = dict.fromkeys(r.id for r in decides)
    return [r.id for r in all_requirements() if r.id in seen]
