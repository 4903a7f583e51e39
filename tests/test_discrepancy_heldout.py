"""The discrepancy workflow on held-out-like cases (discrepancy README, Known limits): another preset (Touch X),
another pair of hidden effects, magnitudes ×0.3 and ×3 of the stored value with the search started from the stored value (off the truth and
off the search grid), per-axis values of an effect other than Coulomb friction, and a null Touch X session. The cases outside the library
(a cogging force periodic in position, a force growing with the speed squared) and the null case on a short session
are in ``test_discrepancy_verdict.py``; the per-drive Coulomb ×3 and an off-grid series elasticity started from the
truth in ``test_discrepancy_estimates.py``.

Known answers: every session is simulated by a preset with the hidden values; the workflow starts from the same
preset without the hidden effects, whose stored values (not the truth) start the search."""

from __future__ import annotations

import numpy as np
import pytest

from haptify.formats.storage import open_session
from haptify_tools.discrepancy.data import load_measured, simulate_all
from haptify_tools.discrepancy.floor import heldout_gap
from haptify_tools.discrepancy.workflow import assess
from haptify_tools.twin.dossier_plan import SimulationOptions
from haptify_tools.twin.model import disable, preset, set_param
from haptify_tools.twin.simulate import simulate_dossier


def _trials(folder, truth, durations: dict[str, float], seed: int):
    opt = SimulationOptions(
        protocols=(*durations, "rig.handle_calibration"),
        reps=1,
        seed=seed,
        durations={**durations, "rig.handle_calibration": 12.0},
        rig_trials=False,
        workers=1,
    )
    return load_measured(open_session(simulate_dossier(truth, folder / "measured", opt).session))


def _hide(name: str, values: dict[str, float | list[float]]):
    """(the ``name`` preset with ``values`` (``effect.parameter`` → value) on, the preset without those effects)."""
    truth, start = preset(name), preset(name)
    for key, value in values.items():
        effect = key.rsplit(".", 1)[0]
        truth = set_param(set_param(truth, key, value), f"{effect}.enabled", True)
        start = disable(start, effect)
    return truth, start


def test_a_hidden_coulomb_friction_on_the_touch_x_is_named_and_explained(tmp_path):
    """The Touch X preset (its own friction 0.025 N·m, viscous damping 0.02–0.03 N·m·s/rad, rotor inertia 4×10⁻⁶ kg·m²)
    with Coulomb friction 0.041 N·m on every drive; the search starts from the stored 0.025 N·m."""
    truth, start = _hide("touch-x", {"friction.coulomb.torque_Nm": 0.041})
    result, sel = assess(start, _trials(tmp_path, truth, {"free_space": 16.0}, 51), {"free_space": 16.0})
    assert [a.effect_id for a in result.accepted] == ["friction.coulomb"]
    assert abs(result.accepted[0].value / 0.041 - 1) < 0.05
    assert result.verdict == "explained"
    assert result.heldout_gap_after_N < result.floor_N < result.heldout_gap_before_N
    assert sel.twin.on("friction.coulomb")


def test_a_null_touch_x_session_with_slow_reversals_names_nothing_and_reads_no_discrepancy(tmp_path):
    """The Touch X twin that generated the session (16 s of free space, seed 51): its own held-out gap, 0.0068 N, is
    twice the median of six replays (a few slow reversals flip the friction along the rebuilt path) and lay above the
    former bound, 0.0049 N — the null session read "unexplained residual". Nothing is named, "no discrepancy"."""
    twin = preset("touch-x")
    trials = _trials(tmp_path, twin, {"free_space": 16.0}, 51)
    result, _ = assess(twin, trials, {"free_space": 16.0})
    assert result.accepted == []
    assert result.verdict == "no discrepancy"
    assert heldout_gap(trials, simulate_all(twin, trials)) < result.floor_N


def test_two_hidden_effects_viscous_friction_and_backlash_are_both_named(tmp_path):
    """Not the demo's pair: viscous damping 0.013 N·m·s/rad (seen in the figure eight) and a 5.5 mrad play (seen where
    the drive torque reverses while sliding on the frictionless surface), hidden together; the search starts from the
    stored 0.001 N·m·s/rad and 2 mrad."""
    hidden = {"friction.viscous.damping_Nms_per_rad": 0.013, "drive.backlash.width_rad": 0.0055}
    truth, start = _hide("touch", hidden)
    durations = {"figure_eight": 16.0, "frictionless_surface": 16.0}
    result, _ = assess(start, _trials(tmp_path, truth, durations, 52), durations)
    named = {a.effect_id: a.value for a in result.accepted}
    assert set(named) == {"friction.viscous", "drive.backlash"}
    assert abs(named["friction.viscous"] / 0.013 - 1) < 0.15
    assert abs(named["drive.backlash"] / 0.0055 - 1) < 0.15
    assert result.verdict == "explained"


@pytest.mark.parametrize("factor, seed, tolerance", [(0.31, 53, 0.01), (2.9, 54, 0.05)])
def test_a_series_elasticity_at_a_third_or_three_times_the_stored_value_is_found_within_its_interval(
    tmp_path, factor, seed, tolerance
):
    """The hidden stiffness is the preset's 11.5 N·m/rad × 0.31 or × 2.9 — between the search grid's points (×¼, ½, 1,
    2, 4 of the stored value the search starts from): its 95 % interval covers the truth and the verdict is "explained".
    The stiff cable is seen less: at the handle, 33 N·m/rad over the ≈ 0.13 m arm is ≈ 2000 N/m in series with the rendered 750 N/m,
    so a 3 % error moves the rendered stiffness by under 1 % — there the interval is ±4 % and the estimate within 5 %;
    the soft one within 1 %."""
    value = factor * 11.5
    truth, start = _hide("touch", {"drive.series_elasticity.stiffness_Nm_per_rad": value})
    result, _ = assess(start, _trials(tmp_path, truth, {"stiffness": 12.0}, seed), {"stiffness": 12.0})
    first = result.accepted[0]
    assert [a.effect_id for a in result.accepted] == ["drive.series_elasticity"]
    assert abs(first.value / value - 1) < tolerance
    assert first.ci95[0] <= value <= first.ci95[1]
    assert first.ci95[1] - first.ci95[0] < 2 * tolerance * value
    assert result.verdict == "explained"


@pytest.mark.parametrize("factor, seed", [(0.3, 55), (3.1, 56)])
def test_a_coulomb_friction_at_a_third_or_three_times_the_stored_value_is_found_within_its_interval(tmp_path, factor, seed):
    """One torque on every drive, ×0.3 or ×3.1 the preset's mean 0.0348 N·m (stored per drive 0.0385 / 0.033 / 0.033,
    where the search starts): within 1 %, inside its 95 % interval, "explained"."""
    value = factor * float(np.mean(preset("touch").effects.friction_coulomb.torque_Nm))
    truth, start = _hide("touch", {"friction.coulomb.torque_Nm": value})
    result, _ = assess(start, _trials(tmp_path, truth, {"free_space": 16.0}, seed), {"free_space": 16.0})
    first = result.accepted[0]
    assert [a.effect_id for a in result.accepted] == ["friction.coulomb"]
    assert first.per_drive is None
    assert abs(first.value / value - 1) < 0.01
    assert first.ci95[0] <= value <= first.ci95[1]
    assert result.verdict == "explained"


def test_per_axis_viscous_friction_is_named_per_drive_and_explained(tmp_path):
    """Viscous damping 0.02 / 0.005 / 0.0125 N·m·s/rad per drive (not only Coulomb friction differs per axis), seen in
    the figure eight: named per drive within 10 %, each value within four standard errors, "explained"."""
    values = [0.02, 0.005, 0.0125]
    truth, start = _hide("touch", {"friction.viscous.damping_Nms_per_rad": values})
    result, sel = assess(start, _trials(tmp_path, truth, {"figure_eight": 16.0}, 57), {"figure_eight": 16.0})
    first = result.accepted[0]
    assert [a.effect_id for a in result.accepted] == ["friction.viscous"]
    assert first.per_drive is not None and first.per_drive_delta_bic > 10
    assert np.allclose(first.per_drive, values, rtol=0.10)
    assert result.verdict == "explained"
    assert sel.twin.effects.friction_viscous.damping_Nms_per_rad == first.per_drive
