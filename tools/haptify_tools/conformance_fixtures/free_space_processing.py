"""Free-space fixtures that probe the processing chain (spec chapter 7, §9.2–§9.3): a glimpse of 0.3 s of
motion capture (sample SD), pushes hidden by occlusion gaps bridged by §7.4, and jitter every low-pass of
§7.2 removes, after a superseded handle_gravity record (§6.4)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from haptify.formats.conventions import quat_from_axis_angle, quat_multiply
from haptify.processing import preprocessing
from haptify_tools import rig_builders as rb
from haptify_tools.conformance_fixtures.records import Fixture, case
from haptify_tools.conformance_fixtures.truth import Z, circle, grid, handle_trial, lowpass_pair_gain, manifest, spin
from haptify_tools.example_session import example_rig


def glimpse_fixture(truth: rb.HandleTruth) -> Fixture:
    """Motion capture sees the handle for 0.3 s only (31 rows of the 100 Hz grid): the force statistics rest on few
    samples, where the sample SD (ddof = 1, §9.2) and the population SD differ by 1.6 %."""
    name, T = "fs-glimpse-csv", 6.0

    def force(t: np.ndarray) -> np.ndarray:
        return np.column_stack([0.3 + 0.4 * t, -0.2 + 0 * t, 0.1 + 0 * t])

    def seen(t: np.ndarray) -> np.ndarray:
        k = np.round(t * 100).astype(int)
        return (k >= 200) & (k <= 230)

    def build(path: Path) -> None:
        w = manifest(f"conf-{name}", example_rig(), truth=truth)
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=T,
            position=circle(0.05, 1.0),
            quaternion=spin(0.07),
            force_w=force,
            truth=truth,
            fmt="csv",
            occluded=lambda t: ~seen(t),
        )
        w.write(path)

    fx = Fixture(name, build)
    tg = grid(T)
    mag = np.linalg.norm(force(tg[seen(tg)]), axis=1)
    how = (
        f"|(0.3 + 0.4t, −0.2, 0.1)| N over the {len(mag)} grid rows t = 2.00 … 2.30 s, the only time motion capture "
        "sees the handle (§7.5: the force counts only where the orientation is known); a force linear in time passes "
        "the §7.2 low-pass exactly (chord removed), so the values are exact: tolerance 1e-4"
    )
    desc = "Edge: a trial whose motion capture is usable for 0.3 s only (sample statistics of 31 values)."
    fx.cases += [
        case(
            "free_space.force_sd.glimpse",
            "free_space.force_sd",
            "9.2",
            name,
            mag.std(ddof=1),
            "N",
            "analytic",
            "sample SD (ddof = 1) of " + how + f"; ddof = 0 gives {mag.std():.6g} N (1.6 % less)",
            desc,
        ),
        case(
            "free_space.force_mean.glimpse",
            "free_space.force_mean",
            "9.2",
            name,
            mag.mean(),
            "N",
            "analytic",
            "mean of " + how,
            desc,
        ),
        case(
            "free_space.force_min.glimpse",
            "free_space.force_min",
            "9.2",
            name,
            mag.min(),
            "N",
            "analytic",
            "minimum (at t = 2.00 s) of " + how,
            desc,
        ),
        case(
            "free_space.force_max.glimpse",
            "free_space.force_max",
            "9.2",
            name,
            mag.max(),
            "N",
            "analytic",
            "maximum (at t = 2.30 s) of " + how,
            desc,
        ),
    ]
    return fx


def pushes_fixture(truth: rb.HandleTruth) -> Fixture:
    """The examiner's hand hides the markers while it pushes: four gaps of seven frames at 150 Hz (t_j − t_i = 53 ms,
    bridged by §7.4 since max_gap_s + Δ = 56.7 ms), each centred on a force pulse. Leaving such a gap open drops the
    rows around each pulse's peak."""
    name, T, rate, centres, width = "fs-occluded-pushes", 10.0, 150.0, (2.0, 4.0, 6.0, 8.0), 0.6
    F0, push = np.array([0.3, 0.1, 0.2]), np.array([0.6, 0.0, 0.0])

    def pulses(t: np.ndarray) -> np.ndarray:
        pulse = (np.where(np.abs(t - c) <= width / 2, np.sin(np.pi * (t - c + width / 2) / width) ** 2, 0.0) for c in centres)
        return sum(pulse, np.zeros_like(t))

    def force(t: np.ndarray) -> np.ndarray:
        return F0 + np.outer(pulses(t), push)

    def hidden(t: np.ndarray) -> np.ndarray:
        k = np.round(t * rate).astype(int)
        return np.any([np.abs(k - round(c * rate)) <= 3 for c in centres], axis=0)

    def build(path: Path) -> None:
        w = manifest(f"conf-{name}", example_rig(), truth=truth)
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=T,
            position=circle(0.05, 1.0),
            quaternion=spin(0.07),
            force_w=force,
            truth=truth,
            rates=(1000.0, 500.0, rate),
            occluded=hidden,
        )
        w.write(path)

    fx = Fixture(name, build)
    mag = np.linalg.norm(force(grid(T)), axis=1)
    how = (
        f"|(0.3, 0.1, 0.2) + p(t)·(0.6, 0, 0)| N with p four sin² pulses {width} s wide centred on t = {centres} s; "
        f"motion capture at {rate:g} Hz misses 7 frames around each centre (t_j − t_i = 8/150 s = 53.3 ms ≤ max_gap_s + Δ "
        "= 56.7 ms: bridged, §7.4), so every grid row counts; the pulses pass the §7.2 low-pass (flat to order 8) to "
        "better than 1e-5: tolerance 1e-3"
    )
    desc = "Tricky: short occlusions exactly where the force peaks (bridged by §7.4's rule, Δ included)."
    fx.cases += [
        case(
            "free_space.force_max.occluded-pushes",
            "free_space.force_max",
            "7.4",
            name,
            mag.max(),
            "N",
            "analytic",
            "maximum (at each pulse's peak, inside a gap) of " + how,
            desc,
        ),
        case(
            "free_space.force_mean.occluded-pushes",
            "free_space.force_mean",
            "7.4",
            name,
            mag.mean(),
            "N",
            "analytic",
            "mean over the grid of " + how,
            desc,
        ),
    ]
    return fx


def envelope(t: np.ndarray, start: float, stop: float, ramp: float = 0.5) -> np.ndarray:
    """0 before ``start`` and after ``stop``, 1 between the two sin² ramps of ``ramp`` s: switches a vibration on
    away from a trial's ends (its spectrum stays within ~2/ramp Hz of the vibration's frequency)."""
    up = np.clip((t - start) / ramp, 0.0, 1.0)
    down = np.clip((stop - t) / ramp, 0.0, 1.0)
    return np.sin(0.5 * np.pi * up) ** 2 * np.sin(0.5 * np.pi * down) ** 2


SUPERSEDED = rb.HandleTruth(mass=0.09, force_bias=np.array([0.1, 0.2, -0.3]), force_noise=0.0, torque_noise=0.0, accel_noise=0.0)
JITTER = {
    "position_m": 3e-4,
    "position_hz": 30.0,
    "angle_rad": math.radians(0.1),
    "angle_hz": 30.0,
    "force_N": 0.5,
    "force_hz": 180.0,
    "plate_N": 2.0,
    "plate_hz": 130.0,
}


def jitter_fixture(truth: rb.HandleTruth) -> Fixture:
    """Free space with vibrations every low-pass of §7.2 removes: 30 Hz marker jitter in position and about the
    vertical, a 180 Hz force on the hand, a 130 Hz plate force. The spec's values are those of the smooth motion and
    forces; a velocity or angular velocity differentiated without the low-pass, a force resampled before filtering
    (180 Hz aliases to 20 Hz on the 100 Hz grid) or an unfiltered plate force are far off."""
    name, T, j = "fs-jitter", 12.0, JITTER
    F0, P0 = np.array([0.4, -0.2, 0.3]), np.array([0.3, 0.0, -16.0])

    def on(t: np.ndarray) -> np.ndarray:
        return envelope(t, 1.0, T - 1.0)

    def position(t: np.ndarray) -> np.ndarray:
        return circle(0.05, 1.0)(t) + np.outer(j["position_m"] * on(t) * np.sin(2 * np.pi * j["position_hz"] * t), Z)

    def quaternion(t: np.ndarray) -> np.ndarray:
        wobble = quat_from_axis_angle(np.tile(Z, (len(t), 1)), j["angle_rad"] * on(t) * np.sin(2 * np.pi * j["angle_hz"] * t))
        return quat_multiply(wobble, spin(0.07)(t))

    def force(t: np.ndarray) -> np.ndarray:
        return F0 + np.outer(j["force_N"] * on(t) * np.sin(2 * np.pi * j["force_hz"] * t), [1.0, 0.0, 0.0])

    def plate(t: np.ndarray) -> np.ndarray:
        return P0 + np.outer(j["plate_N"] * on(t) * np.cos(2 * np.pi * j["plate_hz"] * t), Z)

    def build(path: Path) -> None:
        rig = example_rig()
        bias = rb.plate_bias_vector(rig)
        w = manifest(f"conf-{name}", rig, truth=truth, plate_bias=bias, superseded=SUPERSEDED)
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=T,
            position=position,
            quaternion=quaternion,
            force_w=force,
            truth=truth,
            rates=(1000.0, 500.0, 100.0),
            plate_force_w=plate,
            plate_bias=bias,
        )
        w.write(path)

    fx = Fixture(name, build)
    fc = preprocessing.PARAMETERS.mocap_cutoff_hz
    gains = {
        k: lowpass_pair_gain(f, rate, cut)
        for k, f, rate, cut in (
            ("mocap", j["position_hz"], 100.0, fc),
            ("force", j["force_hz"], 1000.0, preprocessing.PARAMETERS.wrench_cutoff_hz),
            ("plate", j["plate_hz"], 1000.0, preprocessing.PARAMETERS.wrench_cutoff_hz),
            ("angle", j["angle_hz"], 100.0, preprocessing.PARAMETERS.angular_velocity_cutoff_hz),
        )
    }
    jit = (
        f"marker jitter {j['position_m'] * 1000:g} mm along z and {math.degrees(j['angle_rad']):g}° about the vertical "
        f"at {j['position_hz']:g} Hz (switched on by sin² ramps 1 s from the ends), which the §7.4 low-pass at {fc:g} Hz "
        f"passes with gain {gains['mocap']:.1e}"
    )
    f0 = float(np.linalg.norm(F0))
    felt_note = (
        f"constant force {tuple(F0)} N on the hand plus {j['force_N']} N at {j['force_hz']:g} Hz along x (ramped on "
        f"1 s from the ends); the 20 Hz low-pass at the F/T's 1 kHz leaves {gains['force']:.1e} of it (§7.5: filter at "
        "the native rate, then interpolate; resampled first, 180 Hz aliases to 20 Hz on the 100 Hz grid)"
    )
    desc = "Tricky: vibrations above every cut-off of §7.2 (marker jitter, a motor hum in the force, a ringing plate)."
    fx.cases += [
        case(
            "free_space.speed_mean.jitter",
            "free_space.speed_mean",
            "7.4",
            name,
            0.05,
            "m/s",
            "analytic",
            f"circle r = 0.05 m at 1 rad/s (speed r·ω) with {jit}; velocity is the derivative of the LOW-PASSED position. "
            "Tolerance 0.1 %: the circle passes the low-pass unchanged to 1e-5, the jitter adds its square (1e-11)",
            desc,
        ),
        case(
            "free_space.angular_speed_mean.jitter",
            "free_space.angular_speed_mean",
            "7.4",
            name,
            0.07,
            "rad/s",
            "analytic",
            f"constant rotation at 0.07 rad/s with {jit}; the angular velocity is low-passed at "
            f"{preprocessing.PARAMETERS.angular_velocity_cutoff_hz:g} Hz (§7.4 step 4; gain {gains['angle']:.1e} at {j['angle_hz']:g} Hz). "
            "Tolerance 0.1 %: a rotation about the vertical turns the spin axis without changing |ω| to first order",
            desc,
        ),
        case(
            "free_space.force_mean.jitter",
            "free_space.force_mean",
            "9.2",
            name,
            f0,
            "N",
            "analytic",
            f"|F| of the {felt_note}; the jitter about the vertical leaves the connector's weight in the sensor frame "
            f"unchanged; an earlier handle_gravity record (a {SUPERSEDED.mass * 1000:g} g connector) precedes the one that "
            "applies (§6.4: the last). Tolerance 0.2 % as for the other constant forces",
            desc,
        ),
        case(
            "free_space.force_max.jitter",
            "free_space.force_max",
            "9.2",
            name,
            f0,
            "N",
            "analytic",
            f"max |F| of the {felt_note}",
            desc,
        ),
        case(
            "free_space.force_sd.jitter",
            "free_space.force_sd",
            "9.2",
            name,
            0.0,
            "N",
            "analytic",
            f"SD of |F| of the {felt_note}: 0 (tolerance: the rounding of the calibration under rotation, as for the "
            "other constant force)",
            desc,
        ),
        case(
            "free_space.plate_force_mean.jitter",
            "free_space.plate_force_mean",
            "9.3",
            name,
            0.3,
            "N",
            "analytic",
            f"plate force {tuple(P0)} N plus {j['plate_N']} N at {j['plate_hz']:g} Hz vertical (ramped on 1 s from the ends), "
            f"low-passed at 20 Hz (gain {gains['plate']:.1e}) before resampling (§9.3); removing the mean vertical leaves "
            "|(0.3, 0, 0)|. Tolerance 0.5 % as for the other plate cases",
            desc,
        ),
    ]
    return fx
