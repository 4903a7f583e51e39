"""Simulated dossiers (design §4): one valid standard session, truth beside it, deterministic for a seed."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from haptify.cli.main import UI
from haptify.formats.storage import open_session
from haptify.formats.validation import validate_session
from haptify.processing.calibration import handle_calibration
from haptify_tools.twin import cmd_simulate
from haptify_tools.twin.dossier_plan import SimulationOptions, plan
from haptify_tools.twin.model import EFFECT_IDS, load_twin, preset
from haptify_tools.twin.simulate import simulate_dossier

SHORT = {
    "free_space": 4.0,
    "stiffness": 8.0,
    "figure_eight": 3.0,
    "rig.plate_bias": 1.0,
    "rig.handle_calibration": 16.0,
    "rig.plate_impact": 1.5,
    "rig.plate_cop": 28.0,
    "rig.baseline_vibration": 2.0,
}


@pytest.fixture(scope="module")
def dossier(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "dossier"
    opt = SimulationOptions(protocols=("free_space", "figure_eight", "stiffness"), reps=1, seed=4, durations=SHORT, workers=1)
    return simulate_dossier(preset("touch"), out, opt), opt


def test_short_session_is_valid_and_truth_lies_beside_it(dossier):
    res, opt = dossier
    report = validate_session(res.session)
    assert report.errors == [], [str(f) for f in report.errors]
    assert sorted(p.name for p in res.out_dir.iterdir()) == ["session", "truth.json", "truth.npz"]
    assert not any("truth" in p.name for p in res.session.rglob("*"))
    s = open_session(res.session)
    assert [t.id for t in s.trials] == [p.trial_id for p in plan(opt)]
    assert {t.protocol for t in s.trials} >= {"rig.handle_calibration", "rig.plate_cop", "free_space", "stiffness", "other"}
    fig = s.trial("figure_eight-1")
    assert fig.protocol == "other" and fig.label == "figure_eight"
    stiff = s.trial("stiffness-1")
    assert stiff.powered and stiff.rendering.stiffness_N_per_m == 750.0
    # every trial lasts what was asked for and starts after the previous one on the one session clock
    truth = json.loads(res.truth_json.read_text())["trials"]
    for tr, prev in zip(truth, [None] + truth[:-1]):
        if tr["id"].startswith("rig.plate_cop"):
            continue  # its length follows the 30-position schedule
        name = tr["label"] or tr["protocol"]
        assert tr["t_end_s"] - tr["t_start_s"] == pytest.approx(SHORT[name], abs=1.5e-3)  # t_end: the last sample
        assert prev is None or tr["t_start_s"] > prev["t_end_s"]
        sync = s.read(tr["id"], "sync")
        assert sync["t"].iloc[0] == pytest.approx(tr["t_start_s"]) and sync["trigger"].sum() > 0


def test_truth_holds_every_effect_and_the_true_signals(dossier):
    res, _ = dossier
    truth = json.loads(res.truth_json.read_text())
    effects = {**truth["twin"]["effects"], **truth["twin"]["rig"]}
    assert set(EFFECT_IDS) <= set(effects)
    assert truth["rig"]["config"]["mocap_noise_m"] == pytest.approx(0.15e-3)
    arrays = np.load(res.truth_npz)
    s = open_session(res.session)
    # round trip: the stored commanded wrench is the rendering loop's command (truth kept in float32)
    cmd = s.read("stiffness-1", "commanded_wrench")
    assert np.array_equal(cmd[["fx", "fy", "fz"]].to_numpy().astype(np.float32), arrays["stiffness-1/commanded_W"][:, :3])
    assert np.array_equal(cmd["t"].to_numpy(), arrays["stiffness-1/t"])
    assert cmd["fz"].max() > 1.0
    # motion capture = truth + its configured noise
    pose = s.read("free_space-1", "handle_pose")
    true = arrays["free_space-1/position_W"][::10]
    err = pose[["px", "py", "pz"]].to_numpy() - true
    err = err[np.all(np.isfinite(err), axis=1)]
    assert np.std(err) == pytest.approx(0.15e-3 / np.sqrt(3), rel=0.3)
    assert arrays["free_space-1/q"].shape[1] == 3
    # the accelerometer = a perfect accelerometer's reading (truth.npz) + its constant bias, quantised
    acc = s.read("free_space-1", "handle_accel")
    assert np.allclose(acc["t"].to_numpy(), arrays["free_space-1/accel_t"], atol=1e-6)
    diff = acc[["ax", "ay", "az"]].to_numpy() - arrays["free_space-1/accel_A"]
    lsb = truth["rig"]["config"]["accel_lsb_m_per_s2"]
    assert np.ptp(diff, axis=0).max() <= lsb + 1e-5 and np.abs(diff).max() > 0.01  # the bias is there


def test_calibration_trial_recovers_the_true_rig(dossier):
    res, _ = dossier
    truth = json.loads(res.truth_json.read_text())["effective"]
    cal = handle_calibration(open_session(res.session))
    assert cal.force_bias_N == pytest.approx(truth["handle_force_bias_N"], abs=0.01)
    assert cal.connector_mass_kg == pytest.approx(truth["connector_mass_kg"], rel=0.03)
    assert cal.torque_bias_Nm == pytest.approx(truth["handle_torque_bias_Nm"], abs=5e-4)
    assert cal.accel_bias_m_per_s2 == pytest.approx(truth["accel_bias_m_per_s2"], abs=0.02)


def test_deterministic_for_a_seed_and_independent_of_the_other_trials(tmp_path):
    twin = preset("touch-x")
    kw = dict(reps=1, seed=9, durations={"free_space": 2.0}, rig_trials=False, workers=1)
    a = simulate_dossier(twin, tmp_path / "a", SimulationOptions(protocols=("free_space",), **kw))
    b = simulate_dossier(twin, tmp_path / "b", SimulationOptions(protocols=("free_space",), **kw))
    c = simulate_dossier(twin, tmp_path / "c", SimulationOptions(protocols=("free_space",), **{**kw, "seed": 10}))
    ma, mb, mc = (json.loads((r.session / "session.json").read_text()) for r in (a, b, c))
    assert ma == mb
    sha = lambda m: [s["sha256"] for t in m["trials"] for s in t["streams"]]  # noqa: E731
    assert sha(ma) != sha(mc)
    assert a.truth_json.read_text() == b.truth_json.read_text()
    # a trial draws only from its own seeded generators: adding another protocol leaves it unchanged
    d = simulate_dossier(
        twin,
        tmp_path / "d",
        SimulationOptions(
            protocols=("free_space", "figure_eight"), **{**kw, "durations": {"free_space": 2.0, "figure_eight": 1.0}}
        ),
    )
    md = json.loads((d.session / "session.json").read_text())
    assert md["trials"][0]["streams"] == ma["trials"][0]["streams"]


def _args(**kw):
    base = dict(
        preset=None,
        twin=None,
        disable=[],
        set_params=[],
        protocol="all",
        reps=1,
        seed=0,
        out=None,
        overwrite=False,
        no_rig_trials=True,
        clock_offsets=False,
        duration=[],
        workers=1,
        format="parquet",
        compact=False,
        lab_variation=0,
        lab_spread=[],
    )
    base.update(kw)
    return argparse.Namespace(**base)


def test_cli_twin_export_and_simulate(tmp_path):
    twin_file = tmp_path / "t.json"
    code = cmd_simulate.run_twin_export(
        _args(preset="touch", disable=["drive.backlash"], set_params=["friction.coulomb.torque_Nm=0.01"], out=str(twin_file)),
        UI(quiet=True),
    )
    assert code == 0
    twin = load_twin(twin_file)
    assert not twin.on("drive.backlash") and twin.effects.friction_coulomb.torque_Nm == [0.01] * 3
    out = tmp_path / "run"
    code = cmd_simulate.run_simulate(
        _args(
            twin=str(twin_file), protocol="stiffness", out=str(out), clock_offsets=True, duration=["stiffness=6"], compact=True
        ),
        UI(quiet=True),
    )
    assert code == 0
    s = open_session(out / "session")
    import pyarrow.parquet as pq  # --compact: sensor columns FLOAT, t DOUBLE (spec §3.2.1)

    schema = pq.ParquetFile(out / "session" / s.trials[0].streams[0].file).schema
    types = {schema.column(i).name: schema.column(i).physical_type for i in range(len(schema))}
    assert types.pop("t") == "DOUBLE" and set(types.values()) == {"FLOAT"}
    assert [t.id for t in s.trials] == ["stiffness-1"]
    offsets = [c for c in s.manifest.calibration if c.kind == "clock_offset"]
    assert offsets and all(abs(c.offset_s) <= 0.02 for c in offsets)
    assert validate_session(out / "session").errors == []
    with pytest.raises(Exception) as err:
        cmd_simulate.run_simulate(_args(preset="touch", set_params=["friction.coulomb"], out=str(tmp_path / "x")), UI(quiet=True))
    assert getattr(err.value, "findings", None) and err.value.findings[0].code == "E903"


def test_rig_effects_switch_off():
    from haptify_tools.twin.dossier_trials import DossierSimulator
    from haptify_tools.twin.model import disable

    on = DossierSimulator(preset("touch"), SimulationOptions())
    assert on.conn_m > 0 and np.any(on.bias_f != 0) and np.any(on.bias_a != 0) and np.any(on.bias_p != 0)
    twin = disable(disable(preset("touch"), "sensor.bias"), "handle.connector_mass")
    off = DossierSimulator(twin, SimulationOptions())
    assert off.conn_m == 0.0
    for b in (off.bias_f, off.bias_t, off.bias_a, off.bias_p):
        assert np.array_equal(b, np.zeros(3))
