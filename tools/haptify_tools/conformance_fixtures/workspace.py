"""The workspace fixtures and cases (spec chapter 8): spheres, rotated boxes, two lobes, occluded, repaired and
capless spheres, a thin slab, the DH model's swept and half workspaces and balls inside and outside it —
every volume (§8.3–§8.7) known in closed form or by quadrature."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from haptify.formats.conventions import quat_from_axis_angle, quat_rotate
from haptify.metrics import volume_operator
from haptify_tools.conformance_fixtures.records import Fixture, case
from haptify_tools.conformance_fixtures.truth import SEED, manifest, rotated_rig_full
from haptify_tools.conformance_fixtures.workspace_shapes import (
    box_cloud,
    joint_box_sweep,
    lens_volume,
    limits,
    pappus_volume,
    placement_of,
    pose_cloud,
    scaled_device,
    sphere_cloud,
    sphere_spiral,
    sphere_sweep,
)
from haptify_tools.example_session import example_rig


def workspace_fixtures() -> list[Fixture]:
    out: list[Fixture] = []
    pitch = volume_operator.PARAMETERS.voxel_pitch_m
    cr = volume_operator.PARAMETERS.closing_radius_m
    model_bias = (
        "the operator reproduces the full-size Touch models' Pappus volumes closely (spec §8.8); the links here "
        "are scaled by 0.45, so the voxels are 2.2× coarser relative to the solid"
    )
    bias = f"the operator's stated bias (spec §8.8: sub-voxel boundary within 0.5 %; h = {pitch} m, r = {cr} m)"
    tiny = scaled_device(0.45)

    # Sphere, Parquet, the Touch's datasheet box.
    R, C = 0.07, (0.013, -0.021, 0.16)

    def sphere(path: Path) -> None:
        w = manifest("conf-ws-sphere", example_rig(), device=tiny)
        pose_cloud(w, "workspace-1", sphere_cloud(6000, R, C, np.random.default_rng(SEED)), "parquet")
        w.write(path)

    fx = Fixture("ws-sphere", sphere)
    v_sphere = 4 / 3 * math.pi * R**3
    fx.cases += [
        case(
            "workspace.measured_volume.sphere",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            v_sphere,
            "m^3",
            "analytic",
            f"4/3·π·R³ of the sphere (R = {R} m) whose surface the 6 000 positions sample; " + bias,
            "Typical: a convex cloud sampled on its boundary.",
        ),
        case(
            "workspace.spec_box_volume.touch",
            "workspace.spec_box_volume",
            "8.6",
            fx.name,
            0.16 * 0.12 * 0.07,
            "m^3",
            "paper",
            "product of the Touch's datasheet box 16 × 12 × 7 cm (paper §IV-A, Table II)",
            "Typical: the manufacturer's box.",
        ),
        case(
            "workspace.modeled_volume.touch-0.45",
            "workspace.modeled_volume",
            "8.3",
            fx.name,
            pappus_volume(tiny),
            "m^3",
            "analytic",
            "Pappus integral of the coupled joint limits of the Touch with links × 0.45 "
            "(V = Δq1·∬|r| a2 a3 |sin q3| dq2 dq3); " + model_bias,
            "Typical: the DH model's reachable set within coupled joint limits.",
        ),
    ]
    out.append(fx)

    # Rotated box, CSV, another datasheet box.
    edges, q_box = (0.12, 0.09, 0.06), quat_from_axis_angle(np.array([0.3, -0.5, 0.8]), np.array(0.7))
    box_dev = scaled_device(0.45, box=(0.16, 0.12, 0.12))

    def box(path: Path) -> None:
        w = manifest("conf-ws-box", rotated_rig_full(), device=box_dev)
        pose_cloud(w, "workspace-1", box_cloud(12_000, edges, np.random.default_rng(SEED + 1), q_box, (0.02, 0.01, 0.15)), "csv")
        w.write(path)

    fx = Fixture("ws-box-rotated-csv", box)
    fx.cases += [
        case(
            "workspace.measured_volume.box-rotated-csv",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            math.prod(edges),
            "m^3",
            "analytic",
            f"edges {edges} m multiplied; the box is turned 0.7 rad about (0.3, −0.5, 0.8) so no face "
            "is parallel to the voxel lattice; " + bias,
            "Tricky: rotated faces, CSV streams.",
        ),
        case(
            "workspace.spec_box_volume.touch-x",
            "workspace.spec_box_volume",
            "8.6",
            fx.name,
            0.16 * 0.12 * 0.12,
            "m^3",
            "paper",
            "product of the Touch X box 16 × 12 × 12 cm (paper §IV-A)",
            "Typical: another datasheet box.",
        ),
    ]
    out.append(fx)

    # Two lobes: non-convex (a convex hull bridges the waist).
    RL, D = 0.05, 0.08

    def lobes(path: Path) -> None:
        rng = np.random.default_rng(SEED + 2)
        a = np.array([0.0, 0.0, 0.15])
        b = a + [D, 0.0, 0.0]
        pts = np.concatenate([sphere_cloud(9000, RL, a, rng), sphere_cloud(9000, RL, b, rng)])
        keep = (np.linalg.norm(pts - a, axis=1) >= RL - 1e-12) & (np.linalg.norm(pts - b, axis=1) >= RL - 1e-12)
        w = manifest("conf-ws-lobes", example_rig(), device=scaled_device(0.45, box=(0.1, 0.1, 0.1)))
        pose_cloud(w, "workspace-1", pts[keep], "parquet")
        w.write(path)

    fx = Fixture("ws-two-lobes", lobes)
    fx.cases += [
        case(
            "workspace.measured_volume.two-lobes",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            2 * 4 / 3 * math.pi * RL**3 - lens_volume(RL, D),
            "m^3",
            "analytic",
            f"union of two balls R = {RL} m, centres {D} m apart: 2·(4/3)πR³ − π(4R+d)(2R−d)²/12; the closing fills the "
            "waist's crease with a fillet of radius r (spec §8.8: +0.5 % on two R = 6 cm lobes); the convex hull is ~9 % larger",
            "Tricky: a non-convex workspace.",
        ),
        case(
            "workspace.spec_box_volume.cube",
            "workspace.spec_box_volume",
            "8.6",
            fx.name,
            1e-3,
            "m^3",
            "analytic",
            "the datasheet box of this device is a 10 cm cube: 0.1³ m³",
            "Edge: a cubic datasheet box.",
        ),
    ]
    out.append(fx)

    # Occluded sweep: long runs of NaN rows (occlusion) must be dropped, nothing interpolated.
    RO, CO = 0.06, (0.0, 0.03, 0.14)

    def occluded(path: Path) -> None:
        pts = sphere_spiral(9000, RO, CO)
        k = np.arange(len(pts))
        pts[(k % 600) < 90] = np.nan  # 15 % of the sweep occluded, in runs of 90 frames
        w = manifest("conf-ws-occluded", example_rig(), device=tiny)
        pose_cloud(w, "workspace-1", pts, "parquet", rate=120.0)
        w.write(path)

    fx = Fixture("ws-sphere-occluded", occluded)
    fx.cases += [
        case(
            "workspace.measured_volume.occluded",
            "workspace.measured_volume",
            "8.7",
            fx.name,
            4 / 3 * math.pi * RO**3,
            "m^3",
            "analytic",
            f"sphere R = {RO} m swept along a spiral at 120 Hz; 15 % of the frames are NaN in runs "
            "of 90; the finite rows still sample the whole surface more densely than 2r; " + bias,
            "Tricky: occlusion gaps (NaN rows are dropped, never interpolated).",
        ),
    ]
    out.append(fx)

    # Two repetitions of a spiral sweep; the first lost a 4 cm band around the equator to one occlusion gap,
    # which the other repetition's positions repair (spec §8.7).
    RR, CR, band_half = 0.06, (0.01, -0.02, 0.15), 0.02

    def repaired(path: Path) -> None:
        w = manifest("conf-ws-repaired", example_rig(), device=tiny)
        first = sphere_sweep(8000, 24, RR, CR, 0.0)
        first[np.abs(first[:, 2] - CR[2]) < band_half] = np.nan
        pose_cloud(w, "workspace-1", first, "parquet", repetition=1)
        pose_cloud(w, "workspace-2", sphere_sweep(8000, 24, RR, CR, math.pi), "parquet", repetition=2)
        w.write(path)

    fx = Fixture("ws-sphere-repaired", repaired)
    fx.cases += [
        case(
            "workspace.measured_volume.occlusion-repaired",
            "workspace.measured_volume",
            "8.7",
            fx.name,
            4 / 3 * math.pi * RR**3,
            "m^3",
            "analytic",
            f"two sweeps of a sphere R = {RR} m along a spiral of 24 turns (1 mm steps at 100 Hz); the first lost the "
            f"band |z − z_c| < {band_half} m to one occlusion gap (4 cm, narrower than 2r: without the repair the closing "
            "bridges it with a groove of about 8 % of that trial's volume, 4 % of the mean). The gap lasts about a third of "
            "the sweep, so its region holds the whole other sweep; the donors farther than 1 cm from the first sweep's "
            "own positions fill the band but for two 1 cm strips, which the closing bridges flat. Both trials are the "
            "sphere: " + bias,
            "Tricky: an occlusion gap repaired from the other repetition.",
        ),
    ]
    out.append(fx)

    # A sweep whose turns lie farther apart than the normal radius: every boundary sample's neighbours lie along one
    # stroke, so the plane fit says nothing of the surface and the sample takes the indicator normal (spec §8.4 step 5).
    RS, CS, turns, noise = 0.1, (0.0, 0.0, 0.15), 20, 1e-4

    def strokes(path: Path) -> None:
        w = manifest("conf-ws-strokes", example_rig(), device=tiny)
        sweep = sphere_sweep(20000, turns, RS, CS, 0.3)
        pose_cloud(w, "workspace-1", sweep + np.random.default_rng(SEED + 9).normal(0.0, noise, sweep.shape), "parquet")
        w.write(path)

    fx = Fixture("ws-sphere-strokes", strokes)
    fx.cases += [
        case(
            "workspace.measured_volume.one-stroke-neighbourhoods",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            4 / 3 * math.pi * RS**3,
            "m^3",
            "analytic",
            f"sphere R = {RS} m swept along a spiral of {turns} turns (1.6 cm apart, more than the normal radius of 4 voxels) "
            f"with white noise of {noise * 1e3:g} mm per axis: each boundary sample's neighbours lie along one stroke and "
            "take the smoothed-indicator normal (min_normal_planarity); their own plane fits, which the stroke's curvature "
            "and the noise turn, would read about 1 % high. " + bias,
            "Tricky: a sparse sweep whose neighbourhoods are lines, not planes.",
        ),
    ]
    out.append(fx)

    # A sweep that missed a cap of the workspace: its 4 cm hole is narrower than 2r, so the closing bridges it.
    RC, CC, rim = 0.07, (0.0, -0.02, 0.15), 0.02

    def capless(path: Path) -> None:
        pts = sphere_cloud(7000, RC, CC, np.random.default_rng(SEED + 6))
        pts = pts[pts[:, 2] - CC[2] <= math.sqrt(RC**2 - rim**2)]
        w = manifest("conf-ws-capless", example_rig(), device=tiny)
        pose_cloud(w, "workspace-1", pts, "csv")
        w.write(path)

    fx = Fixture("ws-sphere-capless-csv", capless)
    h_sphere, h_ball = RC - math.sqrt(RC**2 - rim**2), cr - math.sqrt(cr**2 - rim**2)
    dented = (
        4 / 3 * math.pi * RC**3 - math.pi * h_sphere**2 * (3 * RC - h_sphere) / 3 - math.pi * h_ball**2 * (3 * cr - h_ball) / 3
    )
    fx.cases += [
        case(
            "workspace.measured_volume.capless",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            dented,
            "m^3",
            "analytic",
            f"sphere R = {RC} m sampled on its surface except a polar cap whose rim has radius {rim} m: the hole "
            f"(4 cm across) is narrower than 2r = {2 * cr:g} m, so the closing by a ball of radius r bridges it (§8.4 steps 2–4) "
            "and the solid is the sphere minus its cap above the rim and minus the part of an r-ball resting on the rim "
            "that dips below it (πh²(3R − h)/3 each: 0.5 % of the sphere in all); the dent has no boundary samples, so "
            "it is resolved on the coarse lattice only (≤ 0.2 %); " + bias,
            "Tricky: a sweep that missed a cap.",
        ),
    ]
    out.append(fx)

    # A thin slab, four voxels thick: near the operator's resolution limit of about 2 h (spec §8.8).
    slab, q_slab = (0.12, 0.12, 0.01), quat_from_axis_angle(np.array([0.3, -0.5, 0.8]), np.array(0.7))

    def thin(path: Path) -> None:
        w = manifest("conf-ws-slab", example_rig(), device=tiny)
        pose_cloud(
            w, "workspace-1", box_cloud(20_000, slab, np.random.default_rng(SEED + 7), q_slab, (0.02, 0.01, 0.15)), "parquet"
        )
        w.write(path)

    fx = Fixture("ws-thin-slab", thin)
    fx.cases += [
        case(
            "workspace.measured_volume.thin-slab",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            math.prod(slab),
            "m^3",
            "analytic",
            f"a box of edges {slab} m turned 0.7 rad about (0.3, −0.5, 0.8), 20 000 samples on its faces; "
            f"1 cm is four voxels of h = {pitch} m, twice the operator's resolution limit of about 2 h (spec §8.8): both "
            "faces' samples lie within every band voxel's search radius, so the sub-voxel ramps place both faces; "
            "tolerance 2 %, the bias allowed for a non-convex or thin solid",
            "Edge: a thin workspace.",
        ),
    ]
    out.append(fx)

    # The model swept through its whole boundary, device placed turned and moved (rotated frames).
    mid = scaled_device(0.45)
    placement = placement_of((0.04, -0.03, 0.01), yaw=2.2, tilt=0.15)

    def swept(path: Path) -> None:
        pts = joint_box_sweep(mid, 20_000, np.random.default_rng(SEED + 3))
        pts = quat_rotate(np.asarray(placement["quaternion"]), pts) + np.asarray(placement["position"])
        w = manifest("conf-ws-swept", rotated_rig_full(), device=mid, placement=placement)
        pose_cloud(w, "workspace-1", pts, "parquet")
        w.write(path)

    fx = Fixture("ws-model-swept-placed", swept)
    fx.cases += [
        case(
            "workspace.modeled_volume.placed",
            "workspace.modeled_volume",
            "8.3",
            fx.name,
            pappus_volume(mid),
            "m^3",
            "analytic",
            "Pappus integral of the model's joint limits; a placement (turned 2.2 rad about z, tilted 0.15 rad) "
            "moves the solid, not its volume; " + model_bias,
            "Tricky: rotated device placement.",
        ),
        case(
            "workspace.volume_ratio.full-sweep",
            "workspace.volume_ratio",
            "8.5",
            fx.name,
            1.0,
            "1",
            "analytic",
            "the measured positions are the model's own boundary (joint-limit faces) placed by device_placement; both "
            "solids come from the same operator, so the ratio is 1 within the two samplings' biases (each below 0.5 % "
            "at this scale)",
            "Typical: a complete boundary sweep.",
        ),
        case(
            "workspace.coverage.full-sweep",
            "workspace.coverage",
            "8.5",
            fx.name,
            1.0,
            "1",
            "analytic",
            "the measured sweep covers the placed model entirely; an implementation that ignores device_placement "
            "(turned 2.2 rad) finds far less overlap",
            "Tricky: coverage needs the placement applied.",
        ),
        case(
            "workspace.measured_volume.model-sweep",
            "workspace.measured_volume",
            "8.4",
            fx.name,
            pappus_volume(mid),
            "m^3",
            "analytic",
            "the measured sweep of the model's boundary encloses the model's reachable set (Pappus); "
            "non-convex (the coupled q3 limit carves the inner side)",
            "Typical: a device-shaped, non-convex sweep.",
        ),
    ]
    out.append(fx)

    # Half the model swept (q1 ≥ 0): by Pappus the volume is exactly Δq1-proportional, so ratio = coverage = 1/2.
    def half(path: Path) -> None:
        q1hi = limits(mid)[1]
        pts = joint_box_sweep(mid, 14_000, np.random.default_rng(SEED + 4), q1_range=(0.0, q1hi))
        w = manifest("conf-ws-half", example_rig(), device=mid)
        pose_cloud(w, "workspace-1", pts, "csv")
        w.write(path)

    fx = Fixture("ws-model-half-csv", half)
    q1lo, q1hi = limits(mid)[:2]
    half_share = q1hi / (q1hi - q1lo)
    fx.cases += [
        case(
            "workspace.volume_ratio.half",
            "workspace.volume_ratio",
            "8.5",
            fx.name,
            half_share,
            "1",
            "analytic",
            "the examiner swept only q1 ∈ [0, 56°] of [−56°, 56°]; the volume of a solid of revolution is proportional to "
            "its angle (Pappus), so measured/modeled = 1/2",
            "Edge: half of the workspace reached.",
        ),
        case(
            "workspace.coverage.half",
            "workspace.coverage",
            "8.5",
            fx.name,
            half_share,
            "1",
            "analytic",
            "the half solid lies inside the model: the overlap is the half solid itself, 1/2 of the model",
            "Edge: partial coverage.",
        ),
        case(
            "workspace.modeled_volume.csv",
            "workspace.modeled_volume",
            "8.3",
            fx.name,
            pappus_volume(mid),
            "m^3",
            "analytic",
            "Pappus integral of the model's joint limits (identity placement, CSV session); " + model_bias,
            "Edge: the model of a CSV session.",
        ),
    ]
    out.append(fx)

    def ball_session(sid: str, n: int, radius: float, centre: tuple, seed: int) -> Callable[[Path], None]:
        """A workspace trial whose cloud samples the surface of one ball, with the mid-size model."""

        def build(path: Path) -> None:
            w = manifest(sid, example_rig(), device=mid)
            pose_cloud(w, "workspace-1", sphere_cloud(n, radius, centre, np.random.default_rng(seed)), "parquet")
            w.write(path)

        return build

    # Ratio below and above 1 by construction: a ball inside the model of known volume.
    fx = Fixture("ws-ball-in-model", ball_session("conf-ws-ball", 6000, 0.02, (0.07, 0.0, 0.02), SEED + 5))
    v_ball = 4 / 3 * math.pi * 0.02**3
    fx.cases += [
        case(
            "workspace.volume_ratio.ball",
            "workspace.volume_ratio",
            "8.5",
            fx.name,
            v_ball / pappus_volume(mid),
            "1",
            "analytic",
            "a ball R = 2 cm (4/3πR³) divided by the model's Pappus volume; tolerance = both operators' biases",
            "Tricky: a small measured solid against the model.",
        ),
        case(
            "workspace.coverage.ball",
            "workspace.coverage",
            "8.5",
            fx.name,
            v_ball / pappus_volume(mid),
            "1",
            "analytic",
            "the ball (centre (7, 0, 2) cm, R = 2 cm) lies inside the reachable set, so the overlap is the ball",
            "Tricky: coverage of an interior solid.",
        ),
    ]
    out.append(fx)

    # A solid outside the model: coverage (the overlap, §8.5) is 0 while the volume ratio is not.
    fx = Fixture("ws-ball-outside-model", ball_session("conf-ws-ball-outside", 8000, 0.03, (0.0, 0.0, 0.45), SEED + 6))
    v_out = 4 / 3 * math.pi * 0.03**3
    fx.cases += [
        case(
            "workspace.volume_ratio.ball-outside",
            "workspace.volume_ratio",
            "8.5",
            fx.name,
            v_out / pappus_volume(mid),
            "1",
            "analytic",
            "a ball R = 3 cm (4/3πR³) divided by the model's Pappus volume",
            "Tricky: a solid the model does not contain.",
        ),
        case(
            "workspace.coverage.ball-outside",
            "workspace.coverage",
            "8.5",
            fx.name,
            0.0,
            "1",
            "analytic",
            "the ball (centre (0, 0, 45) cm, R = 3 cm) lies far outside the reachable set (under 15 cm from the base): no "
            "overlap; the volume ratio would be 0.093",
            "Tricky: coverage of a solid outside the model.",
        ),
    ]
    out.append(fx)
    return out
