"""Verification states, visible (spec §17.3.1): each submission is verified, disagreeing (both values shown) or
unverified; aggregates, leaderboards and comparisons count only verified results unless asked for all;
the others are listed apart and marked; the API, the export and the pages carry the state and filter by it."""

from __future__ import annotations

import csv
import json
import io
import re

import pytest
from fastapi.testclient import TestClient

from _registry_fixtures import base, browser, bundle_for, variant  # noqa: F401  (base: fixture)
from haptify_tools.registry.app import create_app
from haptify_tools.registry.records import Settings

API = "/api/v1"
SCALE = 1.05  # the disagreeing submission's vibration.rms is 5 % off the re-computation (tolerance ≤ 1 %)


@pytest.fixture(scope="module")
def three(base, tmp_path_factory):  # noqa: F811 (base is a fixture)
    """One registry with a verified Touch (raw streams, reference results), a disagreeing Falcon (raw
    streams, vibration.rms × 1.05) and an unverified Omega (no raw streams), all current."""
    tmp = tmp_path_factory.mktemp("three")
    root, session, results, report, impl = base
    plan = [("touch", None, None, True), ("falcon", "Falcon", SCALE, True), ("omega", "Omega", None, False)]
    app = create_app(Settings(data_dir=tmp / "data"))
    token = app.state.registry.create_token("lab-a")
    client = TestClient(app)
    ids, rms = {}, {}
    for name, model, scale, raw in plan:
        s, r = variant(base, tmp, name, model=model, scale=scale)
        archive, _ = bundle_for(s, r, report, tmp / f"{name}.tar.gz", include_raw=raw)
        resp = client.post(
            f"{API}/submissions",
            content=archive.read_bytes(),
            headers={"Authorization": f"Bearer {token}", "Content-Type": "application/gzip"},
        )
        assert resp.status_code == 201, resp.text
        ids[name] = resp.json()["id"]
        rms[name] = next(m["value"] for m in json.loads(r.read_text())["metrics"] if m["id"] == "vibration.rms")
    client.app_ = app
    yield client, ids, rms
    client.close()
    app.state.registry.close()


def test_each_submission_has_its_state(three):
    client, ids, rms = three
    states = {name: client.get(f"{API}/submissions/{sid}").json()["verification"] for name, sid in ids.items()}
    assert states == {"touch": "verified", "falcon": "disagreeing", "omega": "unverified"}
    for state, name in (("verified", "touch"), ("disagreeing", "falcon"), ("unverified", "omega")):
        listed = client.get(f"{API}/submissions", params={"verification": state}).json()
        assert [s["id"] for s in listed] == [ids[name]]
    assert len(client.get(f"{API}/submissions").json()) == 3
    assert client.get(f"{API}/submissions", params={"verification": "maybe"}).status_code == 400


def test_the_leaderboard_ranks_only_verified_results_and_lists_the_others_apart(three):
    client, ids, rms = three
    board = client.get(f"{API}/leaderboard/vibration.rms").json()
    assert board["verification"] == "verified"
    assert [r["device"] for r in board["rows"]] == ["3d-systems-touch"]
    apart = {e["device"]: e for e in board["not_ranked"]}
    assert set(apart) == {"3d-systems-falcon", "3d-systems-omega"}
    falcon, omega = apart["3d-systems-falcon"], apart["3d-systems-omega"]
    assert falcon["verification"] == "disagreeing" and falcon["submitted"] == pytest.approx(rms["falcon"])
    assert falcon["recomputed"] == pytest.approx(rms["falcon"] / SCALE, rel=1e-9)  # both values shown
    assert omega["verification"] == "unverified" and omega["recomputed"] is None and "no raw streams" in omega["why"]
    everything = client.get(f"{API}/leaderboard/vibration.rms", params={"verification": "all"}).json()
    assert sorted(r["device"] for r in everything["rows"]) == ["3d-systems-falcon", "3d-systems-omega", "3d-systems-touch"]
    assert everything["not_ranked"] == []


def test_device_aggregates_count_only_verified_results_by_default(three):
    client, ids, rms = three
    falcon = client.get(f"{API}/devices/3d-systems-falcon").json()
    assert falcon["metrics"] == [] and falcon["submissions"] == 0
    assert {e["metric"] for e in falcon["not_counted"]} >= {"vibration.rms"}
    everything = client.get(f"{API}/devices/3d-systems-falcon", params={"verification": "all"}).json()
    rms_all = next(m for m in everything["metrics"] if m["metric"] == "vibration.rms")
    assert rms_all["mean"] == pytest.approx(rms["falcon"], rel=1e-9) and everything["not_counted"] == []
    touch = client.get(f"{API}/devices/3d-systems-touch").json()
    assert touch["submissions"] == 1 and touch["not_counted"] == []


def test_the_comparison_counts_only_verified_results_and_says_what_it_left_out(three):
    client, ids, rms = three
    q = {"devices": "3d-systems-touch,3d-systems-falcon"}
    table = client.get(f"{API}/compare", params=q).json()
    row = next(r for r in table["rows"] if r[0].startswith("Free-space vibration RMS"))
    assert row[1] != "—" and row[2] == "—"
    assert any(
        n.startswith("3d-systems-falcon: 1 current submission(s) not verified") and "1 disagreeing" in n for n in table["notes"]
    )
    assert [e["verification"] for e in table["not_counted"]["3d-systems-falcon"]][0] == "disagreeing"
    row_all = next(
        r
        for r in client.get(f"{API}/compare", params={**q, "verification": "all"}).json()["rows"]
        if r[0].startswith("Free-space vibration RMS")
    )
    assert row_all[2] != "—"


def test_the_export_carries_the_state_and_filters_by_it(three):
    client, ids, rms = three
    rows = list(csv.DictReader(io.StringIO(client.get(f"{API}/export.csv").text)))
    assert {r["submission"]: r["verification"] for r in rows} == {
        ids["touch"]: "verified",
        ids["falcon"]: "disagreeing",
        ids["omega"]: "unverified",
    }
    only = list(csv.DictReader(io.StringIO(client.get(f"{API}/export.csv", params={"verification": "disagreeing"}).text)))
    assert only and {r["submission"] for r in only} == {ids["falcon"]}


def test_the_pages_mark_the_states_and_filter(three):
    client, ids, rms = three
    html = client.get("/leaderboard/vibration.rms").text
    ranked = re.search(r'<table[^>]*id="leaderboard".*?</table>', html, re.S).group(0)
    assert re.findall(r'<tr data-device="([^"]+)"', ranked) == ["3d-systems-touch"]
    apart = re.search(r'<table[^>]*id="not-ranked-table".*?</table>', html, re.S).group(0)
    marks = dict(re.findall(r'data-submission="(\w+)" data-verification="(\w+)"', apart))
    assert marks == {ids["falcon"]: "disagreeing", ids["omega"]: "unverified"}
    falcon_row = re.search(rf'data-submission="{ids["falcon"]}".*?</tr>', apart, re.S).group(0)
    submitted = re.search(r'class="num submitted">([^<]+)<', falcon_row).group(1)
    recomputed = re.search(r'class="num recomputed">([^<]+)<', falcon_row).group(1)
    assert float(submitted) == pytest.approx(rms["falcon"], rel=1e-4)
    assert float(recomputed) == pytest.approx(rms["falcon"] / SCALE, rel=1e-4)
    assert 'href="?verification=all"' in html
    every = client.get("/leaderboard/vibration.rms?verification=all").text
    assert 'id="not-ranked"' not in every and len(re.findall(r"<tr data-device=", every)) == 3
    device = client.get("/devices/3d-systems-falcon").text
    assert 'id="not-counted"' in device and 'data-verification="disagreeing"' in device
    compare = client.get("/compare", params=[("device", "3d-systems-touch"), ("device", "3d-systems-falcon")]).text
    assert "not verified and not counted" in compare


def test_the_three_states_in_a_real_browser(three, tmp_path):
    """Leaderboard, device page, comparison and a verified submission's report page, in headless Chromium."""
    from haptify_tools.registry.live import serve_in_thread

    client, ids, rms = three
    with serve_in_thread(client.app_) as url, browser(tmp_path / "profile") as page:
        page.goto(f"{url}/leaderboard/vibration.rms")
        assert page.locator("#leaderboard tbody tr td:nth-child(2)").all_inner_texts() == ["3D Systems Touch"]
        rows = page.locator("#not-ranked-table tbody tr")
        states = {r.get_attribute("data-submission"): r.locator("td.mark").inner_text() for r in rows.all()}
        assert states == {ids["falcon"]: "disagreeing", ids["omega"]: "unverified"}
        falcon = page.locator(f'#not-ranked-table tr[data-submission="{ids["falcon"]}"]')
        assert float(falcon.locator("td.submitted").inner_text()) == pytest.approx(rms["falcon"], rel=1e-4)
        assert float(falcon.locator("td.recomputed").inner_text()) == pytest.approx(rms["falcon"] / SCALE, rel=1e-4)
        assert falcon.locator("td.mark").evaluate("el => getComputedStyle(el, '::before').content") == '"✗ "'
        page.get_by_role("link", name="include results that are not verified").click()
        page.wait_for_url(f"{url}/leaderboard/vibration.rms?verification=all")
        assert page.locator("#leaderboard tbody tr").count() == 3 and page.locator("#not-ranked-table").count() == 0
        page.goto(f"{url}/devices/3d-systems-falcon")
        assert page.locator("#device-metrics").count() == 0
        assert page.locator('#not-counted-table tr[data-verification="disagreeing"]').count() >= 1
        page.goto(f"{url}/compare?device=3d-systems-touch&device=3d-systems-falcon")
        assert "not verified and not counted" in page.locator("#comparison").inner_text()
        page.goto(f"{url}/submissions/{ids['touch']}/report/index.html")
        assert "Haptify report" in page.content() and page.locator("img").count() >= 1
        assert page.locator("img").first.evaluate("el => el.naturalWidth") > 0  # the figure loads under the CSP
