"""Speed of the local dynamic model (issue: local dynamic model; spec chapter 11).

Targets on the project's 2-core machine:
- fitting 140 s of data at 100 Hz, 13 inputs → 6 outputs, default structure (10 breakpoints per map,
  nb = nf = 2), all LM iterations the definition allows: under 30 s;
- the kinematic distance of paper eq. 9 for a 140 s training set against 10 minutes of test data
  (window features of both plus every window's nearest training window): under 2 s.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.signal import lfilter

from haptify.conventions import quat_from_axis_angle
from haptify.local_dynamics import (
    DistanceScales,
    FitOptions,
    fit,
    nearest_distances,
    predict,
    rmse,
    segment_distances,
    window_features,
)

RATE = 100.0


def motion(rng: np.random.Generator, seconds: float) -> dict[str, np.ndarray]:
    """Oscillations of rising frequency (0.5 → 4 Hz) in x, y, z around a centre, a wobbling handle."""
    n = int(seconds * RATE)
    t = np.arange(n) / RATE
    f = 0.5 + 3.5 * t / t[-1]
    phase = 2 * np.pi * np.cumsum(f) / RATE
    amp = 0.03 * (1 + 0.3 * lfilter([0.01], [1, -0.99], rng.standard_normal((n, 3)), axis=0))
    pos = np.array([0.0, 0.0, 0.15]) + amp * np.sin(phase[:, None] + [0.0, 1.3, 2.6])
    vel = np.gradient(pos, 1 / RATE, axis=0)
    acc = np.gradient(vel, 1 / RATE, axis=0)
    axis = np.column_stack([np.sin(0.1 * t), np.cos(0.13 * t), np.ones(n)])
    q = quat_from_axis_angle(axis, 0.4 * np.sin(0.2 * t))
    return {"position": pos, "velocity": vel, "acceleration": acc, "quaternion": q}


def device_wrench(rng: np.random.Generator, m: dict[str, np.ndarray]) -> np.ndarray:
    """A passive device: inertia, viscous and Coulomb-like friction, a position spring; torque from a lever."""
    force = (-0.15 * m["acceleration"] - 0.6 * m["velocity"] - 0.2 * np.tanh(m["velocity"] / 0.02)
             - 5.0 * (m["position"] - [0.0, 0.0, 0.15]))
    torque = np.cross([0.0, 0.0, 0.04], force) + 0.002 * m["quaternion"][:, 1:]
    noise = np.r_[[0.05] * 3, [0.002] * 3] * rng.standard_normal((len(force), 6))
    return np.column_stack([force, torque]) + noise


def main() -> None:
    rng = np.random.default_rng(0)
    train = motion(rng, 140.0)
    u = np.column_stack([train["quaternion"], train["position"], train["velocity"], train["acceleration"]])
    y = device_wrench(rng, train)
    options = FitOptions.from_definition()
    start, cpu = time.perf_counter(), time.process_time()
    model, report = fit(u, y, sample_rate_hz=RATE, options=options, quaternion_columns=[0, 1, 2, 3])
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    n_params = sum(len(getattr(m, "values", [])) for m in model.input_maps + model.output_maps) + \
        sum(len(tf.b) + len(tf.f) for row in model.linear for tf in row)
    print(f"fit 140 s @ 100 Hz, 13 -> 6, {n_params} parameters, {report.iterations} iterations "
          f"({report.stop_reason}): {elapsed:.2f} s (target < 30 s; CPU {cpu:.2f} s)")
    print(f"  training RMS error per output: {np.round(rmse(y, predict(model, u)), 4).tolist()}")

    test = motion(rng, 600.0)
    window = int(round(0.2 * RATE))
    scales = DistanceScales.from_definition()
    start, cpu = time.perf_counter(), time.process_time()
    ftrain = window_features(train["position"], train["velocity"], train["acceleration"], train["quaternion"], window)
    ftest = window_features(test["position"], test["velocity"], test["acceleration"], test["quaternion"], window)
    minima = nearest_distances(ftest, ftrain, scales)
    segments = segment_distances(minima, 25)
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    print(f"distance metric, 140 s training vs 600 s test ({len(ftrain)} x {len(ftest)} windows, "
          f"{len(segments)} segments): {elapsed:.3f} s (target < 2 s; CPU {cpu:.3f} s)")


if __name__ == "__main__":
    main()
