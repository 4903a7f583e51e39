"""Inter-lab precision and ties in the registry (spec §17.5.3, §19.6), on SQLite, with values drawn
from a known model: lab effect σ_L, repeatability σ_r, and uncertainties chosen so that the significance
threshold of each difference is known."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from fastapi.testclient import TestClient
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from _registry_fixtures import base, bundle_for, variant  # noqa: F401  (base: fixture)
from haptify_tools.registry.app import create_app
from haptify_tools.registry.leaderboard import leaderboard
from haptify_tools.registry.records import Settings

API = "/api/v1"
METRIC = "vibration.rms"
P = 0.95


def type_a(u: float, dof: float | None) -> dict:
    """An uncertainty record of repeatability only (spec §19.4) with standard uncertainty ``u``."""
    k = float(stats.norm.ppf(0.5 + P / 2) if dof is None else stats.t.ppf(0.5 + P / 2, dof))
    return {
        "method": "type_a",
        "u": u,
        "U": k * u,
        "k": k,
        "coverage_probability": P,
        "dof_eff": dof,
        "budget": [
            {
                "source": "repeatability",
                "type": "A",
                "distribution": "t",
                "u_input": u,
                "unit": "m/s^2",
                "sensitivity": 1.0,
                "contribution": u,
                "dof": dof,
            }
        ],
    }


class Lab:
    """A registry on SQLite and a token per lab: ``submit`` posts results-only bundles of ``vibration.rms``."""

    def __init__(self, base, tmp_path):
        self.base, self.tmp = base, tmp_path
        self.app = create_app(Settings(data_dir=tmp_path / "data"))
        self.client = TestClient(self.app)
        self.tokens: dict[str, str] = {}

    def submit(
        self,
        name: str,
        lab: str,
        values: list[float],
        *,
        model: str | None = None,
        u: float | None = None,
        dof: float | None = None,
    ) -> None:
        session, results = variant(self.base, self.tmp, name, lab=lab, model=model, rms=values)
        if u is not None:
            data = json.loads(results.read_text())
            next(m for m in data["metrics"] if m["id"] == METRIC)["uncertainty"] = type_a(u, dof)
            results.write_text(json.dumps(data))
        if lab not in self.tokens:
            self.tokens[lab] = self.app.state.registry.create_token(lab)
        archive = bundle_for(session, results, self.base[3], self.tmp / f"{name}.tar.gz")[0]
        r = self.client.post(
            f"{API}/submissions",
            content=archive.read_bytes(),
            headers={"Authorization": f"Bearer {self.tokens[lab]}", "Content-Type": "application/gzip"},
        )
        assert r.status_code == 201, r.text


def interlab_of(client, slug: str, verification: str = "all") -> dict | None:
    metrics = client.get(f"{API}/devices/{slug}", params={"verification": verification}).json()["metrics"]
    return next((m for m in metrics if m["metric"] == METRIC), {}).get("interlab")


def test_round_robin_recovers_s_r_and_s_R_and_flags_a_planted_lab(base, tmp_path):
    """50 labs × 4 repetitions of one device, lab effect σ_L = 0.04 and repeatability σ_r = 0.03 (m/s²):
    s_r within 20 % of σ_r, s_R within 20 % of √(σ_r² + σ_L²) (true of 99.2 % of 2000 seeds of this design;
    the seed is fixed). A second model, measured by 8 consistent labs
    and one lab 1 m/s² (≈ 20 σ_R) off, has that lab flagged by Mandel's h and no other (the planted lab's
    spread keeps the others' |h| small: ≈ 1/√8 each)."""
    rng = np.random.default_rng(23)
    sigma_r, sigma_L, labs, reps = 0.03, 0.04, 50, 4
    reg = Lab(base, tmp_path)
    for i in range(labs):
        values = 1.0 + rng.normal(0, sigma_L) + rng.normal(0, sigma_r, reps)
        reg.submit(f"rr{i}", f"lab-{i:02d}", [float(v) for v in values])
    for i in range(9):
        values = 1.0 + rng.normal(0, sigma_L) + rng.normal(0, sigma_r, reps) + (1.0 if i == 8 else 0.0)
        reg.submit(f"out{i}", f"lab-{i:02d}", [float(v) for v in values], model="Planted")
    with reg.client:
        got = interlab_of(reg.client, "3d-systems-touch")
        assert got["s_r"] == pytest.approx(sigma_r, rel=0.2)
        assert got["s_R"] == pytest.approx(math.hypot(sigma_r, sigma_L), rel=0.2)
        assert len(got["labs"]) == labs and got["labs_left_out"] == []
        planted = interlab_of(reg.client, "3d-systems-planted")
        flags = {lab["lab"]: lab["h_flag"] for lab in planted["labs"]}
        assert flags.pop("lab-08") == "outlier" and "lab-08" in planted["outlying"]
        assert not any(flags.values())
        assert interlab_of(reg.client, "3d-systems-touch", "verified") is None  # results-only: unverified, not counted
        page = reg.client.get("/devices/3d-systems-planted?verification=all").text
        assert 'id="interlab"' in page and 'data-lab="lab-08" class="outlying"' in page
        assert 'data-lab="lab-07" class=""' in page


def test_two_labs_give_s_r_and_s_R_without_mandel(base, tmp_path):
    """Two labs: s_r, s_R by hand (ISO 5725-2 §7.4) and no h or k (they need three labs); one repetition is left out."""
    reg = Lab(base, tmp_path)
    reg.submit("a", "lab-a", [1.0, 3.0])
    reg.submit("b", "lab-b", [5.0, 7.0])
    reg.submit("c", "lab-c", [9.0])
    with reg.client:
        got = interlab_of(reg.client, "3d-systems-touch")
    # s_r² = 2; lab means 2 and 6, grand 4: s_d² = 2·(4 + 4)/1 = 16, n̄ = 2, s_L² = (16 − 2)/2 = 7
    assert got["s_r"] == pytest.approx(math.sqrt(2)) and got["s_L"] == pytest.approx(math.sqrt(7))
    assert got["s_R"] == pytest.approx(3.0) and got["h_critical"] is None and got["outlying"] == []
    assert got["labs_left_out"] == ["lab-c"] and [lab["h"] for lab in got["labs"]] == [None, None]


def test_leaderboard_ties_follow_the_significance_threshold(base, tmp_path):
    """u = 0.01 for every device (ν = ∞): the threshold is 1.96·√2·0.01 ≈ 0.0277. A (1.000) and B (1.010)
    are tied, C (1.200) is not; D (0.900) has no uncertainty and is a group of its own though best."""
    reg = Lab(base, tmp_path)
    for model, x, u in (("A", 1.0, 0.01), ("B", 1.01, 0.01), ("C", 1.2, 0.01), ("D", 0.9, None)):
        reg.submit(model, "lab-a", [x - 0.001, x, x + 0.001], model=model, u=u)
    with reg.client:
        body = reg.client.get(f"{API}/leaderboard/{METRIC}", params={"verification": "all"}).json()
        rows = {r["device"]: r for r in body["rows"]}
        page = reg.client.get(f"/leaderboard/{METRIC}?verification=all").text
        default = reg.client.get(f"{API}/leaderboard/{METRIC}").json()
    assert [r["device"] for r in body["rows"]] == ["3d-systems-d", "3d-systems-a", "3d-systems-b", "3d-systems-c"]
    assert [r["tie_group"] for r in body["rows"]] == [1, 2, 2, 3]
    assert rows["3d-systems-d"]["uncertainty"] is None
    assert rows["3d-systems-a"]["uncertainty"]["u"] == pytest.approx(0.01)
    assert rows["3d-systems-a"]["uncertainty"]["U"] == pytest.approx(1.959964 * 0.01, rel=1e-5)
    assert 'data-device="3d-systems-b" data-tie-group="2"' in page and "not tied to anything" in page
    assert default["rows"] == []  # only verified results rank by default


def row(model: str, mean: float, u: float | None) -> dict:
    record = None if u is None else {"u": u, "U": 1.96 * u, "k": 1.96, "coverage_probability": P, "dof_eff": None}
    return {
        "device": {"slug": model.lower(), "manufacturer": "M", "model": model},
        "metrics": [{"metric": METRIC, "mean": mean, "unit": "m/s^2", "uncertainty": record}],
    }


@settings(max_examples=60, deadline=None)
@given(st.floats(1e-4, 1.0), st.floats(1e-4, 1.0), st.floats(0.02, 0.98) | st.floats(1.02, 50.0))
def test_two_devices_tie_exactly_below_the_threshold(u1, u2, fraction):
    """Two devices whose means differ by ``fraction`` of k·√(u₁² + u₂²) (normal k, ν = ∞) tie iff fraction < 1."""
    threshold = stats.norm.ppf(0.5 + P / 2) * math.hypot(u1, u2)
    rows = leaderboard(METRIC, [row("A", 1.0, u1), row("B", 1.0 + fraction * threshold, u2)])
    assert (rows[0].tie_group == rows[1].tie_group) == (fraction < 1)


def test_target_metric_ties_on_the_distance_to_the_target():
    """stiffness.accuracy (closest to 100 % is better): 97 and 103 are equally good, so tied however small u."""
    devices = [
        {
            "device": {"slug": s, "manufacturer": "M", "model": s},
            "metrics": [
                {
                    "metric": "stiffness.accuracy",
                    "mean": x,
                    "unit": "%",
                    "uncertainty": {"u": 0.1, "U": 0.196, "k": 1.96, "coverage_probability": P, "dof_eff": None},
                }
            ],
        }
        for s, x in (("lo", 97.0), ("hi", 103.0), ("far", 110.0))
    ]
    assert [(r.device["slug"], r.tie_group) for r in leaderboard("stiffness.accuracy", devices)] == [
        ("hi", 1),
        ("lo", 1),
        ("far", 2),
    ]


def test_pooled_uncertainty_of_a_mean_by_hand():
    """Two submissions of 2 and 6 repetitions, u = 0.04 and 0.02 with ν = 4 and 10: weights ¼ and ¾, so
    contributions 0.01 and 0.015, u = √(0.01² + 0.015²), ν = u⁴ / (0.01⁴/4 + 0.015⁴/10) (GUM G.2b); one
    submission without a record makes the mean's uncertainty absent."""
    from haptify_tools.registry.interlab import pooled_uncertainty

    rec = lambda u, dof: {"u": u, "dof_eff": dof, "coverage_probability": P}  # noqa: E731
    got = pooled_uncertainty([(2, rec(0.04, 4.0)), (6, rec(0.02, 10.0))])
    u = math.hypot(0.01, 0.015)
    nu = u**4 / (0.01**4 / 4 + 0.015**4 / 10)
    assert got["u"] == pytest.approx(u) and got["dof_eff"] == pytest.approx(nu)
    assert got["k"] == pytest.approx(stats.t.ppf(0.975, nu)) and got["U"] == pytest.approx(got["k"] * u)
    assert pooled_uncertainty([(2, rec(0.04, 4.0)), (6, None)]) is None
