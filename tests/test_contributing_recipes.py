"""CONTRIBUTING.md's recipe "add a metric family", walked through: a definition file, a module with its typed
parameters and ``compute(ctx)``, and an entry point are all the reference needs to compute, aggregate and
report a new metric (spec §0.3, §15.2–15.4); a module whose parameters disagree with the definition file
stops at import with E905. The toy family's files are written by this test; nothing of the repository
changes."""

from __future__ import annotations

import importlib
import json
import shutil
import sys
import textwrap
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path

import jsonschema
import pytest
from metric_sessions import add_handle_trial, circle, spin, writer

import haptify_schemas
from haptify.errors import HaptifyError
from haptify.formats.storage import open_session
from haptify.metrics import metric_definitions
from haptify.pipeline import families
from haptify.pipeline.compute import compute_session

REPO = Path(__file__).resolve().parents[1]

TOY_DEFINITION = {
    "family": "toy",
    "version": "1.0.0",
    "spec_section": "99",
    "parameters": {"min_duration_s": {"value": 1.0, "unit": "s", "description": "Shortest trial the metric accepts."}},
    "metrics": [
        {
            "id": "toy.trial_duration",
            "title": "Recorded length of a free-space trial",
            "unit": "s",
            "protocols": ["free_space"],
            "inputs": ["handle_wrench"],
            "aggregation": "mean over repetitions",
            "description": "Last minus first time stamp of the trial's handle_wrench stream.",
        }
    ],
}

TOY_MODULE = '''
"""The toy family: the recorded length of each free-space trial (a recipe's example)."""

from haptify.processing.caching import session_of
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters
from haptify.pipeline.repetitions import TrialValue, aggregate, protocol_trials

FAMILY = "toy"
METRIC = "toy.trial_duration"


class ToyParameters(FamilyParameters):
    """The parameters of ``metrics/toy.json``, in its units."""

    min_duration_s: float


PARAMETERS = load_parameters(FAMILY, ToyParameters)


def duration_s(ctx, trial_id):
    """Last minus first time stamp of ``handle_wrench``, s."""
    t = session_of(ctx).read(trial_id, "handle_wrench")["t"]
    return float(t.iloc[-1] - t.iloc[0])


def compute(ctx):
    """Every metric of the family the session allows."""
    if not ctx.wants(METRIC):
        return []
    got, missing = protocol_trials(ctx, "free_space", (METRIC,), lambda tid: duration_s(ctx, tid), METRIC)
    if missing:
        return missing
    floor = PARAMETERS.min_duration_s
    return [aggregate(FAMILY, METRIC, [TrialValue(tid, v) for tid, v in got.items() if v >= floor])]
'''


@pytest.fixture
def toy_family(tmp_path, monkeypatch):
    """The recipe's three files: ``schemas/<v>/metrics/toy.json`` (a copy of the definitions with it added), the
    module ``toy_family.py`` and its entry point in the group ``haptify.metric_families``. Yields the path of
    toy.json."""
    defs = tmp_path / "schemas"
    shutil.copytree(REPO / "schemas" / haptify_schemas.SPEC_VERSION, defs)
    toy_json = defs / "metrics" / "toy.json"
    toy_json.write_text(json.dumps(TOY_DEFINITION), encoding="utf-8")
    code = tmp_path / "code"
    code.mkdir()
    (code / "toy_family.py").write_text(textwrap.dedent(TOY_MODULE), encoding="utf-8")
    monkeypatch.syspath_prepend(str(code))
    monkeypatch.delitem(sys.modules, "toy_family", raising=False)  # imported afresh, against this toy.json
    monkeypatch.setattr(haptify_schemas, "_root", lambda: defs)
    plugin = EntryPoint(name="toy", value="toy_family", group=families.FAMILY_ENTRY_POINTS)
    monkeypatch.setattr(
        families,
        "entry_points",
        lambda group: [*entry_points(group=group), *([plugin] if group == families.FAMILY_ENTRY_POINTS else [])],
    )
    _clear_caches()
    yield toy_json
    monkeypatch.undo()
    _clear_caches()


def _clear_caches() -> None:
    haptify_schemas.load.cache_clear()
    metric_definitions.family.cache_clear()
    families.family_modules.cache_clear()


def _session(folder: Path, durations: list[float]) -> Path:
    w = writer("toy")
    for rep, d in enumerate(durations, start=1):
        add_handle_trial(
            w,
            f"free_space-{rep}",
            "free_space",
            duration_s=d,
            position=circle(),
            quaternion=spin(),
            force_w=lambda t: 0.0 * circle()(t),
            repetition=rep,
        )
    return w.write(folder)


def test_a_family_from_a_definition_a_module_and_an_entry_point_is_computed_and_reported(toy_family, tmp_path):
    session = open_session(_session(tmp_path / "s", [4.0, 6.0, 0.5]))
    res = compute_session(session, ["toy.trial_duration"])
    rec = res.get("toy.trial_duration")
    # 4 s and 6 s recorded (1 kHz stamps 0 … d); the 0.5 s trial is below the family's parameter
    assert rec.value == pytest.approx(5.0) and rec.n == 2 and rec.sd == pytest.approx(2**0.5)
    assert rec.unit == "s" and rec.definition_version == "1.0.0"
    jsonschema.validate(res.model_dump(mode="json", exclude_none=True), haptify_schemas.schema("results"))


def test_without_its_entry_point_the_family_is_defined_but_computed_by_nobody(toy_family, tmp_path, monkeypatch):
    monkeypatch.setattr(families, "entry_points", entry_points)
    _clear_caches()
    session = open_session(_session(tmp_path / "s", [4.0]))
    res = compute_session(session, ["toy.trial_duration"])
    assert res.get("toy.trial_duration") is None
    assert "toy" not in dict(families.family_modules())


@pytest.mark.parametrize(
    ("parameters", "key", "expected", "found"),
    [
        ({"min_duration_s": 1.0, "max_duration_s": 9.0}, "max_duration_s", "no parameter", 9.0),
        ({}, "min_duration_s", "float", "no such parameter"),
        ({"min_duration_s": "1 s"}, "min_duration_s", "float", "1 s"),
    ],
)
def test_a_family_whose_parameters_disagree_with_its_module_stops_at_import(toy_family, parameters, key, expected, found):
    doc = dict(TOY_DEFINITION, parameters={k: {"value": v, "unit": "s", "description": "-"} for k, v in parameters.items()})
    toy_family.write_text(json.dumps(doc), encoding="utf-8")
    _clear_caches()
    with pytest.raises(HaptifyError) as exc:
        importlib.import_module("toy_family")
    (finding,) = exc.value.findings
    assert finding.code == "E905" and finding.file == "metrics/toy.json" and key in finding.message
    assert str(finding.expected).startswith(expected) and finding.found == found
