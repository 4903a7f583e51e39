"""The generated benchmark table stays true: benchmarks/RESULTS-table.md was written by
`make bench` from the scripts as they are now."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _runner():
    spec = importlib.util.spec_from_file_location("bench_run", BENCH / "run.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_run"] = module
    spec.loader.exec_module(module)
    return module


run = _runner()


def test_every_reported_script_has_figures_measured_with_its_current_code():
    state = run.read_state()
    reporting = {p.name for p in run.reporting_scripts()}
    assert reporting, "no benchmark script reports figures"
    missing = sorted(reporting - set(state["scripts"]))
    assert not missing, f"never measured into RESULTS-table.md (run `make bench` or `benchmarks/run.py NAME`): {missing}"
    stale = sorted(
        name
        for name, entry in state["scripts"].items()
        if not (BENCH / name).is_file() or entry["sha256"] != run.digest(BENCH / name)
    )
    assert not stale, f"changed or removed since their figures were measured (rerun them): {stale}"


def test_table_text_is_the_rendering_of_its_state():
    text = run.TABLE.read_text(encoding="utf-8")
    assert text == run.render(run.read_state()), "RESULTS-table.md was edited by hand"
    for entry in run.read_state()["scripts"].values():
        assert entry["rows"] and entry["cores"] >= 1
        for row in entry["rows"]:
            assert set(row) == {"figure", "target", "measured", "peer", "ratio", "holds"}


def test_a_changed_script_or_helper_changes_the_digest(tmp_path, monkeypatch):
    # A throwaway benchmark folder: the script, a helper it imports, a peer it runs.
    (tmp_path / "peers").mkdir()
    (tmp_path / "peers" / "peer.py").write_text("print(1)\n")
    (tmp_path / "helper.py").write_text("X = 1\n")
    script = tmp_path / "bench_x.py"
    script.write_text('import helper\nPEER = "peers"\nreport("f", "t", "m")\n')
    monkeypatch.setattr(run, "HERE", tmp_path)
    assert [p.name for p in run.local_dependencies(script)] == ["bench_x.py", "helper.py", "peer.py"]
    before = run.digest(script)
    (tmp_path / "helper.py").write_text("X = 2\n")
    after_helper = run.digest(script)
    (tmp_path / "peers" / "peer.py").write_text("print(2)\n")
    after_peer = run.digest(script)
    assert len({before, after_helper, after_peer}) == 3
    assert [p.name for p in run.reporting_scripts()] == ["bench_x.py"]


def test_rows_of_scripts_not_rerun_are_kept(tmp_path):
    table = tmp_path / "t.md"
    state = {
        "scripts": {
            "bench_a.py": {
                "sha256": "0" * 64,
                "run_at": "2026-11-25 10:00 UTC",
                "cores": 2,
                "load": 1.0,
                "python": "3.11",
                "rows": [{"figure": "f|g", "target": "≤ 1", "measured": "0.5", "peer": "", "ratio": None, "holds": True}],
            }
        }
    }
    run.write_table(state, table)
    assert run.read_state(table) == state
    assert "f\\|g" in table.read_text()  # a bar inside a cell does not split the row


@pytest.mark.parametrize("holds, shown", [(True, "yes"), (False, "**no**"), (None, "—")])
def test_holds_is_shown_plainly(holds, shown):
    assert run._cell(holds) == shown
