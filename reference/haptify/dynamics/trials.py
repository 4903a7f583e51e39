"""The model on a session (spec §11.1, §11.7): a trial's inputs and outputs on the model's grid, the training
and test trials, fitting to a trial or taking a given parameter file (§16.2), and the table of 5 s segments
with their kinematic distance and force error (§11.6).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from haptify.codes import Code
from haptify.dynamics import parameter_file
from haptify.dynamics.distance import (
    DistanceScales,
    WindowFeatures,
    nearest_distances,
    segment_distances,
    segment_force_errors,
    window_features,
)
from haptify.dynamics.fitting import FitOptions, fit
from haptify.dynamics.parameter_file import (
    INPUT_NAMES,
    INPUT_UNITS,
    OUTPUT_NAMES,
    OUTPUT_UNITS,
    HWModelFile,
    load_model,
)
from haptify.dynamics.prediction import predict
from haptify.errors import fail

#: Protocols whose passive trials serve as test sets (spec §11.7).
TEST_PROTOCOLS = ("local_dynamic", "free_space", "other")
REQUIRED_STREAMS = ("handle_pose", "handle_wrench", "handle_accel")


@dataclass
class TrialData:
    """A trial's model inputs u (N, 13) and measured outputs y (N, 6) on the model's grid (spec §11.1).

    Rows where ``valid`` is False (motion capture unusable) hold NaN and are never used.
    """

    trial_id: str
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    valid: np.ndarray

    def runs(self) -> list[slice]:
        """Contiguous valid runs of at least 2 rows, each simulated from zero initial conditions (spec §11.1, §11.3)."""
        return valid_runs(self.valid)


def valid_runs(valid: np.ndarray, min_samples: int = 2) -> list[slice]:
    """Slices of the contiguous True runs of ``valid`` with at least ``min_samples`` samples.
    The runs of spec §11.1."""
    v = np.concatenate([[False], np.asarray(valid, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(v.astype(np.int8)))
    return [slice(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_samples]


def trial_data(ctx_or_session: Any, trial_id: str, rate_hz: float | None = None) -> TrialData:
    """The 13 inputs and 6 outputs of a trial from :func:`haptify.processing.signals.handle_signals` (spec §7.5, §11.1)."""
    from haptify.processing.signals import handle_signals

    rate = parameter_file.PARAMETERS.sample_rate_hz if rate_hz is None else float(rate_hz)
    sig = handle_signals(ctx_or_session, trial_id, rate_hz=rate)
    missing = [name for name, arr in (("handle_accel", sig.acceleration), ("handle_wrench", sig.force)) if arr is None]
    if missing:
        raise fail(
            Code.REQUIRED_STREAM_MISSING,
            f"trial {trial_id!r} has no {' or '.join(missing)} stream; the dynamic model needs it",
            file="session.json",
            expected=list(REQUIRED_STREAMS),
            found=missing,
        )
    assert sig.acceleration is not None and sig.force is not None and sig.torque is not None  # the wrench has both
    u = np.column_stack([sig.quaternion, sig.position, sig.velocity, sig.acceleration])
    y = np.column_stack([sig.force, sig.torque])
    valid = np.asarray(sig.valid, dtype=bool) & np.all(np.isfinite(u), axis=1) & np.all(np.isfinite(y), axis=1)
    return TrialData(trial_id=trial_id, t=np.asarray(sig.t, dtype=float), u=u, y=y, valid=valid)


def predict_trial(model: HWModelFile, data: TrialData) -> np.ndarray:
    """The model's outputs over a trial, run by run from rest; NaN on invalid rows (spec §11.3, §11.7)."""
    out = np.full((len(data.t), model.ny), np.nan)
    for run in data.runs():
        out[run] = predict(model, data.u[run])
    return out


def training_trial(session: Any) -> Any:
    """The training trial: the local_dynamic trial with the lowest repetition (normally 1; spec §11.7)."""
    trials = session.trials_of("local_dynamic")
    if not trials:
        raise fail(
            Code.REQUIRED_STREAM_MISSING,
            "the session has no local_dynamic trial to fit the dynamic model to",
            file="session.json",
            expected="a local_dynamic trial",
            found=[t.protocol for t in session.trials],
        )
    return trials[0]


def held_out_trials(session: Any, train_id: str) -> list[Any]:
    """Test trials (spec §11.7): every other unpowered local_dynamic, free_space or other trial with all three handle streams."""
    return [
        t
        for t in session.trials
        if t.id != train_id
        and t.protocol in TEST_PROTOCOLS
        and not t.powered
        and all(session.stream(t.id, k) is not None for k in REQUIRED_STREAMS)
    ]


def fit_trial(ctx_or_session: Any, trial_id: str, options: FitOptions | None = None) -> tuple[HWModelFile, TrialData]:
    """Fit the model to one trial (spec §11.4, §11.7); E701 when its valid data are shorter than ``min_training_s``."""
    data = trial_data(ctx_or_session, trial_id)
    rate = parameter_file.PARAMETERS.sample_rate_hz
    runs = data.runs()
    seconds = sum(r.stop - r.start for r in runs) / rate
    if seconds < parameter_file.PARAMETERS.min_training_s:
        raise fail(
            Code.DYNAMICS_DATA_INSUFFICIENT,
            f"trial {trial_id!r} has {seconds:.1f} s of valid data; the dynamic model needs at least "
            f"{parameter_file.PARAMETERS.min_training_s} s",
            expected=f">= {parameter_file.PARAMETERS.min_training_s} s",
            found=round(seconds, 2),
        )
    session = getattr(ctx_or_session, "session", ctx_or_session)
    model, _ = fit(
        [data.u[r] for r in runs],
        [data.y[r] for r in runs],
        sample_rate_hz=rate,
        options=options,
        input_names=INPUT_NAMES,
        input_units=INPUT_UNITS,
        output_names=OUTPUT_NAMES,
        output_units=OUTPUT_UNITS,
        quaternion_columns=[0, 1, 2, 3],
        session_id=session.session_id,
        trial_id=trial_id,
    )
    return model, data


def given_model_trial(ctx_or_session: Any, trial_id: str, relative: str) -> tuple[HWModelFile, TrialData]:
    """A parameter file inside the session folder used instead of fitting (spec §16.2 ``parameters.model``):
    the metrics then measure the given model's prediction (§11.3) on the trial. E702 when the path is unsafe."""
    from haptify.formats.session_format import is_safe_relative_path

    session = getattr(ctx_or_session, "session", ctx_or_session)
    if not isinstance(relative, str) or not is_safe_relative_path(relative):
        raise fail(
            Code.HW_MODEL_INVALID, f"model file {relative!r} is not a relative path inside the session folder", file=str(relative)
        )
    model = load_model(session.root / relative)
    return model, trial_data(ctx_or_session, trial_id, model.sample_rate_hz)


def _window_valid(valid: np.ndarray, window: int) -> np.ndarray:
    n = len(valid) // window
    return np.asarray(valid[: n * window].reshape(n, window).all(axis=1))


def trial_features(data: TrialData, window: int) -> tuple[WindowFeatures, np.ndarray]:
    """Window features of a trial and which windows are wholly valid (spec §11.6.1)."""
    filled = np.where(data.valid[:, None], data.u, np.r_[1.0, np.zeros(12)])  # rows outside valid stretches are masked out
    feats = window_features(filled[:, 4:7], filled[:, 7:10], filled[:, 10:13], filled[:, 0:4], window)
    return feats, _window_valid(data.valid, window)


def _subset(f: WindowFeatures, mask: np.ndarray) -> WindowFeatures:
    return WindowFeatures(f.position[mask], f.velocity[mask], f.acceleration[mask], f.orientation[mask])


def segment_table(model: HWModelFile, train: TrialData, tests: list[TrialData], labels: dict[str, str]) -> list[dict[str, Any]]:
    """Every complete, wholly valid 5 s segment of the training and test trials with its kinematic distance to
    the training set and its force error (spec §11.6)."""
    rate = model.sample_rate_hz
    window = int(round(parameter_file.PARAMETERS.window_s * rate))
    if window < 1:  # a parameter file at a few Hz: windows of round(window_s · rate) = 0 samples
        raise fail(
            Code.DYNAMICS_DATA_INSUFFICIENT,
            f"at the model's {rate:g} Hz a {parameter_file.PARAMETERS.window_s} s distance window holds no sample",
            expected="round(window_s · sample_rate_hz) >= 1",
            found=rate,
        )
    per_segment = int(round(parameter_file.PARAMETERS.segment_s / parameter_file.PARAMETERS.window_s))
    scales = DistanceScales.from_definition()
    train_feats, train_ok = trial_features(train, window)
    reference = _subset(train_feats, train_ok)
    rows = []
    for data in [train] + tests:
        feats, ok = trial_features(data, window)
        minima = np.full(len(ok), np.nan)
        if ok.any():
            minima[ok] = nearest_distances(_subset(feats, ok), reference, scales)
        n_seg = len(ok) // per_segment
        seg_ok = ok[: n_seg * per_segment].reshape(n_seg, per_segment).all(axis=1)
        distances = segment_distances(minima, per_segment)
        predicted = predict_trial(model, data)
        errors = segment_force_errors(data.y[:, :3], predicted[:, :3], window * per_segment)
        for k in np.flatnonzero(seg_ok):
            rows.append(
                {
                    "trial": data.trial_id,
                    "set": labels[data.trial_id],
                    "start_s": float(data.t[k * per_segment * window]),
                    "distance": float(distances[k]),
                    "force_error": float(errors[k]),
                }
            )
    return rows
