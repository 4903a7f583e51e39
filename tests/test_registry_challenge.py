"""Conformance by challenge (spec §17.8): the registry generates known-answer sessions from a secret seed,
keeps the answers, judges what an implementation returns and records the verdict; the reference passes, a
wrong implementation fails, a replayed or late answer is refused, and only a passed challenge — never an
uploaded report — makes a submission's conformance "proven"."""

from __future__ import annotations

import io
import json
import tarfile
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import text

from _registry_fixtures import base, browser, bundle_for  # noqa: F401  (base: fixture)
from haptify_conform import cli
from haptify.conform_adapter import analyse
from haptify_tools.registry.app import create_app
from haptify_tools.registry.challenge_sessions import FAMILIES, generate
from haptify_tools.registry.challenge import judge_answer
from haptify_tools.registry.live import serve_in_thread
from haptify_tools.registry.records import Settings

API = "/api/v1"


def auth(token: str) -> dict:
    return {"Authorization": f"Bearer {token}"}


@pytest.fixture
def registry(tmp_path):
    app = create_app(Settings(data_dir=tmp_path / "data"))
    tokens = {lab: app.state.registry.create_token(lab) for lab in ("lab-a", "lab-b")}
    with TestClient(app) as client:
        yield client, app, tokens
    app.state.registry.close()


def reference_answers(client, issued: dict, tmp_path) -> dict:
    """The reference's outputs for every case of ``issued``, computed here from the downloaded sessions."""
    data = client.get(f"{API}/challenges/{issued['id']}/sessions.tar.gz").content
    root = tmp_path / issued["id"]
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        tar.extractall(root, filter="data")
    return {c["id"]: analyse(str(root / c["session"]), c["metric"], c["parameters"]) for c in issued["cases"]}


@pytest.mark.parametrize("seed", [2, 2**127 + 11])
def test_the_reference_meets_the_known_answers_of_generated_challenges(tmp_path, seed):
    """Every family the reference computes is challenged, one session each, and the reference passes."""
    cases = generate(seed, tmp_path, f"t{seed % 1000}")
    assert {c.family for c in cases} == set(FAMILIES) and all(c.session == c.family for c in cases)
    assert {c.metric for c in cases} >= {
        "workspace.measured_volume",
        "free_space.force_mean",
        "vibration.rms",
        "dynamics.force_rmse",
        "surface.planar_force_mean",
        "stiffness.measured",
        "rig.sync_offset",
    }
    for c in cases:
        assert judge_answer(c, analyse(str(tmp_path / c.session), c.metric, c.parameters))["status"] == "passed", c


def test_a_vector_answer_is_judged_per_component(tmp_path):
    """A vector metric passes only with every component within the tolerance and the right length."""
    case = next(c for c in generate(5, tmp_path, "v", families=("rig",)) if c.metric == "rig.plate_natural_frequency")
    tol = case.tolerance["abs"]

    def doc(value) -> dict:
        return {"metrics": [{"id": case.metric, "unit": case.unit, "value": value}]}

    assert judge_answer(case, doc([v + 0.9 * tol for v in case.expected]))["status"] == "passed"
    assert judge_answer(case, doc([case.expected[0] + 1.1 * tol, *case.expected[1:]]))["status"] == "failed"
    assert judge_answer(case, doc(case.expected[:2]))["status"] == "failed"
    assert judge_answer(case, doc(case.expected[0]))["status"] == "failed"


def test_an_open_challenge_reveals_no_answer(registry, tmp_path):
    client, app, tokens = registry
    issued = client.post(f"{API}/challenges", headers=auth(tokens["lab-a"])).json()
    assert issued["state"] == "open" and issued["result"] is None and issued["families"] == list(FAMILIES)
    assert {c["session"] for c in issued["cases"]} == set(FAMILIES)
    text = json.dumps(issued) + json.dumps(client.get(f"{API}/challenges/{issued['id']}").json())
    assert "expected" not in text and "seed" not in text and "tolerance" not in text
    names = tarfile.open(fileobj=io.BytesIO(client.get(f"{API}/challenges/{issued['id']}/sessions.tar.gz").content)).getnames()
    assert names and all(n.split("/")[0] in FAMILIES for n in names)
    assert client.post(f"{API}/challenges").status_code == 401  # a token is needed


def test_answers_are_judged_once_and_a_replay_is_refused(registry, tmp_path):
    client, app, tokens = registry
    a = client.post(f"{API}/challenges", headers=auth(tokens["lab-a"])).json()
    answers = reference_answers(client, a, tmp_path)
    impl = next(iter(answers.values()))["implementation"]
    body = {"implementation": {"name": impl["name"], "version": impl["version"]}, "answers": answers}
    assert client.post(f"{API}/challenges/{a['id']}/answers", json=body, headers=auth(tokens["lab-b"])).status_code == 403
    judged = client.post(f"{API}/challenges/{a['id']}/answers", json=body, headers=auth(tokens["lab-a"]))
    assert judged.status_code == 200 and judged.json()["state"] == "passed", judged.text
    cases = judged.json()["result"]["cases"]
    assert all(
        c["status"] == "passed"
        and all(
            abs(a - e) <= c["tolerance"]["rel"] * abs(e) + c["tolerance"]["abs"]
            for a, e in zip(np.atleast_1d(c["actual"]), np.atleast_1d(c["expected"]))
        )
        for c in cases
    )
    again = client.post(f"{API}/challenges/{a['id']}/answers", json=body, headers=auth(tokens["lab-a"]))
    assert again.status_code == 410 and again.json()["findings"][0]["code"] == "E979"
    b = client.post(f"{API}/challenges", headers=auth(tokens["lab-a"])).json()
    replay = client.post(f"{API}/challenges/{b['id']}/answers", json=body, headers=auth(tokens["lab-a"]))
    assert replay.status_code == 400 and replay.json()["findings"][0]["code"] == "E975"  # the cases of another challenge
    renamed = {
        "implementation": body["implementation"],
        "answers": {cb["id"]: answers[ca["id"]] for ca, cb in zip(a["cases"], b["cases"])},
    }
    judged_b = client.post(f"{API}/challenges/{b['id']}/answers", json=renamed, headers=auth(tokens["lab-a"])).json()
    assert judged_b["state"] == "failed"  # the old values relabelled: new sessions, new answers
    assert client.get(f"{API}/challenges/{a['id']}/sessions.tar.gz").json()["findings"][0]["code"] == "E979"
    for statement in (
        "UPDATE challenge_results SET passed = true",
        "DELETE FROM challenge_results",
        "UPDATE challenges SET expires_at = created_at",
        "DELETE FROM challenges",
    ):
        with pytest.raises(Exception, match="append-only"):  # a verdict cannot be rewritten
            with app.state.registry.engine.begin() as conn:
                conn.execute(text(statement))


def test_a_challenge_expires(tmp_path):
    app = create_app(Settings(data_dir=tmp_path / "data", challenge_ttl_s=0.3))
    token = app.state.registry.create_token("lab-a")
    with TestClient(app) as client:
        issued = client.post(f"{API}/challenges", headers=auth(token)).json()
        time.sleep(0.5)
        assert client.get(f"{API}/challenges/{issued['id']}").json()["state"] == "expired"
        late = client.post(
            f"{API}/challenges/{issued['id']}/answers",
            headers=auth(token),
            json={"implementation": {"name": "x", "version": "1"}, "answers": {}},
        )
        assert late.status_code == 410 and "expired" in late.json()["findings"][0]["message"]
    app.state.registry.close()


def run_cli(url: str, token: str, *adapter: str, report=None) -> int:
    argv = ["--challenge", url, "--token", token, *adapter]
    return cli.main(argv + (["--json-report", str(report)] if report else []))


def test_the_reference_passes_and_a_wrong_implementation_fails_through_haptify_conform(base, tmp_path, capsys):
    root, session, results, report, impl = base
    app = create_app(Settings(data_dir=tmp_path / "data"))
    token = app.state.registry.create_token("lab-a")
    archive, _ = bundle_for(session, results, report, tmp_path / "b.tar.gz")
    try:
        with serve_in_thread(app) as url, TestClient(app) as client:
            sub = client.post(
                f"{API}/submissions", content=archive.read_bytes(), headers={**auth(token), "Content-Type": "application/gzip"}
            ).json()
            # the uploaded report (hand-made by the fixtures, as a forger would) proves nothing
            assert client.get(f"{API}/submissions/{sub['id']}").json()["conformance"] == {
                "status": "self-asserted",
                "challenge": None,
                "families": [],
            }
            assert run_cli(url, token, "--python", "_challenge_impls:off_by_one_percent", report=tmp_path / "w.json") == 1
            wrong = json.loads((tmp_path / "w.json").read_text())
            failed = [c for c in wrong["result"]["cases"] if c["status"] == "failed"]
            assert wrong["state"] == "failed" and {c["metric"] for c in failed} == {"vibration.rms"}
            assert run_cli(url, token, "--python", "_challenge_impls:stiffness_ten_percent", report=tmp_path / "s.json") == 1
            stiff = json.loads((tmp_path / "s.json").read_text())
            assert stiff["state"] == "failed" and {c["metric"] for c in stiff["result"]["cases"] if c["status"] == "failed"} == {
                "stiffness.measured",
                "stiffness.accuracy",
            }
            assert client.get(f"{API}/submissions/{sub['id']}").json()["conformance"]["status"] == "self-asserted"
            assert run_cli(url, token, "--python", "haptify.conform_adapter:analyse", report=tmp_path / "r.json") == 0
            passed = json.loads((tmp_path / "r.json").read_text())
            assert passed["state"] == "passed" and passed["result"]["implementation"] == impl
            assert client.get(f"{API}/submissions/{sub['id']}").json()["conformance"] == {
                "status": "proven",
                "challenge": passed["id"],
                "families": list(FAMILIES),
            }
            listed = {(i["name"], i["version"]): i for i in client.get(f"{API}/implementations").json()}
            assert listed[(impl["name"], impl["version"])]["latest_passed"] == passed["id"]
            assert listed[(impl["name"], impl["version"])]["families"] == list(FAMILIES)
            assert listed[("off-by-one-percent", "0.1")] == {
                "name": "off-by-one-percent",
                "version": "0.1",
                "passed": 0,
                "failed": 1,
                "latest_passed": None,
                "families": [],
            }
            slug = client.get(f"{API}/submissions/{sub['id']}").json()["device"]["slug"]
            device = client.get(f"/devices/{slug}").text
            assert f'/challenges/{passed["id"]}">proven by challenge</a> <span class="families">({", ".join(FAMILIES)})' in device
            with browser(tmp_path / "profile") as page:  # the challenge result pages in a real browser
                page.goto(f"{url}/challenges/{passed['id']}")
                rows = page.locator("#challenge-cases tbody tr")
                assert rows.count() == len(passed["result"]["cases"])
                assert page.locator("#challenge-families").inner_text() == f"Metric families covered: {', '.join(FAMILIES)}."
                assert set(rows.locator("td.mark").all_inner_texts()) == {"passed"}
                assert page.locator("#challenge-state").inner_text() == "passed"
                page.goto(f"{url}/challenges/{wrong['id']}")
                bad = page.locator("#challenge-cases tbody tr.status-failed td:nth-child(2)").all_inner_texts()
                assert bad and set(bad) == {"vibration.rms"}
            out = capsys.readouterr().out
            assert "FAILED" in out and "PASSED" in out
            assert run_cli(url, "hpt_unknown", "--python", "haptify.conform_adapter:analyse") == 2
            assert "E970" in capsys.readouterr().err
    finally:
        app.state.registry.close()
