"""Rig metrics and the rig check against the paper's requirements (spec chapter 14, §14.4–14.8).

Metrics (``schemas/<v>/metrics/rig.json``): ``rig.plate_natural_frequency``, ``rig.cop_error``,
``rig.handle_calibration_rms``, ``rig.handle_force_offset_u``, ``rig.sync_offset``. :func:`check_rig` turns them and the rig
description into PASS / FAIL / WARN / SKIP lines for ``haptify rig-check``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.conventions import quat_to_matrix
from haptify.metrics.metric_definitions import family
from haptify.pipeline.repetitions import TrialValue, aggregate, definition_of, protocol_trials, unavailable
from haptify.pipeline.results import MetricResult, Unavailable
from haptify.processing import calibration, force_plate, preprocessing
from haptify.processing.caching import session_of

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext

FAMILY = "rig"


# --- per-trial computations --------------------------------------------------------------------


def impact_frequencies(ctx_or_session: Any, trial_id: str) -> np.ndarray:
    """Natural frequency per axis (Hz) of one ``rig.plate_impact`` trial (spec §14.4).

    Uses the total plate force without bias (the window's mean is removed anyway).
    """
    session = session_of(ctx_or_session)
    df = session.read(trial_id, "plate_wrench")
    pos, rot = force_plate.corner_geometry(session.manifest.rig)
    force, _ = force_plate.total_wrench(df[force_plate.PLATE_COLUMNS].to_numpy(), pos, rot)
    t = df["t"].to_numpy()
    return force_plate.natural_frequencies(t, force, preprocessing.nominal_rate(t))


def _row_sums(x: np.ndarray) -> np.ndarray:
    """Sums of the rows of ``x (n, 3)``, (x₀ + x₁) + x₂ — what ``x.sum(axis=1)`` computes, one column at a time."""
    out: np.ndarray = x[:, 0] + x[:, 1] + x[:, 2]
    return out


def _gravity_dirs_h(raw: np.ndarray, bias: np.ndarray, r_hs: np.ndarray, sign: float) -> np.ndarray:
    v = sign * (np.asarray(raw, float) - bias) @ r_hs.T
    out: np.ndarray = v / np.maximum(np.sqrt(_row_sums(v * v)), 1e-300)[:, None]
    return out


def _best_lag(score: Callable[[float], float], max_lag: float, coarse: float, fine: float, label: str) -> float:
    """Lag (s) maximising ``score``: a coarse search over ±max_lag, a fine one around the coarse best, a parabola."""

    def search(centre: float, half: float, step: float) -> tuple[np.ndarray, np.ndarray]:
        lags = centre + np.arange(-int(round(half / step)), int(round(half / step)) + 1) * step
        return lags, np.array([score(float(x)) for x in lags])

    lags, c = search(0.0, max_lag, coarse)
    if not np.isfinite(c).any():  # no lag pairs a usable sample with the F/T grid
        raise fail(
            Code.SYNC_UNDETERMINED,
            f"{label}: no lag within ±{max_lag} s finds usable samples to align",
            expected="usable samples overlapping the F/T grid",
            found="none",
        )
    k = int(np.nanargmax(c))
    if k == 0 or k == len(c) - 1:
        raise fail(
            Code.SYNC_UNDETERMINED,
            f"{label}: the best alignment lies at the edge of the ±{max_lag} s search",
            expected=f"a delay within ±{max_lag} s",
            found=float(lags[k]),
        )
    lags, c = search(float(lags[k]), coarse, fine)
    k = int(np.nanargmax(c))
    a, b, d = c[k - 1 : k + 2] if 0 < k < len(c) - 1 else (np.nan, np.nan, np.nan)
    denom = a - 2 * b + d
    if not denom < 0:
        raise fail(
            Code.SYNC_UNDETERMINED,
            f"{label}: the alignment score has no peak (did the handle rotate?)",
            expected="a peaked score",
            found="flat",
        )
    return float(lags[k] + 0.5 * (a - d) / denom * fine)


def recorder_delays(ctx_or_session: Any, trial_id: str) -> dict[str, float]:
    """Delays (s) of the accelerometer and of motion capture against the F/T recorder (spec §14.6).

    In a ``rig.handle_calibration`` trial all three recorders observe the direction of gravity in the
    handle frame: the F/T sensor as its connector load ``F − b_F``, the accelerometer as ``−(a − b_a)``
    and motion capture as ``R_WHᵀ (0, 0, −1)``. With F and a low-passed at ``sync_cutoff_hz`` and u_F resampled on a
    ``sync_rate_hz`` grid, the delay of recorder X is the lag τ in ±``sync_max_lag_s`` that maximises the mean of
    ``u_F(t) · u_X(t + τ)``: searched in steps of ``sync_coarse_step_s``, then in steps of 1/``sync_rate_hz``
    within one coarse step of the best, then refined by a parabola through the best three. A positive
    delay means X's time stamps are late. E624 when the score has no interior peak; E611 when motion
    capture has no usable sample in the trial.
    """
    session = session_of(ctx_or_session)
    cal = calibration.trial_fit(ctx_or_session, trial_id)
    w = session.read(trial_id, "handle_wrench")
    a = session.read(trial_id, "handle_accel")
    track = preprocessing.mocap_track(ctx_or_session, trial_id)
    if not track.valid.any():
        stream = session.stream(trial_id, "handle_pose")
        raise fail(
            Code.MOTION_CAPTURE_UNUSABLE,
            f"trial {trial_id!r}: no usable motion-capture samples to align with the F/T recorder",
            file=stream.file if stream else None,
            expected=f"valid runs of at least {preprocessing.PARAMETERS.min_segment_s} s",
            found="none",
        )
    rate = force_plate.PARAMETERS.sync_rate_hz
    max_lag = force_plate.PARAMETERS.sync_max_lag_s
    t0 = max(w["t"].iloc[0], a["t"].iloc[0], track.t[0]) + max_lag
    t1 = min(w["t"].iloc[-1], a["t"].iloc[-1], track.t[-1]) - max_lag
    grid = preprocessing.uniform_grid(float(t0), float(t1), rate)
    if len(grid) < 10:
        raise fail(
            Code.SYNC_UNDETERMINED,
            f"trial {trial_id!r} is too short for the sync check",
            expected=f"> {2 * max_lag} s of overlap",
            found=len(grid),
        )
    r_hs = calibration.sensor_rotation(session, "ft_sensor")
    r_ha = calibration.sensor_rotation(session, "accelerometer")
    fc = force_plate.PARAMETERS.sync_cutoff_hz
    f_grid = preprocessing.lowpass_resample(w["t"].to_numpy(), w[["fx", "fy", "fz"]].to_numpy(), grid, fc)
    u_f = _gravity_dirs_h(f_grid, cal.force_bias_N, r_hs, 1.0)
    t_a = a["t"].to_numpy()
    acc_f = preprocessing.lowpass(a[["ax", "ay", "az"]].to_numpy(), preprocessing.nominal_rate(t_a), fc)
    m = track.quaternion  # NaN outside segments
    down_h = np.einsum("nji,j->ni", quat_to_matrix(np.where(np.isfinite(m), m, 1.0)), np.array([0.0, 0.0, -1.0]))
    down_h[~track.valid] = np.nan

    def score_accel(tau: float) -> float:
        u = _gravity_dirs_h(preprocessing.interp_columns(t_a, acc_f, grid + tau), cal.accel_bias_m_per_s2, r_ha, -1.0)
        return float(np.mean(_row_sums(u_f * u)))

    def score_mocap(tau: float) -> float:
        u = preprocessing.interp_columns(track.t, down_h, grid + tau)  # NaN next to unusable samples
        u /= np.sqrt(_row_sums(u * u))[:, None]
        return float(np.nanmean(_row_sums(u_f * u)))

    coarse, fine = force_plate.PARAMETERS.sync_coarse_step_s, 1.0 / rate
    return {
        "accel_minus_ft_s": _best_lag(score_accel, max_lag, coarse, fine, f"trial {trial_id!r} accelerometer"),
        "mocap_minus_ft_s": _best_lag(score_mocap, max_lag, coarse, fine, f"trial {trial_id!r} motion capture"),
    }


# --- metric records -----------------------------------------------------------------------------


def _vector_result(metric_id: str, per_trial_values: dict[str, np.ndarray], diagnostics: dict[str, Any]) -> MetricResult:
    vals = np.array(list(per_trial_values.values()), float)
    return MetricResult(
        id=metric_id,
        value=[float(x) for x in vals.mean(axis=0)],
        unit=definition_of(FAMILY, metric_id).unit,
        per_repetition=[[float(x) for x in row] for row in vals],
        trials=list(per_trial_values),
        n=len(vals),
        sd=[float(x) for x in vals.std(axis=0, ddof=1)] if len(vals) >= 2 else None,
        diagnostics=diagnostics,
        definition_version=family(FAMILY).version,
    )


def _trial_results(ctx: ComputeContext, metric_id: str, compute_one: Callable[[str], Any]) -> dict[str, Any] | Unavailable:
    """``compute_one`` on every trial of the metric's protocol (its definition's first); Unavailable
    (E310) without such trials, or with the first trial's error when none worked (each failure is W413)."""
    got, missing = protocol_trials(ctx, definition_of(FAMILY, metric_id).protocols[0], (metric_id,), compute_one, metric_id)
    return missing[0] if missing else got


def _natural_frequency(ctx: ComputeContext, mid: str, got: dict[str, np.ndarray]) -> MetricResult:
    """``rig.plate_natural_frequency`` (spec §14.4): per axis, mean over repetitions."""
    return _vector_result(mid, got, {"axes": ["x", "y", "z"]})


def _cop_error(ctx: ComputeContext, mid: str, got: dict[str, list[force_plate.Placement]]) -> MetricResult:
    """``rig.cop_error`` (spec §14.5): mean over all placements, sd over placements."""
    errors = np.array([p.error for ps in got.values() for p in ps])
    per_rep = [float(np.mean([p.error for p in ps])) for ps in got.values()]
    return MetricResult(
        id=mid,
        value=float(errors.mean()),
        unit=definition_of(FAMILY, mid).unit,
        per_repetition=per_rep,
        trials=list(got),
        n=int(len(errors)),
        sd=float(errors.std(ddof=1)) if len(errors) >= 2 else None,
        diagnostics={
            "placements": [
                {"trial": tid, "t": [p.t0, p.t1], "cop_m": p.cop.tolist(), "mocap_m": p.mocap.tolist(), "error_m": p.error}
                for tid, ps in got.items()
                for p in ps
            ],
            "bias_source": force_plate.plate_bias(ctx)[1],
        },
        definition_version=family(FAMILY).version,
    )


def _calibration_rms(ctx: ComputeContext, mid: str, got: dict[str, calibration.HandleCalibration]) -> MetricResult:
    """``rig.handle_calibration_rms`` (spec §6.2–6.3, §14.7): force, acceleration, torque fit RMS."""
    rms = {tid: np.array([c.rms_force_N, c.rms_accel_m_per_s2, c.rms_torque_Nm]) for tid, c in got.items()}
    diag = {
        "components": ["force_N", "accel_m_per_s2", "torque_Nm"],
        "fits": {tid: {**c.to_record(f"fit-{tid}", tid), "n_samples": c.n_samples, **c.diagnostics} for tid, c in got.items()},
    }
    return _vector_result(mid, rms, diag)


def _force_offset_u(ctx: ComputeContext, mid: str, got: dict[str, calibration.HandleCalibration]) -> MetricResult:
    """``rig.handle_force_offset_u`` (spec §6.2, §14.7): the force sphere's offset uncertainty, mean over repetitions."""
    vals = []
    for tid, c in got.items():
        assert c.force_offset_u_N is not None  # calibration.trial_fit states it for every fit
        vals.append(TrialValue(tid, c.force_offset_u_N))
    return aggregate(FAMILY, mid, vals)


def _sync_offset(ctx: ComputeContext, mid: str, got: dict[str, dict[str, float]]) -> MetricResult:
    """``rig.sync_offset`` (spec §14.6): largest |delay| over recorder pairs, mean over repetitions."""
    vals = [TrialValue(tid, max(abs(v) for v in d.values())) for tid, d in got.items()]
    return aggregate(FAMILY, mid, vals, diagnostics={"delays_s": got})


# metric id → (what is computed per trial, how the per-trial results become the metric)
METRIC_STEPS: dict[str, tuple[Callable[[Any, str], Any], Callable[[Any, str, dict[str, Any]], MetricResult]]] = {
    "rig.plate_natural_frequency": (impact_frequencies, _natural_frequency),
    "rig.cop_error": (force_plate.cop_trial_placements, _cop_error),
    "rig.handle_calibration_rms": (calibration.trial_fit, _calibration_rms),
    "rig.handle_force_offset_u": (calibration.trial_fit, _force_offset_u),
    "rig.sync_offset": (recorder_delays, _sync_offset),
}


def metric(ctx: ComputeContext, metric_id: str) -> MetricResult | Unavailable:
    """One rig metric for the session behind ``ctx`` (spec §14.4–14.7)."""
    per_trial_step, summarise = METRIC_STEPS[metric_id]
    got = _trial_results(ctx, metric_id, lambda tid: per_trial_step(ctx, tid))
    return got if isinstance(got, Unavailable) else summarise(ctx, metric_id, got)


def compute(ctx: ComputeContext) -> list[MetricResult | Unavailable]:
    """Every rig metric the session allows (spec §14; called by ``haptify compute``)."""
    return [_safe_metric(ctx, mid) for mid in METRIC_STEPS if ctx.wants(mid)]


# --- the rig check (spec §14.8) ------------------------------------------------------------------


@dataclass
class Check:
    """One line of ``haptify rig-check``: status PASS, FAIL, WARN (advisory shortfall) or SKIP (no data).
    Spec §14.8."""

    name: str
    status: str
    value: Any
    requirement: str
    detail: str = ""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _axis_capacity(range_vec: np.ndarray, rotations: np.ndarray, axis: np.ndarray, share: float) -> float:
    """Largest load along ``axis`` (W) that keeps every corner within range when each carries ``share`` of it."""
    caps = []
    for r in rotations:
        c = np.abs(r.T @ axis) * share
        caps.append(np.min(np.where(c > 1e-12, range_vec / np.maximum(c, 1e-300), np.inf)))
    return float(min(caps))


def plate_capacity(rig: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """Plate force range (N, per world axis) and moment range (N·m, about x, y, z) from the corner ranges (spec §14.8).

    Forces: each corner carries a quarter of a force along a world axis. Moments about x and y: the
    lever rule on the corners' vertical forces; about z: tangential horizontal corner forces. The
    corners' own torque capacity is not counted (conservative). None when ranges are not described.
    """
    plate = rig.force_plate
    if plate is None or plate.corner_range is None or plate.corner_range.force_N is None:
        return None
    pos, rot = force_plate.corner_geometry(rig)
    frange = np.asarray(plate.corner_range.force_N, float)
    force = np.array([_axis_capacity(frange, rot, e, 0.25) for e in np.eye(3)])
    moments = []
    for lever_axis in (1, 0):  # Mx from y levers, My from x levers
        arm = pos[:, lever_axis]
        moments.append(
            min(
                _axis_capacity(frange, rot[i : i + 1], np.array([0.0, 0.0, 1.0]), abs(arm[i]) / np.sum(arm**2))
                for i in range(4)
                if abs(arm[i]) > 0
            )
        )
    rad = np.linalg.norm(pos[:, :2], axis=1)
    mz = []
    for i in range(4):
        tangent = np.array([-pos[i, 1], pos[i, 0], 0.0]) / rad[i]
        mz.append(_axis_capacity(frange, rot[i : i + 1], tangent, rad[i] / np.sum(rad**2)))
    moments.append(min(mz))
    return force, np.array(moments)


def _status(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def _range_checks(session: Any, ctx: ComputeContext) -> list[Check]:
    rig = session.manifest.rig
    out: list[Check] = []
    cap = plate_capacity(rig)
    if cap is None:
        out.append(
            Check(
                "plate force/moment range (Table I)",
                "SKIP",
                None,
                "rig.force_plate.corner_range",
                "the rig does not describe the plate's corner ranges",
            )
        )
    else:
        force, moment = cap
        note = ""
        try:
            bias, _ = force_plate.plate_bias(ctx)
            pos, rot = force_plate.corner_geometry(rig)
            f, _ = force_plate.total_wrench(bias[None, :], pos, rot)
            force[2] = force[2] - abs(float(f[0, 2]))
            note = f"vertical range reduced by the plate's own weight {abs(float(f[0, 2])):.1f} N"
        except HaptifyError:
            note = "plate weight unknown (no bias); vertical range not reduced by it"
        req_f = np.asarray(force_plate.PARAMETERS.req_plate_force_N, float)
        req_m = np.asarray(force_plate.PARAMETERS.req_plate_moment_Nm, float)
        out.append(
            Check(
                "plate force range (Table I)",
                _status(bool(np.all(force >= req_f))),
                force.round(1).tolist(),
                f">= {req_f.tolist()} N",
                note,
            )
        )
        out.append(
            Check(
                "plate moment range (Table I)",
                _status(bool(np.all(moment >= req_m))),
                moment.round(1).tolist(),
                f">= {req_m.tolist()} N*m",
            )
        )
    handle = rig.handle
    items = [
        (
            "handle F/T force range (Table I)",
            handle and handle.ft_sensor.range and handle.ft_sensor.range.force_N,
            force_plate.PARAMETERS.req_handle_force_N,
            "N",
            "FAIL",
        ),
        (
            "handle F/T torque range (Table I)",
            handle and handle.ft_sensor.range and handle.ft_sensor.range.torque_Nm,
            force_plate.PARAMETERS.req_handle_torque_Nm,
            "N*m",
            "WARN",
        ),
        (
            "accelerometer range (Table I)",
            handle and handle.accelerometer.range and handle.accelerometer.range.accel_m_per_s2,
            force_plate.PARAMETERS.req_accel_m_per_s2,
            "m/s^2",
            "FAIL",
        ),
    ]
    for name, rng, requirement, unit, shortfall in items:
        req = float(np.max(requirement))
        if not rng:
            out.append(Check(name, "SKIP", None, f">= {req} {unit} on every axis", "the rig does not describe this range"))
            continue
        ok = float(np.min(rng)) >= req  # the handle turns, so every sensor axis must cover the requirement
        detail = "" if ok or shortfall == "FAIL" else "advisory: the paper's own Mini27 (±4/±4/±2 N*m) is below Table I too"
        out.append(Check(name, "PASS" if ok else shortfall, list(rng), f">= {req} {unit} on every axis", detail))
    return out


def _safe_metric(ctx: ComputeContext, mid: str) -> MetricResult | Unavailable:
    """:func:`metric`, or its Unavailable record when a problem shared by every trial stops it (spec §15.2)."""
    try:
        return metric(ctx, mid)
    except HaptifyError as exc:  # a problem shared by every trial, e.g. the rig lacks a part
        return unavailable(mid, exc)


def _orientation_errors(res: MetricResult) -> list[float]:
    return [f["orientation_error_deg"] for f in res.diagnostics["fits"].values() if f.get("orientation_error_deg") is not None]


def check_rig(ctx: ComputeContext) -> list[Check]:
    """Every rig-check line for the session of ``ctx`` (a ComputeContext; spec §14.8): Table I ranges, plate
    natural frequency, COP error, calibration residuals and sensor pose, recorder synchronisation."""
    results = {mid: _safe_metric(ctx, mid) for mid in METRIC_STEPS}
    fmin, cmax = force_plate.PARAMETERS.req_natural_frequency_hz, force_plate.PARAMETERS.req_cop_error_m
    rmax = [float(x) for x in force_plate.PARAMETERS.req_calibration_rms]
    omax, smax = force_plate.PARAMETERS.req_orientation_error_deg, force_plate.PARAMETERS.req_sync_offset_s
    # (metric, line name, requirement, pass?, shown value, why the line is skipped although the metric exists)
    lines: list[tuple[str, str, str, Callable[[Any], bool], Callable[[Any], Any], Callable[[Any], str | None]]] = [
        (
            "rig.plate_natural_frequency",
            "plate natural frequency (Appendix 1)",
            f">= {fmin} Hz on every axis",
            lambda r: min(r.value) >= fmin,
            lambda r: [round(x, 1) for x in r.value],
            lambda r: None,
        ),
        (
            "rig.cop_error",
            "COP error (Appendix 2)",
            f"mean <= {cmax * 1000:.1f} mm (Kistler 9281B11)",
            lambda r: r.value <= cmax,
            lambda r: {"mean_mm": round(r.value * 1000, 2), "sd_mm": round((r.sd or 0.0) * 1000, 2), "n": r.n},
            lambda r: None,
        ),
        (
            "rig.handle_calibration_rms",
            "handle calibration RMS (§III-C)",
            f"<= {rmax} (N, m/s^2, N*m)",
            lambda r: all(v <= m for v, m in zip(r.value, rmax)),
            lambda r: [float(f"{x:.3g}") for x in r.value],
            lambda r: None,
        ),
        (
            "rig.handle_calibration_rms",
            "F/T sensor pose vs motion capture",
            f"<= {omax} deg RMS",
            lambda r: max(_orientation_errors(r)) <= omax,
            lambda r: round(max(_orientation_errors(r)), 2),
            lambda r: None if _orientation_errors(r) else "no usable handle_pose in the calibration trials",
        ),
        (
            "rig.sync_offset",
            "recorder synchronisation",
            f"|delay| <= {smax * 1000:.1f} ms",
            lambda r: r.value <= smax,
            lambda r: {
                "max_abs_ms": round(r.value * 1000, 2),
                **{tid: {k: round(v * 1000, 2) for k, v in d.items()} for tid, d in r.diagnostics["delays_s"].items()},
            },
            lambda r: None,
        ),
    ]
    checks = _range_checks(session_of(ctx), ctx)
    for mid, name, requirement, judge, show, skip in lines:
        res = results[mid]
        why = f"{res.code}: {res.reason}" if isinstance(res, Unavailable) else skip(res)
        checks.append(
            Check(name, "SKIP", None, requirement, why) if why else Check(name, _status(judge(res)), show(res), requirement)
        )
    return checks
