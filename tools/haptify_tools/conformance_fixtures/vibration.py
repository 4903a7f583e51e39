"""The vibration fixtures and cases (spec chapter 10): tones of known amplitude and frequency through the
specified high-pass (§10.2–§10.6), their RMS and spectral centroid, free-space repetitions whose mean is
reported (§15.3) and bursts that must be found in time."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from haptify.formats.conventions import quat_from_axis_angle
from haptify.metrics import vibration
from haptify_tools import rig_builders as rb
from haptify_tools.conformance_fixtures.records import Fixture, case
from haptify_tools.conformance_fixtures.truth import Fn, circle, clock, fixed, handle_trial, manifest, rotated_rig_full, spin
from haptify_tools.example_session import example_rig


def hp_gain(f: float) -> float:
    """Net amplitude gain of the zero-phase high-pass of spec §10.2 at f: 1 / (1 + (fc/f)^(2·order))."""
    fc, order = vibration.PARAMETERS.highpass_cutoff_hz, vibration.PARAMETERS.highpass_order
    return 1.0 / (1.0 + (fc / f) ** (2 * order))


def tones_rms(tones: list[tuple[float, float]]) -> float:
    return math.sqrt(sum((a * hp_gain(f)) ** 2 / 2 for f, a in tones))


def tones_centroid(tones: list[tuple[float, float]]) -> float:
    p = [(a * hp_gain(f)) ** 2 for f, a in tones]
    return sum(pi * f for pi, (f, _) in zip(p, tones)) / sum(p)


Tones = dict[int, list[tuple[float, float]]]  # axis → [(frequency Hz, amplitude m/s²)]


def write_vibration_session(
    path: Path, session_id: str, fmt: str, rate: float, secs: float, fs_tones: Tones, base_tones: Tones, rig_kind: str
) -> None:
    """A free-space trial whose handle acceleration carries ``fs_tones`` and a baseline trial carrying
    ``base_tones`` (spec §10), both at ``rate`` Hz for ``secs`` s, on the example or the rotated rig; the
    known answers are :func:`tones_rms` and :func:`tones_centroid` of the tones (every tone an integer
    frequency, so it falls on a DFT bin of the trimmed signal)."""
    rig = example_rig() if rig_kind == "example" else rotated_rig_full()

    def extra(tones: Tones) -> Fn:
        def fn(t: np.ndarray) -> np.ndarray:
            a = np.zeros((len(t), 3))
            for axis, ts in tones.items():
                for f, amp in ts:
                    a[:, axis] += amp * np.sin(2 * np.pi * f * t)
            return a

        return fn

    w = manifest(session_id, rig)
    handle_trial(
        w,
        "free_space-1",
        "free_space",
        duration_s=secs - 1 / rate,
        position=circle(0.03, 0.5),
        quaternion=spin(0.05),
        force_w=lambda t: np.tile([0.1, 0.0, -0.2], (len(t), 1)),
        rates=(250.0, rate, 100.0),
        fmt=fmt,
        accel_extra=extra(fs_tones),
    )
    tb = clock(secs, rate)[:-1]
    a_base = rb.HandleTruth().accel_bias + np.array([0.0, 0.0, 9.81]) + extra(base_tones)(tb)
    w.add_trial("baseline-1", "rig.baseline_vibration", powered=False)
    w.add_stream(
        "baseline-1", "handle_accel", {"t": tb, "ax": a_base[:, 0], "ay": a_base[:, 1], "az": a_base[:, 2]}, rate_hz=rate, fmt=fmt
    )
    w.write(path)


def vibration_fixtures() -> list[Fixture]:
    out: list[Fixture] = []
    variants = [
        # name, fmt, accel rate, seconds, free-space tones per axis, baseline tones, rig
        (
            "vib-tones",
            "parquet",
            2000.0,
            6.0,
            {0: [(150.0, 0.05)], 2: [(230.0, 0.02)]},
            {0: [(110.0, 0.03)]},
            "example",
            "Typical: two tones on two axes (DFT321 combines them).",
        ),
        (
            "vib-two-tone",
            "parquet",
            2000.0,
            6.0,
            {1: [(100.0, 0.1), (300.0, 0.2)]},
            {2: [(60.0, 0.04), (180.0, 0.08)]},
            "rotated",
            "Tricky: two tones on one axis; a magnitude-weighted centroid differs from the power-weighted one.",
        ),
        (
            "vib-near-cutoff-csv",
            "csv",
            1500.0,
            4.0,
            {0: [(12.0, 0.2)], 1: [(400.0, 0.02)]},
            {0: [(15.0, 0.1)]},
            "rotated",
            "Edge: a tone just above the 10 Hz cut-off, an unusual 1.5 kHz rate, CSV (a single-pass filter shows here).",
        ),
        (
            "vib-antiphase-csv",
            "csv",
            1500.0,
            4.0,
            {0: [(200.0, 0.05)], 1: [(200.0, -0.05)]},
            {1: [(90.0, 0.03)], 2: [(90.0, 0.03)]},
            "example",
            "Tricky: one tone in antiphase on two axes; DFT321 keeps both axes' power (the sum of the axes cancels "
            "it, the per-sample vector magnitude doubles its frequency).",
        ),
    ]
    note_filter = (
        "zero-phase Butterworth high-pass gain 1/(1+(10/f)^8) per tone (spec §10.2); every tone falls on a DFT "
        "bin of the trimmed signal"
    )
    for name, fmt, rate, secs, fs_tones, base_tones, rig_kind, desc in variants:

        def build(
            path: Path, fmt=fmt, rate=rate, secs=secs, fs_tones=fs_tones, base_tones=base_tones, rig_kind=rig_kind, name=name
        ) -> None:
            write_vibration_session(path, f"conf-{name}", fmt, rate, secs, fs_tones, base_tones, rig_kind)

        fx = Fixture(name, build)
        all_fs = [tone for ts in fs_tones.values() for tone in ts]
        all_base = [tone for ts in base_tones.values() for tone in ts]
        short = name.removeprefix("vib-")
        fmt_tones = lambda ts: ", ".join(f"{a} m/s² at {f:g} Hz" for f, a in ts)  # noqa: E731
        fx.cases += [
            case(
                f"vibration.rms.{short}",
                "vibration.rms",
                "10.4",
                name,
                tones_rms(all_fs),
                "m/s^2",
                "analytic",
                f"√(Σ (A·g(f))²/2) for {fmt_tones(all_fs)} at {rate:g} Hz; {note_filter}; DFT321 preserves energy",
                desc,
            ),
            case(
                f"vibration.spectral_centroid.{short}",
                "vibration.spectral_centroid",
                "10.5",
                name,
                tones_centroid(all_fs),
                "Hz",
                "analytic",
                f"power-weighted mean frequency Σ f·(A g)² / Σ (A g)² of {fmt_tones(all_fs)}",
                desc,
            ),
            case(
                f"vibration.baseline_rms.{short}",
                "vibration.baseline_rms",
                "10.6",
                name,
                tones_rms(all_base),
                "m/s^2",
                "analytic",
                f"baseline trial (no device): {fmt_tones(all_base)} on top of gravity and bias; {note_filter}",
                desc,
            ),
            case(
                f"vibration.baseline_centroid.{short}",
                "vibration.baseline_centroid",
                "10.6",
                name,
                tones_centroid(all_base),
                "Hz",
                "analytic",
                f"power-weighted mean frequency of {fmt_tones(all_base)}",
                desc,
            ),
        ]
        out.append(fx)
    out.append(repetitions_fixture(note_filter))
    out.append(bursts_fixture())
    return out


REPETITION_TONES = [(120.0, 0.05), (150.0, 0.06), (400.0, 0.20)]  # one tone per free-space repetition: the third is the outlier


def repetitions_fixture(note_filter: str) -> Fixture:
    """Three free-space repetitions, one tone each, the third far larger and higher: the reported value is
    the mean of the per-repetition values (spec §15.3), which the median or the first repetition misses by
    far more than the tolerance."""
    name, rate, secs = "vib-three-reps-csv", 1500.0, 4.0

    def build(path: Path) -> None:
        w = manifest(f"conf-{name}", example_rig())
        for k, (f, amp) in enumerate(REPETITION_TONES):

            def tone(t: np.ndarray, f=f, amp=amp) -> np.ndarray:
                a = np.zeros((len(t), 3))
                a[:, k] = amp * np.sin(2 * np.pi * f * t)
                return a

            handle_trial(
                w,
                f"free_space-{k + 1}",
                "free_space",
                duration_s=secs - 1 / rate,
                position=circle(0.03, 0.5),
                quaternion=spin(0.05),
                force_w=lambda t: np.tile([0.1, 0.0, -0.2], (len(t), 1)),
                rates=(250.0, rate, 100.0),
                fmt="csv",
                repetition=k + 1,
                accel_extra=tone,
            )
        w.write(path)

    fx = Fixture(name, build)
    rms = [tones_rms([tone]) for tone in REPETITION_TONES]
    centroids = [tones_centroid([tone]) for tone in REPETITION_TONES]
    tones = "; ".join(f"repetition {k + 1}: {a} m/s² at {f:g} Hz on {'xyz'[k]}" for k, (f, a) in enumerate(REPETITION_TONES))
    desc = "Tricky: three repetitions, one outlying; the value is their mean (spec §15.3), not their median."
    fx.cases += [
        case(
            "vibration.rms.three-reps",
            "vibration.rms",
            "15.3",
            name,
            float(np.mean(rms)),
            "m/s^2",
            "analytic",
            f"mean over repetitions of √((A·g(f))²/2) — {tones}; {note_filter}. The median "
            f"({np.median(rms):.4g}) and the first repetition ({rms[0]:.4g}) lie ≥ 40 % away",
            desc,
        ),
        case(
            "vibration.spectral_centroid.three-reps",
            "vibration.spectral_centroid",
            "15.3",
            name,
            float(np.mean(centroids)),
            "Hz",
            "analytic",
            f"mean over repetitions of each repetition's single tone frequency — {tones}. "
            f"The median ({np.median(centroids):.4g} Hz) lies 33 % away",
            desc,
        ),
    ]
    return fx


def burst(t: np.ndarray, f: float, amp: float, start: float, stop: float) -> np.ndarray:
    """A tone of ``f`` Hz under a sin² (Hann) envelope from ``start`` to ``stop`` s, zero elsewhere: its spectrum stays
    within a few Hz of f, so the 10 Hz high-pass passes it with the gain at f and spreads none of it in time."""
    inside = (t >= start) & (t <= stop)
    return np.where(inside, amp * np.sin(np.pi * (t - start) / (stop - start)) ** 2 * np.sin(2 * np.pi * f * t), 0.0)


def one_sided_power(a: np.ndarray) -> np.ndarray:
    """P_k = w_k |A_k|² of spec §10.5 (rectangular window, DFT length N)."""
    p = np.abs(np.fft.rfft(a)) ** 2
    w = np.full(len(p), 2.0)
    w[0] = 1.0
    if len(a) % 2 == 0:
        w[-1] = 1.0
    return w * p


BURSTS = {
    "tone": (100.0, 0.05),
    "inner": (400.0, 0.08, 0.55, 0.85),
    "start": (250.0, 0.3, 0.05, 0.45),
    "end": (250.0, 0.3, 1.75, 2.15),
}


def bursts_fixture() -> Fixture:
    """One free-space trial at 1.5 kHz, 2.2 s: a steady 100 Hz tone on x, a 400 Hz burst on y early in the analysed
    window, and 250 Hz bursts inside the two trimmed edges (the start one on z, the end one on y). The analysed signal
    (§10.2: 0.5 s cut from each end) is known exactly; a Hann window before the periodogram weighs the early burst
    down (centroid), analysing the edges adds the edge bursts, and DFT321 before trimming mixes the two edge bursts
    (same band, different axes) into the middle."""
    name, rate, secs = "vib-bursts-csv", 1500.0, 2.2
    (f_tone, a_tone), inner, first, last = BURSTS["tone"], BURSTS["inner"], BURSTS["start"], BURSTS["end"]

    def extra(t: np.ndarray) -> np.ndarray:
        return np.column_stack([a_tone * np.sin(2 * np.pi * f_tone * t), burst(t, *inner) + burst(t, *last), burst(t, *first)])

    def build(path: Path) -> None:
        w = manifest(f"conf-{name}", example_rig())
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=secs - 1 / rate,
            position=circle(0.03, 0.5),
            quaternion=fixed(quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), np.array(0.4))),
            force_w=lambda t: np.tile([0.1, 0.0, -0.2], (len(t), 1)),
            rates=(250.0, rate, 100.0),
            fmt="csv",
            accel_extra=extra,
        )
        w.write(path)

    fx = Fixture(name, build)
    t = clock(secs - 1 / rate, rate)
    trim = int(round(vibration.PARAMETERS.edge_trim_s * rate))
    window = t[trim : len(t) - trim]
    x = hp_gain(f_tone) * a_tone * np.sin(2 * np.pi * f_tone * window)
    y = hp_gain(inner[0]) * burst(window, *inner)
    power = one_sided_power(x) + one_sided_power(y)  # DFT321 keeps |X|² + |Y|² per bin (§10.3)
    freqs = np.fft.rfftfreq(len(window), 1 / rate)
    how = (
        f"{a_tone} m/s² at {f_tone:g} Hz on x (on a DFT bin), a {inner[1]} m/s² {inner[0]:g} Hz sin²-burst on y over "
        f"[{inner[2]}, {inner[3]}] s, {first[1]} m/s² {first[0]:g} Hz sin²-bursts over [{first[2]}, {first[3]}] s on z and "
        f"[{last[2]}, {last[3]}] s on y; after the high-pass (gain 1/(1+(10/f)^8)) and the {trim}-sample trims "
        f"(§10.2) the analysed {len(window)} samples hold the tone and the inner burst only, exactly"
    )
    why_tol = (
        "tolerance 1e-4: the analysed signal is known to ~1e-6 of its amplitude (the high-pass's start-up "
        "transient, from poles near 10 Hz, has decayed to e^−12 by the end of the trim; the bursts' sin² envelopes "
        "keep their spectra within a few Hz of their tones, where the gain is exact)"
    )
    desc = (
        "Tricky: a burst early in the analysed window (a Hann window weighs it down) and bursts inside the trimmed "
        "edges (analysing them, or combining the axes before trimming, lets them in)."
    )
    fx.cases += [
        case(
            "vibration.rms.bursts",
            "vibration.rms",
            "10.2",
            name,
            float(np.sqrt(np.mean(x**2 + y**2))),
            "m/s^2",
            "analytic",
            f"RMS over the analysed samples of {how} (DFT321 keeps the energy, §10.3); {why_tol}",
            desc,
        ),
        case(
            "vibration.spectral_centroid.bursts",
            "vibration.spectral_centroid",
            "10.5",
            name,
            float(np.sum(freqs * power) / np.sum(power)),
            "Hz",
            "analytic",
            f"Σ f_k P_k / Σ P_k of the one-sided rectangular periodograms of {how}; {why_tol}",
            desc,
        ),
    ]
    return fx
