"""Global free-space vibrations (spec chapter 10).

The raw three-axis accelerometer signal at its native rate (paper: 2 kHz) is high-passed, trimmed,
combined into one signal with DFT321 (Landin et al. 2010) and summarised by its RMS and its
power-weighted spectral centroid (paper §IV-C, §VI-C). Parameters: ``schemas/<v>/metrics/vibration.json``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.signal import butter, sosfiltfilt

from haptify.codes import Code
from haptify.errors import fail
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters
from haptify.pipeline.repetitions import TrialValue, aggregate, protocol_trials
from haptify.processing.caching import cached, session_of
from haptify.processing.preprocessing import nominal_rate

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.pipeline.results import MetricResult, Unavailable

FAMILY = "vibration"
ACCEL_COLUMNS = ["ax", "ay", "az"]
GROUPS = {  # protocol → (rms id, centroid id)
    "free_space": ("vibration.rms", "vibration.spectral_centroid"),
    "rig.baseline_vibration": ("vibration.baseline_rms", "vibration.baseline_centroid"),
}


class VibrationParameters(FamilyParameters):
    """The parameters of ``metrics/vibration.json`` (spec §10.1), in the units its definition file states."""

    highpass_cutoff_hz: float
    highpass_order: int
    edge_trim_s: float
    min_duration_s: float


#: The vibration family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = load_parameters(FAMILY, VibrationParameters)


def highpass(x: np.ndarray, rate_hz: float) -> np.ndarray:
    """Zero-phase Butterworth high-pass of ``x (N,)`` or ``(N, k)`` along axis 0 (spec §10.2).

    The per-column mean is subtracted first (so the filter's odd-extension padding starts from a signal
    near zero); then a Butterworth design of ``highpass_order`` with cut-off ``highpass_cutoff_hz`` runs
    forward and backward (``scipy.signal.sosfiltfilt``, default odd padding). Units are kept.
    """
    fc = PARAMETERS.highpass_cutoff_hz
    if not rate_hz > 2.0 * fc:
        raise fail(
            Code.SIGNAL_TOO_SHORT,
            f"a {rate_hz:g} Hz signal cannot be high-passed at {fc:g} Hz",
            expected=f"rate > {2 * fc:g} Hz",
            found=rate_hz,
        )
    sos = butter(PARAMETERS.highpass_order, fc, btype="highpass", fs=rate_hz, output="sos")
    x = np.asarray(x, dtype=float)
    return sosfiltfilt(sos, x - x.mean(axis=0), axis=0)


def dft321(x: np.ndarray) -> np.ndarray:
    """Combine three axes ``x (N, 3)`` into one signal ``(N,)`` (spec §10.3; Landin et al. 2010).

    Per frequency bin of the real DFT: magnitude √(|X|² + |Y|² + |Z|²), phase that of X + Y + Z; the
    rebuilt spectrum is Hermitian by construction (``irfft``), so Σ a² = Σ (x² + y² + z²) exactly.
    """
    x = np.asarray(x, dtype=float)
    spectra = np.fft.rfft(x, axis=0)
    magnitude = np.sqrt(np.sum(np.abs(spectra) ** 2, axis=1))
    phase = np.angle(spectra.sum(axis=1))
    return np.fft.irfft(magnitude * np.exp(1j * phase), n=len(x))


def rms(a: np.ndarray) -> float:
    """Root mean square of a signal, in its units (spec §10.4)."""
    a = np.asarray(a, dtype=float)
    return float(np.sqrt(np.mean(a * a)))


def power_spectrum(a: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided periodogram of ``a (N,)``: frequencies (Hz) and power per bin (spec §10.5).

    Rectangular window, DFT length N, P_k = w_k |A_k|² with w_k = 1 at 0 Hz and (N even) at Nyquist, 2
    elsewhere — the shape of MATLAB's ``periodogram``, whose normalisation cancels in the centroid.
    """
    a = np.asarray(a, dtype=float)
    spec = np.fft.rfft(a)
    power = np.abs(spec) ** 2
    weight = np.full(len(power), 2.0)
    weight[0] = 1.0
    if len(a) % 2 == 0:
        weight[-1] = 1.0
    return np.fft.rfftfreq(len(a), 1.0 / rate_hz), weight * power


def spectral_centroid(a: np.ndarray, rate_hz: float) -> float:
    """Power-weighted mean frequency Σ f_k P_k / Σ P_k of ``a`` (Hz; spec §10.5; MATLAB ``meanfreq``)."""
    f, p = power_spectrum(a, rate_hz)
    total = float(p.sum())
    if not total > 0:
        raise fail(
            Code.SIGNAL_TOO_SHORT,
            "the vibration signal is identically zero: its spectral centroid is undefined",
            expected="a non-zero signal",
            found=0.0,
        )
    return float(np.sum(f * p) / total)


@dataclass
class CombinedVibration:
    """The high-passed, trimmed, DFT321-combined vibration of one trial (spec §10.2–10.3)."""

    trial_id: str
    t: np.ndarray
    signal: np.ndarray
    rate_hz: float

    @property
    def rms(self) -> float:
        return rms(self.signal)

    @property
    def centroid(self) -> float:
        return spectral_centroid(self.signal, self.rate_hz)


def combine(t: np.ndarray, accel: np.ndarray, trial_id: str = "") -> CombinedVibration:
    """High-pass (§10.2), trim ``edge_trim_s`` from each end, DFT321 (§10.3): raw accelerometer samples
    ``accel (N, 3)`` (m/s², any fixed sensor frame, bias and gravity included) at times ``t (N,)`` in s."""
    t = np.asarray(t, dtype=float)
    rate = nominal_rate(t)
    # the length is checked before filtering: a short signal is E316, not the filter's padding error
    trim = int(round(PARAMETERS.edge_trim_s * rate)) if np.isfinite(rate) else len(t)
    if len(t) - 2 * trim < 1 or (len(t) - 2 * trim) / rate < PARAMETERS.min_duration_s:
        duration = float(t[-1] - t[0]) if len(t) else 0.0
        raise fail(
            Code.SIGNAL_TOO_SHORT,
            f"trial {trial_id!r}: {duration:.3g} s of acceleration leave less than "
            f"{PARAMETERS.min_duration_s} s after trimming {PARAMETERS.edge_trim_s} s at each end",
            expected=f">= {2 * PARAMETERS.edge_trim_s + PARAMETERS.min_duration_s} s",
            found=duration,
        )
    filtered = highpass(accel, rate)
    keep = slice(trim, len(t) - trim)
    return CombinedVibration(trial_id=trial_id, t=t[keep], signal=dft321(filtered[keep]), rate_hz=rate)


def trial_vibration(ctx_or_session: Any, trial_id: str) -> CombinedVibration:
    """:func:`combine` on a trial's raw ``handle_accel`` stream (spec §10.6); cached on a ComputeContext."""

    def build() -> CombinedVibration:
        df = session_of(ctx_or_session).read(trial_id, "handle_accel")
        return combine(df["t"].to_numpy(), df[ACCEL_COLUMNS].to_numpy(), trial_id)

    return cached(ctx_or_session, ("vibration", trial_id), build)


def compute(ctx: ComputeContext) -> list[MetricResult | Unavailable]:
    """vibration.rms / spectral_centroid from free-space trials, and the baseline pair from
    rig.baseline_vibration trials (spec §10.6)."""
    out: list[MetricResult | Unavailable] = []
    for protocol, (rms_id, centroid_id) in GROUPS.items():
        if not (ctx.wants(rms_id) or ctx.wants(centroid_id)):
            continue
        done, missing = protocol_trials(ctx, protocol, (rms_id, centroid_id), lambda tid: _summary(ctx, tid), rms_id)
        if missing:
            out += missing
            continue
        diag = {
            "peak_abs_m_per_s2": [d["peak"] for d in done.values()],
            "duration_s": [d["duration"] for d in done.values()],
            "rate_hz": [d["rate"] for d in done.values()],
        }
        out.append(aggregate(FAMILY, rms_id, [TrialValue(tid, d["rms"]) for tid, d in done.items()], diagnostics=diag))
        out.append(aggregate(FAMILY, centroid_id, [TrialValue(tid, d["centroid"]) for tid, d in done.items()]))
    return out


def _summary(ctx: ComputeContext, trial_id: str) -> dict[str, Any]:
    v = trial_vibration(ctx, trial_id)
    return {
        "rms": v.rms,
        "centroid": v.centroid,
        "peak": float(np.max(np.abs(v.signal))),
        "duration": float(len(v.signal) / v.rate_hz),
        "rate": v.rate_hz,
    }


# --- report figures and audio (spec §15.6; paper Fig. 7) ------------------------------------------
