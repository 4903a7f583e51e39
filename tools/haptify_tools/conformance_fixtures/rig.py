"""The rig-check fixtures and cases (spec chapter 14): damped plate modes (§14.4), offset COP markers (§14.5),
known recorder delays (§14.6), sensor noise and the handle calibration's residuals and offset (§14.7)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from haptify.formats.conventions import GRAVITY_W, quat_conjugate, quat_multiply, quat_rotate
from haptify.processing import calibration, force_plate, preprocessing
from haptify_tools import rig_builders as rb
from haptify_tools.conformance_fixtures.records import Fixture, case
from haptify_tools.conformance_fixtures.truth import QUIET, SEED, lowpass_noise_ratio, rotated_rig_full
from haptify_tools.example_session import example_rig


def damped_peak(f_n: float, zeta: float) -> float:
    """Frequency of the maximum of |Fourier transform| of e^(−ζωt) sin(ω_d t): ω_n √(1 − 2ζ²) / 2π."""
    return f_n * math.sqrt(1 - 2 * zeta**2)


def calibration_rms(truth: rb.HandleTruth) -> list[float]:
    """The known rig.handle_calibration_rms (spec §14.7) of a calibration trial of ``truth``'s white sensor noise
    (F/T at 1 kHz, accelerometer at 2 kHz) after the 20 Hz zero-phase low-pass: per channel σ·√(variance gain);
    the torque residual τ − (b + c × F) adds the force noise through c × n_F, E|c × n|² = 2|c|²σ_F² (per axis
    ⅔|c|²σ_F²)."""
    ft_var = lowpass_noise_ratio(preprocessing.PARAMETERS.wrench_cutoff_hz, 1000.0, preprocessing.PARAMETERS.filter_order)
    acc_var = lowpass_noise_ratio(preprocessing.PARAMETERS.accel_cutoff_hz, 2000.0, preprocessing.PARAMETERS.filter_order)
    torque_sigma = math.sqrt(truth.torque_noise**2 + 2 / 3 * float(truth.com @ truth.com) * truth.force_noise**2)
    return [truth.force_noise * math.sqrt(ft_var), truth.accel_noise * math.sqrt(acc_var), torque_sigma * math.sqrt(ft_var)]


def calibration_offset_u(truth: rb.HandleTruth, rig: dict, duration_s: float) -> float:
    """The known rig.handle_force_offset_u (spec §6.2 step 5, §14.7) of a calibration trial of ``truth``'s white F/T
    noise σ (1 kHz) over ``duration_s`` of :func:`rig_builders.tumbling_orientation`: the low-pass keeps the noise's
    spectral density at 0 Hz, so on the fit grid (rate r) the scores' long-run covariance is σ²·(r/1000)·JᵀJ and
    Cov(c, ρ) = σ²·(r/1000)·(JᵀJ)⁻¹, Jᵢ = −(ĝᵢ, 1) with ĝᵢ the gravity direction in the sensor frame."""
    rate = calibration.PARAMETERS.fit_rate_hz
    t = np.arange(int(duration_s * rate)) / rate
    q_ws = quat_multiply(
        rb.tumbling_orientation(t),
        np.broadcast_to(np.asarray(rig["handle"]["ft_sensor"]["pose"]["quaternion"], float), (len(t), 4)),
    )
    g = quat_rotate(quat_conjugate(q_ws), np.broadcast_to(GRAVITY_W, (len(t), 3)))
    jac = np.column_stack([g / np.linalg.norm(g, axis=1, keepdims=True), np.ones(len(t))])
    cov = truth.force_noise**2 * rate / 1000.0 * np.linalg.inv(jac.T @ jac)
    return float(np.sqrt(np.max(np.diag(cov)[:3]) + cov[3, 3]))


def rig_fixtures() -> list[Fixture]:
    out: list[Fixture] = []
    variants = [
        # name, rig, modes, zeta, accel delay, mocap delay, cop offset, truth, seed
        (
            "rig-rotated",
            "rotated",
            (205.0, 206.0, 182.0),
            0.03,
            0.003,
            -0.001,
            0.005,
            rb.HandleTruth(),
            SEED + 10,
            "Typical: the paper's plate modes, rotated handle sensors.",
        ),
        (
            "rig-late-mocap",
            "example",
            (150.0, 163.0, 121.0),
            0.02,
            -0.002,
            0.004,
            0.008,
            rb.HandleTruth(force_noise=0.006),
            SEED + 11,
            "Tricky: late motion capture, an early accelerometer, a weaker plate.",
        ),
        (
            "rig-quiet",
            "rotated-plate",
            (240.0, 230.0, 260.0),
            0.04,
            0.0,
            0.0,
            0.002,
            QUIET,
            SEED + 12,
            "Edge: noise-free handle sensors (residuals vanish), synchronous recorders, yawed corner sensors.",
        ),
    ]
    for name, rig_kind, modes, zeta, acc_d, moc_d, cop_off, truth, seed, desc in variants:

        def build(
            path: Path,
            rig_kind=rig_kind,
            modes=modes,
            zeta=zeta,
            acc_d=acc_d,
            moc_d=moc_d,
            cop_off=cop_off,
            truth=truth,
            seed=seed,
            name=name,
        ) -> None:
            rng = np.random.default_rng(seed)
            rig = {"rotated": rb.rotated_rig, "example": example_rig, "rotated-plate": rotated_rig_full}[rig_kind]()
            rig["motion_capture"]["markers"] = sorted(set(rig["motion_capture"]["markers"]) | {"w1"})
            w = rb.writer(rig=rig, sid=f"conf-{name}")
            rb.add_calibration_trial(w, truth, rng, duration_s=12.0, accel_delay_s=acc_d, mocap_delay_s=moc_d)
            rb.add_plate_bias_trial(w, rng)
            rb.add_impact_trial(w, rng, modes=modes, zeta=zeta)
            pos = np.array([[0.0, 0.0], [0.2, 0.1], [-0.2, -0.2]])
            ang = np.linspace(0, 2 * np.pi, len(pos), endpoint=False)
            rb.add_cop_trial(w, rng, pos, cop_off * np.column_stack([np.cos(ang), np.sin(ang)]))
            w.write(path)

        fx = Fixture(name, build)
        short = name.removeprefix("rig-")
        peaks = [damped_peak(f, zeta) for f in modes]
        expected_rms = calibration_rms(truth)
        rig_desc = {"rotated": rb.rotated_rig, "example": example_rig, "rotated-plate": rotated_rig_full}[rig_kind]()
        quiet = truth.force_noise == 0.0
        fx.cases += [
            case(
                f"rig.plate_natural_frequency.{short}",
                "rig.plate_natural_frequency",
                "14.4",
                name,
                peaks,
                "Hz",
                "analytic",
                f"a ball drop rings each axis as e^(−ζωt) sin(ω_d t) with f_n = {modes} Hz, ζ = {zeta}: the "
                "magnitude spectrum peaks at f_n √(1 − 2ζ²); tolerance = the 0.5 s window's zero-padded bin (0.24 Hz) "
                "refined by a parabola, plus 0.01 N noise",
                desc,
            ),
            case(
                f"rig.cop_error.{short}",
                "rig.cop_error",
                "14.5",
                name,
                cop_off,
                "m",
                "analytic",
                f"three placements of a 1 kg weight whose marker is offset by {cop_off} m from the load point in three "
                "directions; corner readings split the load statically (spec §14.1); noise 5 mN per channel",
                desc,
            ),
            case(
                f"rig.sync_offset.{short}",
                "rig.sync_offset",
                "14.6",
                name,
                max(abs(acc_d), abs(moc_d)),
                "s",
                "analytic",
                f"accelerometer time stamps late by {acc_d} s, motion capture by {moc_d} s against the F/T "
                "recorder; the value is the larger |delay|; tolerance = a third of the 1 ms grid step",
                desc,
            ),
            case(
                f"rig.handle_calibration_rms.{short}",
                "rig.handle_calibration_rms",
                "14.7",
                name,
                expected_rms,
                "[N, m/s^2, N*m]",
                "analytic",
                (
                    "noise-free sensors: the residuals are only the filters' end effects on the tumbling gravity (< 2e-4)"
                    if quiet
                    else f"white noise σ = ({truth.force_noise} N, {truth.accel_noise} m/s², {truth.torque_noise} N·m) per axis, "
                    "low-passed at 20 Hz (zero phase, order 4: variance × (2/fs)∫|H|⁴ df) before the fits: the radial residual "
                    "of an isotropic error has the per-axis σ; the torque residual adds the force noise through the centre of "
                    "mass, √(σ_τ² + ⅔|c|²σ_F²); tolerance 15 % = the sampling spread of an RMS over a few hundred "
                    "independent samples"
                ),
                desc,
            ),
            case(
                f"rig.handle_force_offset_u.{short}",
                "rig.handle_force_offset_u",
                "14.7",
                name,
                calibration_offset_u(truth, rig_desc, 12.0),
                "N",
                "analytic",
                (
                    "noise-free sensors: only the filters' end effects on the tumbling gravity are left to the fit"
                    if quiet
                    else f"white F/T noise σ = {truth.force_noise} N per axis at 1 kHz over 12 s of the tumble: the low-pass keeps its "
                    "density at 0 Hz, so the fitted bias and weight have Cov = σ²·(r/1 kHz)·(JᵀJ)⁻¹ on the 100 Hz fit grid "
                    "(Jᵢ = −(ĝᵢ, 1)); value √(max per-axis variance of the bias + variance of the weight)"
                ),
                desc,
            ),
        ]
        out.append(fx)
    out.append(impact_fixture())
    out.append(early_accel_fixture())
    out.append(cop_spread_fixture())
    return out


def cop_spread_fixture() -> Fixture:
    """A COP trial whose marker offsets differ from placement to placement (0, 5 and 25 mm): their mean, 10 mm, is
    the metric; their root mean square (14.7 mm) or median (5 mm) is not."""
    name, offsets = "rig-cop-spread", np.array([[0.0, 0.0], [0.005, 0.0], [0.0, -0.025]])

    def build(path: Path) -> None:
        rng = np.random.default_rng(SEED + 14)
        rig = example_rig()
        rig["motion_capture"]["markers"] = sorted(set(rig["motion_capture"]["markers"]) | {"w1"})
        w = rb.writer(rig=rig, sid=f"conf-{name}")
        rb.add_plate_bias_trial(w, rng)
        rb.add_cop_trial(w, rng, np.array([[0.05, -0.05], [-0.15, 0.1], [0.2, 0.2]]), offsets)
        w.write(path)

    fx = Fixture(name, build)
    errors = np.linalg.norm(offsets, axis=1)
    fx.cases.append(
        case(
            "rig.cop_error.spread",
            "rig.cop_error",
            "14.5",
            name,
            float(errors.mean()),
            "m",
            "analytic",
            f"three placements of a 1 kg weight whose marker is offset from the load point by {errors.tolist()} m: "
            "the mean distance over the placements; corner readings split the load statically (spec §14.1); "
            "noise 5 mN per channel; tolerance 0.5 mm as for the other COP cases",
            "Tricky: placements of different errors (mean, not RMS or median).",
        )
    )
    return fx


def early_accel_fixture() -> Fixture:
    """A calibration trial whose accelerometer is EARLY by 4 ms and motion capture late by 1.5 ms: the largest |delay|
    is the negative one."""
    name, acc_d, moc_d = "rig-early-accel", -0.004, 0.0015

    def build(path: Path) -> None:
        w = rb.writer(rig=rb.rotated_rig(), sid=f"conf-{name}")
        rb.add_calibration_trial(
            w, rb.HandleTruth(), np.random.default_rng(SEED + 13), duration_s=12.0, accel_delay_s=acc_d, mocap_delay_s=moc_d
        )
        w.write(path)

    fx = Fixture(name, build)
    fx.cases.append(
        case(
            "rig.sync_offset.early-accel",
            "rig.sync_offset",
            "14.6",
            name,
            max(abs(acc_d), abs(moc_d)),
            "s",
            "analytic",
            f"accelerometer time stamps early by {-acc_d} s (delay {acc_d} s), motion "
            f"capture late by {moc_d} s against the F/T recorder; the value is the larger |delay|, that of the "
            "early recorder; tolerance = a third of the 1 ms grid step",
            "Edge: the largest delay is negative.",
        )
    )
    return fx


def impact_peaks(t: np.ndarray, force: np.ndarray, rate: float) -> list[float]:
    """Spec §14.4 steps 2–4 written out for a known total plate force ``force (N, 3)``: the window around the largest
    deviation from the median, per axis the mean removed, zero-padding to a power of two, the largest |FFT| in the band
    and the vertex of the parabola through the log-magnitudes around it (clipped to half a bin)."""
    centre = t[np.argmax(np.linalg.norm(force - np.median(force, axis=0), axis=1))]
    inside = (t >= centre - force_plate.PARAMETERS.impact_pre_s) & (t <= centre + force_plate.PARAMETERS.impact_window_s)
    nfft = 1 << int(math.ceil(math.log2(inside.sum() * force_plate.PARAMETERS.zero_pad_factor)))
    freqs = np.arange(nfft // 2 + 1) * rate / nfft
    band = (freqs >= force_plate.PARAMETERS.impact_band_low_hz) & (
        freqs <= force_plate.PARAMETERS.impact_band_high_fraction * rate / 2
    )
    peaks = []
    for axis in range(3):
        x = force[inside, axis]
        mag = np.abs(np.fft.rfft(x - x.mean(), nfft))
        k = int(np.flatnonzero(band)[np.argmax(mag[band])])
        lo, mid, hi = np.log(mag[k - 1 : k + 2])
        shift = 0.5 * (lo - hi) / (lo - 2 * mid + hi) if lo - 2 * mid + hi < 0 else 0.0
        peaks.append(float(freqs[k] + min(max(shift, -0.5), 0.5) * rate / nfft))
    return peaks


def impact_fixture() -> Fixture:
    """Noise-free ball drops: the value is the §14.4 procedure applied to the exactly known ringing, so its discrete
    choices (no taper, zero-padding, the parabola) are pinned to 1e-4 Hz; broad peaks (ζ = 6 %) make them matter."""
    name, zeta, modes = "rig-impact-clean", 0.06, [(187.0, 214.0, 143.0), (191.0, 209.0, 151.0)]

    def build(path: Path) -> None:
        w = rb.writer(rig=rotated_rig_full(), sid=f"conf-{name}")
        for rep, m in enumerate(modes, start=1):
            rb.add_impact_trial(
                w, np.random.default_rng(SEED), modes=m, zeta=zeta, trial_id=f"impact-{rep}", repetition=rep, noise=0.0
            )
        w.write(path)

    fx = Fixture(name, build)
    t = np.arange(3000) / 1000.0
    per_trial = [
        impact_peaks(t, np.column_stack([rb.damped(t, f, zeta, 1.0, a) for f, a in zip(m, (4.0, 3.0, 20.0))]), 1000.0)
        for m in modes
    ]
    analytic = [[round(damped_peak(f, zeta), 3) for f in m] for m in modes]
    fx.cases.append(
        case(
            "rig.plate_natural_frequency.clean",
            "rig.plate_natural_frequency",
            "14.4",
            name,
            np.mean(per_trial, axis=0),
            "Hz",
            "spec",
            f"two noise-free impact trials ringing as e^(−ζωt) sin(ω_d t), ζ = {zeta}, f_n = {modes} Hz (x, y, z), "
            "split over four corner sensors yawed 0/90/180/270°; the value is the per-axis mean of §14.4's procedure applied to "
            "the known ringing (0.5 s window, no taper, zero-padding to 8× the length, parabola on the log-magnitudes), "
            f"close to the continuous peaks f_n √(1 − 2ζ²) = {analytic} Hz; tolerance 1e-4 Hz: the inputs are exact, only "
            "rounding differs",
            "Tricky: broad, noise-free peaks, where a taper or a shorter FFT moves the estimate.",
        )
    )
    return fx
