"""The conformance suite as files (spec §16.2, §16.7): the fixture families, the validate cases of
``fixtures/invalid`` and ``fixtures/valid``, the case documents with their requirement ids, the fixtures'
digests and the writing of one fixture."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any, Callable

from haptify.versions import SPEC_VERSION
from haptify_conform.fixture_digest import DIGESTS, snapshot_digest
from haptify_conform.requirements import requirements_for_case
from haptify_tools.conformance_fixtures.dynamics import dynamics_fixtures
from haptify_tools.conformance_fixtures.free_space import free_space_fixtures
from haptify_tools.conformance_fixtures.records import Fixture
from haptify_tools.conformance_fixtures.rig import rig_fixtures
from haptify_tools.conformance_fixtures.stiffness import stiffness_fixtures
from haptify_tools.conformance_fixtures.surface import surface_fixtures
from haptify_tools.conformance_fixtures.uncertainty import uncertainty_fixtures
from haptify_tools.conformance_fixtures.vibration import vibration_fixtures
from haptify_tools.conformance_fixtures.workspace import workspace_fixtures


def validate_cases(fixtures_root: Path) -> list[dict]:
    cases = []
    for group in ("valid", "invalid"):
        for sidecar in sorted((fixtures_root / group).glob("*.expected.json")):
            name = sidecar.name.removesuffix(".expected.json")
            meta = json.loads(sidecar.read_text(encoding="utf-8"))
            codes = sorted(meta.get("codes", []))
            accepted = meta.get("exit_code", 1) == 0
            expected: dict[str, Any] = {}
            if codes:
                expected["codes"] = codes
            if accepted:
                expected["valid"] = True
            section = "4" if group == "invalid" else "2"
            cases.append(
                {
                    "id": f"validate.{group}.{name}",
                    "metric": "validate",
                    "spec_section": section,
                    "level": "MUST" if (not accepted or group == "valid") else "SHOULD",
                    "fixture": f"{group}/{name}",
                    "parameters": {},
                    "expected": expected,
                    "tolerance": None,
                    "provenance": {
                        "kind": "spec",
                        "note": f"built by tools/haptify_tools/build_invalid_fixtures.py with "
                        f"one known defect; the codes are the sidecar {group}/{sidecar.name}",
                    },
                    "spec_versions": [SPEC_VERSION],
                    "description": meta.get("description", name),
                }
            )
    return cases


FAMILIES: dict[str, Callable[[], list[Fixture]]] = {
    "workspace": workspace_fixtures,
    "free_space": free_space_fixtures,
    "vibration": vibration_fixtures,
    "surface": surface_fixtures,
    "stiffness": stiffness_fixtures,
    "rig": rig_fixtures,
    "dynamics": dynamics_fixtures,
    "uncertainty": uncertainty_fixtures,
}
FAMILY_TEXT = {
    "workspace": "Workspace volumes (spec chapter 8): analytic shapes sampled on their boundary and the DH model's Pappus volume.",
    "free_space": "Free-space forces and speeds (spec chapter 9): constant and analytic forces on the hand, circles and spins.",
    "vibration": "Free-space vibrations (spec chapter 10): tones of known amplitude and frequency through the specified high-pass.",
    "surface": "Frictionless surface (spec chapter 12): planar forces of known magnitude during rendered contact.",
    "stiffness": "Stiffness (spec chapter 13): linear springs with saturation and giving way, pressed five times.",
    "rig": "Rig checks (spec chapter 14): damped plate modes, offset COP markers, known recorder delays and sensor noise.",
    "dynamics": "Local dynamics (spec chapter 11): H-W prediction from a given parameter file, and fitting quality on a known law.",
    "uncertainty": "Measurement uncertainty (spec chapter 19): Type A, coverage factor and expanded uncertainty of repetitions with known values.",
}


def all_fixtures() -> dict[str, list[Fixture]]:
    return {fam: fn() for fam, fn in FAMILIES.items()}


def with_requirements(c: dict) -> dict:
    """The case with the ids of the requirements it tests after its level (spec §16.7)."""
    ids = requirements_for_case(c["metric"], c["expected"].get("codes"), c.get("quantity", "value"))
    out = {}
    for key, value in c.items():
        out[key] = value
        if key == "level":
            out["requirements"] = ids
    return out


def case_documents(fixtures: dict[str, list[Fixture]], fixtures_root: Path) -> dict[str, str]:
    """File name → text of every case file."""
    docs: dict[str, dict[str, Any]] = {}
    for fam, fxs in fixtures.items():
        docs[f"{fam}.json"] = {"description": FAMILY_TEXT[fam], "cases": [c for fx in fxs for c in fx.cases]}
    docs["validate.json"] = {
        "description": "Validation (spec chapters 2–4): every invalid session of fixtures/invalid must be "
        "rejected (or warned about) with its codes; every fixture of fixtures/valid must be accepted.",
        "cases": validate_cases(fixtures_root),
    }
    for doc in docs.values():
        doc["cases"] = [with_requirements(c) for c in doc["cases"]]
        for c in doc["cases"]:
            if c.get("tolerance") is None:
                c.pop("tolerance", None)
    return {name: json.dumps(doc, indent=2, ensure_ascii=False) + "\n" for name, doc in docs.items()}


def write_digests(root: Path, names: list[str]) -> None:
    """``fixtures/conformance/digests.json``: the logical digest of every fixture, for the suite linter (spec §16.7)."""
    digests = {n: snapshot_digest(root / n) for n in sorted(names)}
    (root / DIGESTS).write_text(
        json.dumps(
            {
                "$comment": "written by haptify_tools.build_conformance_fixtures; checked by haptify-conform --lint",
                "digests": digests,
            },
            indent=1,
        )
        + "\n",
        encoding="utf-8",
    )


def build_fixture(fx: Fixture, target: Path) -> None:
    if target.exists():
        shutil.rmtree(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fx.build(target)
