"""The sessions of a conformance challenge and their known answers (spec §17.8): one generator per metric
family the reference computes — workspace (chapter 8), free space (9), vibration (10), local dynamics (11),
frictionless surface (12), stiffness (13) and the rig (14) — each writing a session with the conformance
suite's fixture generators (:mod:`haptify_tools.conformance_fixtures`) from values drawn from the
challenge's secret seed, and returning its cases' answers, known by construction."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from haptify.dynamics import parameter_file
from haptify.formats.conventions import quat_from_axis_angle
from haptify.versions import SPEC_VERSION
from haptify_tools import rig_builders as rb
from haptify_tools.conformance_fixtures.dynamics import LineMotion, Prediction, prediction_fixture
from haptify_tools.conformance_fixtures.records import Fixture
from haptify_tools.conformance_fixtures.rig import calibration_rms, impact_peaks
from haptify_tools.conformance_fixtures.stiffness import DEPTH, spring_fixture
from haptify_tools.conformance_fixtures.surface import surface_fixture
from haptify_tools.conformance_fixtures.truth import QUIET, circle, handle_trial, manifest, rotated_rig_full
from haptify_tools.conformance_fixtures.truth import spin as spin_motion
from haptify_tools.conformance_fixtures.vibration import tones_centroid, tones_rms, write_vibration_session
from haptify_tools.conformance_fixtures.workspace_shapes import pappus_volume, pose_cloud, scaled_device, sphere_cloud
from haptify_tools.example_session import example_rig
from haptify_tools.registry.checks import tolerances

Truth = tuple[str, Any, str, dict]  # metric, expected value (number or list), unit, case parameters
RATES_HZ = (1000.0, 1500.0, 2000.0)  # accelerometer rates of a vibration session
SECONDS = (4.0, 6.0)
LOWEST_HZ = 20  # well above the 10 Hz high-pass cut-off (§10.2): the filter's gain is then analytic to < 1e-4


@dataclass(frozen=True)
class ChallengeCase:
    """One case of a challenge: public id, metric, session folder (relative to the archive), parameters and
    the secret expected value with its tolerance (spec §17.8)."""

    id: str
    metric: str
    session: str
    expected: float | list[float]
    unit: str
    tolerance: dict[str, float]
    parameters: dict = field(default_factory=dict)

    @property
    def family(self) -> str:
        return self.metric.split(".", 1)[0]

    def public(self) -> dict:
        """What the implementation is told: id, metric, session folder, parameters, unit; never the expected value."""
        return {"id": self.id, "metric": self.metric, "session": self.session, "parameters": self.parameters, "unit": self.unit}


def _fmt(rng: np.random.Generator) -> str:
    return "csv" if rng.random() < 0.5 else "parquet"


def _rig_kind(rng: np.random.Generator) -> str:
    return "rotated" if rng.random() < 0.5 else "example"


def _round(x, digits: int) -> Any:
    return np.round(np.asarray(x, float), digits).tolist()


def _fixture_truths(fx: Fixture, path: Path) -> list[Truth]:
    """Write a fixture of the suite's generators and return its cases' known answers."""
    fx.build(path)
    return [(c["metric"], c["expected"]["value"], c["expected"]["unit"], c["parameters"]) for c in fx.cases]


def _tones(rng: np.random.Generator, rate: float) -> dict[int, list[tuple[float, float]]]:
    """One to three tones on one to three axes: integer frequencies in [LOWEST_HZ, 0.45·rate], amplitudes
    0.01–0.2 m/s² (rounded, so the session files carry them exactly)."""
    out: dict[int, list[tuple[float, float]]] = {}
    for _ in range(int(rng.integers(1, 4))):
        axis = int(rng.integers(0, 3))
        f = float(rng.integers(LOWEST_HZ, int(0.45 * rate)))
        amp = round(float(rng.uniform(0.01, 0.2)), 4)
        if all(f != g for tones in out.values() for g, _ in tones):  # one frequency once: the power adds per tone
            out.setdefault(axis, []).append((f, amp))
    return out


def workspace(rng: np.random.Generator, path: Path, sid: str) -> list[Truth]:
    """Chapter 8: a sphere of drawn radius and centre sampled on its surface (measured volume 4/3·π·R³), a
    Touch-type device with drawn link scale (modeled volume: the Pappus integral of its joint limits) and
    datasheet box (the product of its edges)."""
    radius, centre = round(float(rng.uniform(0.05, 0.08)), 4), _round(rng.uniform([-0.02, -0.02, 0.13], [0.02, 0.02, 0.17]), 3)
    box = _round(rng.uniform(0.06, 0.2, 3), 3)
    device = scaled_device(round(float(rng.uniform(0.45, 0.55)), 3), box=box)
    w = manifest(sid, example_rig(), device=device)
    pose_cloud(w, "workspace-1", sphere_cloud(6000, radius, centre, rng), _fmt(rng))
    w.write(path)
    return [
        ("workspace.measured_volume", 4 / 3 * math.pi * radius**3, "m^3", {}),
        ("workspace.spec_box_volume", math.prod(box), "m^3", {}),
        ("workspace.modeled_volume", pappus_volume(device), "m^3", {}),
    ]


def free_space(rng: np.random.Generator, path: Path, sid: str) -> list[Truth]:
    """Chapter 9: a drawn constant force on the hand (mean, min and max |F|, SD 0) under a connector's
    weight and bias, the gimbal centre on a drawn circle (speed r·ω), a drawn spin rate, and a drawn
    constant horizontal plate force on top of the plate bias."""
    truth = rb.HandleTruth(force_noise=0.0, torque_noise=0.0, accel_noise=0.0, mass=0.06)
    rig = example_rig() if _rig_kind(rng) == "example" else rotated_rig_full()
    bias = rb.plate_bias_vector(rig)
    force = np.array(_round(rng.uniform(0.2, 1.0, 3) * rng.choice([-1.0, 1.0], 3), 3))
    radius, omega = round(float(rng.uniform(0.03, 0.06)), 3), round(float(rng.uniform(0.5, 2.0)), 2)
    spin, side, down = (
        round(float(rng.uniform(0.05, 0.3)), 3),
        round(float(rng.uniform(0.1, 0.8)), 3),
        round(float(rng.uniform(12, 20)), 2),
    )
    rates = ((500.0, 500.0, 100.0), (400.0, 250.0, 120.0))[int(rng.integers(0, 2))]
    w = manifest(sid, rig, truth=truth, plate_bias=bias)
    handle_trial(
        w,
        "free_space-1",
        "free_space",
        duration_s=8.0,
        position=circle(radius, omega, (0.0, 0.03, 0.14)),
        quaternion=spin_motion(spin),
        force_w=lambda t: np.tile(force, (len(t), 1)),
        truth=truth,
        rates=rates,
        fmt=_fmt(rng),
        plate_force_w=lambda t: np.tile([0.0, side, -down], (len(t), 1)),
        plate_bias=bias,
    )
    w.write(path)
    size = float(np.linalg.norm(force))
    return [
        ("free_space.force_mean", size, "N", {}),
        ("free_space.force_sd", 0.0, "N", {}),
        ("free_space.force_min", size, "N", {}),
        ("free_space.force_max", size, "N", {}),
        ("free_space.plate_force_mean", side, "N", {}),
        ("free_space.speed_mean", radius * omega, "m/s", {}),
        ("free_space.angular_speed_mean", spin, "rad/s", {}),
    ]


def vibration(rng: np.random.Generator, path: Path, sid: str) -> list[Truth]:
    """Chapter 10: drawn tones (frequencies, amplitudes, axes) in a free-space and a baseline trial at a drawn
    accelerometer rate and length; answers :func:`~haptify_tools.conformance_fixtures.vibration.tones_rms` and
    :func:`~haptify_tools.conformance_fixtures.vibration.tones_centroid` of the tones."""
    rate, secs = float(rng.choice(RATES_HZ)), float(rng.choice(SECONDS))
    fmt, rig_kind = _fmt(rng), _rig_kind(rng)
    fs_tones, base_tones = _tones(rng, rate), _tones(rng, rate)
    write_vibration_session(path, sid, fmt, rate, secs, fs_tones, base_tones, rig_kind)
    fs_all = [t for ts in fs_tones.values() for t in ts]
    base_all = [t for ts in base_tones.values() for t in ts]
    return [
        ("vibration.rms", tones_rms(fs_all), "m/s^2", {}),
        ("vibration.spectral_centroid", tones_centroid(fs_all), "Hz", {}),
        ("vibration.baseline_rms", tones_rms(base_all), "m/s^2", {}),
        ("vibration.baseline_centroid", tones_centroid(base_all), "Hz", {}),
    ]


def dynamics(rng: np.random.Generator, path: Path, sid: str) -> list[Truth]:
    """Chapter 11 (prediction from a given parameter file, §11.3, §11.6, §11.7): a training trial on a drawn
    straight line at constant velocity with a drawn orientation and a force linear in time, a test trial
    moved by a drawn distance perpendicular to the velocity, and one of the suite's H-W parameter files."""
    v = np.array(_round(rng.uniform(-0.003, 0.003, 3), 4))
    away = rng.normal(size=3)
    away -= (away @ v) / (v @ v) * v  # perpendicular: every test window's nearest training window is its twin
    shift = away / np.linalg.norm(away) * parameter_file.PARAMETERS.R_p * float(rng.uniform(0.3, 1.0))
    q = quat_from_axis_angle(rng.normal(size=3), np.array(float(rng.uniform(0.0, 1.0))))
    motion = LineMotion(
        np.array(_round(rng.uniform([-0.05, -0.03, 0.11], [0.05, 0.03, 0.16]), 3)),
        v,
        q,
        np.array(_round(rng.uniform(-0.3, 0.3, 3), 3)),
        np.array(_round(rng.uniform(-0.01, 0.01, 3), 4)),
    )
    pr = Prediction(
        sid.removeprefix("conf-"),
        _fmt(rng),
        _rig_kind(rng),
        motion,
        shift,
        np.array(_round(rng.uniform(-0.5, 0.5, 3), 3)),
        "registry challenge",
        models=(str(rng.choice(["a", "b", "c"])),),
    )
    return _fixture_truths(prediction_fixture(pr), path)


def surface(rng: np.random.Generator, path: Path, sid: str) -> list[Truth]:
    """Chapter 12: a drawn planar force (level, swing, frequency) against the hand's circling during one
    contact of drawn span with a plane of drawn tilt; mean and SD over the guarded contact rows. The planar
    force runs on unchanged outside contact (no step: a step's ringing past the guard moved a drawn SD of
    0.0104 N by 0.0004 N, beyond the 1 % tolerance)."""
    on = round(float(rng.uniform(0.8, 1.5)), 2)
    off = round(on + float(rng.uniform(4.0, 6.0)), 2)
    level, swing, freq = (
        round(float(rng.uniform(0.2, 0.6)), 3),
        round(float(rng.uniform(0.05, 0.15)), 3),
        round(float(rng.uniform(0.2, 0.5)), 2),
    )
    rates = ((1000.0, 500.0, 100.0), (400.0, 250.0, 150.0))[int(rng.integers(0, 2))]
    fx = surface_fixture(
        sid.removeprefix("conf-"),
        _fmt(rng),
        _rig_kind(rng),
        _round(rng.uniform(-0.3, 0.3, 2), 2) + [1.0],
        (0.0, round(float(rng.uniform(0.0, 0.05)), 3), round(float(rng.uniform(0.09, 0.12)), 3)),
        ((on, off),),
        round(off + 1.0, 2),
        lambda t: level + swing * np.sin(2 * np.pi * freq * t),
        rates,
        "registry challenge",
        0.0,
        outside=None,
    )
    return _fixture_truths(fx, path)


def stiffness(rng: np.random.Generator, path: Path, sid: str) -> list[Truth]:
    """Chapter 13: five presses into a plane of drawn tilt of a spring of drawn stiffness that saturates at a
    drawn force (measured stiffness, accuracy against the rendered 750 N/m, peak force)."""
    k = round(float(rng.uniform(300.0, 650.0)), 1)
    peak = round(k * DEPTH * float(rng.uniform(0.6, 0.75)), 3)
    rates = ((1000.0, 500.0, 100.0), (400.0, 250.0, 150.0))[int(rng.integers(0, 2))]
    fx = spring_fixture(
        sid.removeprefix("conf-"),
        _fmt(rng),
        _rig_kind(rng),
        _round(rng.uniform(-0.2, 0.2, 2), 2) + [1.0],
        (0.0, round(float(rng.uniform(0.0, 0.04)), 3), round(float(rng.uniform(0.09, 0.12)), 3)),
        k,
        peak,
        None,
        rates,
        "registry challenge",
    )
    return _fixture_truths(fx, path)


def rig(rng: np.random.Generator, path: Path, sid: str) -> list[Truth]:
    """Chapter 14: a handle calibration trial with drawn recorder delays (whole ms), a noise-free ball drop
    ringing at drawn plate modes (answer: the §14.4 procedure applied to the known ringing, as the suite's
    clean impact case), and a weight whose marker sits a drawn offset from each load point.

    The handle sensors are noise-free (the suite's quiet rig: calibration residuals only the filters' end
    effects): with drawn white noise the reference's §14.6 lag estimate strays up to 0.4 ms from the true
    delay on some draws (24 s trials), beyond the suite's 0.3 ms budget, so noisy sensors would fail the
    reference itself."""
    kind = ("rotated", "example", "rotated-plate")[int(rng.integers(0, 3))]
    setup = {"rotated": rb.rotated_rig, "example": example_rig, "rotated-plate": rotated_rig_full}[kind]()
    setup["motion_capture"]["markers"] = sorted(set(setup["motion_capture"]["markers"]) | {"w1"})
    delays = [int(d) / 1000 for d in rng.integers(-4, 5, 2)]
    modes, zeta = _round(rng.uniform(140.0, 260.0, 3), 1), round(float(rng.uniform(0.02, 0.05)), 3)
    offsets = rng.uniform(0.0, 0.015, 3)[:, None] * np.column_stack([np.cos(a := rng.uniform(0, 2 * np.pi, 3)), np.sin(a)])
    w = rb.writer(rig=setup, sid=sid)
    rb.add_calibration_trial(w, QUIET, rng, duration_s=12.0, accel_delay_s=delays[0], mocap_delay_s=delays[1])
    rb.add_plate_bias_trial(w, rng)
    rb.add_impact_trial(w, rng, modes=modes, zeta=zeta, noise=0.0)
    rb.add_cop_trial(w, rng, np.array([[0.0, 0.0], [0.2, 0.1], [-0.2, -0.2]]), offsets)
    w.write(path)
    t = np.arange(3000) / 1000.0  # the impact trial of rig_builders.add_impact_trial: 3 s at 1 kHz, amplitudes 4, 3, 20 N
    ringing = np.column_stack([rb.damped(t, f, zeta, 1.0, a) for f, a in zip(modes, (4.0, 3.0, 20.0))])
    return [
        ("rig.plate_natural_frequency", impact_peaks(t, ringing, 1000.0), "Hz", {}),
        ("rig.cop_error", float(np.linalg.norm(offsets, axis=1).mean()), "m", {}),
        ("rig.sync_offset", max(abs(d) for d in delays), "s", {}),
        ("rig.handle_calibration_rms", calibration_rms(QUIET), "[N, m/s^2, N*m]", {}),
    ]


FAMILIES: dict[str, Callable[[np.random.Generator, Path, str], list[Truth]]] = {
    "workspace": workspace,
    "free_space": free_space,
    "vibration": vibration,
    "dynamics": dynamics,
    "surface": surface,
    "stiffness": stiffness,
    "rig": rig,
}


def generate(seed: int, root: Path, tag: str, families: tuple[str, ...] = tuple(FAMILIES)) -> list[ChallengeCase]:
    """Write the challenge's sessions under ``root`` — one folder per family, named after it — and return its
    cases (spec §17.8).

    Deterministic in ``seed``; ``tag`` (the challenge id) makes the case ids and session ids unique to
    this challenge. Each family draws from its own stream of the seed.
    """
    tol = tolerances(SPEC_VERSION)
    cases: list[ChallengeCase] = []
    for k, family in enumerate(families):
        rng = np.random.default_rng([seed, k])
        truths = FAMILIES[family](rng, root / family, f"conf-challenge-{tag}-{family}".replace("_", "-"))
        for metric, expected, unit, parameters in truths:
            expected = [float(x) for x in expected] if isinstance(expected, (list, tuple, np.ndarray)) else float(expected)
            cases.append(
                ChallengeCase(f"challenge-{tag}.{metric}", metric, family, expected, unit, dict(tol[metric]), dict(parameters))
            )
    return cases
