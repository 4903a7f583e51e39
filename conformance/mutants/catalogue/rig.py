"""Mutants of the rig checks (spec chapter 14) and of the handle calibration's fit and residuals (§6.2, §6.3):
COP error and sign, sync offset, the calibration fit and the impact spectrum."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable

import numpy as np

from haptify.metrics import rig_checks
from haptify.processing import calibration, force_plate
from haptify.processing.caching import session_of
from haptify_mutants.catalogue.model import Mutant, Patch, _parameters, _post


def _cop_kistler_sign(result: tuple, *_: Any) -> tuple:
    """Y = −M_x / F_z as printed in the paper (Kistler's z-down frame) instead of +M_x / F_z."""
    cop, valid = result
    cop = np.array(cop, copy=True)
    cop[:, 1] *= -1.0
    return cop, valid


def _signed_sync(result: Any, family_name: str, metric_id: str, values: Any, **kw: Any) -> Any:
    """rig.sync_offset as the largest SIGNED delay of each trial (a recorder that is early does not count); the rig
    family's aggregate is patched, the signed delays are in the record's diagnostics."""
    if metric_id != "rig.sync_offset":
        return result
    per_trial = [max(d.values()) for d in result.diagnostics["delays_s"].values()]
    return result.model_copy(update={"value": float(np.mean(per_trial)), "per_repetition": per_trial})


def _cop_rms(step: tuple) -> tuple:
    """rig.cop_error as the root mean square of the placements' errors instead of their mean."""
    per_trial, summarise = step

    def rms_summary(ctx: Any, metric_id: str, got: dict) -> Any:
        result = summarise(ctx, metric_id, got)
        errors = np.array([p.error for placements in got.values() for p in placements])
        return result.model_copy(update={"value": float(np.sqrt(np.mean(errors**2)))})

    return per_trial, rms_summary


def _fit_raw_samples(real: Callable) -> Callable:
    """The calibration spheres and torque fit on the raw samples at their native rates (no Fig. 3 low-pass and
    resampling)."""

    def fit_trial(ctx_or_session: Any, trial_id: str) -> Any:
        session = session_of(ctx_or_session)
        w = session.read(trial_id, "handle_wrench")[["fx", "fy", "fz", "tx", "ty", "tz"]].to_numpy()
        a = session.read(trial_id, "handle_accel")[["ax", "ay", "az"]].to_numpy()
        return calibration.fit_from_samples(w[:, :3], w[:, 3:], a, source=f"trial:{trial_id}")

    return fit_trial


def _hann_impact(real: Callable) -> Callable:
    """A Hann taper over the impact window before the FFT."""

    def dominant_frequency(x: np.ndarray, rate_hz: float, band_hz: Any = None) -> float:
        x = np.asarray(x, dtype=float)
        return real((x - x.mean()) * np.hanning(len(x)), rate_hz, band_hz)

    return dominant_frequency


MUTANTS: tuple[Mutant, ...] = (
    # rig
    Mutant(
        "cop_error_rms",
        "14.5",
        "R14.5-1",
        "rig.cop_error is the MEAN distance over all placements",
        "their root mean square",
        (Patch(rig_checks.METRIC_STEPS, "rig.cop_error", _cop_rms),),
        ("rig.cop_error",),
    ),
    Mutant(
        "cop_kistler_sign",
        "14.3",
        "R14.3-1",
        "Y = +M_x / F_z in the z-up plate frame",
        "Y = −M_x / F_z as the paper prints it",
        (Patch(force_plate, "center_of_pressure", _post(_cop_kistler_sign)),),
        ("rig.cop_error",),
    ),
    Mutant(
        "sync_offset_signed_max",
        "14.6",
        "R14.6-1",
        "rig.sync_offset is the largest |delay| of the two recorders",
        "the largest signed delay",
        (Patch(rig_checks, "aggregate", _post(_signed_sync)),),
        ("rig.sync_offset",),
    ),
    Mutant(
        "calibration_fit_on_raw_samples",
        "6.2",
        "R6.2-1",
        "the calibration fits use the low-passed samples resampled to 100 Hz",
        "the raw samples at their native rates",
        (Patch(calibration, "fit_trial", _fit_raw_samples),),
        ("rig.handle_calibration_rms",),
    ),
    Mutant(
        "offset_u_is_fit_rms",
        "6.2",
        "R6.2-2",
        "the offset uncertainty is the fitted bias and weight's batch-means standard uncertainty",
        "the force fit's per-sample RMS",
        (
            Patch(
                calibration, "fit_from_samples", _post(lambda cal, *_: dataclasses.replace(cal, force_offset_u_N=cal.rms_force_N))
            ),
        ),
        ("rig.handle_force_offset_u",),
    ),
    Mutant(
        "torque_rms_per_vector",
        "6.3",
        "R6.3-1",
        "torque fit RMS = √(Σ|e_i|² / 3N) (per component)",
        "√(Σ|e_i|² / N) (per vector)",
        (Patch(calibration, "fit_torque", _post(lambda r, *_: (r[0], r[1], r[2] * math.sqrt(3)))),),
        ("rig.handle_calibration_rms",),
    ),
    Mutant(
        "impact_hann_taper",
        "14.4",
        "R14.4-1",
        "no taper over the impact window",
        "a Hann taper",
        (Patch(force_plate, "dominant_frequency", _hann_impact),),
        ("rig.plate_natural_frequency",),
    ),
    Mutant(
        "impact_not_zero_padded",
        "14.4",
        "R14.4-1",
        "the window is zero-padded to ≥ 8× its length",
        "only to the next power of two",
        (Patch(force_plate, "PARAMETERS", _parameters(zero_pad_factor=1)),),
        ("rig.plate_natural_frequency",),
    ),
)
