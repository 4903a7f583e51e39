"""Known-bad implementations: the reference with ONE realistic mistake each (spec chapter 16, issue 6).

Each function has the ``--python`` signature ``(session, metric, parameters) -> dict`` and runs the
reference (:func:`haptify_conform.reference.analyse`, uncached) while one piece of it is replaced, the
replacement scoped to the call (``unittest.mock.patch`` restores it afterwards). ``BREAKS`` names, per
function, the metric whose cases must catch the mistake; ``tests/test_conformance_suite.py`` runs the
suite against each one and checks that a case of that metric fails.

    haptify-conform --python conform_impls.bad_impls:single_pass_filter    (with tests/ on PYTHONPATH)
"""

from __future__ import annotations

import dataclasses
import math
from contextlib import ExitStack
from typing import Any, Callable
from unittest import mock

import numpy as np
from scipy.signal import sosfilt
from scipy.spatial import ConvexHull

from haptify import (calibration, free_space, local_dynamics, repetitions, rig_checks, signals, stiffness, storage,
                     surface, vibration, workspace)
from haptify_conform import reference

# --- the mistakes --------------------------------------------------------------------------------


def _one_pass(sos: np.ndarray, x: np.ndarray, axis: int = -1, **_: Any) -> np.ndarray:
    """A causal, single-pass filter where the spec (§7.2, §10.2) runs it forward and backward."""
    return sosfilt(sos, x, axis=axis)


def _magnitude_spectrum(a: np.ndarray, rate_hz: float):
    """Magnitude weights |A_k| instead of the power |A_k|² (the other spectral-centroid convention)."""
    f, p = _REAL["power_spectrum"](a, rate_hz)
    return f, np.sqrt(p)


def _hull_solid(points: np.ndarray, **kw: Any):
    """The convex hull's volume instead of the spec's voxel operator (§8.4): the solid's fractions are
    scaled so that its volume is the hull's."""
    solid = _REAL["volume_solid"](points, **kw)
    hull = ConvexHull(np.asarray(points, float)).volume
    return dataclasses.replace(solid, fraction=solid.fraction * (hull / solid.volume))


def _weight_kept(raw, q_handle, cal, pose):
    """The connector's weight is not removed (only the bias is)."""
    return _REAL["compensate_wrench"](raw, q_handle, dataclasses.replace(cal, connector_mass_kg=0.0), pose)


def _flipped_sign(raw, q_handle, cal, pose):
    """The force the hand applies to the device instead of the force on the hand (§6.5 sign)."""
    force, torque = _REAL["compensate_wrench"](raw, q_handle, cal, pose)
    return -force, -torque


def _degrees(ctx, trial_id):
    """Angular speed reported in deg/s under the unit rad/s."""
    out = _REAL["_speed_summary"](ctx, trial_id)
    return {**out, "angular": out["angular"] * 180.0 / math.pi}


def _millimetres(self, trial_id, kind, **kw):
    """Motion-capture positions taken for millimetres and divided by 1000."""
    table = _REAL["read"](self, trial_id, kind, **kw)
    if kind in ("handle_pose", "markers"):
        table = table.copy()
        cols = [c for c in table.columns if c in ("px", "py", "pz") or c.endswith(("_x", "_y", "_z"))]
        table[cols] = table[cols] / 1000.0
    return table


def _bridge_everything(t, position, quaternion, max_gap_s=None):
    """Every occlusion gap interpolated across, however long (§7.4 bridges only gaps ≤ max_gap_s)."""
    return _REAL["bridge_gaps"](t, position, quaternion, max_gap_s=math.inf)


def _no_hemisphere(u, hemi):
    """The quaternion hemisphere rule of §11.3 step 1 ignored."""
    return np.array(u, dtype=float, copy=True)


def _summed_axes(x: np.ndarray) -> np.ndarray:
    """The three axes added sample by sample where the spec (§10.3) combines them with DFT321."""
    return np.asarray(x, dtype=float).sum(axis=1)


def _vector_magnitude(x: np.ndarray) -> np.ndarray:
    """The per-sample vector magnitude √(x² + y² + z²) where the spec (§10.3) combines the axes with DFT321."""
    return np.linalg.norm(np.asarray(x, dtype=float), axis=1)


def _median_aggregate(family_name, metric_id, values, **kw):
    """The median of the per-repetition values where the spec (§15.3) reports their mean."""
    result = _REAL["aggregate"](family_name, metric_id, values, **kw)
    if getattr(result, "per_repetition", None):
        result.value = float(np.median(result.per_repetition))
    return result


_REAL: dict[str, Callable] = {
    "aggregate": repetitions.aggregate,
    "power_spectrum": vibration.power_spectrum, "volume_solid": workspace.volume_solid,
    "compensate_wrench": calibration.compensate_wrench, "_speed_summary": free_space._speed_summary,
    "read": storage.SessionFolder.read, "bridge_gaps": signals.bridge_gaps,
}


def _run(patches: list[tuple[Any, str, Any]], session: str, metric: str, parameters: dict) -> dict:
    with ExitStack() as stack:
        for owner, name, new in patches:
            stack.enter_context(mock.patch.object(owner, name, new))
        return reference.analyse(session, metric, parameters, cache=False)


# --- the implementations (--python targets) ---------------------------------------------------------

def single_pass_filter(session: str, metric: str, parameters: dict) -> dict:
    return _run([(vibration, "sosfiltfilt", _one_pass), (signals, "sosfiltfilt", _one_pass)], session, metric, parameters)


def magnitude_centroid(session: str, metric: str, parameters: dict) -> dict:
    return _run([(vibration, "power_spectrum", _magnitude_spectrum)], session, metric, parameters)


def convex_hull(session: str, metric: str, parameters: dict) -> dict:
    return _run([(workspace, "volume_solid", _hull_solid)], session, metric, parameters)


def connector_weight_kept(session: str, metric: str, parameters: dict) -> dict:
    return _run([(calibration, "compensate_wrench", _weight_kept)], session, metric, parameters)


def degrees_for_radians(session: str, metric: str, parameters: dict) -> dict:
    return _run([(free_space, "_speed_summary", _degrees)], session, metric, parameters)


def opposite_force_sign(session: str, metric: str, parameters: dict) -> dict:
    return _run([(calibration, "compensate_wrench", _flipped_sign)], session, metric, parameters)


def mm_for_m(session: str, metric: str, parameters: dict) -> dict:
    return _run([(storage.SessionFolder, "read", _millimetres)], session, metric, parameters)


def gaps_interpolated(session: str, metric: str, parameters: dict) -> dict:
    return _run([(signals, "bridge_gaps", _bridge_everything)], session, metric, parameters)


def hemisphere_ignored(session: str, metric: str, parameters: dict) -> dict:
    return _run([(local_dynamics, "hemisphere_align", _no_hemisphere)], session, metric, parameters)


def axes_summed(session: str, metric: str, parameters: dict) -> dict:
    return _run([(vibration, "dft321", _summed_axes)], session, metric, parameters)


def vector_magnitude(session: str, metric: str, parameters: dict) -> dict:
    return _run([(vibration, "dft321", _vector_magnitude)], session, metric, parameters)


def median_of_repetitions(session: str, metric: str, parameters: dict) -> dict:
    families = (free_space, rig_checks, stiffness, surface, vibration, workspace)
    return _run([(m, "aggregate", _median_aggregate) for m in families], session, metric, parameters)


# function name → the metric whose cases must catch its mistake
BREAKS: dict[str, str] = {
    "single_pass_filter": "vibration.rms",
    "magnitude_centroid": "vibration.spectral_centroid",
    "convex_hull": "workspace.measured_volume",
    "connector_weight_kept": "free_space.force_mean",
    "degrees_for_radians": "free_space.angular_speed_mean",
    "opposite_force_sign": "stiffness.measured",
    "mm_for_m": "free_space.speed_mean",
    "gaps_interpolated": "free_space.speed_mean",
    "hemisphere_ignored": "dynamics.error_vs_distance",
    "median_of_repetitions": "vibration.rms",
    "axes_summed": "vibration.rms",
    "vector_magnitude": "vibration.spectral_centroid",
}
