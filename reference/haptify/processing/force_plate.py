"""The force plate: total wrench, centre of pressure, natural frequency, COP error (spec chapter 14, §14.1–14.5).

Sign convention (spec §14.1). Each corner sensor reports, in its own frame C_i, the force and the
moment (about its frame origin) that the **plate exerts on the sensor**. The plate is static and its
own weight is removed as bias, so the sum of the corner readings is the wrench the load (the device,
a weight, a ball) exerts **on the plate**:

    F = Σ_i R_i (f_i − b_f,i),      M = Σ_i [ R_i (τ_i − b_τ,i) + p_i × R_i (f_i − b_f,i) ],

with M about the world origin, the centre of the plate's top surface. A weight W resting at
(X, Y, 0) gives F = (0, 0, −W) and M = (−Y·W, X·W, 0).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import reduce
from typing import Any

import numpy as np

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.conventions import quat_to_matrix
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters
from haptify.processing.caching import cached, session_of
from haptify.processing.platform_wrench import cross
from haptify.processing.preprocessing import nominal_rate, table_columns

FAMILY = "rig"


class RigParameters(FamilyParameters):
    """The parameters of ``metrics/rig.json`` (spec chapter 14), in the units its definition file states."""

    cop_min_force_N: float
    cop_min_hold_s: float
    cop_trim_s: float
    impact_pre_s: float
    impact_window_s: float
    impact_band_low_hz: float
    impact_band_high_fraction: float
    zero_pad_factor: int
    sync_max_lag_s: float
    sync_rate_hz: float
    sync_coarse_step_s: float
    sync_cutoff_hz: float
    req_plate_force_N: tuple[float, float, float]
    req_plate_moment_Nm: tuple[float, float, float]
    req_handle_force_N: tuple[float, float, float]
    req_handle_torque_Nm: tuple[float, float, float]
    req_accel_m_per_s2: tuple[float, float, float]
    req_natural_frequency_hz: float
    req_cop_error_m: float
    req_calibration_rms: tuple[float, float, float]
    req_orientation_error_deg: float
    req_sync_offset_s: float


#: The rig family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = load_parameters(FAMILY, RigParameters)

CORNERS = ("c1", "c2", "c3", "c4")
AXES = ("fx", "fy", "fz", "tx", "ty", "tz")
PLATE_COLUMNS = [f"{c}_{a}" for c in CORNERS for a in AXES]


def corner_geometry(rig: Any) -> tuple[np.ndarray, np.ndarray]:
    """Corner sensor positions ``(4, 3)`` (m, in W) and rotations ``(4, 3, 3)`` (C_i → W), ordered c1…c4.
    Spec §14.1.

    Raises E603 when the rig has no force plate.
    """
    plate = getattr(rig, "force_plate", None)
    if plate is None:
        raise fail(
            Code.RIG_PART_MISSING,
            "the rig does not describe the force plate",
            file="session.json",
            pointer="/rig/force_plate",
            expected="rig.force_plate with four corner poses",
            found=None,
        )
    by_id = {c.id: c.pose for c in plate.corners}
    pos = np.array([by_id[c].position for c in CORNERS], float)
    rot = quat_to_matrix(np.array([by_id[c].quaternion for c in CORNERS], float))
    return pos, rot


def total_wrench(
    raw: np.ndarray, positions: np.ndarray, rotations: np.ndarray, bias: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Force (N) and moment about the world origin (N·m) the load exerts on the plate (spec §14.1).

    ``raw (N, 24)`` in the column order c1_fx … c4_tz; ``bias (24,)`` subtracted first (zeros if None).
    Each corner's force and moment are rotated to W a signal at a time (rows of ``raw.T``, contiguous
    for a table's columns), then summed c1 … c4.
    """
    x = np.asarray(raw, float)
    if bias is not None:
        x = x - np.asarray(bias, float)
    rows = x.T
    forces = [_rotated(rotations[c], rows[6 * c : 6 * c + 3]) for c in range(len(CORNERS))]
    moments = [_rotated(rotations[c], rows[6 * c + 3 : 6 * c + 6]) + cross(positions[c], forces[c]) for c in range(len(CORNERS))]
    return np.ascontiguousarray(reduce(np.add, forces).T), np.ascontiguousarray(reduce(np.add, moments).T)


def _rotated(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``r v`` for a rotation ``r (3, 3)`` and vectors as the rows of ``v (3, N)``, summed in the order j = 0, 1, 2."""
    return np.stack([r[i, 0] * v[0] + r[i, 1] * v[1] + r[i, 2] * v[2] for i in range(3)])


def center_of_pressure(force: np.ndarray, moment: np.ndarray, min_force_N: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """COP on the plate's top surface, ``(N, 2)`` m, and its validity mask (spec §14.3).

    ``X = −M_y / F_z``, ``Y = M_x / F_z`` with M about the centre of the top surface (exact for any
    horizontal force component, because the load acts in the plane z = 0). Valid where
    ``|F_z| ≥ cop_min_force_N``; NaN elsewhere.
    """
    min_force_N = PARAMETERS.cop_min_force_N if min_force_N is None else min_force_N
    fz = np.asarray(force, float)[:, 2]
    valid = np.abs(fz) >= min_force_N
    cop = np.full((len(fz), 2), np.nan)
    cop[valid, 0] = -moment[valid, 1] / fz[valid]
    cop[valid, 1] = moment[valid, 0] / fz[valid]
    return cop, valid


def plate_bias(ctx_or_session: Any) -> tuple[np.ndarray, str]:
    """The plate bias ``(24,)`` (c1_fx … c4_tz, sensor units) and where it came from (spec §14.2).

    The last ``plate_bias`` record in manifest order; otherwise the mean of every column over the last
    ``rig.plate_bias`` trial (highest repetition); otherwise E621. Cached on a context.
    """

    def build() -> tuple[np.ndarray, str]:
        session = session_of(ctx_or_session)
        recs = [c for c in session.manifest.calibration if c.kind == "plate_bias"]
        if recs:
            return np.asarray(recs[-1].bias, float), f"record:{recs[-1].id}"
        trials = session.trials_of("rig.plate_bias")
        if not trials:
            raise fail(
                Code.PLATE_BIAS_MISSING,
                f"session {session.session_id!r} has no plate_bias record and no rig.plate_bias trial",
                file="session.json",
                pointer="/calibration",
                expected="a plate_bias record or a rig.plate_bias trial",
                found=None,
            )
        df = session.read(trials[-1].id, "plate_wrench")
        return table_columns(df, PLATE_COLUMNS).mean(axis=0), f"trial:{trials[-1].id}"

    return cached(ctx_or_session, ("plate_bias",), build)


@dataclass
class PlateSignals:
    """A trial's plate wrench at the plate's native samples, world frame (spec §14.1–14.3)."""

    trial_id: str
    t: np.ndarray
    force: np.ndarray  # (N, 3) N, force the load exerts on the plate
    moment: np.ndarray  # (N, 3) N·m about the centre of the top surface
    cop: np.ndarray  # (N, 2) m, NaN where cop_valid is False
    cop_valid: np.ndarray
    bias_source: str
    rate_hz: float


def plate_signals(ctx_or_session: Any, trial_id: str) -> PlateSignals:
    """Bias-removed total plate wrench and COP of a trial, unfiltered (spec §14.1–14.3); cached on a context.

    Raises E302 when the trial has no plate_wrench, E603 without a plate in the rig, E621 without a bias.
    """

    def build() -> PlateSignals:
        session = session_of(ctx_or_session)
        df = session.read(trial_id, "plate_wrench")
        pos, rot = corner_geometry(session.manifest.rig)
        bias, source = plate_bias(ctx_or_session)
        force, moment = total_wrench(table_columns(df, PLATE_COLUMNS), pos, rot, bias)
        cop, ok = center_of_pressure(force, moment)
        t = df["t"].to_numpy()
        return PlateSignals(
            trial_id=trial_id, t=t, force=force, moment=moment, cop=cop, cop_valid=ok, bias_source=source, rate_hz=nominal_rate(t)
        )

    return cached(ctx_or_session, ("plate_signals", trial_id), build)


# --- natural frequency (spec §14.4) --------------------------------------------------------------


def impact_window(t: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Indices of the analysis window of an impact trial (spec §14.4).

    The impact is the sample of largest ``|F − median(F)|`` (Euclidean over the three axes); the
    window runs from ``impact_pre_s`` before it to ``impact_window_s`` after it, clipped to the trial.
    """
    f = np.asarray(force, float)
    dev = np.linalg.norm(f - np.median(f, axis=0), axis=1)
    k = int(np.argmax(dev))
    t = np.asarray(t, float)
    lo = t[k] - PARAMETERS.impact_pre_s
    hi = t[k] + PARAMETERS.impact_window_s
    return np.flatnonzero((t >= lo) & (t <= hi))


def dominant_frequency(x: np.ndarray, rate_hz: float, band_hz: tuple[float, float] | None = None) -> float:
    """Frequency (Hz) of the most prominent peak of ``|FFT|`` of ``x`` inside ``band_hz`` (spec §14.4).

    The mean is removed, no taper is applied (the impact response decays inside the window), the
    signal is zero-padded to ``zero_pad_factor`` times its length (next power of two) and the peak is
    refined by a parabola through the log-magnitudes of the peak bin and its neighbours. The default
    band is ``[impact_band_low_hz, impact_band_high_fraction · Nyquist]``. E622 when the band holds no
    spectral line or the spectrum is flat zero.
    """
    x = np.asarray(x, float) - np.mean(x)
    if band_hz is None:
        band_hz = (PARAMETERS.impact_band_low_hz, PARAMETERS.impact_band_high_fraction * rate_hz / 2.0)
    nfft = int(2 ** np.ceil(np.log2(max(len(x), 2) * PARAMETERS.zero_pad_factor)))
    mag = np.abs(np.fft.rfft(x, nfft))
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate_hz)
    band = np.flatnonzero((freqs >= band_hz[0]) & (freqs <= band_hz[1]))
    if len(band) < 3 or not np.any(mag[band] > 0):
        raise fail(
            Code.PLATE_IMPACT_NOT_FOUND,
            f"no spectral peak between {band_hz[0]:.1f} and {band_hz[1]:.1f} Hz",
            expected="an impact response inside the band",
            found="flat spectrum" if len(band) >= 3 else "band empty",
        )
    k = band[int(np.argmax(mag[band]))]
    if 0 < k < len(mag) - 1 and np.all(mag[k - 1 : k + 2] > 0):
        a, b, c = np.log(mag[k - 1 : k + 2])
        denom = a - 2 * b + c
        delta = 0.5 * (a - c) / denom if denom < 0 else 0.0
        return float(freqs[k] + np.clip(delta, -0.5, 0.5) * (freqs[1] - freqs[0]))
    return float(freqs[k])


def natural_frequencies(t: np.ndarray, force: np.ndarray, rate_hz: float) -> np.ndarray:
    """Plate natural frequency per axis (x, y, z), Hz, from an impact trial's total force (spec §14.4)."""
    idx = impact_window(t, force)
    return np.array([dominant_frequency(np.asarray(force, float)[idx, j], rate_hz) for j in range(3)])


# --- COP error against motion capture (spec §14.5) --------------------------------------------------


@dataclass
class Placement:
    """One static placement of the weight: time span, plate COP and mocap position (m), error (m).
    Spec §14.5."""

    t0: float
    t1: float
    cop: np.ndarray
    mocap: np.ndarray
    error: float


def placements(
    t: np.ndarray, force: np.ndarray, cop: np.ndarray, cop_valid: np.ndarray, marker_t: np.ndarray, marker_xy: np.ndarray
) -> list[Placement]:
    """Static placements of the weight and their COP errors (spec §14.5).

    A placement is a maximal run of samples with a valid COP lasting at least ``cop_min_hold_s``;
    ``cop_trim_s`` is cut from both ends (placing and lifting). Its plate COP is the mean COP over
    the trimmed span; its mocap position the mean of ``marker_xy`` (the centroid of the weight's
    markers, x and y) over the samples in the same span that are not NaN. Error = Euclidean distance.
    """
    hold = PARAMETERS.cop_min_hold_s
    trim = PARAMETERS.cop_trim_s
    t = np.asarray(t, float)
    edges = np.flatnonzero(np.diff(np.r_[0, np.asarray(cop_valid).astype(int), 0]))
    out = []
    for a, b in zip(edges[::2], edges[1::2]):
        ta, tb = t[a] + trim, t[b - 1] - trim
        if t[b - 1] - t[a] < hold or tb <= ta:
            continue
        m = (t >= ta) & (t <= tb)
        mk = (marker_t >= ta) & (marker_t <= tb) & np.all(np.isfinite(marker_xy), axis=1)
        if not mk.any():
            continue
        c = cop[m].mean(axis=0)
        p = marker_xy[mk].mean(axis=0)
        out.append(Placement(t0=float(ta), t1=float(tb), cop=c, mocap=p, error=float(np.linalg.norm(c - p))))
    return out


def cop_trial_placements(ctx_or_session: Any, trial_id: str) -> list[Placement]:
    """The placements of a ``rig.plate_cop`` trial (spec §14.5); E623 when there are none."""
    session = session_of(ctx_or_session)
    ps = plate_signals(ctx_or_session, trial_id)
    mk = session.read(trial_id, "markers")
    ents = session.stream(trial_id, "markers").entities or []
    xs = mk[[f"{e}_x" for e in ents]].to_numpy()
    ys = mk[[f"{e}_y" for e in ents]].to_numpy()
    with np.errstate(all="ignore"):
        xy = np.column_stack([xs.mean(axis=1), ys.mean(axis=1)])  # NaN when any marker is occluded
    found = placements(ps.t, ps.force, ps.cop, ps.cop_valid, mk["t"].to_numpy(), xy)
    if not found:
        raise fail(
            Code.COP_PLACEMENTS_NOT_FOUND,
            f"trial {trial_id!r}: no static placement of the weight found",
            expected=f"loads of |Fz| >= {PARAMETERS.cop_min_force_N} N held >= {PARAMETERS.cop_min_hold_s} s with visible markers",
            found="none",
        )
    return found
