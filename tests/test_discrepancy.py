"""The discrepancy workflow on hidden effects (design §5): sessions simulated by the twin WITH an effect, the
workflow started from the twin WITHOUT it must name it, identify its parameter and shrink the gap; with
nothing hidden nothing is named; an effect outside the library is reported as unexplained."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from haptify.cli.main import UI
from haptify.formats.storage import open_session
from haptify_tools.discrepancy import cmd_discrepancy
from haptify_tools.discrepancy.data import load_measured, simulate_all
from haptify_tools.discrepancy.demo import DEMO_TRUTH, demo_session
from haptify_tools.discrepancy.floor import gap_above_floor, heldout_gap
from haptify_tools.discrepancy.identify import select_effects
from haptify_tools.discrepancy.model import DiscrepancyFile
from haptify_tools.discrepancy.workflow import run_discrepancy
from haptify_tools.twin.dossier_plan import SimulationOptions
from haptify_tools.twin.model import disable, load_twin, preset, set_param, write_twin
from haptify_tools.twin.simulate import simulate_dossier

FREE = {"free_space": 16.0, "figure_eight": 16.0, "stiffness": 8.0, "workspace": 60.0, "rig.handle_calibration": 12.0}


def _session(folder, truth, seed, durations=FREE, protocols=("free_space",), reps=1):
    rig = () if protocols == ("workspace",) else ("rig.handle_calibration",)
    opt = SimulationOptions(protocols=(*protocols, *rig), reps=reps, seed=seed, durations=durations, rig_trials=False, workers=1)
    return simulate_dossier(truth, folder / f"measured-{seed}", opt).session


def _rel(a, b):
    return abs(a - b) / abs(b)


def test_every_simulator_effect_is_a_candidate_or_reported_not_observable():
    from haptify_tools.discrepancy.library import LIBRARY_IDS, NOT_OBSERVABLE
    from haptify_tools.twin.model import EFFECT_IDS

    assert set(LIBRARY_IDS) | set(NOT_OBSERVABLE) == set(EFFECT_IDS)
    assert not set(LIBRARY_IDS) & set(NOT_OBSERVABLE)


@pytest.mark.parametrize("seed", [11, 12])
def test_hidden_coulomb_friction_is_named_identified_and_the_gap_shrinks(tmp_path, seed):
    torque = float(np.random.default_rng(seed).uniform(0.02, 0.06))
    truth = set_param(preset("touch"), "friction.coulomb.torque_Nm", torque)
    session = _session(tmp_path, truth, seed)
    start = disable(truth, "friction.coulomb")
    if seed == 11:  # once through the command line: every output written, the twin updated
        twin_file = tmp_path / "start.json"
        write_twin(start, twin_file)
        args = argparse.Namespace(
            session=str(session),
            twin=str(twin_file),
            out=str(tmp_path / "out"),
            max_effects=5,
            workers=1,
            no_overlay=False,
            overwrite=False,
        )
        assert cmd_discrepancy.run(args, UI(quiet=True)) == 0
        result = DiscrepancyFile.model_validate(json.loads((tmp_path / "out" / "discrepancy.json").read_text()))
        for name in ("twin.json", "report.html", "residual_vs_state.png", "workspace_residual.png", "overlay.rrd"):
            assert (tmp_path / "out" / name).is_file()
        updated = load_twin(tmp_path / "out" / "twin.json")
        assert updated.on("friction.coulomb")
        assert "identified by haptify discrepancy" in updated.effects.friction_coulomb.sources["torque_Nm"]
        assert _rel(updated.effects.friction_coulomb.torque_Nm[0], torque) < 0.15
    else:
        result, _ = run_discrepancy(session, start, None)
    assert result.accepted and result.accepted[0].effect_id == "friction.coulomb"
    assert _rel(result.accepted[0].value, torque) < 0.15
    assert result.accepted[0].per_drive is None  # equal on every drive: the shared value is kept (README §2)
    assert result.accepted[0].stderr is not None and result.accepted[0].stderr < 0.15 * torque
    assert result.heldout_gap_after_N <= 0.5 * result.heldout_gap_before_N
    assert result.verdict == "explained"
    # where: the free-space benchmark is ranked, with the residual mostly gone after
    fs = next(p for p in result.where if p.kind == "benchmark" and p.label == "free_space")
    assert fs.rms_after_N < 0.5 * fs.rms_before_N
    _benchmark_gap_halves(result, "free_space.force_mean")  # the paper's story: friction in the free-space force


def test_hidden_gravity_is_named_with_its_acceleration(tmp_path):
    truth = preset("touch")
    session = _session(tmp_path, truth, 21)
    result, _ = run_discrepancy(session, disable(truth, "gravity"), None)
    assert result.accepted[0].effect_id == "gravity"
    assert _rel(result.accepted[0].value, truth.effects.gravity.g_m_per_s2) < 0.15
    assert result.heldout_gap_after_N <= 0.5 * result.heldout_gap_before_N
    _benchmark_gap_halves(result, "free_space.force_mean")  # the paper's story: gravity in the free-space force


def _benchmark_gap_halves(result, metric):
    """The benchmark ``metric`` of the updated twin is at least twice as close to the measured one as before."""
    gap = next(b for b in result.benchmark_gaps if b.metric == metric)
    assert abs(gap.twin_after - gap.measured) < 0.5 * abs(gap.twin_before - gap.measured)


@pytest.mark.parametrize(
    "effect, parameter, low, high, protocols",
    [
        ("friction.viscous", "damping_Nms_per_rad", 0.005, 0.02, ("figure_eight",)),
        ("kinematics.link_length", "delta_a_m", 0.003, 0.01, ("free_space",)),
        ("drive.torque_saturation", "max_torque_Nm", 0.12, 0.22, ("stiffness",)),
        ("drive.force_cutoff", "trip_force_N", 1.5, 2.5, ("stiffness",)),
        ("inertia", "rotor_inertia_kg_m2", 0.5e-6, 2e-6, ("local_dynamic",)),
        ("handle.connector_mass", "mass_kg", 0.02, 0.06, ("local_dynamic",)),
        # the play shows where the drive torque reverses while the motors render: sliding on the surface
        ("drive.backlash", "width_rad", 0.003, 0.008, ("frictionless_surface",)),
        # the Stribeck excess lives at the reversals, where the path's velocity error matters most
        ("friction.stribeck", "excess_torque_Nm", 0.035, 0.105, ("free_space",)),
    ],
)
def test_hidden_effect_is_named_first_and_identified(tmp_path, effect, parameter, low, high, protocols):
    """One library effect hidden with a random plausible value; the twin starts from the preset without it
    (its stored, different value is only the search's starting point).
    The held-out gap must halve, as it is and above the floor the true twin itself leaves (its own held-out gap:
    ≈ 0.004 N on the figure eight, 0.007–0.009 N in the local-dynamic trial, where a 20 g connector's gap before
    is 0.09–0.10 N, benchmarks/RESULTS.md)."""
    value = float(np.random.default_rng(7).uniform(low, high))
    truth = set_param(set_param(preset("touch"), f"{effect}.{parameter}", value), f"{effect}.enabled", True)
    result, sel = run_discrepancy(
        _session(tmp_path, truth, 7, FREE, protocols), disable(preset("touch"), effect), None, max_effects=1
    )
    assert result.accepted[0].effect_id == effect
    assert _rel(result.accepted[0].value, value) < 0.15
    trials = sel.rounds[0].design.trials
    floor = heldout_gap(trials, simulate_all(truth, trials))
    assert result.heldout_gap_after_N <= 0.5 * result.heldout_gap_before_N
    assert gap_above_floor(result.heldout_gap_after_N, floor) <= 0.5 * gap_above_floor(result.heldout_gap_before_N, floor)
    if effect == "drive.torque_saturation":
        _benchmark_gap_halves(result, "stiffness.peak_force")  # the paper's story: saturation is the force plateau
    # the workflow's own floor (replays the updated twin generates along other examiner paths): their median estimates
    # the true one to within the spread of the floor between paths (0.0035–0.019 N, a factor of 5.4, over nine 12 s
    # stiffness sessions; 0.008–0.018 N in 16 s of free space; benchmarks/RESULTS.md), and their prediction bound,
    # the floor the verdict uses, lies above what the true twin leaves
    assert 1 / 6 < result.floor_median_N / floor < 6
    assert floor < result.floor_N


def test_gap_above_floor_is_the_energy_difference():
    assert gap_above_floor(0.05, 0.03) == pytest.approx(0.04)
    assert gap_above_floor(0.03, 0.05) == 0.0
    assert gap_above_floor(0.02, 0.0) == pytest.approx(0.02)


def test_hidden_base_collision_explains_the_missing_workspace_lobe(tmp_path):
    """The paper's Fig. 5 story: the twin without the base predicts a lower lobe the sweep never reaches."""
    from haptify_tools.discrepancy import workspace as ws

    top = float(np.random.default_rng(8).uniform(0.075, 0.125))
    truth = ws.apply(preset("touch"), top)
    start = disable(preset("touch"), "kinematics.base_collision")
    result, _ = run_discrepancy(_session(tmp_path, truth, 8, protocols=("workspace",)), start, None)
    assert [a.effect_id for a in result.accepted] == ["kinematics.base_collision"]
    assert _rel(result.accepted[0].value, top) < 0.15
    gap = result.workspace_gaps[0]
    assert gap.rms_after_m <= 0.5 * gap.rms_before_m
    # the twin's volume comes down to the measured one; the worst region before is low in the workspace
    assert abs(gap.twin_after_volume_m3 - gap.measured_volume_m3) < 0.5 * abs(gap.twin_before_volume_m3 - gap.measured_volume_m3)
    assert "z low" in gap.regions[0].label


def test_two_hidden_effects_series_elasticity_and_coulomb_are_both_found(tmp_path):
    """The demo's case and the paper's story: the drive's series elasticity explains the soft stiffness."""
    session = demo_session(tmp_path, seed=3)
    start = disable(disable(preset("touch"), "drive.series_elasticity"), "friction.coulomb")
    result, _ = run_discrepancy(session, start, None, max_effects=2, workers=2)
    named = {a.effect_id: a.value for a in result.accepted}
    assert set(named) == {"drive.series_elasticity", "friction.coulomb"}
    assert _rel(named["drive.series_elasticity"], DEMO_TRUTH["drive.series_elasticity.stiffness_Nm_per_rad"]) < 0.15
    assert _rel(named["friction.coulomb"], DEMO_TRUTH["friction.coulomb.torque_Nm"]) < 0.15
    # the values are refined together once both are named: the one named first no longer keeps the bias the then
    # missing one caused (the demo's Coulomb friction, named first, read 0.0387 N·m, interval [0.0385, 0.0390], for 0.04)
    coulomb = next(a for a in result.accepted if a.effect_id == "friction.coulomb")
    assert coulomb.ci95[0] <= DEMO_TRUTH["friction.coulomb.torque_Nm"] <= coulomb.ci95[1]
    assert _rel(named["friction.coulomb"], DEMO_TRUTH["friction.coulomb.torque_Nm"]) < 0.01
    assert _rel(named["drive.series_elasticity"], DEMO_TRUTH["drive.series_elasticity.stiffness_Nm_per_rad"]) < 0.01
    assert result.heldout_gap_after_N <= 0.5 * result.heldout_gap_before_N
    k = next(b for b in result.benchmark_gaps if b.metric == "stiffness.measured")
    assert _rel(k.twin_after, k.measured) < 0.1 < _rel(k.twin_before, k.measured)
    contact = next(p for p in result.where if p.kind == "contact" and p.label.startswith("in contact"))
    assert contact.rms_after_N < 0.5 * contact.rms_before_N


def test_nothing_is_named_without_a_hidden_effect_in_20_seeds(tmp_path):
    """Twin and data both lack the friction effects (so three friction candidates are offered): 20 independent
    short free-space trials (own path and noise each) analysed one by one; at most one false positive."""
    twin = disable(disable(disable(preset("touch"), "friction.coulomb"), "friction.viscous"), "friction.stribeck")
    session = _session(tmp_path, twin, 5, durations={"free_space": 4.0, "rig.handle_calibration": 12.0}, reps=20)
    trials = load_measured(open_session(session))
    assert len(trials) == 20
    named = [select_effects(twin, [tr]) for tr in trials]
    assert sum(bool(s.accepted) for s in named) <= 1
    assert sum(s.structure["structured"] for s in named) <= 1


def test_a_hidden_sensor_bias_is_reported_not_observable_and_nothing_is_named(tmp_path):
    """Large constant sensor offsets (2 N, 0.05 N·m, 0.5 m/s², 3× the preset's) in the measured session, a twin
    without them: the session's handle calibration removes them, so the force residual cannot see them — nothing
    is named and the output says why."""
    truth = preset("touch")
    for name, value in (
        ("handle_force_N", [2.0, -1.5, 2.5]),
        ("handle_torque_Nm", [0.05, -0.04, 0.03]),
        ("accel_m_per_s2", [0.5, -0.4, 0.6]),
    ):
        truth = set_param(truth, f"sensor.bias.{name}", value)
    result, _ = run_discrepancy(_session(tmp_path, truth, 9), disable(truth, "sensor.bias"), None)
    assert result.accepted == []
    assert result.verdict == "no discrepancy"
    assert "calibration" in result.not_observable["sensor.bias"]


def test_an_effect_outside_the_library_is_reported_unexplained_not_misnamed(tmp_path):
    """A link mass error (no effect id models it) with the friction candidates on offer."""
    twin = disable(disable(disable(preset("touch"), "friction.coulomb"), "friction.viscous"), "friction.stribeck")
    truth = set_param(twin, "links.1.mass_kg", 1.6 * twin.links[1].mass_kg)
    result, _ = run_discrepancy(_session(tmp_path, truth, 6), twin, None)
    assert result.accepted == []
    assert result.verdict == "unexplained residual"
