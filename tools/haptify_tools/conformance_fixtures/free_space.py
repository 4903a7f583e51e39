"""The free-space fixtures and cases (spec chapter 9): constant and analytic forces on the hand (§9.2), plate
forces (§9.3) and speeds (§9.4) on circles and spins, rotated and CSV sessions and occlusion gaps."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from haptify_tools import rig_builders as rb
from haptify_tools.conformance_fixtures.free_space_processing import glimpse_fixture, jitter_fixture, pushes_fixture
from haptify_tools.conformance_fixtures.records import Fixture, case
from haptify_tools.conformance_fixtures.truth import circle, grid, handle_trial, manifest, rotated_rig_full, spin
from haptify_tools.conformance_fixtures.workspace_shapes import placement_of
from haptify_tools.example_session import example_rig


def felt(t: np.ndarray) -> np.ndarray:
    """|F| = √(0.5² + 0.4² + (0.3 + 0.2 sin 0.5t)²): min at sin = −1, max at sin = +1 (both reached in 12 s)."""
    return np.column_stack([0.5 + 0 * t, -0.4 + 0 * t, 0.3 + 0.2 * np.sin(0.5 * t)])


def plate_truth(t: np.ndarray) -> np.ndarray:
    return np.column_stack([0.2 * np.cos(0.3 * t), 0 * t, -17.4 + 0.3 * np.sin(0.5 * t)])


def free_space_fixtures() -> list[Fixture]:
    out: list[Fixture] = []
    sec_f, sec_p, sec_s = "9.2", "9.3", "9.4"
    truth = rb.HandleTruth(force_noise=0.0, torque_noise=0.0, accel_noise=0.0, mass=0.06)
    T = 12.0
    tg = grid(T)
    mag = np.linalg.norm(felt(tg), axis=1)
    P = plate_truth(tg)
    plate_dev = np.linalg.norm(P - np.array([0.0, 0.0, P[:, 2].mean()]), axis=1)

    def typical(path: Path) -> None:
        rig = example_rig()
        bias = rb.plate_bias_vector(rig)
        w = manifest("conf-fs-typical", rig, truth=truth, plate_bias=bias)
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=T,
            position=circle(0.05, 1.0),
            quaternion=spin(0.07),
            force_w=felt,
            truth=truth,
            plate_force_w=plate_truth,
            plate_bias=bias,
        )
        w.write(path)

    fx = Fixture("fs-typical", typical)
    weight = (
        f"the raw F/T stream holds a {truth.mass} kg connector's weight and a bias, removed by the handle_gravity record "
        "(spec §6.5)"
    )
    fx.cases += [
        case(
            "free_space.force_mean.typical",
            "free_space.force_mean",
            sec_f,
            fx.name,
            mag.mean(),
            "N",
            "analytic",
            "mean over the 100 Hz grid (t = 0 … 12 s) of |(0.5, −0.4, 0.3 + 0.2 sin 0.5t)| N; " + weight,
            "Typical: a slowly varying force on the hand.",
        ),
        case(
            "free_space.force_sd.typical",
            "free_space.force_sd",
            sec_f,
            fx.name,
            mag.std(ddof=1),
            "N",
            "analytic",
            "sample SD (ddof 1) of the same magnitudes on the grid",
            "Typical.",
        ),
        case(
            "free_space.force_min.typical",
            "free_space.force_min",
            sec_f,
            fx.name,
            math.hypot(0.5, 0.4, 0.1),
            "N",
            "analytic",
            "|(0.5, −0.4, 0.1)|: sin 0.5t reaches −1 at t = 3π",
            "Typical.",
        ),
        case(
            "free_space.force_max.typical",
            "free_space.force_max",
            sec_f,
            fx.name,
            math.hypot(0.5, 0.4, 0.5),
            "N",
            "analytic",
            "|(0.5, −0.4, 0.5)|: sin 0.5t reaches +1 at t = π",
            "Typical.",
        ),
        case(
            "free_space.plate_force_mean.typical",
            "free_space.plate_force_mean",
            sec_p,
            fx.name,
            plate_dev.mean(),
            "N",
            "analytic",
            "mean on the grid of |P − (0, 0, mean P_z)| for P = (0.2 cos 0.3t, 0, −17.4 + 0.3 sin 0.5t) N, "
            "split over the four corner sensors (statically determinate) on top of the recorded plate bias",
            "Typical.",
        ),
        case(
            "free_space.speed_mean.typical",
            "free_space.speed_mean",
            sec_s,
            fx.name,
            0.05,
            "m/s",
            "analytic",
            "gimbal centre on a circle of radius 0.05 m at 1 rad/s: speed r·ω",
            "Typical: uniform circular motion.",
        ),
        case(
            "free_space.angular_speed_mean.typical",
            "free_space.angular_speed_mean",
            sec_s,
            fx.name,
            0.07,
            "rad/s",
            "analytic",
            "handle turning at a constant 0.07 rad/s about a fixed axis",
            "Typical.",
        ),
    ]
    out.append(fx)

    # Rotated rig frames, CSV, unusual rates, constant force (SD zero, min = max = mean).
    F0 = np.array([0.3, 0.6, -0.9])

    def rotated(path: Path) -> None:
        rig = rotated_rig_full()
        bias = rb.plate_bias_vector(rig)
        w = manifest("conf-fs-rotated", rig, truth=truth, plate_bias=bias, placement=placement_of((0.02, 0.0, 0.0), yaw=1.0))
        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=10.0,
            position=circle(0.04, 2.0, (0.01, 0.0, 0.15)),
            quaternion=spin(0.11, axis=(1.0, 0.4, 0.2), tilt=2.5),
            force_w=lambda t: np.tile(F0, (len(t), 1)),
            truth=truth,
            rates=(400.0, 250.0, 120.0),
            fmt="csv",
            plate_force_w=lambda t: np.column_stack([0 * t, 0.4 + 0 * t, -15.0 + 0 * t]),
            plate_bias=bias,
        )
        w.write(path)

    fx = Fixture("fs-rotated-csv", rotated)
    f0 = float(np.linalg.norm(F0))
    rot = "handle F/T and accelerometer frames turned (90° about z, 180° about x), corner sensors yawed 0/90/180/270°"
    fx.cases += [
        case(
            "free_space.force_mean.rotated-csv",
            "free_space.force_mean",
            sec_f,
            fx.name,
            f0,
            "N",
            "analytic",
            f"constant force (0.3, 0.6, −0.9) N on the hand in W; {rot}; F/T at 500 Hz, mocap at 120 Hz",
            "Tricky: rotated rig frames, CSV, unusual rates.",
        ),
        case(
            "free_space.force_sd.constant",
            "free_space.force_sd",
            sec_f,
            fx.name,
            0.0,
            "N",
            "analytic",
            "a constant force has SD 0 (tolerance: the rounding of the calibration under rotation)",
            "Edge: zero spread.",
        ),
        case(
            "free_space.force_min.constant",
            "free_space.force_min",
            sec_f,
            fx.name,
            f0,
            "N",
            "analytic",
            "min of |F| over the trial equals |F| = |(0.3, 0.6, −0.9)| N of the constant force",
            "Edge.",
        ),
        case(
            "free_space.force_max.constant",
            "free_space.force_max",
            sec_f,
            fx.name,
            f0,
            "N",
            "analytic",
            "max of |F| over the trial equals |F| = |(0.3, 0.6, −0.9)| N of the constant force",
            "Edge.",
        ),
        case(
            "free_space.plate_force_mean.rotated-corners",
            "free_space.plate_force_mean",
            sec_p,
            fx.name,
            0.4,
            "N",
            "analytic",
            "constant plate force (0, 0.4, −15) N; removing the mean vertical leaves |(0, 0.4, 0)|; corner sensors "
            "yawed by 0/90/180/270° must be rotated into W",
            "Tricky: rotated corner frames.",
        ),
        case(
            "free_space.speed_mean.rotated-csv",
            "free_space.speed_mean",
            sec_s,
            fx.name,
            0.08,
            "m/s",
            "analytic",
            "circle r = 0.04 m at 2 rad/s sampled at 120 Hz: speed 0.08 m/s",
            "Tricky: unusual mocap rate.",
        ),
        case(
            "free_space.angular_speed_mean.rotated-csv",
            "free_space.angular_speed_mean",
            sec_s,
            fx.name,
            0.11,
            "rad/s",
            "analytic",
            "constant rotation at 0.11 rad/s about (1, 0.4, 0.2) from a 2.5 rad tilt",
            "Tricky: large tilt.",
        ),
    ]
    out.append(fx)

    # Occlusion gaps: one long gap (never interpolated across) and short ones (bridged).
    def occlusion(path: Path) -> None:
        rig = example_rig()
        bias = rb.plate_bias_vector(rig)
        w = manifest("conf-fs-occluded", rig, truth=truth, plate_bias=bias)

        def gone(t: np.ndarray) -> np.ndarray:
            k = np.round(t * 100).astype(int)
            return ((t > 3.0) & (t < 6.0)) | (k % 150 == 77) | (k % 150 == 78)

        handle_trial(
            w,
            "free_space-1",
            "free_space",
            duration_s=12.0,
            position=circle(0.05, 1.0),
            quaternion=spin(0.2),
            force_w=lambda t: np.column_stack([0.2 + 0 * t, 0.1 * np.sin(t), 0 * t]),
            truth=truth,
            occluded=gone,
            plate_force_w=lambda t: np.column_stack([0 * t, 0 * t, -16.0 + 0.5 * np.sin(2 * t)]),
            plate_bias=bias,
        )
        w.write(path)

    fx = Fixture("fs-occlusion-gaps", occlusion)
    tg = grid(12.0)
    usable = ~((tg > 3.0 + 1e-9) & (tg < 6.0 - 1e-9))  # the samples at 3.00 s and 6.00 s are valid
    m_occ = np.hypot(0.2, 0.1 * np.sin(tg[usable]))
    fx.cases += [
        case(
            "free_space.speed_mean.occlusion",
            "free_space.speed_mean",
            sec_s,
            fx.name,
            0.05,
            "m/s",
            "analytic",
            "circle r = 0.05 m at 1 rad/s; motion capture lost for 3 s (t = 3 … 6 s: a 3 rad arc whose chord is 30 % shorter) "
            "and for two frames every 1.5 s; only the short gaps may be bridged (spec §7.4), so the speed is r·ω",
            "Tricky: occlusion gaps (interpolating across the long one lowers the speed).",
        ),
        case(
            "free_space.angular_speed_mean.occlusion",
            "free_space.angular_speed_mean",
            sec_s,
            fx.name,
            0.2,
            "rad/s",
            "analytic",
            "constant rotation at 0.2 rad/s; the rows of the 3 s gap are excluded, the two-frame gaps bridged by slerp",
            "Tricky: occlusion gaps.",
        ),
        case(
            "free_space.force_mean.occlusion",
            "free_space.force_mean",
            sec_f,
            fx.name,
            m_occ.mean(),
            "N",
            "analytic",
            "mean of |(0.2, 0.1 sin t, 0)| over the grid rows where motion capture is usable (t outside the 3 s gap): the "
            "force is used only where the handle orientation is known (spec §7.5)",
            "Tricky: usable samples only.",
        ),
        case(
            "free_space.force_sd.occlusion",
            "free_space.force_sd",
            sec_f,
            fx.name,
            m_occ.std(ddof=1),
            "N",
            "analytic",
            "sample SD (ddof 1) of |(0.2, 0.1 sin t, 0)| over the usable grid rows",
            "Tricky: usable samples only.",
        ),
        case(
            "free_space.force_min.occlusion",
            "free_space.force_min",
            sec_f,
            fx.name,
            m_occ.min(),
            "N",
            "analytic",
            "minimum of |(0.2, 0.1 sin t, 0)| over the usable rows (0.2 N where sin t = 0)",
            "Tricky: usable samples only.",
        ),
        case(
            "free_space.force_max.occlusion",
            "free_space.force_max",
            sec_f,
            fx.name,
            m_occ.max(),
            "N",
            "analytic",
            "maximum of |(0.2, 0.1 sin t, 0)| over the usable rows (√0.05 N where sin t = ±1)",
            "Tricky: usable samples only.",
        ),
        case(
            "free_space.plate_force_mean.sinusoid",
            "free_space.plate_force_mean",
            sec_p,
            fx.name,
            float(np.mean(np.abs(0.5 * np.sin(2 * grid(12.0)) - np.mean(0.5 * np.sin(2 * grid(12.0)))))),
            "N",
            "analytic",
            "vertical plate force −16 + 0.5 sin 2t N: mean of |P_z − mean P_z| over the grid; the plate stream has no occlusion",
            "Edge: a purely vertical oscillation.",
        ),
    ]
    out.append(fx)
    out.append(jitter_fixture(truth))
    out.append(glimpse_fixture(truth))
    out.append(pushes_fixture(truth))
    return out
