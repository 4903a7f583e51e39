"""The verdict cannot say "fine" wrongly (discrepancy README §3): a force outside the effect library is "unexplained
residual" with its shape described, never "no discrepancy"; null sessions, long and short, name nothing and their true
twin's held-out gap stays under the floor; benchmarks the operators cannot compute are listed with their code.

Known answers: the sessions are simulated by the ``touch`` preset, and the outside forces (:mod:`.outside`) are added
with known amplitude, period and state dependence."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from haptify.formats.storage import open_session
from haptify_tools.discrepancy.data import load_measured, simulate_all
from haptify_tools.discrepancy.floor import GAP_ALPHA, Floor, heldout_gap
from haptify_tools.discrepancy.outside import Cogging, SpeedSquared, with_field
from haptify_tools.discrepancy.workflow import assess, benchmark_gaps, verdict_of
from haptify_tools.twin.dossier_plan import SimulationOptions
from haptify_tools.twin.model import preset
from haptify_tools.twin.simulate import simulate_dossier


def _trials(folder, seconds, seed, protocol="free_space"):
    opt = SimulationOptions(
        protocols=(protocol, "rig.handle_calibration"),
        reps=1,
        seed=seed,
        durations={protocol: seconds, "rig.handle_calibration": 12.0},
        rig_trials=False,
        workers=1,
    )
    return load_measured(open_session(simulate_dossier(preset("touch"), folder / f"{protocol}-{seconds}-{seed}", opt).session))


@pytest.fixture(scope="module")
def free16(tmp_path_factory):
    return _trials(tmp_path_factory.mktemp("free16"), 16.0, 31)


def test_a_cogging_force_outside_the_library_is_unexplained_with_its_period_and_amplitude(free16):
    """0.2 N · sin(2πx / 5 mm) along x: a field that must never read "no discrepancy"."""
    result, _ = assess(preset("touch"), with_field(free16, Cogging(0.2, 0.005)), {"free_space": 16.0})
    assert result.verdict == "unexplained residual"
    assert result.accepted == []
    assert result.gap_significant and result.heldout_gap_after_N > result.floor_N
    shape = result.residual
    assert shape.follows == "x" and shape.states[0].kind == "periodic"
    assert abs(shape.states[0].period / 0.005 - 1) < 0.10
    assert abs(shape.states[0].amplitude_N / 0.2 - 1) < 0.20
    assert "periodic in x" in shape.description
    assert (shape.where[0].protocol, shape.where[0].channel) == ("free_space", "fx")


def test_a_speed_dependent_force_outside_the_library_is_unexplained_and_follows_the_velocity(free16):
    """20 N·s²/m² · |v|² along x (even in the velocity: no friction of the library can take it)."""
    result, _ = assess(preset("touch"), with_field(free16, SpeedSquared(20.0)), {"free_space": 16.0})
    assert result.verdict == "unexplained residual"
    assert result.residual.follows in ("speed", "vx", "vy", "vz")
    assert result.residual.states[0].heldout_r2 > 0.5


@pytest.mark.parametrize("seconds, seed", [(4.0, 41), (16.0, 42)])
def test_a_null_session_long_or_short_names_nothing_and_its_true_gap_is_under_the_floor(tmp_path, seconds, seed):
    """The twin that generated the session: nothing named, "no discrepancy", and the floor (the replays' prediction
    bound) above the gap the true twin leaves, on a long and on a short session."""
    trials = _trials(tmp_path, seconds, seed)
    twin = preset("touch")
    result, _ = assess(twin, trials, {"free_space": seconds})
    assert result.accepted == []
    assert result.verdict == "no discrepancy"
    assert heldout_gap(trials, simulate_all(twin, trials)) < result.floor_N
    assert len(result.floor_replays_N) >= 5 and result.floor_median_N < result.floor_N


def test_the_verdict_rule_never_says_fine_with_structure_or_a_significant_gap():
    for accepted in (False, True):
        assert verdict_of(accepted, True, False) == verdict_of(accepted, False, True) == "unexplained residual"
    assert verdict_of(False, False, False) == "no discrepancy"
    assert verdict_of(True, False, False) == "explained"


@settings(max_examples=50, deadline=None)
@given(hst.lists(hst.floats(0.002, 0.05), min_size=3, max_size=8), hst.floats(0.001, 0.2))
def test_the_gap_test_and_the_floor_bound_agree(replays, gap):
    """p < α exactly when the gap is above the bound; the bound is above the replays' median."""
    floor = Floor(tuple(replays))
    assert (floor.p_value(gap) < GAP_ALPHA) == (gap > floor.bound_N) or np.isclose(gap, floor.bound_N)
    assert floor.bound_N > floor.median_N


def test_a_benchmark_the_operator_cannot_compute_is_listed_with_its_code(tmp_path):
    """A stiffness trial whose twin force never presses: the stiffness operator's E315 (no press qualifies) is listed."""
    trials = _trials(tmp_path, 8.0, 5, "stiffness")
    tr = trials[0]
    flat = {tr.trial_id: np.zeros_like(tr.force)}
    gaps, missing = benchmark_gaps(trials, flat, {tr.trial_id: tr.force})
    assert not any(g.metric.startswith("stiffness.") for g in gaps)
    assert [(m.force, m.code) for m in missing] == [("twin before", "E315")]
    assert missing[0].metrics == ["stiffness.measured", "stiffness.peak_force"]
    # and a trial without contact: every force's operator fails
    _, missing = benchmark_gaps([replace(tr, contact=np.zeros_like(tr.contact))], flat, flat)
    assert {m.force for m in missing} == {"measured", "twin before", "twin after"}
