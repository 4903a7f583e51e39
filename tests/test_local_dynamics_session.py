"""The dynamics family on a whole session (spec §11.7, §11.8): compute(ctx), the commands, coded failures.

The session is built by construction: the handle calibration is the identity (no bias, no connector
mass), the handle orientation is a slow rotation about z, and the device's force on the hand is the
linear law F = −m a − c v (+ a small white noise), expressed in the sensor frame as the rig would
record it. A linear law lies inside the model class, so the training force error is known to be of
the order of the (filtered) noise.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from haptify.dynamics import compute, line_fit, load_model, predict, trial_data
from haptify.errors import HaptifyError
from haptify.formats.conventions import GRAVITY_W, quat_conjugate, quat_from_axis_angle, quat_rotate
from haptify.formats.storage import SessionWriter, open_session
from haptify.pipeline.compute import ComputeContext
from haptify_tools.example_session import IDENTITY, TOUCH_DEVICE, example_rig

MASS, DAMPING, NOISE = 0.15, 0.8, 0.01
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")


def _trial_signals(rng: np.random.Generator, seconds: float, amplitude: float, centre: np.ndarray, freq: float) -> dict:
    """Analytic motion on a 1 kHz clock: oscillation in x, y, z with rising frequency, slow yaw."""
    t = np.arange(int(seconds * 1000)) / 1000.0
    chirp = 2 * np.pi * (freq * t + 0.02 * t**2)
    dphase = 2 * np.pi * (freq + 0.04 * t)
    ddphase = 2 * np.pi * 0.04
    amp = amplitude * np.array([1.0, 0.7, 0.5])
    shift = np.array([0.0, 1.1, 2.3])
    ph = chirp[:, None] + shift
    pos = centre + amp * np.sin(ph)
    vel = amp * np.cos(ph) * dphase[:, None]
    acc = -amp * np.sin(ph) * dphase[:, None] ** 2 + amp * np.cos(ph) * ddphase
    yaw = 0.3 * np.sin(2 * np.pi * 0.05 * t)
    q = quat_from_axis_angle(np.tile([0.0, 0.0, 1.0], (len(t), 1)), yaw)
    force_w = -MASS * acc - DAMPING * vel + NOISE * rng.standard_normal((len(t), 3))
    return {"t": t, "pos": pos, "q": q, "acc": acc, "force_w": force_w}


def _add_trial(
    w: SessionWriter, rng, trial_id: str, protocol: str, repetition: int, gap: tuple[float, float] | None = None, **motion
) -> None:
    s = _trial_signals(rng, **motion)
    w.add_trial(trial_id, protocol, powered=False, repetition=repetition, label="figure_eight" if protocol == "other" else None)
    t, q = s["t"], s["q"]
    p_sensor = np.array([0.0, 0.0, -0.03])  # example_rig: F/T sensor below the gimbal centre
    f_h = quat_rotate(quat_conjugate(q), s["force_w"])  # handle frame = sensor frame (identity rotation)
    tau_s = -np.cross(p_sensor, f_h)  # zero torque about the gimbal centre
    wrench = {
        "t": t,
        **{c: f_h[:, k] for k, c in enumerate(("fx", "fy", "fz"))},
        **{c: tau_s[:, k] for k, c in enumerate(("tx", "ty", "tz"))},
    }
    w.add_stream(trial_id, "handle_wrench", wrench, rate_hz=1000)
    a_h = quat_rotate(quat_conjugate(q), s["acc"] - GRAVITY_W)  # specific force: +g up at rest
    w.add_stream(trial_id, "handle_accel", {"t": t, "ax": a_h[:, 0], "ay": a_h[:, 1], "az": a_h[:, 2]}, rate_hz=1000)
    k = slice(None, None, 10)
    pose = {
        "t": t[k],
        "px": s["pos"][k, 0],
        "py": s["pos"][k, 1],
        "pz": s["pos"][k, 2],
        "qw": q[k, 0],
        "qx": q[k, 1],
        "qy": q[k, 2],
        "qz": q[k, 3],
    }
    if gap is not None:  # a motion-capture occlusion
        hidden = (pose["t"] >= gap[0]) & (pose["t"] < gap[1])
        for c in ("px", "py", "pz", "qw", "qx", "qy", "qz"):
            pose[c] = np.where(hidden, np.nan, pose[c])
    w.add_stream(trial_id, "handle_pose", pose, rate_hz=100)


def build_session(path: Path, tests: bool = True, train_s: float = 21.0, gap: tuple[float, float] | None = None) -> Path:
    rng = np.random.default_rng(0)
    calib = {
        "kind": "handle_gravity",
        "id": "cal-1",
        "force_bias_N": [0.0, 0.0, 0.0],
        "connector_mass_kg": 0.0,
        "connector_com_m": [0.0, 0.0, 0.0],
        "torque_bias_Nm": [0.0, 0.0, 0.0],
        "accel_bias_m_per_s2": [0.0, 0.0, 0.0],
        "gravity_m_per_s2": float(-GRAVITY_W[2]),
    }
    w = SessionWriter(
        manifest={
            "session_id": "dyn-0001",
            "date": "2026-11-22",
            "lab": {"id": "lab"},
            "examiner": {"id": "ex"},
            "device": TOUCH_DEVICE,
            "device_placement": IDENTITY,
            "rig": example_rig(),
            "calibration": [calib],
        }
    )
    centre = np.array([0.0, 0.0, 0.15])
    _add_trial(w, rng, "ld-1", "local_dynamic", 1, seconds=train_s, amplitude=0.03, centre=centre, freq=0.8)
    if tests:
        _add_trial(w, rng, "ld-2", "local_dynamic", 2, seconds=10.5, amplitude=0.03, centre=centre, freq=0.9, gap=gap)
        _add_trial(w, rng, "fs-1", "free_space", 1, seconds=10.5, amplitude=0.06, centre=centre + [0.08, 0.0, 0.0], freq=0.1)
    return w.write(path)


@pytest.fixture(scope="module")
def session_path(tmp_path_factory) -> Path:
    return build_session(tmp_path_factory.mktemp("dyn") / "session")


@pytest.fixture(scope="module")
def results(session_path):
    ctx = ComputeContext(session=open_session(session_path))
    items = compute(ctx)
    return {i.id: i for i in items}, ctx


def test_training_errors_are_near_the_noise(results):
    items, _ = results
    force = items["dynamics.force_rmse"]
    assert force.unit == "N" and len(force.value) == 3 and force.trials == ["ld-1"]
    # the force law is linear in the inputs; what remains is the low-passed noise and start-up transients
    assert max(force.value) < 2 * NOISE
    assert items["dynamics.force_rmse_mean"].value == pytest.approx(np.mean(force.value))
    torque = items["dynamics.torque_rmse"]
    assert torque.unit == "N*m" and max(torque.value) < 0.01
    assert items["dynamics.torque_rmse_mean"].value == pytest.approx(np.mean(torque.value))


def test_error_vs_distance_segments_and_line(results):
    items, _ = results
    evd = items["dynamics.error_vs_distance"]
    rows = evd.diagnostics["segments"]
    by_set = {}
    for r in rows:
        by_set.setdefault(r["set"], []).append(r)
    assert len(by_set["training"]) == 4 and len(by_set["local_dynamic"]) == 2 and len(by_set["free_space"]) == 2
    assert all(r["distance"] < 1e-6 for r in by_set["training"])  # every window matches itself
    assert max(r["distance"] for r in by_set["local_dynamic"]) < min(r["distance"] for r in by_set["free_space"])
    slope, intercept = line_fit(np.array([r["distance"] for r in rows]), np.array([r["force_error"] for r in rows]))
    assert evd.value == pytest.approx([slope, intercept])
    assert evd.n == 8 and evd.trials == ["ld-1", "ld-2", "fs-1"]


def test_without_test_trials_the_line_is_unavailable(tmp_path, results):
    ctx = ComputeContext(session=open_session(build_session(tmp_path / "s", tests=False)))
    # the training trial is built identically (same seed, built first): reuse the fitted model
    ctx.cached(("dynamics_model", "ld-1"), lambda: results[1].cached(("dynamics_model", "ld-1"), None))
    items = {i.id: i for i in compute(ctx)}
    assert items["dynamics.error_vs_distance"].code == "E701"
    assert hasattr(items["dynamics.force_rmse"], "value")


def test_an_occlusion_splits_runs_and_drops_its_segment(tmp_path, results):
    """ld-2 loses motion capture for 0.5 s at t = 2 s: its first segment is dropped, the rest is predicted."""
    session = open_session(build_session(tmp_path / "s", gap=(2.0, 2.5)))
    ctx = ComputeContext(session=session)
    ctx.cached(("dynamics_model", "ld-1"), lambda: results[1].cached(("dynamics_model", "ld-1"), None))
    items = {i.id: i for i in compute(ctx)}
    data = trial_data(session, "ld-2")
    runs = data.runs()
    assert len(runs) == 2 and not data.valid[210:240].any()
    rows = [r for r in items["dynamics.error_vs_distance"].diagnostics["segments"] if r["trial"] == "ld-2"]
    assert [r["start_s"] for r in rows] == [pytest.approx(data.t[500])]
    assert all(np.isfinite(r["force_error"]) for r in rows)


def test_short_training_trial_is_unavailable_not_nan(tmp_path):
    ctx = ComputeContext(session=open_session(build_session(tmp_path / "s", tests=False, train_s=8.0)))
    items = compute(ctx)
    assert {i.id for i in items} == {
        "dynamics.force_rmse",
        "dynamics.force_rmse_mean",
        "dynamics.torque_rmse",
        "dynamics.torque_rmse_mean",
        "dynamics.error_vs_distance",
    }
    assert all(i.code == "E701" for i in items)


def test_no_local_dynamic_trial(example_session):
    items = compute(ComputeContext(session=open_session(example_session)))
    assert items and all(i.code == "E302" for i in items)


def _haptify(argv: list[str]) -> int:
    """Run a ``haptify dynamics …`` command line through the plugin's own parser."""
    import argparse

    from haptify.cli.cmd_dynamics import register
    from haptify.cli.main import UI

    parser = argparse.ArgumentParser(prog="haptify")
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return args.func(args, UI(quiet=True))


def test_fit_and_predict_commands(session_path, tmp_path):
    model_path, mat_path, pred_path = tmp_path / "m.json", tmp_path / "m.mat", tmp_path / "p.parquet"
    fit_cmd = ["dynamics", "fit", str(session_path), "-o", str(model_path), "--mat", str(mat_path)]
    assert _haptify(fit_cmd) == 0
    assert mat_path.stat().st_size > 0
    model = load_model(model_path)
    assert model.fit.trial_id == "ld-1" and [c.name for c in model.inputs][:4] == ["qw", "qx", "qy", "qz"]
    with pytest.raises(HaptifyError) as err:  # no silent overwrite
        _haptify(fit_cmd)
    assert err.value.code == "E901"
    assert _haptify(["dynamics", "predict", str(model_path), str(session_path), "--trial", "ld-2", "-o", str(pred_path)]) == 0
    table = pd.read_parquet(pred_path)
    assert list(table.columns[:7]) == ["t", "fx", "fy", "fz", "tx", "ty", "tz"]
    data = trial_data(open_session(session_path), "ld-2")
    expected = predict(model, data.u[data.valid])  # one valid run: the whole trial
    assert np.allclose(table[["fx", "fy", "fz", "tx", "ty", "tz"]].to_numpy()[data.valid], expected, atol=1e-12)
    assert json.loads(model_path.read_text())["format"] == "haptify-hw-model"
    with pytest.raises(HaptifyError) as err:
        _haptify(["dynamics", "predict", str(tmp_path / "none.json"), str(session_path), "-o", str(tmp_path / "q.parquet")])
    assert err.value.code == "E702"


def _given_model_copy(tmp_path: Path, rate_hz: float) -> Path:
    """The dyn-predict conformance fixture with its model-a.json re-declared at ``rate_hz`` (model-slow.json)."""
    import shutil

    folder = tmp_path / "dyn-predict"
    shutil.copytree(Path(__file__).resolve().parents[1] / "fixtures" / "conformance" / "dyn-predict", folder)
    model = json.loads((folder / "model-a.json").read_text(encoding="utf-8"))
    model["sample_rate_hz"] = rate_hz
    (folder / "model-slow.json").write_text(json.dumps(model), encoding="utf-8")
    return folder


def test_a_given_model_too_slow_for_distance_windows_leaves_the_rmse(tmp_path):
    # at 2 Hz a 0.2 s window holds round(0.4) = 0 samples: a ZeroDivisionError (E999) before; now E701 (spec §11.6.1)
    ctx = ComputeContext(session=open_session(_given_model_copy(tmp_path, 2.0)))
    ctx.parameters = {"model": "model-slow.json"}
    items = {i.id: i for i in compute(ctx)}
    assert items["dynamics.error_vs_distance"].code == "E701"
    assert all(np.isfinite(items["dynamics.force_rmse"].value))


def test_a_given_model_with_only_single_row_runs_is_e701_not_nan(tmp_path):
    # motion capture usable 0.21 s in every 0.5 s: on the 4 Hz grid of the model every valid row stands alone,
    # so no run can be predicted; the RMS of nothing was NaN (a pydantic ValueError, E999) before (spec §11.1, §15.2)
    from haptify_tools.invalid_fixtures import session_edits

    folder = _given_model_copy(tmp_path, 4.0)

    def occlude(df):
        phase = np.mod(df["t"].to_numpy() - df["t"].iloc[0], 0.5)
        keep = (phase >= 0.4 - 1e-9) | (phase <= 0.11 + 1e-9)
        for c in ("px", "py", "pz", "qw", "qx", "qy", "qz"):
            df[c] = np.where(keep, df[c], np.nan)
        return df

    session_edits.rewrite_data(folder, "handle_pose", occlude, trial_id="local_dynamic-1")
    ctx = ComputeContext(session=open_session(folder))
    ctx.parameters = {"model": "model-slow.json"}
    data = trial_data(ctx, "local_dynamic-1", 4.0)
    assert data.valid.any() and data.runs() == []
    items = compute(ctx)
    assert len(items) == 5 and all(i.code == "E701" for i in items)
