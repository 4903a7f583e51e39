"""The stiffness fixtures and cases (spec chapter 13): linear springs with saturation and giving way, pressed
five times (§13.3 the fitted stiffness, §13.4 the maximum force), a contact kick and a falling release."""

from __future__ import annotations

import math

import numpy as np

from haptify_tools.conformance_fixtures.records import Fixture, case
from haptify_tools.conformance_fixtures.truth import active_session


K_CMD = 750.0
HOVER = 0.005  # m above the plane between presses
DEPTH = 0.012  # m, the deepest penetration of every press
PRESS_S, GAP_S, PRESSES = 1.2, 0.5, 5


def duration(press_s: float = PRESS_S) -> float:
    """Length (s) of a stiffness fixture's trial: PRESSES presses of ``press_s`` with their gaps, and 0.5 s after."""
    return GAP_S + PRESSES * (press_s + GAP_S) + 0.5


def press_phase(t: np.ndarray, press_s: float = PRESS_S) -> tuple[np.ndarray, np.ndarray]:
    """(τ, inside): time since the current press began (s) and whether a press is under way."""
    tau = np.mod(t - GAP_S, press_s + GAP_S)
    return tau, (t >= GAP_S) & (tau < press_s) & (t < GAP_S + PRESSES * (press_s + GAP_S))


def press_depth(t: np.ndarray, press_s: float = PRESS_S, scales: tuple[float, ...] = (1.0,) * PRESSES) -> np.ndarray:
    """Penetration (m): from hovering HOVER above the plane, PRESSES presses −HOVER + (s_k·DEPTH + HOVER)·sin²(π τ / press_s),
    τ the time since press k began, s_k = ``scales[k]``, separated by GAP_S. Smooth throughout (at the default 1.2 s the
    hand crosses the plane at about 0.04 m/s, the protocol's pace), so the motion-capture low-pass of §7.4 has no step to
    ring at."""
    tau, inside = press_phase(t, press_s)
    k = np.clip(np.floor((t - GAP_S) / (press_s + GAP_S)).astype(int), 0, PRESSES - 1)
    deepest = DEPTH * np.asarray(scales, dtype=float)[k]
    return np.where(inside, -HOVER + (deepest + HOVER) * np.sin(np.pi * tau / press_s) ** 2, -HOVER)


def press_time(depth: float, press_s: float = PRESS_S) -> float:
    """Time (s) after a press begins at which its loading stroke reaches ``depth`` (m): the inverse of press_depth."""
    return press_s / np.pi * math.asin(math.sqrt((depth + HOVER) / (DEPTH + HOVER)))


def loading_stroke(t: np.ndarray, press_s: float = PRESS_S) -> np.ndarray:
    """True while a press's penetration grows (its first half, up to its deepest instant)."""
    tau, inside = press_phase(t, press_s)
    return inside & (tau <= press_s / 2)


def contact_kick(t: np.ndarray, amplitude: float, length_s: float, press_s: float = PRESS_S) -> np.ndarray:
    """A force kick (N) at every press's contact instant: amplitude·sin²(π (τ − τ_c) / length_s) for
    τ_c ≤ τ < τ_c + length_s, τ_c the instant the press crosses the plane."""
    tau, inside = press_phase(t, press_s)
    tau = tau - press_time(0.0, press_s)
    on = inside & (tau >= 0) & (tau < length_s)
    return np.where(on, amplitude * np.sin(np.pi * np.clip(tau, 0, length_s) / length_s) ** 2, 0.0)


FIT_RULE = (
    "after the contact transient (the first 4 grid samples of a press), from the force there up to 90 % of "
    "the rise to where the force stops rising (spec §13.2)"
)


def spring_fixture(
    name: str, fmt: str, rig_kind: str, normal_raw, point, k: float, peak: float, after: float | None, rates, desc: str
) -> Fixture:
    """A stiffness fixture (spec §13.2–§13.4): five presses into a rendered K_CMD N/m plane (normal ``normal_raw``
    through ``point``) of a device whose force is ``k`` N/m × penetration, saturating at ``peak`` N (``after`` None)
    or giving way to ``after`` N once it reaches ``peak``. Cases: the measured stiffness, the accuracy and, when
    it saturates, the peak force."""
    n = np.asarray(normal_raw, float) / np.linalg.norm(normal_raw)
    pp = np.asarray(point, float)

    def law(t, k=k, peak=peak, after=after):
        d = press_depth(t)
        if after is None:
            return np.clip(k * d, 0.0, peak)
        # gives way: once k·d reaches the peak the force drops to `after` for the rest of that press
        tau, _ = press_phase(t)
        return np.where(d <= 0, 0.0, np.where(tau < press_time(peak / k), k * d, after))

    def position(t, n=n, pp=pp):
        return pp - press_depth(t)[:, None] * n

    def force(t, n=n, law=law):
        side = np.array([0.1, 0.0, 0.0]) - (np.array([0.1, 0.0, 0.0]) @ n) * n  # a small planar force
        return law(t)[:, None] * n + side

    def commanded(t, n=n):
        return (K_CMD * np.maximum(press_depth(t), 0.0))[:, None] * n

    rendering = {"surface_point_m": list(point), "surface_normal": [float(c) for c in n], "stiffness_N_per_m": K_CMD}

    fx = Fixture(
        name,
        active_session(
            name, rig_kind, "stiffness-1", "stiffness", duration(), 0.03, position, force, commanded, rendering, rates, fmt
        ),
    )
    short = name.removeprefix("stiff-")
    how = (
        f"five presses from {HOVER * 1000:g} mm above to {DEPTH * 1000:g} mm into a rendered {K_CMD:g} N/m surface (normal "
        f"{normal_raw}); the device's force is {k:g} N/m × penetration "
        + (f"saturating at {peak} N" if after is None else f"up to {peak} N, then {after} N until the press ends")
        + "; the fit samples, "
        + FIT_RULE
        + ", lie on the linear part"
    )
    fx.cases += [
        case(f"stiffness.measured.{short}", "stiffness.measured", "13.3", name, k, "N/m", "analytic", how, desc),
        case(
            f"stiffness.accuracy.{short}",
            "stiffness.accuracy",
            "13.4",
            name,
            100 * k / K_CMD,
            "%",
            "analytic",
            how + f"; accuracy = 100·{k:g}/{K_CMD:g}",
            desc,
        ),
    ]
    if after is None:
        fx.cases.append(
            case(
                f"stiffness.peak_force.{short}",
                "stiffness.peak_force",
                "13.4",
                name,
                peak,
                "N",
                "analytic",
                how + "; every press reaches the saturation plateau",
                desc,
            )
        )
    return fx


def stiffness_fixtures() -> list[Fixture]:
    variants = [
        (
            "stiff-saturating",
            "parquet",
            "example",
            [0.0, -0.15, 1.0],
            (0.01, 0.04, 0.11),
            360.0,
            2.7,
            None,
            (1000.0, 500.0, 100.0),
            "Typical: a linear spring that saturates (the Touch, paper §VI-F).",
        ),
        (
            "stiff-rotated-csv",
            "csv",
            "rotated",
            [0.2, 0.1, 1.0],
            (0.0, 0.02, 0.09),
            520.0,
            4.0,
            None,
            (400.0, 250.0, 150.0),
            "Tricky: rotated sensor frames, a tilted surface, CSV and unusual rates.",
        ),
        (
            "stiff-giving-way",
            "parquet",
            "example",
            [0.0, 0.0, 1.0],
            (0.0, 0.0, 0.10),
            600.0,
            5.7,
            1.0,
            (1000.0, 500.0, 100.0),
            "Edge: a spring that gives way after its peak (the Touch X, paper §VI-F).",
        ),
    ]
    out: list[Fixture] = [spring_fixture(*v) for v in variants]
    up = np.array([0.0, 0.0, 1.0])

    def linear_presses(name: str, scales: tuple[float, ...]) -> Fixture:
        """A purely linear 300 N/m spring pressed PRESSES times, press k ``scales[k]``·DEPTH deep."""
        depth = lambda t: press_depth(t, scales=scales)  # noqa: E731
        return Fixture(
            name,
            active_session(
                name,
                "example",
                "stiffness-1",
                "stiffness",
                duration(),
                0.03,
                lambda t: np.array([0.0, 0.01, 0.1]) - depth(t)[:, None] * up,
                lambda t: np.clip(300.0 * depth(t), 0.0, None)[:, None] * up,
                lambda t: (K_CMD * np.maximum(depth(t), 0.0))[:, None] * up,
                {"surface_point_m": [0.0, 0.01, 0.1], "surface_normal": [0.0, 0.0, 1.0], "stiffness_N_per_m": K_CMD},
                (500.0, 500.0, 100.0),
                "parquet",
            ),
        )

    # A third peak-force case: a press that never saturates, so its peak is k·depth.
    fx = linear_presses("stiff-linear", (1.0,) * PRESSES)
    fx.cases += [
        case(
            "stiffness.peak_force.linear",
            "stiffness.peak_force",
            "13.4",
            fx.name,
            300.0 * DEPTH,
            "N",
            "analytic",
            "a purely linear 300 N/m spring pressed 12 mm deep: the peak is 3.6 N (the sin² press is smooth at its bottom, "
            "so the 20 Hz low-pass leaves the peak)",
            "Edge: no saturation.",
        ),
        case(
            "stiffness.measured.linear",
            "stiffness.measured",
            "13.3",
            fx.name,
            300.0,
            "N/m",
            "analytic",
            "a purely linear 300 N/m spring pressed five times 12 mm deep: the least-squares slope of force against "
            "penetration over the fit samples is the spring constant (the rise ends at the deepest sample)",
            "Edge: no saturation.",
        ),
    ]
    out.append(fx)
    # Presses of unequal depth: the peak force is the MEAN of the presses' peaks (§13.4), not the largest.
    scales = (0.7, 0.85, 1.0, 1.15, 1.3)
    fx = linear_presses("stiff-linear-uneven", scales)
    peaks = [300.0 * DEPTH * sc for sc in scales]
    fx.cases += [
        case(
            "stiffness.peak_force.linear-uneven",
            "stiffness.peak_force",
            "13.4",
            fx.name,
            float(np.mean(peaks)),
            "N",
            "analytic",
            f"a purely linear 300 N/m spring pressed {', '.join(f'{1000 * DEPTH * sc:g}' for sc in scales)} mm "
            f"deep: the press peaks are {', '.join(f'{pk:.3g}' for pk in peaks)} N and the value is their mean (the largest "
            f"is {max(peaks) / np.mean(peaks) - 1:.0%} higher)",
            "Tricky: presses of unequal depth.",
        ),
        case(
            "stiffness.measured.linear-uneven",
            "stiffness.measured",
            "13.3",
            fx.name,
            300.0,
            "N/m",
            "analytic",
            "a purely linear 300 N/m spring: every press's fit samples lie on one line whatever its depth",
            "Tricky: presses of unequal depth.",
        ),
    ]
    out.append(fx)
    out += [kick_dip_fixture(), falling_release_fixture()]
    return out


KICK_N, KICK_S = 3.0, 0.01  # the contact kick of stiff-kick-dip: 3 N for 10 ms
SLOW_S = 2.4  # stiff-kick-dip's presses last 2.4 s: the plane is crossed at 0.02 m/s


def kick_dip_law(t: np.ndarray) -> np.ndarray:
    """stiff-kick-dip's normal force (N): 400 N/m up to 1.6 N at 4 mm, a sag to 1.0 N and back to 1.6 N at 11 mm,
    then 400 N/m to 2.0 N at the 12 mm bottom; a 3 N, 10 ms kick at every contact."""
    d = press_depth(t, SLOW_S)
    sag = 1.6 - 0.6 * np.sin(np.pi * np.clip((d - 0.004) / 0.007, 0.0, 1.0))
    spring = np.where(d <= 0, 0.0, np.where(d <= 0.004, 400.0 * d, np.where(d <= 0.011, sag, 1.6 + 400.0 * (d - 0.011))))
    return spring + contact_kick(t, KICK_N, KICK_S, SLOW_S)


def kick_dip_fixture() -> Fixture:
    """A rendering that kicks at contact and whose plateau sags and climbs above its first top: the fit must
    leave out the contact transient and end the rise at the first top (spec §13.2). The previous rule (rising
    phase up to the press's largest force, 20–80 % of it) takes in the sag; a fit over the whole rise from the
    first contact sample takes in the kick."""
    up = np.array([0.0, 0.0, 1.0])
    pp = np.array([0.0, 0.02, 0.1])
    fx = Fixture(
        "stiff-kick-dip",
        active_session(
            "stiff-kick-dip",
            "example",
            "stiffness-1",
            "stiffness",
            duration(SLOW_S),
            0.03,
            lambda t: pp - press_depth(t, SLOW_S)[:, None] * up,
            lambda t: kick_dip_law(t)[:, None] * up,
            lambda t: (K_CMD * np.maximum(press_depth(t, SLOW_S), 0.0))[:, None] * up,
            {"surface_point_m": pp.tolist(), "surface_normal": up.tolist(), "stiffness_N_per_m": K_CMD},
            (1000.0, 500.0, 100.0),
            "parquet",
        ),
    )
    how = (
        "five slow presses (2.4 s, crossing the plane at 0.02 m/s) 12 mm deep; force 400 N/m × penetration up to 1.6 N at 4 mm, a sag to 1.0 N and back to 1.6 N at "
        "11 mm, then 400 N/m more to 2.0 N at the bottom; a 3 N, 10 ms sin² kick at each contact. The fit samples, "
        + FIT_RULE
        + ", lie on the first 400 N/m part: the rise ends at the first top (the force stays below 1.6 N for "
        "0.39 s after it), and the kick has decayed through the 20 Hz low-pass before the first settled sample"
    )
    desc = "Edge: a kick at contact and a plateau that sags and climbs again (the fit window of §13.2)."
    fx.cases += [
        case("stiffness.measured.kick-dip", "stiffness.measured", "13.3", fx.name, 400.0, "N/m", "analytic", how, desc),
        case(
            "stiffness.peak_force.kick-dip",
            "stiffness.peak_force",
            "13.4",
            fx.name,
            2.0,
            "N",
            "analytic",
            how + "; the peak is the loading stroke's largest force, 2.0 N at the smooth bottom of the press",
            desc,
        ),
    ]
    return fx


WEIGHT_N = 0.8  # stiff-falling-release: the device's uncompensated weight pulls the hand into the plane


def falling_release_law(t: np.ndarray) -> np.ndarray:
    """stiff-falling-release's normal force (N): 360 N/m up to 2.88 N at 8 mm, 2.88 N for 2 mm, then falling linearly
    with depth to 1.44 N at the 12 mm bottom; on the release stroke 0.15 N more wherever the spring is past its
    knee; the device's weight (−0.8 N) throughout."""
    d = press_depth(t)
    d_sat, top = 0.008, 360.0 * 0.008
    spring = np.where(
        d <= 0,
        0.0,
        np.where(
            d <= d_sat,
            360.0 * d,
            np.where(d <= d_sat + 0.002, top, top - top / 2 * (d - d_sat - 0.002) / (DEPTH - d_sat - 0.002)),
        ),
    )
    return spring + np.where(loading_stroke(t) | (d <= d_sat), 0.0, 0.15) - WEIGHT_N


def falling_release_fixture() -> Fixture:
    """A device whose force saturates, then falls with depth, and pushes harder on the way back up than on the way
    in (the peak and the fit must come from the loading stroke, spec §13.2), with its weight uncompensated (the line's
    intercept is −0.8 N, not 0)."""
    up = np.array([0.0, 0.0, 1.0])
    pp = np.array([0.01, 0.0, 0.12])
    fx = Fixture(
        "stiff-falling-release",
        active_session(
            "stiff-falling-release",
            "example",
            "stiffness-1",
            "stiffness",
            duration(),
            0.03,
            lambda t: pp - press_depth(t)[:, None] * up,
            lambda t: falling_release_law(t)[:, None] * up,
            lambda t: (K_CMD * np.maximum(press_depth(t), 0.0))[:, None] * up,
            {"surface_point_m": pp.tolist(), "surface_normal": up.tolist(), "stiffness_N_per_m": K_CMD},
            (1000.0, 500.0, 100.0),
            "parquet",
        ),
    )
    how = (
        "five presses 12 mm deep; force 360 N/m × penetration up to 2.88 N at 8 mm, flat for 2 mm, then falling with "
        "depth to 1.44 N at the bottom; 0.15 N more on the release stroke past the knee (the whole press's largest force, "
        "3.03 N − the weight, "
        f"lies on the release); the device's weight −{WEIGHT_N:g} N throughout. The fit samples, "
        + FIT_RULE
        + ", lie on the 360 N/m part"
    )
    desc = "Edge: a force that falls with depth and is higher on the release stroke (the loading stroke of §13.2)."
    fx.cases += [
        case("stiffness.measured.falling-release", "stiffness.measured", "13.3", fx.name, 360.0, "N/m", "analytic", how, desc),
        case(
            "stiffness.peak_force.falling-release",
            "stiffness.peak_force",
            "13.4",
            fx.name,
            2.88 - WEIGHT_N,
            "N",
            "analytic",
            how + f"; the peak is the loading stroke's largest force, 2.88 − {WEIGHT_N:g} N on its 2 mm plateau",
            desc,
        ),
    ]
    return fx
