"""Hand-path primitives of the virtual examiner (design §4): the uniform sample clock, smooth and
band-limited noise, finite-difference derivatives, rotation vectors as quaternions (spec §1.3), physiological
tremor (8–12 Hz), the natural orientation of the grip and :class:`HandTrajectory`, the path every protocol
generator of :mod:`haptify_tools.twin.examiner` returns."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from haptify.formats.conventions import (
    quat_angle,
    quat_from_axis_angle,
    quat_multiply,
    quat_normalize,
)

DEG = math.pi / 180.0
DEFAULT_RATE_HZ = 2000.0
TREMOR_BAND_HZ = (8.0, 12.0)  # physiological tremor band
# Tremor acceleration RMS per axis (m/s²). Kept small: the paper's rig-only vibration floor after a 10 Hz
# high-pass is 0.0332 m/s² RMS (§VI-C) and includes the hand, so the tremor must stay below it.
TREMOR_ACCEL_RMS = 0.01
# Tremor rotation RMS per axis (rad): the sensors sit 3–5 cm from the gimbal centre, where 0.002° at 10 Hz
# already gives ≈ 0.007 m/s² of tangential acceleration.
TREMOR_ANGLE_RMS = 0.002 * DEG
# The examiner's natural grip: the handle frame parallel to W. The twins align their gimbals so that every
# gimbal angle is zero in this grip at the centre of the joint-limit box, so a hand that keeps it stays far
# from the gimbal's singularity; the natural orientation changes wander about it.
NATURAL_GRIP = np.array([1.0, 0.0, 0.0, 0.0])


def clock(duration_s: float, rate_hz: float = DEFAULT_RATE_HZ, t0: float = 0.0) -> np.ndarray:
    """Uniform sample times ``t0 + k / rate_hz`` covering ``duration_s`` seconds (spec §2.6)."""
    n = int(round(duration_s * rate_hz))
    if n < 2:
        raise ValueError(f"duration {duration_s} s at {rate_hz} Hz gives fewer than two samples")
    return t0 + np.arange(n) / rate_hz


def minimum_jerk(s: np.ndarray) -> np.ndarray:
    """The minimum-jerk blend ``10s³ − 15s⁴ + 6s⁵`` of ``s`` clipped to [0, 1] (Flash & Hogan 1985)."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


def smooth_noise(
    rng: np.random.Generator, t: np.ndarray, f_lo: float, f_hi: float, dims: int = 1, components: int = 7
) -> np.ndarray:
    """A smooth random signal ``(len(t), dims)``: a sum of sinusoids with random frequencies in [f_lo, f_hi] Hz.

    Amplitudes fall as 1/f (so motion is dominated by its slow parts, like a hand's); each column is
    scaled to unit RMS over ``t``. Analytic in ``t``, so it can be evaluated on any clock.
    """
    out = np.zeros((len(t), dims))
    for d in range(dims):
        f = rng.uniform(f_lo, f_hi, components)
        ph = rng.uniform(0, 2 * np.pi, components)
        out[:, d] = np.sum(np.sin(2 * np.pi * f[None, :] * t[:, None] + ph[None, :]) / f[None, :], axis=1)
        out[:, d] /= np.sqrt(np.mean(out[:, d] ** 2)) or 1.0
    return out


def band_noise(rng: np.random.Generator, n: int, rate_hz: float, f_lo: float, f_hi: float, dims: int = 1) -> np.ndarray:
    """Gaussian noise ``(n, dims)`` confined to [f_lo, f_hi] Hz by an FFT brick-wall filter, unit RMS per column."""
    white = rng.standard_normal((n, dims))
    spec = np.fft.rfft(white, axis=0)
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    spec[(f < f_lo) | (f > f_hi)] = 0.0
    out = np.fft.irfft(spec, n=n, axis=0)
    rms = np.sqrt(np.mean(out**2, axis=0))
    return out / np.where(rms > 0, rms, 1.0)


def derivative(x: np.ndarray, rate_hz: float, order: int = 1) -> np.ndarray:
    """Finite-difference time derivative (second-order accurate, ``numpy.gradient``) along axis 0.
    Units of ``x`` per s^order."""
    for _ in range(order):
        x = np.gradient(x, 1.0 / rate_hz, axis=0)
    return x


def angular_speed(quaternion: np.ndarray, rate_hz: float) -> np.ndarray:
    """Angular speed (rad/s) between consecutive orientations, one value per sample (last repeated)."""
    ang = quat_angle(quaternion[:-1], quaternion[1:]) * rate_hz
    return np.append(ang, ang[-1])


def rotation_vector_to_quat(r: np.ndarray) -> np.ndarray:
    """Quaternions of rotation vectors ``r (N, 3)`` (axis × angle, rad; [w, x, y, z], spec §1.3)."""
    ang = np.linalg.norm(r, axis=-1)
    axis = np.where(ang[:, None] > 1e-15, r / np.where(ang > 1e-15, ang, 1.0)[:, None], [1.0, 0.0, 0.0])
    return quat_from_axis_angle(axis, ang)


def tremor(
    rng: np.random.Generator, n: int, rate_hz: float, accel_rms: float = TREMOR_ACCEL_RMS, angle_rms: float = TREMOR_ANGLE_RMS
) -> tuple[np.ndarray, np.ndarray]:
    """Physiological tremor: displacement ``(n, 3)`` in m and small rotation vectors ``(n, 3)`` in rad.

    Band 8–12 Hz; the displacement is scaled so that its acceleration has ``accel_rms`` (m/s²) per axis.
    """
    if n < 8 or accel_rms == 0 and angle_rms == 0:
        return np.zeros((n, 3)), np.zeros((n, 3))
    disp = band_noise(rng, n, rate_hz, *TREMOR_BAND_HZ, dims=3)
    acc = derivative(disp, rate_hz, 2)
    disp *= accel_rms / np.sqrt(np.mean(acc**2, axis=0))
    rot = band_noise(rng, n, rate_hz, *TREMOR_BAND_HZ, dims=3) * angle_rms
    return disp, rot


@dataclass
class HandTrajectory:
    """A hand path: gimbal-centre position (m, W) and handle orientation (wxyz, H → W) on a uniform clock.
    Spec §1.3."""

    t: np.ndarray
    position_W: np.ndarray
    quaternion_W: np.ndarray
    rate_hz: float
    protocol: str
    label: str | None = None
    meta: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0] + 1.0 / self.rate_hz)

    def velocity(self) -> np.ndarray:
        """Velocity (m/s, W) by finite differences."""
        return derivative(self.position_W, self.rate_hz)

    def acceleration(self) -> np.ndarray:
        """Acceleration (m/s², W) by finite differences."""
        return derivative(self.position_W, self.rate_hz, 2)

    def speed(self) -> np.ndarray:
        return np.linalg.norm(self.velocity(), axis=1)

    def angular_speed(self) -> np.ndarray:
        return angular_speed(self.quaternion_W, self.rate_hz)


def natural_orientation(
    rng: np.random.Generator,
    t: np.ndarray,
    rate_hz: float,
    *,
    base_quat: np.ndarray,
    mean_rate: float,
    max_rate: float,
    f_band: tuple[float, float] = (0.02, 0.25),
) -> np.ndarray:
    """A natural, slowly wandering hand orientation around ``base_quat`` (wxyz).

    The wander is a smooth random rotation vector; its amplitude is set so that the mean angular speed
    is ``mean_rate`` (rad/s) unless that would exceed ``max_rate`` anywhere, in which case the peak is
    held at ``max_rate``. Returns quaternions ``(len(t), 4)``.
    """
    shape = smooth_noise(rng, t, *f_band, dims=3)
    shape_q = rotation_vector_to_quat(shape * 1e-3)
    w = angular_speed(shape_q, rate_hz) / 1e-3  # angular speed per unit amplitude (small-angle)
    scale = min(mean_rate / max(float(np.mean(w)), 1e-12), max_rate / max(float(np.max(w)), 1e-12))
    scale = min(scale, 35 * DEG)  # a wrist wanders, it does not spin
    q = quat_multiply(base_quat[None, :], rotation_vector_to_quat(shape * scale))
    return quat_normalize(q)


def _finish(
    rng: np.random.Generator,
    t: np.ndarray,
    rate_hz: float,
    position: np.ndarray,
    quaternion: np.ndarray,
    protocol: str,
    label: str | None,
    meta: dict,
    *,
    tremor_accel_rms: float = TREMOR_ACCEL_RMS,
    tremor_angle_rms: float = TREMOR_ANGLE_RMS,
) -> HandTrajectory:
    """Add physiological tremor and package a trajectory."""
    disp, rot = tremor(rng, len(t), rate_hz, tremor_accel_rms, tremor_angle_rms)
    q = quat_normalize(quat_multiply(quaternion, rotation_vector_to_quat(rot)))
    meta = {
        **meta,
        "tremor_accel_rms_m_per_s2": tremor_accel_rms,
        "tremor_angle_rms_rad": tremor_angle_rms,
        "tremor_band_hz": list(TREMOR_BAND_HZ),
    }
    return HandTrajectory(
        t=t, position_W=position + disp, quaternion_W=q, rate_hz=rate_hz, protocol=protocol, label=label, meta=meta
    )
