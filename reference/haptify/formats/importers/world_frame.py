"""The world frame W of an imported recording (spec §5.6): from a force platform's corners (the rig's
plate) or from the map's lab_to_world pose; the platform's wrench as plate_wrench (§5.6.1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail
from haptify.formats.conventions import matrix_to_quat, quat_to_matrix
from haptify.formats.importers.import_map import PlatformWrenchMap
from haptify.formats.importers.recording import C3DPlatform, Recording
from haptify.formats.importers.units import Unit, unit_conversion
from haptify.formats.session_format import (
    Pose,
)
from haptify.processing.force_plate import CORNERS, PLATE_COLUMNS
from haptify.processing.platform_wrench import (
    CHANNEL_DIMENSIONS,
    PLATFORM_CHANNELS,
    calibrated,
    equivalent_corners,
    origin_by_rule,
    wrench_at_origin,
    wrench_at_surface,
)

# --- geometry: the world frame from a force platform (spec §5.6) ----------------------------------

PLATE_RECTANGLE_TOLERANCE_M = 0.001  # corners within 1 mm of a flat rectangle: silent (§5.6)
PLATE_SHAPE_LIMIT = 0.1  # a deviation beyond 10 % of the shorter side is no rectangle at all (E505)
PLATE_MIN_SIDE_M = 0.01  # a side shorter than 10 mm: coincident corners (E505)


@dataclass
class WorldFrame:
    """``p_W = R · (p_lab − centre)``; ``description`` says how W was chosen (kept in the trial notes).
    Positions in m; spec §5.6."""

    rotation: np.ndarray
    centre: np.ndarray
    description: str

    def apply(self, p: np.ndarray) -> np.ndarray:
        out: np.ndarray = (p - self.centre) @ self.rotation.T
        return out


def _meaningless(number: int, why: str, file: str, found: Any) -> HaptifyError:
    return fail(
        Code.IMPORT_PLATE_GEOMETRY_MEANINGLESS,
        f"force platform {number}: {why}",
        file=file,
        pointer="/FORCE_PLATFORM/CORNERS",
        expected="four corners of a plate, in C3D order",
        found=found,
    )


def plate_frame(corners_m: np.ndarray, *, file: str, number: int) -> tuple[WorldFrame, np.ndarray, list[float], float]:
    """W from a C3D platform's corners (metres, lab frame), spec §5.6.

    C3D numbers corners by the plate's own quadrants (+x+y, −x+y, −x−y, +x−y) and its z axis points
    into the plate. W's origin is the centre of the four corners, x the plate's x, z up (−plate z),
    y = z × x. Returns W, the plate axes in W (3 × 3, columns x, y, z), the size [x, y] in m and the
    largest deviation of a corner from the flat rectangle of that size (m). E505 when the corners
    cannot define a plate: not finite, coincident (two corners within 10 mm), collinear, crossed (a
    corner outside its quadrant), or further from a rectangle than 10 % of the shorter side.
    """
    c = np.asarray(corners_m, dtype=np.float64)
    if not np.isfinite(c).all():
        raise _meaningless(number, "a corner coordinate is not finite", file, c.tolist())
    gaps = [float(np.linalg.norm(c[i] - c[j])) for i in range(4) for j in range(i + 1, 4)]
    if min(gaps) < PLATE_MIN_SIDE_M:
        raise _meaningless(number, f"its corners coincide (two are {min(gaps) * 1000:.3g} mm apart)", file, c.tolist())
    crossed = "its corners are not in C3D order (the outline crosses itself)"
    x = (c[0] + c[3]) / 2 - (c[1] + c[2]) / 2
    y_raw = (c[0] + c[1]) / 2 - (c[2] + c[3]) / 2
    size = [float(np.linalg.norm(x)), float(np.linalg.norm(y_raw))]
    if min(size) < PLATE_MIN_SIDE_M:
        raise _meaningless(number, crossed, file, c.tolist())
    x /= size[0]
    z_plate = np.cross(x, y_raw)
    if np.linalg.norm(z_plate) < PLATE_MIN_SIDE_M * size[1]:
        raise _meaningless(number, "its corners are collinear", file, c.tolist())
    z_plate /= np.linalg.norm(z_plate)
    y_plate = np.cross(z_plate, x)
    zw = -z_plate
    yw = np.cross(zw, x)
    rotation = np.stack([x, yw, zw])
    centre = c.mean(axis=0)
    local = (c - centre) @ rotation.T
    quadrants = np.array([[1, -1], [-1, -1], [-1, 1], [1, 1]])
    if (np.sign(local[:, :2]) != quadrants).any():
        raise _meaningless(number, crossed, file, c.tolist())
    ideal = quadrants * np.array(size) / 2
    deviation = float(max(np.abs(local[:, :2] - ideal).max(), np.abs(local[:, 2]).max()))
    if deviation > PLATE_SHAPE_LIMIT * min(size):
        raise _meaningless(
            number,
            f"its corners are {deviation * 1000:.3g} mm from a flat rectangle, more than "
            f"{PLATE_SHAPE_LIMIT:.0%} of its shorter side",
            file,
            c.tolist(),
        )
    axes_in_w = rotation @ np.stack([x, y_plate, z_plate], axis=1)
    desc = (
        f"W: centre of C3D force platform {number}'s corners, x along the platform's x axis, z up (opposite to the platform's z)"
    )
    return WorldFrame(rotation, centre, desc), axes_in_w, size, deviation


# Haptify names corner sensors by their quadrant of W (spec §5.6); C3D numbers them in the platform's
# own frame, whose y axis is W's −y, so C3D corner 1 becomes c4, 2 → c3, 3 → c2, 4 → c1.
CORNER_QUADRANTS = {"c1": (1.0, 1.0), "c2": (-1.0, 1.0), "c3": (-1.0, -1.0), "c4": (1.0, -1.0)}


def plate_description(platform: C3DPlatform, to_m: Unit, *, file: str) -> tuple[WorldFrame, dict[str, Any], list[Finding]]:
    """W and the rig's ``force_plate`` from a C3D platform (spec §5.6): one corner sensor at each C3D
    corner, named by its quadrant of W (``CORNER_QUADRANTS``), lowered to the depth |ORIGIN z| of the
    platform's sensing origin and oriented as the platform's frame. A W502 finding gives the corners'
    deviation from a flat rectangle when it exceeds 1 mm."""
    if platform.corners is None:
        raise fail(
            Code.IMPORT_CHANNEL_UNKNOWN,
            f"force platform {platform.number} has no FORCE_PLATFORM:CORNERS",
            file=file,
            pointer="/FORCE_PLATFORM/CORNERS",
            expected="corners",
            found=None,
        )
    corners = to_m.to_si(platform.corners)
    world, axes, size, deviation = plate_frame(corners, file=file, number=platform.number)
    warnings = []
    if deviation > PLATE_RECTANGLE_TOLERANCE_M:
        warnings.append(
            Finding(
                Code.IMPORT_PLATE_NOT_RECTANGULAR,
                f"the corners of force platform {platform.number} are {deviation * 1000:.3g} mm "
                "from a flat rectangle; W and the plate size come from the best-fitting rectangle",
                file=file,
                pointer="/FORCE_PLATFORM/CORNERS",
                expected=f"≤ {PLATE_RECTANGLE_TOLERANCE_M * 1000:g} mm",
                found=f"{deviation * 1000:.3g} mm",
            )
        )
    origin = to_m.to_si(platform.origin) if platform.origin is not None else np.zeros(3)
    if not np.isfinite(origin).all():
        raise fail(
            Code.IMPORT_PLATE_GEOMETRY_MEANINGLESS,
            f"force platform {platform.number}: its origin is not finite",
            file=file,
            pointer="/FORCE_PLATFORM/ORIGIN",
            expected="a finite origin",
            found=origin.tolist(),
        )
    depth = float(abs(origin[2]))
    q = [float(v) for v in matrix_to_quat(axes)]
    in_w = world.apply(corners)
    sensors = []
    for cid, (sx, sy) in CORNER_QUADRANTS.items():
        corner = next(c for c in in_w if np.sign(c[0]) == sx and np.sign(c[1]) == sy)
        sensors.append({"id": cid, "pose": {"position": [float(corner[0]), float(corner[1]), -depth], "quaternion": q}})
    return world, {"size_m": size, "corners": sensors}, warnings


def pose_frame(pose: Pose) -> WorldFrame:
    """W from a ``lab_to_world`` pose (the lab frame in W): ``p_W = R · p_lab + position``.
    Spec §5.6 rule 2."""
    rotation = quat_to_matrix(np.asarray(pose.quaternion, dtype=np.float64))
    centre = -rotation.T @ np.asarray(pose.position, dtype=np.float64)
    return WorldFrame(rotation, centre, "W: the C3D lab frame placed in W by the map's lab_to_world pose")


# --- the platform's wrench (spec §5.6.1) ------------------------------------------------------------

_SI_OF_DIMENSION = {"force": "N", "torque": "N*m", "length": "m"}


def platform_plate_wrench(
    rec: Recording, platform: C3DPlatform, pm: PlatformWrenchMap, plate: dict[str, Any], to_m: Unit, *, label: str
) -> tuple[dict[str, np.ndarray], list[Finding]]:
    """The ``plate_wrench`` columns (``t`` excluded) of the platform that defines W (spec §5.6.1): its
    outputs (types 1–4, calibration matrix applied) in SI, the wrench moved to the top surface's
    centre (W's origin), rotated into W and reversed (the channels hold the reaction), shared among the rig's four corner sensors
    (:func:`~haptify.processing.platform_wrench.equivalent_corners`). Returns the columns and W503 findings.

    E506 when the platform's type is not 1–4, its channels are missing or its calibration matrix or
    origin is unusable; E504 for a unit that is not a force, torque or length as the output needs.
    """
    src, number = str(rec.path), platform.number
    kind = platform.type
    if kind not in PLATFORM_CHANNELS:
        raise fail(
            Code.IMPORT_PLATFORM_WRENCH_UNREADABLE,
            f"force platform {number} is of type {kind}; its wrench is imported for types {sorted(PLATFORM_CHANNELS)}",
            file=src,
            pointer="/FORCE_PLATFORM/TYPE",
            expected=sorted(PLATFORM_CHANNELS),
            found=kind,
        )
    need = PLATFORM_CHANNELS[kind]
    if len(platform.channels) < need:
        raise fail(
            Code.IMPORT_PLATFORM_WRENCH_UNREADABLE,
            f"force platform {number} (type {kind}) names {len(platform.channels)} of the {need} analog "
            "channels its type records in FORCE_PLATFORM:CHANNEL",
            file=src,
            pointer="/FORCE_PLATFORM/CHANNEL",
            expected=need,
            found=[c + 1 for c in platform.channels],
        )
    if platform.origin is None:
        raise fail(
            Code.IMPORT_PLATFORM_WRENCH_UNREADABLE,
            f"force platform {number} has no FORCE_PLATFORM:ORIGIN",
            file=src,
            pointer="/FORCE_PLATFORM/ORIGIN",
            expected="3 numbers",
            found=None,
        )
    chans = platform.channels[:need]
    out = calibrated(kind, rec.analogs[chans], platform.cal_matrix, number=number, file=src)
    given = {"force": pm.force_unit, "torque": pm.torque_unit, "length": pm.length_unit}
    si = np.empty_like(out)
    for row, (ch, dim) in enumerate(zip(chans, CHANNEL_DIMENSIONS[kind])):
        unit = given[dim] if given[dim] is not None else (rec.analog_units[ch] or None)
        si[row] = unit_conversion(
            unit,
            _SI_OF_DIMENSION[dim],
            file=label if given[dim] else src,
            pointer=f"/platform_wrench/{dim}_unit" if given[dim] else "/ANALOG/UNITS",
            column=rec.analog_labels[ch],
        ).to_si(out[row])
    bad = ~np.isfinite(si)
    if bad.any():
        row, i = (int(v[0]) for v in np.nonzero(bad))
        raise fail(
            Code.NAN_NOT_ALLOWED,
            f"force platform {number}: channel {rec.analog_labels[chans[row]]!r} is not finite at sample {i}",
            file=src,
            column=rec.analog_labels[chans[row]],
            expected="finite values",
            found=str(si[row, i]),
        )
    geometry, notes = origin_by_rule(kind, to_m.to_si(platform.origin), number=number, file=src)
    force, moment_o = wrench_at_origin(kind, si, geometry)
    moment_c = wrench_at_surface(force, moment_o, geometry)
    sensors = {c["id"]: c["pose"] for c in plate["corners"]}
    positions = np.array([sensors[c]["position"] for c in CORNERS], dtype=np.float64)
    rotations = quat_to_matrix(np.array([sensors[c]["quaternion"] for c in CORNERS], dtype=np.float64))
    axes = rotations[0]  # every corner sensor is oriented as the platform (§5.6): platform → W
    # the channels are the platform's reaction on the load; §14.1's wrench is the load's on the plate
    readings = equivalent_corners(-(axes @ force), -(axes @ moment_c), positions, rotations)
    return dict(zip(PLATE_COLUMNS, readings)), notes
