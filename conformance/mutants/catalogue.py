"""The mutant set: the reference with ONE realistic mistake each (spec §16.8.3).

Each :class:`Mutant` is a choice a lab engineer could plausibly make while reading the spec — averaging
where the spec says something else, another filter, another frame, another unit — written as one or more
:class:`Patch` es that replace a piece of the reference (``haptify.*``) for the duration of a run
(``unittest.mock``; nothing is changed on disk). Every mutant names the spec section it violates, the rule
in one line, the wrong reading in one line, and the metric(s) whose cases are expected to catch it.

A mutant is an implementation in the sense of spec §16.4.3::

    haptify-conform --python haptify_mutants.catalogue:hann_window_centroid

``make mutants`` (:mod:`haptify_mutants.run`) runs the whole suite against every mutant; ``make test`` runs
the ``cheap`` ones against the cases of the metrics they break (``tests/test_conformance_suite.py``).
Mistakes whose outcome no metric can see (e.g. the phase DFT321 gives the combined signal: RMS and centroid
depend on magnitudes only) are not mutants: nothing could catch them and nothing depends on them.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Iterator
from unittest import mock

import numpy as np
from scipy import ndimage
from scipy.signal import butter, cheby1, sosfilt, sosfiltfilt
from scipy.spatial import ConvexHull

from haptify import (
    calibration,
    force_plate,
    free_space,
    preprocessing,
    repetitions,
    rig_checks,
    stiffness,
    storage,
    surface,
    uncertainty,
    vibration,
    workspace,
)
from haptify.caching import session_of
from haptify.local_dynamics import distance as ld_distance
from haptify.local_dynamics import fitting as ld_fitting
from haptify.local_dynamics import metrics as ld_metrics
from haptify.local_dynamics import prediction as ld_prediction
from haptify.local_dynamics import trials as ld_trials
from haptify.conventions import STANDARD_GRAVITY, quat_conjugate, quat_rotate
from haptify import conform_adapter as reference

Make = Callable[[Any], Any]  # the real object → its replacement


@dataclass(frozen=True)
class Patch:
    """Replace ``owner.name`` (or the item ``owner[name]`` of a dict such as a dispatch table) by ``make(real)``
    while a mutant is applied.

    With ``everywhere`` the replacement also goes into every ``haptify`` module that bound the same object
    by name (``from haptify.preprocessing import lowpass_resample``), so the whole reference sees one mistake.
    """

    owner: Any
    name: str
    make: Make
    everywhere: bool = False

    def real(self) -> Any:
        """The object replaced (looked up before anything is patched)."""
        return self.owner[self.name] if isinstance(self.owner, dict) else getattr(self.owner, self.name)

    def targets(self) -> list[Any]:
        """The objects whose attribute ``name`` is replaced (looked up before anything is patched)."""
        if not self.everywhere:
            return [self.owner]
        real = self.real()
        loaded = [m for n, m in sorted(sys.modules.items()) if n == "haptify" or n.startswith("haptify.")]
        return [self.owner] + [m for m in loaded if m is not self.owner and getattr(m, self.name, None) is real]

    def patchers(self) -> list[Any]:
        """The ``unittest.mock`` patchers that apply it."""
        new = self.make(self.real())
        if isinstance(self.owner, dict):
            return [mock.patch.dict(self.owner, {self.name: new})]
        return [mock.patch.object(target, self.name, new) for target in self.targets()]


@dataclass(frozen=True)
class Mutant:
    """One wrong variant of the reference: what it violates, how it reads the spec, how it is patched in.

    ``section``: the spec section whose rule it breaks; ``requirement``: the id of that rule
    (``schemas/<v>/requirements.json``, spec §16.7); ``metrics``: the metric ids whose cases are
    expected to catch it; ``cheap``: part of the fast subset run by ``make test``.
    """

    name: str
    section: str
    requirement: str
    rule: str
    wrong: str
    patches: tuple[Patch, ...]
    metrics: tuple[str, ...]
    cheap: bool = False

    @contextmanager
    def applied(self) -> Iterator[None]:
        """The reference with this mistake, for the duration of the ``with`` block."""
        with ExitStack() as stack:
            for patcher in [q for p in self.patches for q in p.patchers()]:
                stack.enter_context(patcher)
            yield

    def analyse(self, session: str, metric: str = "", parameters: dict | None = None) -> dict:
        """The ``--python`` entry point (spec §16.4.3): the reference's answer with the mistake, computed afresh."""
        with self.applied():
            return reference.analyse(session, metric, parameters, cache=False)


def _rmse_of_magnitude(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """Per column block of three (force, torque) the RMS of the error vector's magnitude, for each of its axes."""
    d = np.asarray(y, dtype=float) - np.asarray(yhat, dtype=float)
    out = np.sqrt(np.mean(d * d, axis=0))
    for start in range(0, d.shape[1] - 2, 3):
        out[start : start + 3] = np.sqrt(np.mean(np.sum(d[:, start : start + 3] ** 2, axis=1)))
    return out


# --- building blocks -------------------------------------------------------------------------------


def _replace(fn: Callable) -> Make:
    """A replacement that ignores the real object."""
    return lambda real: fn


def _params(**values: Any) -> Make:
    """A family's parameter accessor (``vp(key)``, ``param(family, key)``) with some keys answered otherwise."""

    def make(real: Callable) -> Callable:
        def accessor(*args: Any) -> Any:
            return values[args[-1]] if args[-1] in values else real(*args)

        return accessor

    return make


def _post(fn: Callable) -> Make:
    """The real function, its result passed through ``fn(result, *args)`` (positional arguments only)."""

    def make(real: Callable) -> Callable:
        def wrapped(*args: Any, **kw: Any) -> Any:
            return fn(real(*args, **kw), *args)

        return wrapped

    return make


# --- aggregation over repetitions (spec §15.3) -------------------------------------------------------


def _aggregate_by(pick: Callable[[list[float]], float]) -> tuple[Patch, ...]:
    """Every family's repetition aggregate reports ``pick(per_repetition)`` instead of the mean."""

    def make(real: Callable) -> Callable:
        def aggregate(family_name: str, metric_id: str, values: Any, **kw: Any) -> Any:
            result = real(family_name, metric_id, values, **kw)
            if getattr(result, "per_repetition", None):
                result.value = float(pick(result.per_repetition))
            return result

        return aggregate

    return (Patch(repetitions, "aggregate", make, everywhere=True),)


# --- vibration: axes, filter, window (spec chapter 10) ------------------------------------------------


def _summed_axes(x: np.ndarray) -> np.ndarray:
    """x + y + z sample by sample."""
    return np.asarray(x, dtype=float).sum(axis=1)


def _vector_magnitude(x: np.ndarray) -> np.ndarray:
    """√(x² + y² + z²) sample by sample."""
    return np.linalg.norm(np.asarray(x, dtype=float), axis=1)


def _z_axis(x: np.ndarray) -> np.ndarray:
    """The accelerometer's z axis alone."""
    return np.asarray(x, dtype=float)[:, 2]


def _loudest_axis(x: np.ndarray) -> np.ndarray:
    """The axis with the largest RMS alone."""
    x = np.asarray(x, dtype=float)
    return x[:, int(np.argmax(np.mean(x * x, axis=0)))]


def _one_pass(sos: np.ndarray, x: np.ndarray, axis: int = -1, **_: Any) -> np.ndarray:
    """A causal single pass where the spec runs the filter forward and backward."""
    return sosfilt(sos, x, axis=axis)


def _butter_order_halved(real: Callable) -> Callable:
    """Butterworth of half the order, so that the forward-backward pair has the stated order."""
    return lambda order, wn, *a, **k: real(max(1, order // 2), wn, *a, **k)


def _butter_rad_per_s(real: Callable) -> Callable:
    """The cut-off taken for an angular frequency (rad/s) and divided by 2π."""
    return lambda order, wn, *a, **k: real(order, wn / (2.0 * math.pi), *a, **k)


def _chebyshev(real: Callable) -> Callable:
    """A Chebyshev type I design (0.5 dB ripple) of the same order and cut-off."""
    return lambda order, wn, *a, **k: cheby1(order, 0.5, wn, *a, **k)


def _hann_spectrum(real: Callable) -> Callable:
    """A Hann window applied before the periodogram (as Welch-type estimators do)."""

    def power_spectrum(a: np.ndarray, rate_hz: float) -> Any:
        a = np.asarray(a, dtype=float)
        return real(a * np.hanning(len(a)), rate_hz)

    return power_spectrum


def _magnitude_spectrum(real: Callable) -> Callable:
    """|A_k| instead of |A_k|² as the centroid's weight (librosa's convention)."""

    def power_spectrum(a: np.ndarray, rate_hz: float) -> Any:
        f, p = real(a, rate_hz)
        return f, np.sqrt(p)

    return power_spectrum


def _combine_then_trim(real: Callable) -> Callable:
    """DFT321 over the whole filtered signal; the edges are cut from the combined signal afterwards."""

    def combine(t: np.ndarray, accel: np.ndarray, trial_id: str = "") -> Any:
        out = real(t, accel, trial_id)
        whole = vibration.dft321(vibration.highpass(accel, preprocessing.nominal_rate(np.asarray(t, dtype=float))))
        trim = (len(t) - len(out.t)) // 2
        return dataclasses.replace(out, signal=whole[trim : trim + len(out.t)])

    return combine


def _trim_start_only(real: Callable) -> Callable:
    """edge_trim_s cut from the start only (the filter's start-up), the end kept."""

    def combine(t: np.ndarray, accel: np.ndarray, trial_id: str = "") -> Any:
        out = real(t, accel, trial_id)
        trim = (len(t) - len(out.t)) // 2
        kept = slice(trim, len(t))
        filtered = vibration.highpass(accel, preprocessing.nominal_rate(np.asarray(t, dtype=float)))
        return dataclasses.replace(out, t=np.asarray(t, dtype=float)[kept], signal=vibration.dft321(filtered[kept]))

    return combine


# --- resampling and low-pass filtering (spec chapter 7) ----------------------------------------------


def _lowpass_rad_per_s(real: Callable) -> Callable:
    """Every low-pass cut-off taken for rad/s and divided by 2π."""
    return lambda x, rate_hz, cutoff_hz, *, order=None: real(x, rate_hz, cutoff_hz / (2.0 * math.pi), order=order)


def _lowpass_ends_untreated(real: Callable) -> Callable:
    """Forward-backward Butterworth without §7.2's chord removal and odd padding (filter started at the
    first sample's value)."""

    def lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float, *, order: int | None = None) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if len(x) < 2:
            return x.copy()
        order = int(preprocessing.sp("filter_order")) if order is None else order
        sos = butter(order, preprocessing.effective_cutoff(cutoff_hz, rate_hz), fs=rate_hz, output="sos")
        return sosfiltfilt(sos, x, axis=0, padtype=None)

    return lowpass


def _resample_then_lowpass(real: Callable) -> Callable:
    """Interpolate the raw stream onto the grid first, then low-pass it there."""

    def lowpass_resample(t_src: np.ndarray, x_src: np.ndarray, t_dst: np.ndarray, cutoff_hz: float) -> np.ndarray:
        on_grid = preprocessing.interp_columns(t_src, x_src, t_dst)
        return preprocessing.lowpass(on_grid, preprocessing.nominal_rate(t_dst), cutoff_hz)

    return lowpass_resample


def _nearest_columns(t_src: np.ndarray, x_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Nearest-neighbour resampling (the sample nearest each grid time) instead of linear interpolation."""
    t_src = np.asarray(t_src, dtype=float)
    t_dst = np.asarray(t_dst, dtype=float)
    k = np.clip(np.searchsorted(t_src, t_dst), 1, len(t_src) - 1)
    k = k - ((t_dst - t_src[k - 1]) <= (t_src[k] - t_dst))
    return np.asarray(x_src, dtype=float)[k]


def _grid_on_clock_multiples(real: Callable) -> Callable:
    """The grid anchored at multiples of 1/rate on the session clock (pandas-style resampling)."""
    return lambda t0, t1, rate_hz: real(math.ceil(t0 * rate_hz - 1e-9) / rate_hz, t1, rate_hz)


# --- frames, signs and calibration (spec chapters 1, 6) ---------------------------------------------------


def _pose_table(transform: Callable[[Any], None], kinds: tuple[str, ...] = ("handle_pose",)) -> Make:
    """``SessionFolder.read`` with ``transform(table)`` applied (in place, on a copy) to streams of ``kinds``."""

    def make(real: Callable) -> Callable:
        def read(self: Any, trial_id: str, kind: str, **kw: Any) -> Any:
            table = real(self, trial_id, kind, **kw)
            if kind in kinds:
                table = table.copy()
                transform(table)
            return table

        return read

    return make


def _millimetres(table: Any) -> None:
    """Motion-capture positions taken for millimetres and divided by 1000."""
    cols = [c for c in table.columns if c in ("px", "py", "pz") or c.endswith(("_x", "_y", "_z"))]
    table[cols] = table[cols] / 1000.0


def _conjugated(table: Any) -> None:
    """Stored quaternions read as world → body (the passive convention)."""
    table[["qx", "qy", "qz"]] = -table[["qx", "qy", "qz"]]


def _scalar_last(table: Any) -> None:
    """The four quaternion columns read as x, y, z, w (scipy / ROS order) instead of w, x, y, z."""
    q = table[["qw", "qx", "qy", "qz"]].to_numpy()
    table[["qw", "qx", "qy", "qz"]] = q[:, [3, 0, 1, 2]]


def _with_calibration(**changes: Callable[[Any], Any]) -> Make:
    """``compensate_wrench``/``compensate_accel`` with calibration fields replaced (``field=lambda cal: value``)."""

    def make(real: Callable) -> Callable:
        def compensate(raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> Any:
            return real(raw, q_handle, dataclasses.replace(cal, **{k: f(cal) for k, f in changes.items()}), pose)

        return compensate

    return make


def _wrench_inverse_rotation(result: tuple, raw: np.ndarray, q_handle: np.ndarray, *_: Any) -> tuple:
    """F_W = R_WHᵀ F_H: the handle orientation applied inverted (world → body)."""
    conj = quat_conjugate(q_handle)
    return tuple(quat_rotate(conj, quat_rotate(conj, v)) for v in result)


def _torque_about_sensor(result: tuple, raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> tuple:
    """The torque left about the sensor origin (the p_S × F_H term of §6.5 omitted)."""
    force, torque = result
    return force, torque - np.cross(quat_rotate(q_handle, np.asarray(pose.position, dtype=float)), force)


def _sensor_rotation_inverted(real: Callable) -> Callable:
    """The F/T sensor's rig quaternion read as the pose of H in S (R_SH) instead of S in H."""

    def compensate_wrench(raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> tuple:
        inverted = pose.model_copy(update={"quaternion": [float(v) for v in quat_conjugate(np.asarray(pose.quaternion))]})
        return real(raw, q_handle, cal, inverted)

    return compensate_wrench


def _accel_in_handle_frame(real: Callable) -> Callable:
    """R_HA (a − b_a) − g: the acceleration never rotated into W."""

    def compensate_accel(raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> np.ndarray:
        identity = np.tile([1.0, 0.0, 0.0, 0.0], (len(np.asarray(q_handle)), 1))
        return real(raw, identity, cal, pose)

    return compensate_accel


def _gravity_added_back(g: Callable[[Any], float]) -> Make:
    """``compensate_accel`` with ``g(cal)`` added to the vertical component of its result."""

    def post(a: np.ndarray, raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> np.ndarray:
        a = np.array(a, copy=True)
        a[:, 2] += g(cal)
        return a

    return _post(post)


# --- motion capture (spec §7.4) ----------------------------------------------------------------------------


def _raw_derivative(which: str) -> Make:
    """``process_mocap`` whose velocity (or angular velocity) is differentiated without the §7.4 low-pass."""

    def make(real: Callable) -> Callable:
        def process_mocap(t: np.ndarray, position: np.ndarray, quaternion: np.ndarray) -> Any:
            track = real(t, position, quaternion)
            t = np.asarray(t, dtype=float)
            raw, _, _ = preprocessing.bridge_gaps(t, position, quaternion)
            out = np.array(getattr(track, which), copy=True)
            for k in range(int(track.segment.max()) + 1 if len(t) else 0):
                m = np.flatnonzero(track.segment == k)
                out[m] = (
                    np.gradient(raw[m], t[m], axis=0)
                    if which == "velocity"
                    else preprocessing.angular_velocity(t[m], track.quaternion[m])
                )
            return dataclasses.replace(track, **{which: out})

        return process_mocap

    return make


def _population_sd(stats: dict, values: np.ndarray, *_: Any) -> dict:
    """The standard deviation with ddof = 0 (numpy's default) where the spec says ddof = 1."""
    n = len(values)
    return {**stats, "sd": stats["sd"] * math.sqrt((n - 1) / n)}


def _first_record(real: Callable) -> Callable:
    """The FIRST handle_gravity record in manifest order applies (the last one is the spec's)."""

    def handle_calibration(ctx_or_session: Any) -> Any:
        session = session_of(ctx_or_session)
        records = [c for c in session.manifest.calibration if c.kind == "handle_gravity"]
        return calibration.HandleCalibration.from_record(records[0]) if records else real(ctx_or_session)

    return handle_calibration


def _gap_limit_strict(real: Callable) -> Callable:
    """Gaps bridged only when t_j − t_i ≤ max_gap_s (the sample interval Δ of §7.4 left out)."""

    def bridge_gaps(t: np.ndarray, position: np.ndarray, quaternion: np.ndarray, max_gap_s: float | None = None) -> Any:
        limit = float(preprocessing.sp("max_gap_s") if max_gap_s is None else max_gap_s)
        return real(t, position, quaternion, max_gap_s=limit - float(np.median(np.diff(np.asarray(t, dtype=float)))))

    return bridge_gaps


# --- surface contact (spec chapter 12) ------------------------------------------------------------------


def _contact_unguarded(cs: Any, *_: Any) -> Any:
    """Every contact sample used: the §12.2 guard around contact transitions left out."""
    return dataclasses.replace(cs, used=cs.contact & cs.valid)


def _contact_from_measured(cs: Any, *_: Any) -> Any:
    """Contact decided from the measured normal force F·n instead of the commanded one."""
    with np.errstate(invalid="ignore"):
        touching = surface.contact_of(np.nan_to_num(cs.normal_force, nan=-np.inf))
    return dataclasses.replace(cs, contact=touching & cs.valid, used=surface.guarded(cs.t, touching, cs.t) & cs.valid)


# --- workspace (spec chapter 8) ---------------------------------------------------------------------------


def _hull_solid(real: Callable) -> Callable:
    """The convex hull's volume instead of the §8.4 voxel operator (the solid scaled to the hull)."""

    def volume_solid(points: np.ndarray, **kw: Any) -> Any:
        solid = real(points, **kw)
        hull = ConvexHull(np.asarray(points, dtype=float)).volume
        return dataclasses.replace(solid, fraction=solid.fraction * (hull / solid.volume))

    return volume_solid


def _placement_inverted(real: Callable) -> Callable:
    """device_placement applied inverted (read as the pose of W in the device frame)."""

    def modeled_solid(
        kin: Any, placement_position: Any = (0.0, 0.0, 0.0), placement_quaternion: Any = (1.0, 0.0, 0.0, 0.0)
    ) -> Any:
        conj = quat_conjugate(np.asarray(placement_quaternion, dtype=float))
        return real(kin, -quat_rotate(conj, np.asarray(placement_position, dtype=float)), conj)

    return modeled_solid


# --- rig (spec chapter 14) --------------------------------------------------------------------------------


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


# --- local dynamics (spec chapter 11) ------------------------------------------------------------------------


def _scales(theta: Callable[[float], float]) -> Make:
    """``DistanceScales.from_definition`` with R_θ replaced by ``theta(R_θ in rad)``."""
    return lambda real: staticmethod(lambda: dataclasses.replace(real(), theta=theta(real().theta)))


def _angle_not_doubled(real: Callable) -> Callable:
    """θ_ab = arccos|q̄_a·q̄_b| (the half angle) instead of 2 arccos|q̄_a·q̄_b|."""

    def pair_distance(a: Any, b: Any, scales: Any) -> np.ndarray:
        half = np.arccos(np.clip(np.abs(a.orientation @ b.orientation.T), 0.0, 1.0))
        return real(a, b, scales) - half / scales.theta

    return pair_distance


def _euclidean_terms(real: Callable) -> Callable:
    """Δ as the Euclidean norm of the four normalised differences instead of their sum."""

    def pair_distance(a: Any, b: Any, scales: Any) -> np.ndarray:
        inf = math.inf
        alone = [
            dataclasses.replace(scales, **{k: inf for k in ("p", "v", "a", "theta") if k != keep})
            for keep in ("p", "v", "a", "theta")
        ]
        return np.sqrt(sum(real(a, b, s) ** 2 for s in alone))

    return pair_distance


def _mean_to_training(test: Any, train: Any, scales: Any, chunk: int = 512) -> np.ndarray:
    """A test window's distance to the training set as the mean over training windows, not the minimum."""
    return ld_distance.pair_distance(test, train, scales).mean(axis=1)


def _vector_rms_errors(force: np.ndarray, predicted: np.ndarray, segment_samples: int) -> np.ndarray:
    """A segment's force error as the RMS of the error vector's norm, not the mean of per-axis RMS errors."""
    n_seg = len(force) // segment_samples
    d = (np.asarray(force, dtype=float) - np.asarray(predicted, dtype=float))[: n_seg * segment_samples]
    return np.sqrt(np.mean(np.sum(d.reshape(n_seg, segment_samples, -1) ** 2, axis=2), axis=1))


def _clamped_map(breakpoints: np.ndarray, values: np.ndarray, u: np.ndarray) -> np.ndarray:
    """A piecewise-linear map held constant beyond its end breakpoints (``numpy.interp``)."""
    return np.interp(u, breakpoints, values)


def _denominator_sign(real: Callable) -> Callable:
    """F(q) = 1 − f_1 q⁻¹ − … (the autoregressive sign convention) instead of 1 + f_1 q⁻¹ + …."""

    def lfilter(b: Any, a: Any, x: Any, *args: Any, **kw: Any) -> Any:
        a = np.asarray(a, dtype=float)
        return real(b, np.concatenate([a[:1], -a[1:]]), x, *args, **kw)

    return lfilter


def _delays_ignored(real: Callable) -> Callable:
    """Every block's input delay nk taken as 0."""

    def predict(model: Any, u: np.ndarray) -> np.ndarray:
        rows = [[tf.model_copy(update={"nk": 0}) for tf in row] for row in model.linear]
        return real(model.model_copy(update={"linear": rows}), u)

    return predict


def _test_segments_only(rows: list, *_: Any) -> list:
    """The error-vs-distance line fitted through the test segments only."""
    return [r for r in rows if r["set"] != "training"]


# --- stiffness (spec chapter 13) ------------------------------------------------------------------------------


def _through_origin(fit: Any, *_: Any) -> Any:
    """f = k·d without an intercept."""
    x, y = fit.penetration, fit.normal_force
    return dataclasses.replace(fit, stiffness=float(x @ y / (x @ x)), intercept=0.0)


# --- uncertainty (spec chapter 19) ---------------------------------------------------------------------------


def _sd_as_type_a(real: Callable) -> Callable:
    """Type A = the sample standard deviation itself, not that of the mean."""

    def type_a(per_repetition: Any) -> Any:
        u, dof = real(per_repetition)
        return u * math.sqrt(len(per_repetition)), dof

    return type_a


def _normal_coverage(real: Callable) -> Callable:
    """k from the normal distribution whatever the degrees of freedom."""
    return lambda dof, p: real(math.inf, p)


# --- the set -----------------------------------------------------------------------------------------------------


MUTANTS: tuple[Mutant, ...] = (
    # aggregation over repetitions
    Mutant(
        "median_of_repetitions",
        "15.3",
        "R15.3-1",
        "a metric's value is the arithmetic mean of its per-repetition values",
        "the median of the repetitions (robust to an outlying repetition)",
        _aggregate_by(np.median),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    Mutant(
        "first_repetition_only",
        "15.3",
        "R15.3-1",
        "a metric's value is the arithmetic mean of its per-repetition values",
        "the first repetition's value (the others taken for retries)",
        _aggregate_by(lambda v: v[0]),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    Mutant(
        "last_repetition_only",
        "15.3",
        "R15.3-1",
        "a metric's value is the arithmetic mean of its per-repetition values",
        "the last repetition's value (as §6.4 takes the most recent calibration)",
        _aggregate_by(lambda v: v[-1]),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    Mutant(
        "quadratic_mean_of_repetitions",
        "15.3",
        "R15.3-1",
        "a metric's value is the arithmetic mean of its per-repetition values",
        "the root mean square of the per-repetition values (pooling their energy)",
        _aggregate_by(lambda v: math.sqrt(float(np.mean(np.square(v))))),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "sd_ddof_0",
        "9.2",
        "R9.2-1",
        "force_sd and planar_force_sd are sample standard deviations (ddof = 1)",
        "numpy's default ddof = 0",
        (Patch(free_space, "magnitude_stats", _post(_population_sd)), Patch(surface, "planar_stats", _post(_population_sd))),
        ("free_space.force_sd",),
        cheap=True,
    ),
    # vibration: axis combination
    Mutant(
        "axes_summed",
        "10.3",
        "R10.3-1",
        "the three axes are combined by DFT321",
        "the axes added sample by sample",
        (Patch(vibration, "dft321", _replace(_summed_axes)),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "vector_magnitude",
        "10.3",
        "R10.3-1",
        "the three axes are combined by DFT321",
        "the per-sample vector magnitude √(x² + y² + z²)",
        (Patch(vibration, "dft321", _replace(_vector_magnitude)),),
        ("vibration.spectral_centroid",),
        cheap=True,
    ),
    Mutant(
        "single_axis_z",
        "10.3",
        "R10.3-1",
        "the three axes are combined by DFT321",
        "only the accelerometer's z axis is analysed",
        (Patch(vibration, "dft321", _replace(_z_axis)),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "loudest_axis",
        "10.3",
        "R10.3-1",
        "the three axes are combined by DFT321",
        "only the axis with the largest RMS is analysed",
        (Patch(vibration, "dft321", _replace(_loudest_axis)),),
        ("vibration.rms",),
        cheap=True,
    ),
    # vibration: filter
    Mutant(
        "single_pass_filter",
        "7.2",
        "R7.2-1",
        "every filter runs forward and backward (zero phase)",
        "a causal single pass (sosfilt)",
        (Patch(vibration, "sosfiltfilt", _replace(_one_pass)), Patch(preprocessing, "sosfiltfilt", _replace(_one_pass))),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "highpass_order_halved",
        "10.2",
        "R10.2-1",
        "a Butterworth of highpass_order = 4, run forward and backward",
        "order 2, so that the forward-backward pair has order 4",
        (Patch(vibration, "butter", _butter_order_halved),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "highpass_cutoff_rad_per_s",
        "10.2",
        "R10.2-1",
        "the high-pass cut-off is 10 Hz",
        "10 read as rad/s: a 1.6 Hz cut-off",
        (Patch(vibration, "butter", _butter_rad_per_s),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "chebyshev_highpass",
        "10.2",
        "R10.2-1",
        "the high-pass is a Butterworth design",
        "a Chebyshev type I design (0.5 dB ripple) of the same order",
        (Patch(vibration, "butter", _chebyshev),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "edge_trim_off",
        "10.2",
        "R10.2-2",
        "edge_trim_s = 0.5 s is cut from each end after filtering",
        "the whole filtered signal is analysed",
        (Patch(vibration, "vp", _params(edge_trim_s=0.0)),),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    Mutant(
        "edge_trim_start_only",
        "10.2",
        "R10.2-2",
        "edge_trim_s is cut from EACH end",
        "only from the start (the filter's start-up)",
        (Patch(vibration, "combine", _trim_start_only),),
        ("vibration.rms",),
        cheap=True,
    ),
    Mutant(
        "dft321_before_trim",
        "10.2",
        "R10.2-2",
        "the filtered axes are trimmed, then combined by DFT321",
        "DFT321 over the whole filtered signal, trimmed afterwards",
        (Patch(vibration, "combine", _combine_then_trim),),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    # vibration: spectral weighting
    Mutant(
        "magnitude_centroid",
        "10.5",
        "R10.5-1",
        "the centroid weights frequencies by power |A_k|²",
        "by magnitude |A_k| (librosa)",
        (Patch(vibration, "power_spectrum", _magnitude_spectrum),),
        ("vibration.spectral_centroid",),
        cheap=True,
    ),
    Mutant(
        "hann_window_centroid",
        "10.5",
        "R10.5-1",
        "the periodogram uses a rectangular window",
        "a Hann window before the DFT",
        (Patch(vibration, "power_spectrum", _hann_spectrum),),
        ("vibration.spectral_centroid",),
        cheap=True,
    ),
    # low-pass filtering and resampling
    Mutant(
        "lowpass_cutoff_rad_per_s",
        "7.2",
        "R7.2-1",
        "low-pass cut-offs are in Hz (wrench 20 Hz, mocap 10 Hz)",
        "read as rad/s and divided by 2π",
        (Patch(preprocessing, "lowpass", _lowpass_rad_per_s, everywhere=True),),
        ("surface.planar_force_sd", "free_space.speed_mean"),
        cheap=True,
    ),
    Mutant(
        "filter_ends_untreated",
        "7.2",
        "R7.2-1",
        "the chord is removed and the ends odd-padded before filtering",
        "sosfiltfilt without padding, started from the first sample",
        (Patch(preprocessing, "lowpass", _lowpass_ends_untreated, everywhere=True),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "sensor_streams_unfiltered",
        "7.5",
        "R7.5-1",
        "raw F/T and accelerometer streams are low-passed before resampling",
        "they are interpolated onto the grid as recorded",
        (
            Patch(
                preprocessing,
                "lowpass_resample",
                _replace(lambda t_src, x_src, t_dst, cutoff_hz: preprocessing.interp_columns(t_src, x_src, t_dst)),
                everywhere=True,
            ),
        ),
        ("free_space.force_max",),
        cheap=True,
    ),
    Mutant(
        "lowpass_after_resampling",
        "7.5",
        "R7.5-1",
        "raw streams are low-passed at their native rate, then interpolated",
        "interpolated onto the grid first, then low-passed at the grid rate",
        (Patch(preprocessing, "lowpass_resample", _resample_then_lowpass, everywhere=True),),
        ("free_space.force_max",),
        cheap=True,
    ),
    Mutant(
        "nearest_resampling",
        "7.2",
        "R7.2-2",
        "values between samples are interpolated linearly",
        "the nearest sample is taken",
        (Patch(preprocessing, "interp_columns", _replace(_nearest_columns), everywhere=True),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "grid_on_clock_multiples",
        "7.3",
        "R7.3-1",
        "the grid starts at the latest first sample of the trial's streams",
        "the grid is anchored at multiples of 1/rate on the session clock",
        (Patch(preprocessing, "uniform_grid", _grid_on_clock_multiples, everywhere=True),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "clock_offset_opposite_sign",
        "2.8",
        "R1.4-1",
        "a clock_offset record's offset_s is ADDED to the stream's t",
        "subtracted from the stream's t",
        (Patch(storage.SessionFolder, "clock_offset", lambda real: lambda self, s: -real(self, s)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "clock_offset_ignored",
        "2.8",
        "R1.4-1",
        "clock_offset records put streams on the session clock",
        "the records are ignored",
        (Patch(storage.SessionFolder, "clock_offset", _replace(lambda self, s: 0.0)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    # units
    Mutant(
        "mm_for_m",
        "1.1",
        "R1.1-1",
        "motion-capture positions are in metres",
        "read as millimetres and divided by 1000",
        (Patch(storage.SessionFolder, "read", _pose_table(_millimetres, ("handle_pose", "markers"))),),
        ("free_space.speed_mean",),
        cheap=True,
    ),
    Mutant(
        "degrees_for_radians",
        "9.4",
        "R9.4-1",
        "angular speed is reported in rad/s",
        "in deg/s under the unit rad/s",
        (Patch(free_space, "_speed_summary", _post(lambda out, *_: {**out, "angular": out["angular"] * 180.0 / math.pi})),),
        ("free_space.angular_speed_mean",),
        cheap=True,
    ),
    # frames, rotations, signs
    Mutant(
        "opposite_force_sign",
        "6.5",
        "R1.5-1",
        "the reported force is the one the device applies to the hand",
        "the force the hand applies to the device",
        (Patch(calibration, "compensate_wrench", _post(lambda r, *_: (-r[0], -r[1]))),),
        ("stiffness.measured", "dynamics.error_vs_distance"),
    ),
    Mutant(
        "inverse_handle_rotation",
        "6.5",
        "R6.5-1",
        "F_W = R_WH F_H with R_WH from the handle quaternion (body → world)",
        "the handle rotation applied inverted (R_WHᵀ)",
        (Patch(calibration, "compensate_wrench", _post(_wrench_inverse_rotation)),),
        ("surface.planar_force_mean", "dynamics.error_vs_distance"),
        cheap=True,
    ),
    Mutant(
        "quaternion_conjugate_convention",
        "1.3",
        "R1.3-1",
        "stored quaternions rotate body → world",
        "read as world → body (passive, conjugated)",
        (Patch(storage.SessionFolder, "read", _pose_table(_conjugated)),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "quaternion_scalar_last",
        "1.3",
        "R1.3-1",
        "quaternion columns are w, x, y, z (scalar first)",
        "read as x, y, z, w (scalar last, as scipy and ROS store them)",
        (Patch(storage.SessionFolder, "read", _pose_table(_scalar_last)),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "torque_about_sensor_origin",
        "6.5",
        "R6.5-2",
        "the torque is moved to the gimbal centre (+ p_S × F_H)",
        "the torque is left about the F/T sensor's origin",
        (Patch(calibration, "compensate_wrench", _post(_torque_about_sensor)),),
        ("dynamics.torque_rmse",),
    ),
    Mutant(
        "ft_rotation_inverted",
        "1.2",
        "R1.2-1",
        "a rig pose gives the sensor frame in the handle frame (R_HS)",
        "read as the handle frame in the sensor frame (R_SH)",
        (Patch(calibration, "compensate_wrench", _sensor_rotation_inverted),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "accel_not_rotated_to_world",
        "6.6",
        "R6.6-1",
        "a_W = R_WH R_HA (a_A − b_a) − (0, 0, g)",
        "the handle rotation R_WH left out (acceleration in the handle frame)",
        (Patch(calibration, "compensate_accel", _accel_in_handle_frame),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "gravity_left_in_acceleration",
        "6.6",
        "R6.6-1",
        "gravity is removed from the handle acceleration",
        "the specific force is reported (gravity left in)",
        (Patch(calibration, "compensate_accel", _gravity_added_back(lambda cal: cal.gravity_m_per_s2)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "accel_bias_kept",
        "6.6",
        "R6.6-1",
        "the accelerometer bias b_a is subtracted",
        "the bias is left in the acceleration",
        (Patch(calibration, "compensate_accel", _with_calibration(accel_bias_m_per_s2=lambda c: np.zeros(3))),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "accel_gravity_9_81",
        "6.6",
        "R6.6-1",
        "gravity is removed with the accelerometer's own g (the sphere radius)",
        "with a hard-coded 9.81 m/s²",
        (Patch(calibration, "compensate_accel", _gravity_added_back(lambda cal: cal.gravity_m_per_s2 - 9.81)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "connector_weight_kept",
        "6.5",
        "R6.5-1",
        "the connector's weight m g is removed from the force",
        "only the bias is removed",
        (Patch(calibration, "compensate_wrench", _with_calibration(connector_mass_kg=lambda c: 0.0)),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "calibration_first_record",
        "6.4",
        "R6.4-1",
        "the LAST handle_gravity record in manifest order applies",
        "the first one",
        (Patch(calibration, "handle_calibration", _first_record),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "connector_weight_at_9_8",
        "6.4",
        "R6.5-1",
        "the connector weight removed is m·g0 (g0 = 9.80665 m/s²)",
        "m·9.8 (the rounded g of textbooks)",
        (
            Patch(
                calibration,
                "compensate_wrench",
                _with_calibration(connector_mass_kg=lambda c: c.connector_mass_kg * 9.8 / STANDARD_GRAVITY),
            ),
        ),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    # motion capture
    Mutant(
        "gaps_interpolated",
        "7.4",
        "R7.4-1",
        "occlusion gaps longer than max_gap_s are never interpolated across",
        "every gap is bridged",
        (Patch(preprocessing, "bridge_gaps", lambda real: lambda t, p, q, max_gap_s=None: real(t, p, q, max_gap_s=math.inf)),),
        ("free_space.speed_mean",),
        cheap=True,
    ),
    Mutant(
        "gap_limit_without_sample_interval",
        "7.4",
        "R7.4-1",
        "a gap is bridged when t_j − t_i ≤ max_gap_s + Δ",
        "when t_j − t_i ≤ max_gap_s",
        (Patch(preprocessing, "bridge_gaps", _gap_limit_strict),),
        ("free_space.force_max",),
        cheap=True,
    ),
    Mutant(
        "speed_from_raw_positions",
        "7.4",
        "R7.4-2",
        "velocity is the derivative of the low-passed position",
        "of the raw positions",
        (Patch(preprocessing, "process_mocap", _raw_derivative("velocity")),),
        ("free_space.speed_mean",),
        cheap=True,
    ),
    Mutant(
        "angular_velocity_unfiltered",
        "7.4",
        "R7.4-2",
        "the angular velocity is low-passed at angular_velocity_cutoff_hz",
        "it is used as differentiated",
        (Patch(preprocessing, "process_mocap", _raw_derivative("angular_velocity")),),
        ("free_space.angular_speed_mean",),
        cheap=True,
    ),
    # free space: the plate
    Mutant(
        "plate_mean_removed_on_all_axes",
        "9.3",
        "R9.3-1",
        "only the mean VERTICAL plate force is subtracted",
        "the mean force vector is subtracted",
        (Patch(free_space, "plate_force_about_weight", _replace(lambda f: f - np.asarray(f, dtype=float).mean(axis=0))),),
        ("free_space.plate_force_mean",),
        cheap=True,
    ),
    Mutant(
        "plate_force_unfiltered",
        "9.3",
        "R9.3-1",
        "the plate force is low-passed at wrench_cutoff_hz before resampling",
        "it is resampled unfiltered",
        (Patch(free_space, "lowpass_resample", _replace(lambda t, x, grid, fc: preprocessing.interp_columns(t, x, grid))),),
        ("free_space.plate_force_mean",),
        cheap=True,
    ),
    Mutant(
        "plate_bias_ignored",
        "14.2",
        "R14.2-1",
        "the plate bias (record or rig.plate_bias trial) is subtracted from every corner",
        "the bias is left in (the vertical de-meaning of §9.3 taken to remove it)",
        (Patch(force_plate, "plate_bias", _replace(lambda ctx: (np.zeros(24), "none"))),),
        ("free_space.plate_force_mean",),
        cheap=True,
    ),
    Mutant(
        "plate_corner_frames_ignored",
        "14.1",
        "R14.1-1",
        "each corner reading is rotated from its sensor frame into W",
        "the corner frames are taken for W",
        (
            Patch(
                force_plate,
                "corner_geometry",
                _post(lambda r, *_: (r[0], np.broadcast_to(np.eye(3), r[1].shape).copy())),
                everywhere=True,
            ),
        ),
        ("free_space.plate_force_mean",),
        cheap=True,
    ),
    # surface
    Mutant(
        "contact_guard_ignored",
        "12.2",
        "R12.2-1",
        "a sample is used only when every commanded sample within ±0.05 s is in contact",
        "every contact sample is used",
        (Patch(surface, "contact_signals", _post(_contact_unguarded), everywhere=True),),
        ("surface.planar_force_mean",),
        cheap=True,
    ),
    Mutant(
        "contact_from_measured_force",
        "12.2",
        "R12.2-1",
        "contact is decided on the COMMANDED normal force",
        "on the measured normal force F·n",
        (Patch(surface, "contact_signals", _post(_contact_from_measured), everywhere=True),),
        ("surface.planar_force_mean",),
        cheap=True,
    ),
    Mutant(
        "planar_force_not_projected",
        "12.3",
        "R12.3-1",
        "the planar force is F − (F·n)n",
        "the whole force |F|",
        (Patch(surface, "planar_force", _replace(lambda force, normal: np.asarray(force, dtype=float))),),
        ("surface.planar_force_mean",),
        cheap=True,
    ),
    # workspace
    Mutant(
        "convex_hull",
        "8.4",
        "R8.4-1",
        "volumes come from the voxel operator",
        "the convex hull's volume",
        (Patch(workspace, "volume_solid", _hull_solid),),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "device_placement_ignored",
        "8.3",
        "R8.2-1",
        "the modeled workspace is placed in W by device_placement",
        "left in the device frame",
        (Patch(workspace, "modeled_solid", lambda real: lambda kin, *a, **k: real(kin)),),
        ("workspace.coverage",),
    ),
    Mutant(
        "device_placement_inverted",
        "8.3",
        "R8.2-1",
        "p_W = R_placement p_device + t_placement",
        "the placement applied inverted",
        (Patch(workspace, "modeled_solid", _placement_inverted),),
        ("workspace.coverage",),
    ),
    Mutant(
        "no_hole_filling",
        "8.4",
        "R8.4-1",
        "cavities of the dilated shell are filled before erosion",
        "dilation and erosion only (a plain closing)",
        (Patch(ndimage, "binary_fill_holes", _replace(lambda x, *a, **k: np.asarray(x, dtype=bool))),),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "voxel_pitch_5mm",
        "8.1",
        "R8.4-1",
        "voxel_pitch_m = 2.5 mm",
        "5 mm voxels",
        (Patch(workspace, "wp", _params(voxel_pitch_m=0.005)),),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "closing_diameter_for_radius",
        "8.4",
        "R8.4-1",
        "the closing ball has radius r = closing_radius_m = 3 cm",
        "3 cm taken for the ball's diameter (radius 1.5 cm)",
        (Patch(workspace, "wp", _params(closing_radius_m=0.015)),),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "occlusion_gaps_not_repaired",
        "8.7",
        "R8.7-1",
        "a trial's occlusion gaps are repaired from the other repetitions' positions in the gaps' regions",
        "the finite positions of the trial alone",
        (
            Patch(
                workspace,
                "repaired_points",
                _replace(lambda t, position, donors, **k: (position[np.all(np.isfinite(position), axis=1)], 0)),
            ),
        ),
        ("workspace.measured_volume",),
    ),
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
        (Patch(force_plate, "param", _params(zero_pad_factor=1)),),
        ("rig.plate_natural_frequency",),
    ),
    # local dynamics
    Mutant(
        "training_trial_first_listed",
        "11.7",
        "R11.7-2",
        "the training trial is the local_dynamic trial with the LOWEST repetition",
        "the first local_dynamic trial in manifest order",
        (
            Patch(
                ld_metrics,
                "training_trial",
                _replace(lambda session: next(t for t in session.trials if t.protocol == "local_dynamic")),
            ),
        ),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "hemisphere_ignored",
        "11.3",
        "R11.3-1",
        "quaternions are flipped to the hemisphere of the file's reference",
        "the hemisphere rule is left out",
        (Patch(ld_prediction, "hemisphere_align", _replace(lambda u, hemi: np.array(u, dtype=float)), everywhere=True),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "pwl_clamped_ends",
        "11.3",
        "R11.3-1",
        "piecewise-linear maps extend their end segments linearly",
        "values beyond the end breakpoints are clamped (numpy.interp)",
        (Patch(ld_prediction, "pwl_eval", _replace(_clamped_map)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "denominator_sign_flipped",
        "11.3",
        "R11.3-1",
        "F(q) = 1 + f_1 q⁻¹ + … + f_nf q^−nf",
        "1 − f_1 q⁻¹ − … (autoregressive sign)",
        (Patch(ld_prediction, "lfilter", _denominator_sign), Patch(ld_fitting, "lfilter", _denominator_sign)),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "input_delay_ignored",
        "11.3",
        "R11.3-1",
        "each block delays its input by nk samples",
        "nk is ignored",
        (Patch(ld_trials, "predict", _delays_ignored),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "orientation_rad_over_86",
        "11.6.2",
        "R11.6-1",
        "R_θ = 86° is converted to radians; θ is in radians",
        "θ in radians divided by 86",
        (Patch(ld_distance.DistanceScales, "from_definition", _scales(lambda th: 86.0)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "orientation_degrees_over_rad",
        "11.6.2",
        "R11.6-1",
        "R_θ = 86° is converted to radians; θ is in radians",
        "θ in degrees divided by R_θ in radians",
        (Patch(ld_distance.DistanceScales, "from_definition", _scales(lambda th: th * math.pi / 180.0)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "orientation_angle_not_doubled",
        "11.6.2",
        "R11.6-1",
        "θ_ab = 2 arccos|q̄_a·q̄_b|",
        "arccos|q̄_a·q̄_b| (the half angle)",
        (Patch(ld_distance, "pair_distance", _angle_not_doubled),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "distance_euclidean",
        "11.6.2",
        "R11.6-1",
        "Δ is the SUM of the four normalised differences",
        "their Euclidean norm",
        (Patch(ld_distance, "pair_distance", _euclidean_terms),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "distance_mean_over_training",
        "11.6.2",
        "R11.6-1",
        "a window's distance to the training set is the minimum over training windows",
        "the mean over training windows",
        (Patch(ld_trials, "nearest_distances", _replace(_mean_to_training)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "segment_error_vector_rms",
        "11.6.4",
        "R11.6-2",
        "a segment's force error is the mean over x, y, z of per-axis RMS errors",
        "the RMS of the error vector's norm",
        (Patch(ld_trials, "segment_force_errors", _replace(_vector_rms_errors)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "line_through_test_segments_only",
        "11.6.5",
        "R11.6-2",
        "the line is fitted through the training AND test segments",
        "through the test segments only",
        (Patch(ld_metrics, "segment_table", _post(_test_segments_only)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    # stiffness
    Mutant(
        "stiffness_contact_transient_kept",
        "13.2",
        "R13.2-1",
        "the first contact_settle_s of a press (the contact transient) enter neither the fit nor the peak",
        "the fit and the peak start at the first contact sample",
        (Patch(stiffness, "stp", _params(contact_settle_s=0.0)),),
        ("stiffness.measured", "stiffness.peak_force"),
    ),
    Mutant(
        "stiffness_fit_to_the_peak",
        "13.2",
        "R13.2-1",
        "the fit ends at fit_high_fraction of the rise, where the force stops rising",
        "every loading-stroke sample up to the largest force",
        (Patch(stiffness, "stp", _params(fit_high_fraction=1.0, rise_hold_s=1e9)),),
        ("stiffness.measured",),
    ),
    Mutant(
        "peak_force_largest_press",
        "13.4",
        "R13.4-1",
        "stiffness.peak_force is the MEAN of the qualifying presses' peaks",
        "the largest press's peak",
        (Patch(stiffness.StiffnessFit, "peak_force", _replace(property(lambda fit: max(p.peak_force for p in fit.presses)))),),
        ("stiffness.peak_force",),
    ),
    Mutant(
        "box_volume_in_cm3",
        "8.6",
        "R8.6-1",
        "workspace.spec_box_volume is in m³",
        "the datasheet's cm³ figure under the unit m³",
        (Patch(workspace, "spec_box_volume", _post(lambda v, *a: v * 1e6)),),
        ("workspace.spec_box_volume",),
        cheap=True,
    ),
    Mutant(
        "coverage_as_volume_ratio",
        "8.5",
        "R8.5-1",
        "coverage is the overlap of the measured and modeled solids over the modeled volume",
        "measured volume / modeled volume (the ratio again)",
        (Patch(workspace, "overlap_volume", _replace(lambda solid, model: solid.volume)),),
        ("workspace.coverage",),
    ),
    Mutant(
        "rmse_of_error_magnitude",
        "11.7",
        "R11.7-1",
        "force (torque) RMSE is the per-axis RMS of the prediction error",
        "the RMS of the error vector's magnitude for every axis",
        (Patch(ld_prediction, "rmse", _replace(_rmse_of_magnitude), everywhere=True),),
        ("dynamics.force_rmse", "dynamics.force_rmse_mean"),
    ),
    Mutant(
        "stiffness_through_origin",
        "13.3",
        "R13.3-1",
        "the line f = k·d + c has an intercept",
        "f = k·d through the origin",
        (Patch(stiffness, "fit_stiffness", _post(_through_origin)),),
        ("stiffness.measured",),
    ),
    # uncertainty
    Mutant(
        "type_a_without_root_n",
        "19.2",
        "R19.2-1",
        "Type A of a mean of n repetitions is s/√n",
        "the repetitions' standard deviation s (the spread of one repetition)",
        (Patch(uncertainty, "type_a", _sd_as_type_a),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "coverage_factor_normal",
        "19.4",
        "R19.4-1",
        "k is Student's t at the effective degrees of freedom",
        "k = 1.96 from the normal distribution (the large-sample value)",
        (Patch(uncertainty, "coverage_factor", _normal_coverage),),
        ("free_space.force_mean",),
        cheap=True,
    ),
)

BY_NAME: dict[str, Mutant] = {m.name: m for m in MUTANTS}


def cheap_mutants() -> list[Mutant]:
    """The fast subset that ``make test`` runs against the cases of the metrics each one breaks."""
    return [m for m in MUTANTS if m.cheap]


def __getattr__(name: str) -> Callable[[str, str, dict | None], dict]:
    """``haptify_mutants.catalogue:<mutant name>`` as a ``--python`` implementation (spec §16.4.3)."""
    if name in BY_NAME:
        return BY_NAME[name].analyse
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
