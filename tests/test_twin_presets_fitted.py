"""The table "Preset parameters fitted to the paper" (spec §20.1, informative)
against the preset files and the paper's values: every listed value is the preset's, every cited paper
value is the one in schemas/1.0/paper-values.json, and every parameter whose source says "tuned" is listed.

Cheap by design: the fidelity itself (10 seeds × 2 presets) is measured by benchmarks/bench_table_iii_seeds.py.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from haptify import schemas
from haptify_tools.twin.model import preset, twin_to_dict

SPEC_TWIN = Path(__file__).resolve().parents[1] / "spec" / "20-device-twin.md"
PRESETS = {"touch": "Touch", "touch-x": "Touch X"}


def fitted_table() -> list[dict]:
    """The rows of spec §20.1's table of fitted parameters: preset, parameter path, values, {metric: paper value}."""
    text = SPEC_TWIN.read_text(encoding="utf-8")
    section = text.split("## 20.1 Preset parameters fitted to the paper", 1)[1]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 4 or cells[0] not in PRESETS:
            continue
        cited = dict(part.split(" = ") for part in cells[3].split("; "))
        rows.append(
            {
                "preset": cells[0],
                "parameter": cells[1],
                "value": [float(v) for v in cells[2].split(",")],
                "cited": {m: float(v) for m, v in cited.items()},
            }
        )
    return rows


def resolve(data: dict, path: str):
    """The value at a table path: ``<effect id>.<parameter>…`` under ``effects``, else dotted from the file's root."""
    effect = next((e for e in sorted(data["effects"], key=len, reverse=True) if path.startswith(e + ".")), None)
    node, keys = (data["effects"][effect], path[len(effect) + 1 :].split(".")) if effect else (data, path.split("."))
    for key in keys:
        node = node[int(key)] if isinstance(node, list) else node[key]
    return node


def paper_value(metric: str, device: str) -> float:
    paper = schemas.load("paper-values.json")
    row = next((r for r in paper["rows"] if r["metric"] == metric), None)
    values = row["values"] if row else paper["other"][metric]
    return float(values.get(device, values.get("rig", np.nan)))


def tuned_paths(data: dict) -> set[str]:
    """Table paths of every parameter whose ``sources`` entry (or a link's / the gimbal body's ``source``) says "tuned"."""
    out = set()
    for group, prefix in ((data["effects"], ""), (data["rig"], "rig.")):
        for name, effect in group.items():
            out |= {f"{prefix}{name}.{p}" for p, why in effect.get("sources", {}).items() if "tuned" in why}
    out |= {f"links.{i}" for i, link in enumerate(data["links"]) if "tuned" in link.get("source", "")}
    if "tuned" in data["gimbal_body"].get("source", ""):
        out.add("gimbal_body")
    return out


ROWS = fitted_table()


def test_the_table_lists_both_presets():
    assert {r["preset"] for r in ROWS} == set(PRESETS) and len(ROWS) >= 20


@pytest.mark.parametrize("row", ROWS, ids=lambda r: f"{r['preset']}:{r['parameter']}")
def test_a_listed_value_is_the_presets_and_its_paper_values_are_the_papers(row):
    value = resolve(twin_to_dict(preset(row["preset"])), row["parameter"])
    assert np.allclose(np.atleast_1d(np.asarray(value, float)), row["value"], rtol=1e-12, atol=0.0), value
    for metric, cited in row["cited"].items():
        assert cited == pytest.approx(paper_value(metric, PRESETS[row["preset"]]), rel=1e-12), metric


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_tuned_parameter_is_in_the_table(name):
    listed = [r["parameter"] for r in ROWS if r["preset"] == name]
    missing = [
        p for p in sorted(tuned_paths(twin_to_dict(preset(name)))) if not any(q == p or q.startswith(p + ".") for q in listed)
    ]
    assert not missing, f"{name}: tuned but not in spec §20.1's table: {missing}"


def test_the_table_parser_rejects_a_value_that_differs_from_the_preset():
    data = json.loads(json.dumps(twin_to_dict(preset("touch"))))
    row = next(r for r in ROWS if r["preset"] == "touch" and r["parameter"] == "friction.coulomb.torque_Nm")
    data["effects"]["friction.coulomb"]["torque_Nm"][0] *= 1.01
    assert not np.allclose(resolve(data, row["parameter"]), row["value"], rtol=1e-12, atol=0.0)
    assert re.fullmatch(r"[\w.]+", row["parameter"])
