"""A simulated round robin (TWIN.md, Round robins; tools/haptify_tools/twin/round_robin.py): N virtual labs measure one
Touch twin, the reference computes each lab's session, the labs submit to a registry on SQLite, and the
registry's ISO 5725-2 s_r and s_R (spec §17.5.3) are checked against the variation that was simulated."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest
from _registry_fixtures import bundle_for, passing_report
from fastapi.testclient import TestClient

from haptify.cli.main import UI
from haptify.formats.storage import open_session
from haptify.pipeline.compute import compute_session
from haptify_tools.registry.app import create_app
from haptify_tools.registry.interlab import LabCell, components
from haptify_tools.registry.records import Settings
from haptify_tools.twin import cmd_simulate
from haptify_tools.twin.dossier_plan import SimulationOptions
from haptify_tools.twin.model import preset
from haptify_tools.twin.rig import RigConfig
from haptify_tools.twin.round_robin import SPREADS, draw_labs, parse_spreads, simulate_round_robin

METRIC = "stiffness.measured"
LABS, REPS = 14, 7
SIGMA_G, SIGMA_W = 0.03, 0.06  # between-lab F/T gain sd, within-lab (trial to trial) gain drift sd
API = "/api/v1"


def pooled_sd(cells: list[np.ndarray]) -> float:
    """√(Σ(nᵢ − 1)sᵢ² / Σ(nᵢ − 1)): the pooled within-lab standard deviation."""
    return math.sqrt(sum((len(c) - 1) * np.var(c, ddof=1) for c in cells) / sum(len(c) - 1 for c in cells))


@pytest.fixture(scope="module")
def round_robin(tmp_path_factory):
    """14 labs × 7 stiffness trials of 8 s (plus each lab's handle calibration), every other lab property at its
    default spread; each lab's session computed by the reference and submitted (results only) to a registry."""
    root = tmp_path_factory.mktemp("rr")
    opt = SimulationOptions(
        protocols=("rig.handle_calibration", "stiffness"),
        reps=REPS,
        seed=23,
        rig_trials=False,
        durations={"stiffness": 8.0, "rig.handle_calibration": 10.0},
        workers=1,
    )
    spreads = parse_spreads([f"ft_gain={SIGMA_G}", f"ft_gain_drift={SIGMA_W}"])
    res = simulate_round_robin(preset("touch"), root / "rr", opt, LABS, spreads)
    labs = json.loads(res.labs_json.read_text())
    app = create_app(Settings(data_dir=root / "registry"))
    client = TestClient(app)
    measured: dict[str, tuple[list[float], list[float]]] = {}  # lab → (values, the F/T gains of their trials)
    report = None
    for rec in labs["labs"]:
        session = res.sessions[rec["lab"]]
        results = compute_session(open_session(session), metrics=[METRIC]).model_dump(mode="json")
        target = root / f"{rec['lab']}.results.json"
        target.write_text(json.dumps(results))
        if report is None:
            report = passing_report(root / "conformance.json", results["implementation"])
        m = next(x for x in results["metrics"] if x["id"] == METRIC)
        measured[rec["lab"]] = (m["per_repetition"], [rec["trial_ft_gains"][t] for t in m["trials"]])
        archive = bundle_for(session, target, report, root / f"{rec['lab']}.tar.gz")[0]
        token = app.state.registry.create_token(rec["lab"])
        r = client.post(
            f"{API}/submissions",
            content=archive.read_bytes(),
            headers={"Authorization": f"Bearer {token}", "Content-Type": "application/gzip"},
        )
        assert r.status_code == 201, r.text
    with client:
        body = client.get(f"{API}/devices/3d-systems-touch", params={"verification": "all"}).json()
        page = client.get("/devices/3d-systems-touch?verification=all").text
    interlab = next(m for m in body["metrics"] if m["metric"] == METRIC)["interlab"]
    return labs, measured, interlab, page


def test_registry_recovers_the_simulated_s_r_and_s_R(round_robin):
    """The F/T gain scales the measured stiffness (a force-over-penetration slope; the bias and connector
    offsets a gain mismatch leaves do not change a slope): lab L's trial r reads g_L·(1 + δ_Lr)·X_Lr, with
    g_L = 1 + σ_g·z_L (σ_g = 3 %) and δ_Lr ~ N(0, σ_w = 6 %) injected by the simulator, and X_Lr the stiffness
    a perfectly calibrated rig reads (mean μ, natural repeatability σ_n ≈ 1.5 % of μ from the examiner's
    presses and the sensors' noise, the same in every lab: the other lab properties, at their default
    spreads, do not move a force-over-penetration slope — the plate is not read, mocap noise of tenths of a
    millimetre is small against presses of centimetres, the connector mass is calibrated out, and the
    press speed does not enter a quasi-static slope). X_Lr is known exactly: the measured value over the
    gain labs.json says that trial had. So by construction

        s_r² = E[g²]·(μ²σ_w² + (1 + σ_w²)·σ_n²),   s_R² = μ²σ_g² + s_r².

    Why 14 labs × 7 repetitions: the sample s_r has p(n − 1) = 84 degrees of freedom (relative standard
    error 1/√168 ≈ 7.7 %, so 20 % is 2.6 standard errors) and the sample s_R is dominated by s_r with the
    between-lab part s_L = 3 % ≈ ½·s_r; 3000 draws of this design (normal z, δ and X with σ_n = 1.9 %)
    put both within 20 % in 98.3 % of them (s_r outside in 1.0 %, s_R in 1.0 %); the seed is fixed.

    Second, against the variation as it was drawn: the same ISO 5725-2 statistics of μ·g_L·(1 + δ_Lr) (the
    injected gains of labs.json), with σ_n² added to s_r² and to s_R², must also be within 20 % — only the
    natural noise's cross terms separate them."""
    labs, measured, got, page = round_robin
    assert got is not None and len(got["labs"]) == LABS and got["labs_left_out"] == []
    x_cells = [np.array(v) / np.array(g) for v, g in measured.values()]
    mu = float(np.mean(np.concatenate(x_cells)))
    sigma_n = pooled_sd(x_cells)
    assert sigma_n < 0.5 * SIGMA_W * mu  # the injected drift dominates the within-lab spread
    s_r = math.sqrt((1 + SIGMA_G**2) * ((mu * SIGMA_W) ** 2 + (1 + SIGMA_W**2) * sigma_n**2))
    s_R = math.hypot(mu * SIGMA_G, s_r)
    assert got["s_r"] == pytest.approx(s_r, rel=0.2)
    assert got["s_R"] == pytest.approx(s_R, rel=0.2)
    drawn = [LabCell(lab, list(mu * np.array(g))) for lab, (_, g) in measured.items()]
    _, dr_r, _, dr_R = components(drawn)
    assert got["s_r"] == pytest.approx(math.hypot(dr_r, sigma_n), rel=0.2)
    assert got["s_R"] == pytest.approx(math.hypot(dr_R, sigma_n), rel=0.2)
    assert 'id="interlab"' in page and all(f'data-lab="{lab}"' in page for lab in measured)


def test_labs_json_says_what_each_lab_was_given(round_robin):
    """Every lab has its own seed, examiner and rig; the lab gains are those :func:`draw_labs` draws from the
    round robin's seed, every trial's gain is its lab's times its drift, and the drift has the asked sd."""
    labs, measured, _, _ = round_robin
    again = draw_labs(preset("touch"), RigConfig(), LABS, 23, parse_spreads([f"ft_gain={SIGMA_G}", f"ft_gain_drift={SIGMA_W}"]))
    assert [r["lab"] for r in labs["labs"]] == [d.lab for d in again] == sorted(measured)
    assert len({r["seed"] for r in labs["labs"]}) == LABS and len({r["examiner"]["id"] for r in labs["labs"]}) == LABS
    assert [r["rig"]["ft_gain"] for r in labs["labs"]] == [d.rig.ft_gain for d in again]
    drift = np.concatenate([np.array(list(r["trial_ft_gains"].values())) / r["rig"]["ft_gain"] - 1 for r in labs["labs"]])
    assert len(drift) == LABS * (REPS + 1)  # the stiffness trials and the handle calibration
    # 112 draws: the sample sd of N(0, 0.06) is within 20 % with probability > 0.99 (relative se 6.7 %)
    assert np.std(drift, ddof=1) == pytest.approx(SIGMA_W, rel=0.2)
    assert len({tuple(r["rig"]["plate_modes_hz"]) for r in labs["labs"]}) == LABS
    assert len({r["examiner"]["pace"] for r in labs["labs"]}) == LABS
    assert labs["spreads"]["mocap_noise"] == SPREADS["mocap_noise"].default


def test_a_lab_does_not_depend_on_how_many_labs_there_are():
    spreads = parse_spreads([])
    few, many = (draw_labs(preset("touch"), RigConfig(), n, 5, spreads) for n in (2, 6))
    assert few == many[:2] and few[0].rig != few[1].rig
    assert all(d.rig.ft_gain_drift_sd == 0.0 for d in many)


@pytest.mark.parametrize(
    "argv",
    [
        ["--lab-variation", "1"],
        ["--lab-variation", "3", "--lab-spread", "ft_gain=-0.1"],
        ["--lab-variation", "3", "--lab-spread", "colour=0.1"],
        ["--lab-spread", "ft_gain=0.1"],
    ],
)
def test_bad_round_robin_options_are_refused_with_e903(tmp_path, argv):
    parser = argparse.ArgumentParser()
    cmd_simulate.register_simulate(parser.add_subparsers())
    args = parser.parse_args(["simulate", "--preset", "touch", "-o", str(tmp_path / "x"), *argv])
    with pytest.raises(Exception) as err:
        args.func(args, UI(quiet=True))
    assert err.value.findings[0].code == "E903"
    assert not (tmp_path / "x").exists()
