"""The registry service (spec §17.3–§17.7) through its JSON API, on SQLite always and on PostgreSQL when a
server can be started: acceptance and verification, every refusal's code, supersession and withdrawal,
append-only records, aggregation with known answers, concurrency, rate limits."""

from __future__ import annotations

import json
import statistics
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import text

from _registry_fixtures import base, bundle_for, passing_report, pg_server, variant  # noqa: F401  (base: fixture)
from haptify_conform.cases import load_cases, select
from haptify_tools.registry.app import create_app
from haptify_tools.registry.records import Settings

API = "/api/v1"


@pytest.fixture(params=["sqlite", "postgresql"])
def registry(request, tmp_path):
    """(client, app, admin token, token of lab-a, token of lab-b) on each database."""
    db_url = None
    if request.param == "postgresql":
        server = request.getfixturevalue("pg_server")
        db_url = server.new_database(f"t{abs(hash(request.node.nodeid)) % 10**9}")
    app = create_app(Settings(data_dir=tmp_path / "data", db_url=db_url))
    reg = app.state.registry
    tokens = {"admin": reg.create_token("lab-admin", "admin"), "a": reg.create_token("lab-a"), "b": reg.create_token("lab-b")}
    with TestClient(app) as client:
        yield client, app, tokens


@pytest.fixture(params=["sqlite", "postgresql"])
def backend_url(request):
    """A function giving a fresh database URL in a folder: a SQLite file, or a new PostgreSQL database."""
    if request.param == "sqlite":
        return lambda folder: f"sqlite:///{folder / 'r.sqlite3'}"
    server = request.getfixturevalue("pg_server")
    return lambda folder: server.new_database(f"m{abs(hash(request.node.nodeid)) % 10**9}")


def auth(token: str) -> dict:
    return {"Authorization": f"Bearer {token}", "Content-Type": "application/gzip"}


def post(client, archive: Path, token: str, **params):
    return client.post(f"{API}/submissions", content=archive.read_bytes(), headers=auth(token), params=params)


def codes(response) -> list[str]:
    return [f["code"] for f in response.json()["findings"]]


def test_raw_bundle_is_verified_and_a_replay_is_idempotent(base, tmp_path):
    root, session, results, report, impl = base
    app = create_app(Settings(data_dir=tmp_path / "data"))
    token = app.state.registry.create_token("lab-a")
    archive, digest = bundle_for(session, results, report, tmp_path / "b.tar.gz", include_raw=True)
    with TestClient(app) as client:
        r = post(client, archive, token)
        assert r.status_code == 201, r.text
        body = r.json()
        assert body["status"] == "accepted" and body["digest"] == digest and body["id"] == digest[:20]
        assert body["verification"]["status"] == "verified"
        assert {c["status"] for c in body["verification"]["checks"]} == {"agrees"}
        again = post(client, archive, token)
        assert again.status_code == 200 and again.json()["status"] == "duplicate" and again.json()["id"] == body["id"]
        assert len(client.get(f"{API}/submissions").json()) == 1
        stored = client.get(f"{API}/submissions/{body['id']}/bundle")
        assert stored.content == archive.read_bytes()
        detail = client.get(f"{API}/submissions/{body['id']}").json()
        assert detail["state"] == "current" and detail["has_raw"] and detail["lab"] == "lab-a"
        folder = app.state.registry.session_folder(body["id"])  # for report figures and the viewer
        assert (folder / "session.json").read_bytes() == (session / "session.json").read_bytes()
        assert sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*.parquet")) == sorted(
            p.relative_to(session).as_posix() for p in session.rglob("*.parquet")
        )


def disagreeing_bundle(base, tmp_path) -> Path:
    """A bundle with raw streams whose vibration.rms is 1 % off the reference's (far beyond the loosest
    vibration.rms case tolerance): the registry re-computes it and finds it disagreeing."""
    root, session, results, report, impl = base
    data = json.loads(results.read_text())
    rms = next(m for m in data["metrics"] if m["id"] == "vibration.rms")
    rms["value"] *= 1.01
    rms["per_repetition"] = [v * 1.01 for v in rms["per_repetition"]]
    bad = tmp_path / "results.json"
    bad.write_text(json.dumps(data))
    return bundle_for(session, bad, report, tmp_path / "b.tar.gz", include_raw=True)[0]


def test_a_disagreeing_metric_is_named(base, tmp_path):
    archive = disagreeing_bundle(base, tmp_path)
    app = create_app(Settings(data_dir=tmp_path / "data"))
    token = app.state.registry.create_token("lab-a")
    with TestClient(app) as client:
        r = post(client, archive, token)
        assert r.status_code == 201
        v = r.json()["verification"]
        assert v["status"] == "disagreeing"
        wrong = [c for c in v["checks"] if c["status"] != "agrees"]
        assert [c["metric"] for c in wrong] == ["vibration.rms"]
        cases = [c for c in select(load_cases(), spec_version="1.0") if c.metric == "vibration.rms" and c.tolerance]
        loosest = {"abs": max(c.tolerance.abs for c in cases), "rel": max(c.tolerance.rel for c in cases)}
        assert loosest["rel"] < 0.01 and wrong[0]["tolerance"] == loosest and wrong[0]["code"] == "W969"
        assert wrong[0]["recomputed"] == pytest.approx(wrong[0]["submitted"] / 1.01, rel=1e-12)


def test_results_without_raw_are_unverified_and_the_report_stays_on_file(registry, base, tmp_path):
    client, app, tokens = registry
    root, session, results, report, impl = base
    s1, r1 = variant(base, tmp_path, "one")
    archive, _ = bundle_for(s1, r1, report, tmp_path / "1.tar.gz")
    r = post(client, archive, tokens["a"])
    assert r.status_code == 201 and r.json()["verification"]["status"] == "unverified"
    # the same implementation's passing report is now on file: a later bundle may omit it
    s2, r2 = variant(base, tmp_path, "two", lab="lab-b")
    archive2, _ = bundle_for(s2, r2, None, tmp_path / "2.tar.gz")
    assert post(client, archive2, tokens["b"]).status_code == 201


def test_refusals_are_coded(registry, base, tmp_path):
    client, app, tokens = registry
    root, session, results, report, impl = base
    s1, r1 = variant(base, tmp_path, "one")
    archive, _ = bundle_for(s1, r1, report, tmp_path / "ok.tar.gz")
    # token missing, unknown, wrong scope, wrong lab
    r = client.post(f"{API}/submissions", content=archive.read_bytes())
    assert r.status_code == 401 and codes(r) == ["E970"]
    r = post(client, archive, "hpt_not-a-token")
    assert r.status_code == 401 and codes(r) == ["E970"]
    r = client.post(f"{API}/tokens", json={"lab": "lab-z"}, headers={"Authorization": f"Bearer {tokens['a']}"})
    assert r.status_code == 403 and codes(r) == ["E971"]
    r = post(client, archive, tokens["b"])
    assert r.status_code == 403 and codes(r) == ["E977"]
    f = r.json()["findings"][0]
    assert f["pointer"] == "/lab/id" and f["expected"] == "lab-b" and f["found"] == "lab-a"
    # no report at all (none on file yet), a failing one, one of another implementation, another spec version
    none, _ = bundle_for(s1, r1, None, tmp_path / "none.tar.gz")
    r = post(client, none, tokens["a"])
    assert r.status_code == 422 and codes(r) == ["E967"]
    failing = passing_report(tmp_path / "failing.json", impl, fail_case="vibration.rms.tones")
    other = passing_report(tmp_path / "other.json", {"name": "someone-else", "version": "9"})
    old = passing_report(tmp_path / "old.json", impl, spec_version="0.9")
    for name, rep in [("failing", failing), ("other", other), ("old", old)]:
        bad, _ = bundle_for(s1, r1, rep, tmp_path / f"{name}.tar.gz")
        r = post(client, bad, tokens["a"])
        assert r.status_code == 422 and "E967" in codes(r), (name, r.text)
    # malformed request parameters and non-archives
    assert codes(client.get(f"{API}/submissions", params={"limit": "many"})) == ["E975"]
    r = client.post(f"{API}/submissions", content=b"garbage", headers=auth(tokens["a"]))
    assert r.status_code == 422 and codes(r) == ["E961"]
    assert codes(client.get(f"{API}/devices/no-such-device")) == ["E973"]
    r = client.post(
        f"{API}/submissions/abc/withdraw",
        content=b'{"reason": ',
        headers={"Authorization": f"Bearer {tokens['a']}", "Content-Type": "application/json"},
    )
    assert r.status_code == 400 and codes(r) == ["E975"]  # malformed JSON body
    # nothing was stored by any refusal
    assert client.get(f"{API}/submissions").json() == []
    paths = client.get("/openapi.json").json()["paths"]  # the API describes itself
    assert {f"{API}/submissions", f"{API}/devices/{{slug}}", f"{API}/compare", f"{API}/export.csv"} <= set(paths)
    data = Path(app.state.registry.data)
    assert list((data / "tmp").iterdir()) == [] and [p for p in (data / "bundles").rglob("*") if p.is_file()] == []
    # a dry run checks everything and stores nothing
    r = post(client, archive, tokens["a"], dry_run="true")
    assert r.status_code == 200 and r.json()["status"] == "would-accept"
    assert client.get(f"{API}/submissions").json() == []


def test_upload_size_limit(base, tmp_path):
    root, session, results, report, impl = base
    app = create_app(Settings(data_dir=tmp_path / "data"))
    app.state.registry.settings.limits = type(app.state.registry.settings.limits)(max_archive_bytes=1000)
    token = app.state.registry.create_token("lab-a")
    archive, _ = bundle_for(session, results, report, tmp_path / "b.tar.gz")
    with TestClient(app) as client:
        r = post(client, archive, token)
        assert r.status_code == 413 and codes(r) == ["E960"]


def test_supersede_and_withdraw_keep_every_record(registry, base, tmp_path):
    client, app, tokens = registry
    root, session, results, report, impl = base
    s1, r1 = variant(base, tmp_path, "first")
    first = post(client, bundle_for(s1, r1, report, tmp_path / "1.tar.gz")[0], tokens["a"]).json()["id"]
    s2, r2 = variant(base, tmp_path, "fixed", scale=2.0)
    correction, _ = bundle_for(s2, r2, report, tmp_path / "2.tar.gz", supersedes=first)
    assert post(client, correction, tokens["b"]).status_code == 403  # another lab's token
    second = post(client, correction, tokens["a"])
    assert second.status_code == 201 and second.json()["supersedes"] == first
    second = second.json()["id"]
    old = client.get(f"{API}/submissions/{first}").json()
    assert old["state"] == "superseded" and old["superseded_by"] == second
    # superseding a superseded record again is a conflict
    s3, r3 = variant(base, tmp_path, "again", scale=3.0)
    r = post(client, bundle_for(s3, r3, report, tmp_path / "3.tar.gz", supersedes=first)[0], tokens["a"])
    assert r.status_code == 409 and codes(r) == ["E974"]
    # withdrawal: reason required, own lab only (admin any), once
    assert codes(
        client.post(
            f"{API}/submissions/{second}/withdraw", json={"reason": ""}, headers={"Authorization": f"Bearer {tokens['a']}"}
        )
    ) == ["E975"]
    r = client.post(
        f"{API}/submissions/{second}/withdraw", json={"reason": "wrong rig"}, headers={"Authorization": f"Bearer {tokens['b']}"}
    )
    assert r.status_code == 403 and codes(r) == ["E971"]
    r = client.post(
        f"{API}/submissions/{second}/withdraw",
        json={"reason": "sensor cable loose"},
        headers={"Authorization": f"Bearer {tokens['a']}"},
    )
    assert r.status_code == 200 and r.json()["state"] == "withdrawn" and r.json()["withdrawal"]["reason"] == "sensor cable loose"
    r = client.post(
        f"{API}/submissions/{second}/withdraw", json={"reason": "again"}, headers={"Authorization": f"Bearer {tokens['admin']}"}
    )
    assert r.status_code == 409 and codes(r) == ["E974"]
    states = {s["id"]: s["state"] for s in client.get(f"{API}/submissions").json()}
    assert states == {first: "superseded", second: "withdrawn"}
    assert client.get(f"{API}/devices/3d-systems-touch?verification=all").json()["metrics"] == []  # nothing current


def test_records_are_append_only_in_the_database(registry, base, tmp_path):
    client, app, tokens = registry
    s1, r1 = variant(base, tmp_path, "one")
    sid = post(client, bundle_for(s1, r1, base[3], tmp_path / "1.tar.gz")[0], tokens["a"]).json()["id"]
    engine = app.state.registry.engine
    for statement in (
        "UPDATE submissions SET verification = 'verified'",
        "DELETE FROM submissions",
        "UPDATE metric_values SET value = 0",
        "DELETE FROM metric_values",
    ):
        with pytest.raises(Exception, match="append-only"):
            with engine.begin() as conn:
                conn.execute(text(statement))
    assert client.get(f"{API}/submissions/{sid}").json()["verification"] == "unverified"


def test_aggregation_over_labs_and_repetitions_and_comparison(registry, base, tmp_path):
    client, app, tokens = registry
    report = base[3]
    plan = [("a1", "lab-a", None, [1.0, 2.0, 3.0]), ("b1", "lab-b", None, [4.0, 5.0]), ("x1", "lab-a", "Touch X", [0.5, 0.7])]
    for name, lab, model, rms in plan:
        s, r = variant(base, tmp_path, name, lab=lab, model=model, rms=rms)
        resp = post(client, bundle_for(s, r, report, tmp_path / f"{name}.tar.gz")[0], tokens["a" if lab == "lab-a" else "b"])
        assert resp.status_code == 201, resp.text
    devices = {d["slug"]: d["submissions"] for d in client.get(f"{API}/devices").json()}
    assert devices == {"3d-systems-touch": 2, "3d-systems-touch-x": 1}
    agg = {m["metric"]: m for m in client.get(f"{API}/devices/3d-systems-touch?verification=all").json()["metrics"]}
    rms = agg["vibration.rms"]
    assert rms["mean"] == pytest.approx(3.0) and rms["sd"] == pytest.approx(statistics.stdev([1, 2, 3, 4, 5]))
    assert (rms["min"], rms["max"], rms["repetitions"], rms["submissions"], rms["labs"]) == (1.0, 5.0, 5, 2, 2)
    assert rms["lab_means"] == {"lab-a": pytest.approx(2.0), "lab-b": pytest.approx(4.5)}
    assert rms["between_lab_sd"] == pytest.approx(statistics.stdev([2.0, 4.5]))
    table = client.get(f"{API}/compare", params={"devices": "3d-systems-touch,3d-systems-touch-x", "verification": "all"}).json()
    assert table["header"] == ["Metric", "3D Systems Touch", "3D Systems Touch X"]
    row = next(r for r in table["rows"] if r[0].startswith("Free-space vibration RMS"))
    assert row[1].startswith("3 ± 1.6") and row[2].startswith("0.6 ± 0.14")
    csv_text = client.get(f"{API}/export.csv").text.splitlines()
    assert csv_text[0].startswith("submission,state,verification,lab,device")
    assert len(csv_text) == 1 + 3 * len(json.loads(base[2].read_text())["metrics"])
    assert client.get(f"{API}/compare", params={"devices": "3d-systems-touch", "format": "csv"}).text.startswith("Metric,")


def test_rate_limit_per_token(base, tmp_path):
    app = create_app(Settings(data_dir=tmp_path / "data"))
    token = app.state.registry.create_token("lab-a", rate_per_minute=3)
    with TestClient(app) as client:
        answers = [client.post(f"{API}/submissions", content=b"x", headers=auth(token)) for _ in range(4)]
        assert [a.status_code for a in answers] == [422, 422, 422, 429]
        assert codes(answers[-1]) == ["E972"] and int(answers[-1].headers["Retry-After"]) >= 1
        other = app.state.registry.create_token("lab-b", rate_per_minute=3)  # limits are per token
        assert client.post(f"{API}/submissions", content=b"x", headers=auth(other)).status_code == 422


def test_fifty_submissions_from_two_labs_at_once(registry, base, tmp_path):
    """50 distinct submissions (and 4 replays racing their originals) from 8 threads, on SQLite and PostgreSQL."""
    client, app, tokens = registry
    report = base[3]
    jobs = []
    for lab in ("a", "b"):
        for i in range(25):
            s, r = variant(base, tmp_path, f"{lab}{i}", lab=f"lab-{lab}", rms=[1.0 + i, 2.0 + i])
            jobs.append((bundle_for(s, r, report, tmp_path / f"{lab}{i}.tar.gz")[0], tokens[lab]))
    jobs += jobs[:4]  # replays racing their originals
    with ThreadPoolExecutor(8) as pool:
        answers = list(pool.map(lambda job: post(client, *job), jobs))
    assert all(a.status_code in (200, 201) for a in answers), [a.text for a in answers if a.status_code >= 300]
    ids = [a.json()["id"] for a in answers]
    assert len(set(ids)) == 50 and ids[50:] == ids[:4]
    assert sum(a.json()["status"] == "accepted" for a in answers) == 50
    listed = client.get(f"{API}/submissions").json()
    assert sorted(s["id"] for s in listed) == sorted(set(ids))
    files = [p for p in (Path(app.state.registry.data) / "bundles").rglob("*.tar.gz")]
    assert len(files) == 50


def test_migrations_go_down_and_up_again(tmp_path, backend_url):
    """Every migration reverts (down to r0001, then to nothing) and re-applies, on SQLite and PostgreSQL."""
    from sqlalchemy import inspect

    from haptify_tools.registry import db

    engine = db.make_engine(backend_url(tmp_path))
    try:
        db.migrate(engine)
        tables = lambda: set(inspect(engine).get_table_names()) - {"alembic_version"}  # noqa: E731
        assert {"challenges", "challenge_results", "submissions"} <= tables()
        db.migrate(engine, "r0001", down=True)
        assert "challenges" not in tables() and "submissions" in tables()
        db.migrate(engine, "base", down=True)
        assert tables() == set()
        db.migrate(engine)
        assert {"challenges", "challenge_results", "submissions"} <= tables()
    finally:
        engine.dispose()


def test_the_disagreeing_state_is_converted_by_its_migration_both_ways(base, tmp_path, backend_url):
    """r0003 renames the stored state disagrees → disagreeing (column and verification record) and back."""
    from haptify_tools.registry import db

    app = create_app(Settings(data_dir=tmp_path / "data", db_url=backend_url(tmp_path)))
    reg = app.state.registry
    token = reg.create_token("lab-a")

    def stored(sid: str) -> tuple[str, str]:
        with reg.engine.connect() as conn:
            state, record = conn.execute(
                text("SELECT verification, verification_json FROM submissions WHERE id = :i"), {"i": sid}
            ).one()
        return state, json.loads(record)["status"]

    try:
        with TestClient(app) as client:
            sid = post(client, disagreeing_bundle(base, tmp_path), token).json()["id"]
            assert stored(sid) == ("disagreeing", "disagreeing")
            db.migrate(reg.engine, "r0002", down=True)
            assert stored(sid) == ("disagrees", "disagrees")
            db.migrate(reg.engine)
            assert stored(sid) == ("disagreeing", "disagreeing")
            got = client.get(f"{API}/submissions/{sid}").json()
            assert got["verification"] == got["verification_details"]["status"] == "disagreeing"
            with pytest.raises(Exception, match="append-only"):  # the triggers are back
                with reg.engine.begin() as conn:
                    conn.execute(text("UPDATE submissions SET verification = 'verified'"))
    finally:
        reg.close()


def test_migrations_build_exactly_the_orm_models(registry):
    """Alembic's migrated schema and the SQLAlchemy models agree (autogenerate finds nothing to do)."""
    from alembic.autogenerate import compare_metadata
    from alembic.migration import MigrationContext

    from haptify_tools.registry.db import Base

    client, app, tokens = registry
    with app.state.registry.engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    assert diff == []
