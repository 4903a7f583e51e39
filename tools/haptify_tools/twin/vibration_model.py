"""The parasitic vibration the twin's device adds at the handle (TWIN.md, Physics; effect
``vibration.device``): band-limited noise through a second-order resonator, in world axes, m/s²."""

from __future__ import annotations

import numpy as np
from scipy import signal

from haptify_tools.twin.hand_path import band_noise as _band_noise
from haptify_tools.twin.model import TwinFile


def _resonance_noise(rng: np.random.Generator, n: int, fs: float, f0: float, q_factor: float) -> np.ndarray:
    """Unit-RMS noise ``(n, 3)`` through a second-order resonator at ``f0`` Hz with quality ``q_factor``."""
    f0 = min(f0, 0.45 * fs)
    b, a = signal.iirpeak(f0, q_factor, fs=fs)
    y = signal.lfilter(b, a, rng.standard_normal((n + 2000, 3)), axis=0)[2000:]
    rms = np.sqrt(np.mean(y**2, axis=0))
    return y / np.where(rms > 0, rms, 1.0)


def _sample_rate(t: np.ndarray) -> float:
    if len(t) < 2:
        raise ValueError("vibration needs at least two samples")
    return 1.0 / float(np.median(np.diff(t)))


def device_vibration(twin: TwinFile, t: np.ndarray, speed: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Parasitic acceleration ``(N, 3)`` the device adds at the handle, world axes, m/s² (effect ``vibration.device``).

    ``t`` uniform (the accelerometer's 2 kHz clock), ``speed`` the handle speed at ``t`` in m/s. Each
    broadband and resonant source is unit-RMS coloured noise scaled by its RMS at the reference speed,
    its axis weights (normalised so the three-axis RMS equals the configured value) and the speed law
    ``idle + (1 − idle)·(v/v_ref)^p``. Zeros when the effect is off.
    """
    t = np.asarray(t, dtype=float)
    eff = twin.effects.vibration_device
    out = np.zeros((len(t), 3))
    if not eff.enabled or len(t) < 2:
        return out
    fs = _sample_rate(t)
    v = np.maximum(np.asarray(speed, dtype=float), 0.0)
    law = eff.idle_fraction + (1.0 - eff.idle_fraction) * (v / eff.ref_speed_m_per_s) ** eff.speed_exponent
    for src in eff.broadband:
        w = np.asarray(src.axis_weights, dtype=float)
        w = w / np.linalg.norm(w)
        band = _band_noise(rng, len(t), fs, src.band_hz[0], min(src.band_hz[1], fs / 2), dims=3)
        out += src.rms_at_ref_speed_m_per_s2 * w * band * law[:, None]
    for res in eff.resonances:
        w = np.asarray(res.axis_weights, dtype=float)
        w = w / np.linalg.norm(w)
        out += (
            res.rms_at_ref_speed_m_per_s2 * w * _resonance_noise(rng, len(t), fs, res.frequency_hz, res.q_factor) * law[:, None]
        )
    return out
