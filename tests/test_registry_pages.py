"""The registry's web pages and read-side endpoints on real submissions (spec §17.5).

Submissions go through the core's API (TestClient ``POST /api/v1/submissions`` with lab tokens): three
devices from two labs with repetition values chosen by construction, so every mean, spread and ranking
is known. The same read-side checks run on SQLite and on a throwaway PostgreSQL server (skipped with
the reason when it cannot start). A real headless Chromium (the system's, driven by Playwright) reads
the pages from a live uvicorn on 127.0.0.1.
"""

from __future__ import annotations

import copy
import json
import re
import uuid
from dataclasses import dataclass
from pathlib import Path
from statistics import fmean, stdev

import pytest
from _registry_fixtures import base, browser, bundle_for, example_session, passing_report, pg_server, skip_or_fail  # noqa: F401 (base: fixture)
from fastapi.testclient import TestClient

from haptify.formats.storage import sha256_file
from haptify.metrics.metric_definitions import family
from haptify.pipeline.compare import _fmt
from haptify.pipeline.results import Implementation, MetricResult, ResultsFile
from haptify.versions import PACKAGE_VERSION
from haptify_tools.registry.app import create_app
from haptify_tools.registry.records import Settings

# (lab, manufacturer, model, vibration.rms repetitions in m/s², workspace.measured_volume repetitions in m³)
PLAN = [
    ("lab-a", "3D Systems", "Touch", [0.066, 0.071], [0.0118, 0.0116]),
    ("lab-b", "3D Systems", "Touch", [0.070, 0.069, 0.073], [0.0119]),
    ("lab-a", "3D Systems", "Touch X", [0.040, 0.042], [0.0104, 0.0105]),
    ("lab-b", "Novint", "Falcon", [0.055, 0.052], [0.0010]),
]
LABS = ("lab-a", "lab-b")


@dataclass
class Populated:
    client: TestClient
    app: object
    tokens: dict[str, str]
    ids: list[str]


@pytest.fixture(scope="module")
def base_results() -> dict:
    """A results file of the reference implementation; its device, session and metrics are set per plan line."""
    results = ResultsFile(
        implementation=Implementation(name="haptify-reference", version=PACKAGE_VERSION),
        session_id="-",
        manifest_sha256="0" * 64,
        metrics=[
            MetricResult(id="free_space.speed_mean", value=0.05, unit="m/s", n=1, definition_version=family("free_space").version)
        ],
    )
    return results.model_dump(mode="json")


def set_metric(results: dict, metric_id: str, unit: str, reps: list[float]) -> None:
    """Put ``metric_id`` with these repetitions (value = their mean, sd ddof 1) into a results dict."""
    m = {
        **copy.deepcopy(results["metrics"][0]),
        "id": metric_id,
        "unit": unit,
        "value": fmean(reps),
        "per_repetition": reps,
        "trials": [],
        "n": len(reps),
        "sd": stdev(reps) if len(reps) > 1 else None,
        "diagnostics": {},
        "warnings": [],
    }
    results["metrics"] = [x for x in results["metrics"] if x["id"] != metric_id] + [m]


def build_bundles(root: Path, template: dict) -> list[tuple[str, Path]]:
    """One bundle per plan line: ``(lab, archive)``; the session's manifest is re-labelled per lab and device."""
    out = []
    for i, (lab, manufacturer, model, rms, volume) in enumerate(PLAN):
        folder = root / f"case{i}"
        session = example_session(folder / "session", lab=lab, session_id=f"sess-{i:03d}", manufacturer=manufacturer, model=model)
        results = copy.deepcopy(template)
        results["session_id"] = f"sess-{i:03d}"
        results["device"] = {"manufacturer": manufacturer, "model": model, "serial": None}
        results["manifest_sha256"] = sha256_file(session / "session.json")
        set_metric(results, "vibration.rms", "m/s^2", rms)
        set_metric(results, "workspace.measured_volume", "m^3", volume)
        (folder / "results.json").write_text(json.dumps(results))
        report = passing_report(folder / "conformance.json", results["implementation"])
        archive, _ = bundle_for(session, folder / "results.json", report, folder / "bundle.tar.gz")
        out.append((lab, archive))
    return out


@pytest.fixture(scope="module")
def bundles(tmp_path_factory, base_results) -> list[tuple[str, Path]]:
    return build_bundles(tmp_path_factory.mktemp("bundles"), base_results)


def populate(data_dir: Path, bundles: list[tuple[str, Path]], db_url: str | None = None) -> Populated:
    """A registry app with every bundle submitted through the API by its lab's token."""
    app = create_app(Settings(data_dir=data_dir, db_url=db_url))
    tokens = {lab: app.state.registry.create_token(lab) for lab in LABS}
    client = TestClient(app)
    ids = []
    for lab, archive in bundles:
        r = client.post(
            "/api/v1/submissions",
            content=archive.read_bytes(),
            headers={"Authorization": f"Bearer {tokens[lab]}", "Content-Type": "application/gzip"},
        )
        assert r.status_code == 201, r.text
        ids.append(r.json()["id"])
    return Populated(client, app, tokens, ids)


@pytest.fixture(params=["sqlite", "postgresql"], scope="module")
def backend(request):
    """A function returning a fresh database URL: None (SQLite in the data folder) or a new PostgreSQL database."""
    if request.param == "sqlite":
        return lambda: None
    server = request.getfixturevalue("pg_server")
    return lambda: server.new_database("t_" + uuid.uuid4().hex[:12])


def _close(pop: Populated) -> None:
    pop.client.close()
    pop.app.state.registry.close()


@pytest.fixture(scope="module")
def registry(backend, tmp_path_factory, bundles):
    """The populated registry (read-only tests share it) on SQLite and on a throwaway PostgreSQL server."""
    pop = populate(tmp_path_factory.mktemp("registry"), bundles, backend())
    yield pop
    _close(pop)


@pytest.fixture
def fresh_registry(backend, tmp_path, bundles):
    """A populated registry of its own, for a test that changes it."""
    pop = populate(tmp_path / "registry", bundles, backend())
    yield pop
    _close(pop)


def devices_in_order(html: str, table_id: str) -> list[str]:
    table = re.search(rf'<table[^>]*id="{table_id}".*?</table>', html, re.S)
    assert table, f"no table #{table_id}"
    return re.findall(r'<tr data-device="([^"]+)"', table.group(0))


def all_reps(model: str, column: int) -> list[float]:
    return [x for line in PLAN if line[2] == model for x in line[column]]


# --- pages on SQLite and PostgreSQL --------------------------------------------------------------


def test_index_lists_devices_and_leaderboards(registry):
    html = registry.client.get("/").text
    assert devices_in_order(html, "device-list") == ["3d-systems-touch", "3d-systems-touch-x", "novint-falcon"]
    assert "3 devices · 2 labs · 4 current submissions" in " ".join(html.split())
    assert 'href="http://testserver/leaderboard/vibration.rms"' in html


def test_leaderboard_order_and_values(registry):
    # every submission of PLAN is without raw streams (unverified), so they rank only with verification=all
    default = registry.client.get("/leaderboard/vibration.rms").text
    assert 'id="leaderboard"' not in default and default.count('data-verification="unverified"') == len(PLAN)
    r = registry.client.get("/leaderboard/vibration.rms?verification=all")
    assert r.status_code == 200
    # lower vibration is better: Touch X (0.041) < Falcon (0.0535) < Touch (mean of 5 repetitions 0.0698)
    assert devices_in_order(r.text, "leaderboard") == ["3d-systems-touch-x", "novint-falcon", "3d-systems-touch"]
    assert _fmt(fmean(all_reps("Touch", 3))) in r.text and _fmt(stdev(all_reps("Touch", 3))) in r.text
    # a larger workspace is better: Touch > Touch X > Falcon
    vol = registry.client.get("/leaderboard/workspace.measured_volume?verification=all").text
    assert devices_in_order(vol, "leaderboard") == ["3d-systems-touch", "3d-systems-touch-x", "novint-falcon"]
    api = registry.client.get("/api/v1/leaderboard/vibration.rms?verification=all").json()
    assert [(row["rank"], row["device"]) for row in api["rows"]] == [
        (1, "3d-systems-touch-x"),
        (2, "novint-falcon"),
        (3, "3d-systems-touch"),
    ]
    assert api["rows"][2]["mean"] == pytest.approx(fmean(all_reps("Touch", 3)))
    menu = {m["id"]: m["devices"] for m in registry.client.get("/api/v1/leaderboards").json()}
    assert menu["vibration.rms"] == 3 and menu["workspace.measured_volume"] == 3


def test_device_page_shows_spread_over_labs_and_repetitions(registry):
    html = registry.client.get("/devices/3d-systems-touch?verification=all").text
    row = re.search(r'<tr data-metric="vibration.rms">(.*?)</tr>', html, re.S).group(1)
    reps = all_reps("Touch", 3)
    lab_a, lab_b = fmean(PLAN[0][3]), fmean(PLAN[1][3])
    assert _fmt(fmean(reps)) in row and _fmt(stdev(reps)) in row  # mean and sd over all 5 repetitions
    assert _fmt(stdev([lab_a, lab_b])) in row  # between-lab spread
    assert f"lab-a: {_fmt(lab_a)}" in row and f"lab-b: {_fmt(lab_b)}" in row
    assert f"{_fmt(min(reps))} – {_fmt(max(reps))}" in row
    assert html.count('class="state-current"') == 2
    assert 'id="no-figures"' in html and 'id="no-recording"' in html  # no report figures, no raw streams
    assert "haptify submit … --include-raw" in html


def test_withdrawn_submission_leaves_the_aggregates(fresh_registry):
    registry = fresh_registry
    before = registry.client.get("/devices/3d-systems-touch?verification=all").text  # the read cache now holds this state
    assert "lab-b" in re.search(r'<tr data-metric="vibration.rms">(.*?)</tr>', before, re.S).group(1)
    sid = registry.ids[1]  # lab-b's Touch
    r = registry.client.post(
        f"/api/v1/submissions/{sid}/withdraw",
        json={"reason": "wrong calibration file"},
        headers={"Authorization": f"Bearer {registry.tokens['lab-b']}"},
    )
    assert r.status_code == 200, r.text
    html = registry.client.get("/devices/3d-systems-touch?verification=all").text
    row = re.search(r'<tr data-metric="vibration.rms">(.*?)</tr>', html, re.S).group(1)
    assert _fmt(fmean(PLAN[0][3])) in row and "lab-b" not in row
    assert "withdrawn: wrong calibration file" in html  # the record stays, with its reason
    board = registry.client.get("/api/v1/leaderboard/vibration.rms?verification=all").json()["rows"]
    assert next(r for r in board if r["device"] == "3d-systems-touch")["mean"] == pytest.approx(fmean(PLAN[0][3]))


def test_compare_page_is_table_iii_for_the_chosen_devices(registry):
    r = registry.client.get(
        "/compare",
        params=[("device", "3d-systems-touch"), ("device", "3d-systems-touch-x"), ("paper", "true"), ("verification", "all")],
    )
    assert r.status_code == 200
    table = re.search(r'<div id="comparison">(.*?)</div>', r.text, re.S).group(1)
    header = re.findall(r"<th>(.*?)</th>", table)
    assert header == ["Metric", "3D Systems Touch", "3D Systems Touch X", "paper: Touch", "paper: Touch X"]
    rms = re.search(r"<tr><td>Free-space vibration RMS \(m/s\^2\)</td>(.*?)</tr>", table).group(1)
    cells = re.findall(r"<td>(.*?)</td>", rms)
    touch, touch_x = all_reps("Touch", 3), all_reps("Touch X", 3)
    assert cells == [_fmt(fmean(touch), stdev(touch)), _fmt(fmean(touch_x), stdev(touch_x)), "0.0685", "0.0408"]
    volume = re.search(r"<tr><td>Workspace volume \(cm\^3\)</td>(.*?)</tr>", table).group(1)
    assert re.findall(r"<td>(.*?)</td>", volume)[0].startswith(_fmt(fmean(all_reps("Touch", 4)) * 1e6))
    csv = registry.client.get("/api/v1/compare", params={"devices": "3d-systems-touch,3d-systems-touch-x", "format": "csv"}).text
    assert csv.splitlines()[0] == "Metric,3D Systems Touch,3D Systems Touch X"


def test_unknown_records_are_coded_pages(registry):
    for url in ("/devices/no-such-device", "/compare?device=no-such-device", "/leaderboard/no.such_metric"):
        r = registry.client.get(url)
        assert r.status_code == 404 and "E973" in r.text and r.headers["content-type"].startswith("text/html"), url
    r = registry.client.get("/compare", params=[("device", f"d{i}") for i in range(51)])
    assert r.status_code == 400 and "E975" in r.text


def test_empty_registry_pages(tmp_path):
    app = create_app(Settings(data_dir=tmp_path / "empty"))
    with TestClient(app) as client:
        assert "No results have been submitted yet" in client.get("/").text
        assert client.get("/leaderboard", follow_redirects=False).status_code == 303
        assert "No device has a verified current value" in client.get("/leaderboard/vibration.rms").text
        assert "Choose one or more devices" in client.get("/compare").text
        assert client.get("/static/registry.css").status_code == 200


def test_raw_submission_has_report_figures_and_a_recording(base, tmp_path):  # noqa: F811 (base is a fixture)
    root, session, results, report, impl = base
    archive, digest = bundle_for(session, results, report, tmp_path / "raw.tar.gz", include_raw=True)
    app = create_app(Settings(data_dir=tmp_path / "registry"))
    token = app.state.registry.create_token("lab-a")
    with TestClient(app) as client:
        r = client.post(
            "/api/v1/submissions",
            content=archive.read_bytes(),
            headers={"Authorization": f"Bearer {token}", "Content-Type": "application/gzip"},
        )
        assert r.status_code == 201 and r.json()["verification"]["status"] == "verified", r.text
        sid = r.json()["id"]
        page = client.get("/devices/3d-systems-touch").text
        assert f'/submissions/{sid}/report/index.html">Draw the report' in page and "no-figures" not in page
        assert not (tmp_path / "registry" / "cache").exists()  # showing the page unpacks nothing
        assert f'/submissions/{sid}/recording.rrd">download the recording' in page
        rrd = client.get(f"/submissions/{sid}/recording.rrd")
        assert rrd.status_code == 200 and rrd.content[:4] == b"RRF2" and len(rrd.content) > 10_000
        index = client.get(f"/submissions/{sid}/report/index.html")
        assert index.status_code == 200 and "Haptify report" in index.text
        pngs = re.findall(r'<img src="([^"]+\.png)"', index.text)
        assert pngs, "the report has no figure"
        figure = client.get(f"/submissions/{sid}/report/{pngs[0]}")
        assert figure.status_code == 200 and figure.content[:8] == b"\x89PNG\r\n\x1a\n"
        page = client.get("/devices/3d-systems-touch").text  # the figures now show on the device page
        assert f'<img src="http://testserver/submissions/{sid}/report/{pngs[0]}"' in page
        for bad in ("..", ".hidden", "session.json", "a%2Fb"):
            assert client.get(f"/submissions/{sid}/report/{bad}").status_code == 404, bad
        assert client.get("/submissions/00000000000000000000/recording.rrd").status_code == 404
    app.state.registry.close()


def test_results_only_submission_has_no_report(registry):
    sid = registry.ids[0]
    for url in (f"/submissions/{sid}/report/index.html", f"/submissions/{sid}/recording.rrd"):
        r = registry.client.get(url)
        assert r.status_code == 404 and "E973" in r.text and "no raw streams" in r.text


# --- a real browser against a live server --------------------------------------------------------


def test_pages_in_a_real_headless_browser(tmp_path, bundles):
    from haptify_tools.registry.live import serve_in_thread

    pop = populate(tmp_path / "registry", bundles)
    shot = tmp_path / "compare.png"
    try:
        with serve_in_thread(pop.app) as url, browser(tmp_path / "chromium-profile") as page:
            page.goto(f"{url}/")
            page.get_by_role("link", name="Free-space vibration RMS").click()
            page.wait_for_url(f"{url}/leaderboard/vibration.rms")
            # nothing here is verified (no raw streams): nothing ranks, all is listed apart and marked
            assert page.locator("#leaderboard").count() == 0
            marks = page.locator("#not-ranked-table tbody td.mark").all_inner_texts()
            assert len(marks) == len(PLAN) and set(marks) == {"unverified"}
            mark = page.locator("#not-ranked-table tbody td.mark").first.evaluate(
                "el => getComputedStyle(el, '::before').content"
            )
            assert mark == '"? "'  # the stylesheet marks the state
            page.get_by_role("link", name="include results that are not verified").click()
            page.wait_for_url(f"{url}/leaderboard/vibration.rms?verification=all")
            ranked = page.locator("#leaderboard tbody tr td:nth-child(2)").all_inner_texts()
            assert ranked == ["3D Systems Touch X", "Novint Falcon", "3D Systems Touch"]
            assert page.locator("#leaderboard tbody tr td.rank").all_inner_texts() == ["1", "2", "3"]
            page.select_option("select[name=metric]", "workspace.measured_volume")  # the metric picker (no script)
            page.get_by_role("button", name="Show").click()
            page.wait_for_url(f"{url}/leaderboard/workspace.measured_volume?verification=all")
            ranked = page.locator("#leaderboard tbody tr td:nth-child(2)").all_inner_texts()
            assert ranked == ["3D Systems Touch", "3D Systems Touch X", "Novint Falcon"]  # larger is better
            page.get_by_role("link", name="3D Systems Touch X").click()
            page.wait_for_url(f"{url}/devices/3d-systems-touch-x?verification=all")
            cells = page.locator('#device-metrics tr[data-metric="vibration.rms"] td').all_inner_texts()
            assert cells[1] == _fmt(fmean(all_reps("Touch X", 3))) and cells[2] == "m/s^2"
            page.goto(f"{url}/")
            page.check('input[value="3d-systems-touch"]')
            page.check('input[value="3d-systems-touch-x"]')
            page.check('#devices input[name="verification"]')
            page.get_by_role("button", name="Compare the chosen devices").click()
            page.wait_for_selector("#comparison table")
            header = page.locator("#comparison thead th").all_inner_texts()
            assert header == ["Metric", "3D Systems Touch", "3D Systems Touch X"]
            row = page.locator("#comparison tbody tr", has_text="Free-space vibration RMS").locator("td").all_inner_texts()
            assert row[1].startswith(_fmt(fmean(all_reps("Touch", 3)))) and row[2].startswith(_fmt(fmean(all_reps("Touch X", 3))))
            page.screenshot(path=str(shot), full_page=True)
    finally:
        pop.client.close()
        pop.app.state.registry.close()
    assert shot.stat().st_size > 10_000 and shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_skip_or_fail_fails_under_ci(monkeypatch):
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI=true"):
        skip_or_fail("no browser")
    monkeypatch.setenv("CI", "false")
    with pytest.raises(pytest.skip.Exception, match="no browser"):
        skip_or_fail("no browser")


def test_live_server_binds_loopback_only(tmp_path):
    from haptify_tools.registry.live import serve_in_thread

    app = create_app(Settings(data_dir=tmp_path / "r"))
    try:
        with pytest.raises(ValueError, match="loopback"):
            with serve_in_thread(app, host="0.0.0.0"):
                pass
        with serve_in_thread(app) as url:
            assert url.startswith("http://127.0.0.1:")
            import urllib.request

            with urllib.request.urlopen(f"{url}/api/v1/health", timeout=10) as r:
                assert json.loads(r.read())["ok"] is True
    finally:
        app.state.registry.close()
