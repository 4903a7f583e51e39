"""The discrepancy workflow's candidate search on a Dask cluster (spec §17.9): the same fits, values and
simulations as the serial search, to the bit, for a session with a hidden Coulomb friction."""

from __future__ import annotations

import numpy as np
import pytest

from haptify.formats.storage import open_session
from haptify_tools.cluster import dask_client
from haptify_tools.discrepancy.data import load_measured
from haptify_tools.discrepancy.identify import select_effects
from haptify_tools.twin.dossier_plan import SimulationOptions
from haptify_tools.twin.model import disable, preset, set_param
from haptify_tools.twin.simulate import simulate_dossier

TORQUE = 0.04  # N·m, the hidden friction


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    truth = set_param(preset("touch"), "friction.coulomb.torque_Nm", TORQUE)
    opt = SimulationOptions(
        protocols=("free_space", "rig.handle_calibration"),
        reps=1,
        seed=21,
        rig_trials=False,
        workers=1,
        durations={"free_space": 8.0, "rig.handle_calibration": 12.0},
    )
    session = simulate_dossier(truth, tmp_path_factory.mktemp("disc") / "measured", opt).session
    return disable(truth, "friction.coulomb"), load_measured(open_session(session))


def _trials_held() -> int:
    from haptify_tools.discrepancy.data import _WORKER_TRIALS

    return len(_WORKER_TRIALS)


def _digest(sel):
    return (
        [(f.candidate.effect_id, f.value, f.stderr, f.score.delta_bic) for r in sel.rounds for f in r.fits],
        [(f.candidate.effect_id, f.value) for f in sel.accepted],
    )


def test_candidate_search_on_a_cluster_equals_the_serial_search(case):
    start, trials = case
    serial = select_effects(start, trials, max_effects=1, workers=1)
    with dask_client(workers=2) as client:
        clustered = select_effects(start, trials, max_effects=1, client=client)
        assert not any(client.run(_trials_held).values())  # the workers let the trials go after the search
    assert _digest(clustered) == _digest(serial)
    assert serial.accepted[0].candidate.effect_id == "friction.coulomb"
    assert abs(serial.accepted[0].value - TORQUE) / TORQUE < 0.2
    for tid in serial.final_sim:
        np.testing.assert_array_equal(clustered.final_sim[tid], serial.final_sim[tid])
