"""``haptify batch compute`` (spec §15.4, §17.9): many sessions, each into its own output folder, on a Dask LocalCluster,
with exactly the files ``haptify compute`` writes and the serial run's bytes; a refused session gets its
findings document and does not stop the others."""

from __future__ import annotations

import argparse
import json

import pytest
from _registry_fixtures import example_session

from haptify.cli.cmd_compute import compute_folder
from haptify.cli.main import UI
from haptify.errors import HaptifyError
from haptify_tools import cmd_batch
from haptify_tools.cluster import dask_client

METRICS = ["free_space.speed_mean", "vibration.rms", "workspace.spec_box_volume"]


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    root = tmp_path_factory.mktemp("batch")
    good = [example_session(root / f"lab{i}" / f"session-{i}", lab=f"lab-{i}", session_id=f"s-{i}") for i in range(3)]
    broken = example_session(root / "broken" / "session-broken", session_id="broken")
    manifest = json.loads((broken / "session.json").read_text())
    del manifest["trials"]
    (broken / "session.json").write_text(json.dumps(manifest))
    return good, broken


def test_batch_on_a_local_cluster_writes_what_compute_and_the_serial_batch_write(sessions, tmp_path):
    good, broken = sessions
    serial = cmd_batch.batch_compute([*good, broken], tmp_path / "serial", None, METRICS)
    with dask_client(workers=2) as client:
        cluster = cmd_batch.batch_compute([*good, broken], tmp_path / "cluster", client, METRICS)
    assert [e["status"] for e in serial] == [e["status"] for e in cluster] == ["computed"] * 3 + ["refused"]
    assert all(e["worker"].startswith("tcp://") for e in cluster) and {e["worker"] for e in serial} == {"serial"}
    for session in good:
        expected = compute_folder(session, METRICS).model_dump_json(indent=2) + "\n"
        for run in ("serial", "cluster"):
            assert (tmp_path / run / session.name / "results.json").read_text() == expected
    with pytest.raises(HaptifyError) as err:
        compute_folder(broken, METRICS)
    expected_codes = sorted({f.code for f in err.value.findings})
    for run, entries in (("serial", serial), ("cluster", cluster)):
        findings = json.loads((tmp_path / run / broken.name / "findings.json").read_text())["findings"]
        assert sorted({f["code"] for f in findings}) == entries[-1]["codes"] == expected_codes
        assert not (tmp_path / run / broken.name / "results.json").exists()


def test_the_command_exits_1_when_a_session_is_refused_and_refuses_clashing_names(sessions, tmp_path):
    good, broken = sessions
    args = argparse.Namespace(
        sessions=[good[0], broken], out=tmp_path / "out", metrics=",".join(METRICS), params=None, workers=0, scheduler=None
    )
    assert cmd_batch.run_compute(args, UI(quiet=True)) == 1
    assert (tmp_path / "out" / good[0].name / "results.json").is_file()
    args.sessions = [good[0]]
    assert cmd_batch.run_compute(args, UI(quiet=True)) == 0
    twin = example_session(tmp_path / "elsewhere" / good[0].name)
    with pytest.raises(HaptifyError) as err:
        cmd_batch.output_folders([good[0], twin], tmp_path / "out")
    assert err.value.findings[0].code == "E903"
