"""Registry-wide re-verification on Dask (spec §17.9): a small registry of five submissions with raw
streams (four agreeing, one with vibration.rms submitted × 1.05) re-verified serially, on a LocalCluster, on a
scheduler and workers started as separate commands, with a worker killed mid-run, interrupted and resumed; and
a planted earlier re-computation that differs by more than the tolerance is marked as moved."""

from __future__ import annotations

import argparse
import json
import shutil

import pytest
from _dask_cluster import separate_cluster
from _registry_fixtures import base, bundle_for, variant  # noqa: F401  (base: fixture)
from sqlalchemy import func, select, text
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession

from haptify.cli.main import UI
from haptify.errors import HaptifyError
from haptify.versions import PACKAGE_VERSION
from haptify_tools.cluster import dask_client
from haptify_tools.registry import cmd_registry, db
from haptify_tools.registry.checks import tolerances
from haptify_tools.registry.records import Caller, Settings
from haptify_tools.registry.reverify import plan, record_values, run_reverify, start_run
from haptify_tools.registry.service import Registry
from haptify_tools.registry.storage import LocalFolderStore, open_store

N = 5
SCALE = 1.05  # submission s4's vibration.rms is submitted 5 % off (its tolerance is 0.02 %)


@pytest.fixture(scope="module")
def stored(base, tmp_path_factory):  # noqa: F811 (base is a fixture)
    """A registry data folder with N submissions with raw streams; returns (folder, submission ids by name)."""
    tmp = tmp_path_factory.mktemp("reverify")
    report = base[3]
    registry = Registry(Settings(data_dir=tmp / "data"), lock=False)
    registry.create_token("lab-a")
    ids = {}
    try:
        for i in range(N):
            s, r = variant(base, tmp, f"s{i}", scale=SCALE if i == N - 1 else None)
            archive, _ = bundle_for(s, r, report, tmp / f"s{i}.tar.gz", include_raw=True)
            ids[f"s{i}"] = registry.submit(archive, Caller(1, "lab-a", "submit")).id
    finally:
        registry.close()
    return tmp / "data", ids


@pytest.fixture
def registry(stored, tmp_path):
    """A fresh copy of the stored registry (runs append records), its engine and its store."""
    data = tmp_path / "data"
    shutil.copytree(stored[0], data)
    reg = Registry(Settings(data_dir=data), lock=False)
    yield reg, LocalFolderStore(str(data)), stored[1]
    reg.close()


def records(reg, run_id):
    with DBSession(reg.engine) as s:
        return s.scalar(select(func.count()).select_from(db.ReverifyRecord).where(db.ReverifyRecord.run_id == run_id))


def serial_values(reg, store):
    run = start_run(reg.engine, "serial")
    summary = run_reverify(reg.engine, store, run)
    assert summary.complete and summary.errors == {}
    return record_values(reg.engine, run)


def test_serial_run_recomputes_every_submission_and_nothing_moved(registry):
    reg, store, ids = registry
    run = start_run(reg.engine, "serial")
    summary = run_reverify(reg.engine, store, run)
    assert (summary.planned, summary.recorded, summary.computed_now) == (N, N, N)
    # the same reference re-computes what it computed at acceptance: every value unchanged, every state kept
    assert summary.submissions == {"changed": 0, "unchanged": N, "failed": 0}
    assert summary.transitions == {} and summary.changed == {}
    assert all(counts == {"changed": 0, "unchanged": N, "first": 0, "failed": 0} for counts in summary.metrics.values())
    values = record_values(reg.engine, run)
    with DBSession(reg.engine) as s:
        for sid in ids.values():
            sub = s.get(db.Submission, sid)
            accepted = {c["metric"]: c["recomputed"] for c in json.loads(sub.verification_json)["checks"]}
            assert values[sid]["values"] == accepted and values[sid]["verification"] == sub.verification
    assert values[ids["s4"]]["verification"] != values[ids["s0"]]["verification"]  # the ×1.05 one still disagrees


def test_local_cluster_gives_the_serial_records(registry):
    reg, store, ids = registry
    serial = serial_values(reg, store)
    run = start_run(reg.engine, "local")
    with dask_client(workers=2) as client:
        summary = run_reverify(reg.engine, store, run, client)
    assert summary.complete and summary.errors == {}
    assert record_values(reg.engine, run) == serial
    with DBSession(reg.engine) as s:
        workers = set(s.scalars(select(db.ReverifyRecord.worker).where(db.ReverifyRecord.run_id == run)))
    assert all(w.startswith("tcp://") for w in workers)  # computed on the cluster's workers, not in this process


def test_separately_started_scheduler_and_workers_give_the_serial_records(registry, tmp_path):
    reg, store, ids = registry
    serial = serial_values(reg, store)
    with separate_cluster(2, tmp_path / "logs") as cluster:
        args = argparse.Namespace(
            data=reg.data, db=None, storage=None, since_version=None, resume=None, workers=2, scheduler=cluster.address
        )
        assert cmd_registry.run_reverify_command(args, UI(quiet=True)) == 0
    with DBSession(reg.engine) as s:
        run = s.scalar(select(db.ReverifyRun.id).where(db.ReverifyRun.executor == f"dask scheduler {cluster.address}"))
        workers = set(s.scalars(select(db.ReverifyRecord.worker).where(db.ReverifyRecord.run_id == run)))
    assert record_values(reg.engine, run) == serial
    assert workers <= set(cluster.workers)


def test_a_worker_killed_mid_run_loses_nothing_and_records_nothing_twice(registry, tmp_path):
    from distributed import Client

    reg, store, ids = registry
    serial = serial_values(reg, store)
    killed = []
    with separate_cluster(2, tmp_path / "logs") as cluster, Client(cluster.address) as client:

        def kill_a_busy_worker(sid, status):
            if killed:
                return
            busy = {w: tasks for w, tasks in client.processing().items() if tasks and w in cluster.workers}
            if busy:
                victim = sorted(busy)[0]
                killed.append((victim, busy[victim]))
                cluster.kill_worker(victim)

        run = start_run(reg.engine, "kill test")
        summary = run_reverify(reg.engine, store, run, client, on_record=kill_a_busy_worker)
    assert killed, "no worker was busy when the first record was written"
    victim, tasks = killed[0]
    assert victim not in cluster.workers and any(str(t).startswith(f"reverify-{run}-") for t in tasks)
    assert summary.complete and summary.errors == {} and summary.duplicates_refused == 0
    assert records(reg, run) == N  # one row per submission: the primary key (submission, version, run) allows no other
    assert record_values(reg.engine, run) == serial


def test_an_interrupted_run_resumes_without_recomputing_or_duplicating(registry):
    reg, store, ids = registry
    run = start_run(reg.engine, "serial")
    seen = []

    def interrupt_after_two(sid, status):
        seen.append(sid)
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_reverify(reg.engine, store, run, on_record=interrupt_after_two)
    assert records(reg, run) == 2
    resumed = run_reverify(reg.engine, store, run, on_record=lambda sid, status: seen.append(sid))
    assert (resumed.skipped, resumed.computed_now, resumed.recorded) == (2, N - 2, N) and resumed.complete
    assert sorted(seen) == sorted(ids.values())  # each submission computed once over both invocations
    again = run_reverify(reg.engine, store, run)
    assert (again.computed_now, again.recorded) == (0, N)
    with DBSession(db.writer(reg.engine)) as s, pytest.raises(IntegrityError), s.begin():  # the key refuses a second row
        s.add(
            db.ReverifyRecord(
                submission_id=ids["s0"],
                reference_version=PACKAGE_VERSION,
                run_id=run,
                status="unchanged",
                verification=None,
                previous_verification="x",
                checks_json="[]",
                findings_json="[]",
                worker="test",
                seconds=0.0,
            )
        )
    with reg.writer.begin() as conn, pytest.raises(Exception, match="append-only"):
        conn.execute(text("UPDATE reverify_records SET status = 'changed'"))


def _plant(reg, sid: str, factors: dict[str, float], version: str = "0.0.9") -> None:
    """An earlier run by reference ``version`` whose re-computation of ``sid`` is the accepted one with each
    metric of ``factors`` multiplied by its factor."""
    with DBSession(db.writer(reg.engine)) as s, s.begin():
        sub = s.get(db.Submission, sid)
        checks = [
            {**c, "recomputed": c["recomputed"] * factors.get(c["metric"], 1.0), "status": "unchanged"}
            for c in json.loads(sub.verification_json)["checks"]
        ]
        s.add(
            db.ReverifyRun(
                id="planted",
                reference_version=version,
                spec_version=sub.spec_version,
                since_version=None,
                executor="planted",
                planned_json=json.dumps([sid]),
            )
        )
        s.flush()
        s.add(
            db.ReverifyRecord(
                submission_id=sid,
                reference_version=version,
                run_id="planted",
                status="unchanged",
                verification=sub.verification,
                previous_verification=sub.verification,
                checks_json=json.dumps(checks),
                findings_json="[]",
                worker="planted",
                seconds=0.0,
            )
        )


def test_a_value_that_moved_beyond_its_tolerance_is_marked(registry):
    reg, store, ids = registry
    tol = tolerances()
    inside = 1 + 0.5 * tol["free_space.speed_mean"]["rel"]  # half the tolerance: not a move
    _plant(reg, ids["s2"], {"vibration.rms": 1 / SCALE, "free_space.speed_mean": inside})
    run = start_run(reg.engine, "serial")
    summary = run_reverify(reg.engine, store, run)
    assert summary.submissions == {"changed": 1, "unchanged": N - 1, "failed": 0}
    assert summary.changed == {ids["s2"]: ["vibration.rms"]}
    assert summary.metrics["vibration.rms"]["changed"] == 1 and summary.metrics["free_space.speed_mean"]["changed"] == 0
    with DBSession(reg.engine) as s:
        rec = s.get(db.ReverifyRecord, (ids["s2"], PACKAGE_VERSION, run))
        moved = {c["metric"]: c for c in json.loads(rec.checks_json)}["vibration.rms"]
        planted = s.get(db.ReverifyRecord, (ids["s2"], "0.0.9", "planted"))
    assert moved["code"] == "W982" and moved["recomputed"] == pytest.approx(moved["previous"] * SCALE, rel=1e-12)
    assert planted is not None  # the old record stays beside the new one
    lines = cmd_registry.summary_lines(summary)
    assert any(line.startswith(f"  W982 {ids['s2']}") for line in lines)


def test_since_version_skips_what_a_reference_that_recent_re_verified(registry):
    reg, store, ids = registry
    _plant(reg, ids["s1"], {}, version="0.0.9")
    with DBSession(reg.engine) as s:
        assert plan(s) == sorted(ids.values())
        assert plan(s, "0.0.9") == sorted(v for k, v in ids.items() if k != "s1")
        assert plan(s, "0.0.10") == sorted(ids.values())  # numeric order, not text order
        with pytest.raises(HaptifyError) as err:
            plan(s, "latest")
    assert err.value.findings[0].code == "E903"


def test_bad_locations_and_runs_are_coded_errors(registry):
    reg, store, ids = registry
    for location, code in (("s3://bucket/registry", "E903"),):
        with pytest.raises(HaptifyError) as err:
            open_store(location)
        assert err.value.findings[0].code == code
    with pytest.raises(HaptifyError) as err:
        run_reverify(reg.engine, store, "nosuchrun")
    assert err.value.findings[0].code == "E973"
    with pytest.raises(HaptifyError) as err, dask_client("tcp://127.0.0.1:9"):
        pass
    assert err.value.findings[0].code == "E980"
    _plant(reg, ids["s0"], {}, version="0.0.9")  # a run another reference version started
    with pytest.raises(HaptifyError) as err:
        run_reverify(reg.engine, store, "planted")
    assert err.value.findings[0].code == "E981"
    args = argparse.Namespace(
        data=reg.data, db=None, storage=None, since_version="0.1.0", resume="planted", workers=0, scheduler=None
    )
    with pytest.raises(HaptifyError) as err:
        cmd_registry.run_reverify_command(args, UI(quiet=True))
    assert err.value.findings[0].code == "E903"


def test_an_archive_the_store_cannot_give_is_not_recorded_and_a_resume_retries_it(registry):
    reg, store, ids = registry
    with DBSession(reg.engine) as s:
        archive = reg.data / s.get(db.Submission, ids["s3"]).archive_path
    hidden = archive.with_suffix(".away")
    archive.rename(hidden)
    run = start_run(reg.engine, "serial")
    summary = run_reverify(reg.engine, store, run, retries=0)
    assert not summary.complete and list(summary.errors) == [ids["s3"]] and "StoreUnavailable" in summary.errors[ids["s3"]]
    assert records(reg, run) == N - 1
    hidden.rename(archive)
    resumed = run_reverify(reg.engine, store, run)
    assert resumed.complete and (resumed.computed_now, resumed.skipped) == (1, N - 1)
