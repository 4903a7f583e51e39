"""Mutants of the workspace (spec chapter 8): the hull, the device placement, hole filling, the voxel pitch, the
closing radius, occlusion repair, the box volume's unit and the coverage."""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull

from haptify.formats.conventions import quat_conjugate, quat_rotate
from haptify.metrics import volume_operator, workspace
from haptify_mutants.catalogue.model import Mutant, Patch, _parameters, _post, _replace


def _hull_solid(real: Callable) -> Callable:
    """The convex hull's volume instead of the §8.4 voxel operator (the solid scaled to the hull)."""

    def volume_solid(points: np.ndarray, **kw: Any) -> Any:
        solid = real(points, **kw)
        hull = ConvexHull(np.asarray(points, dtype=float)).volume
        return dataclasses.replace(solid, fraction=solid.fraction * (hull / solid.volume))

    return volume_solid


def _placement_inverted(real: Callable) -> Callable:
    """device_placement applied inverted (read as the pose of W in the device frame)."""

    def modeled_solid(
        kin: Any, placement_position: Any = (0.0, 0.0, 0.0), placement_quaternion: Any = (1.0, 0.0, 0.0, 0.0)
    ) -> Any:
        conj = quat_conjugate(np.asarray(placement_quaternion, dtype=float))
        return real(kin, -quat_rotate(conj, np.asarray(placement_position, dtype=float)), conj)

    return modeled_solid


MUTANTS: tuple[Mutant, ...] = (
    # workspace
    Mutant(
        "convex_hull",
        "8.4",
        "R8.4-1",
        "volumes come from the voxel operator",
        "the convex hull's volume",
        (Patch(workspace, "volume_solid", _hull_solid),),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "device_placement_ignored",
        "8.3",
        "R8.2-1",
        "the modeled workspace is placed in W by device_placement",
        "left in the device frame",
        (Patch(workspace, "modeled_solid", lambda real: lambda kin, *a, **k: real(kin)),),
        ("workspace.coverage",),
    ),
    Mutant(
        "device_placement_inverted",
        "8.3",
        "R8.2-1",
        "p_W = R_placement p_device + t_placement",
        "the placement applied inverted",
        (Patch(workspace, "modeled_solid", _placement_inverted),),
        ("workspace.coverage",),
    ),
    Mutant(
        "no_hole_filling",
        "8.4",
        "R8.4-1",
        "cavities of the dilated shell are filled before erosion",
        "dilation and erosion only (a plain closing)",
        (Patch(ndimage, "binary_fill_holes", _replace(lambda x, *a, **k: np.asarray(x, dtype=bool))),),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "voxel_pitch_5mm",
        "8.1",
        "R8.4-1",
        "voxel_pitch_m = 2.5 mm",
        "5 mm voxels",
        (Patch(volume_operator, "PARAMETERS", _parameters(voxel_pitch_m=0.005), everywhere=True),),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "one_stroke_plane_normals",
        "8.4",
        "R8.4-1",
        "a boundary sample whose neighbours lie along a line takes the smoothed-indicator normal (min_normal_planarity)",
        "every sample keeps its plane fit's normal",
        (Patch(volume_operator, "PARAMETERS", _parameters(min_normal_planarity=0.0), everywhere=True),),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "closing_diameter_for_radius",
        "8.4",
        "R8.4-1",
        "the closing ball has radius r = closing_radius_m = 3 cm",
        "3 cm taken for the ball's diameter (radius 1.5 cm)",
        (Patch(volume_operator, "PARAMETERS", _parameters(closing_radius_m=0.015), everywhere=True),),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "occlusion_gaps_not_repaired",
        "8.7",
        "R8.7-1",
        "a trial's occlusion gaps are repaired from the other repetitions' positions in the gaps' regions",
        "the finite positions of the trial alone",
        (
            Patch(
                workspace,
                "repaired_points",
                _replace(lambda t, position, donors, **k: (position[np.all(np.isfinite(position), axis=1)], 0)),
            ),
        ),
        ("workspace.measured_volume",),
    ),
    Mutant(
        "box_volume_in_cm3",
        "8.6",
        "R8.6-1",
        "workspace.spec_box_volume is in m³",
        "the datasheet's cm³ figure under the unit m³",
        (Patch(workspace, "spec_box_volume", _post(lambda v, *a: v * 1e6)),),
        ("workspace.spec_box_volume",),
        cheap=True,
    ),
    Mutant(
        "coverage_as_volume_ratio",
        "8.5",
        "R8.5-1",
        "coverage is the overlap of the measured and modeled solids over the modeled volume",
        "measured volume / modeled volume (the ratio again)",
        (Patch(workspace, "overlap_volume", _replace(lambda solid, model: solid.volume)),),
        ("workspace.coverage",),
    ),
)
