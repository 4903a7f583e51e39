"""A C3D force platform's channels as the plate's wrench (spec §5.6.1; §14.1 defines what it becomes).

A C3D platform records one wrench in one of the standard channel layouts (``FORCE_PLATFORM:TYPE``):
the force and moment **the platform exerts on the load** (the ground reaction, as ezc3d and
biomechanics software read the channels: a subject standing on it gives a negative Fz), in the
platform's own frame (x, y in the top surface, z down into the plate), about the platform's sensing
origin O:

- type 1: ``Fx Fy Fz Px Py Tz`` — force, centre of pressure (in the top surface, measured from O along
  x and y) and the free moment about the vertical through it;
- type 2: ``Fx Fy Fz Mx My Mz`` — force and moment about O;
- type 3 (Kistler, eight channels): ``fx12 fx34 fy14 fy23 fz1 fz2 fz3 fz4`` from four piezo sensors at
  ``(±a, ±b)`` in the plane of O (1 at +a+b, 2 at −a+b, 3 at −a−b, 4 at +a−b);
- type 4: type 2's six channels through the 6 × 6 ``CAL_MATRIX`` (``output = CAL · channels``); a
  type-3 platform with an 8 × 8 ``CAL_MATRIX`` applies it the same way.

``FORCE_PLATFORM:ORIGIN`` is the vector from O to the geometric centre C of the top surface, in the
platform frame, so its z is ≤ 0 (the surface lies above O and z points down); for type 3 it holds
``(a, b, az0)``, Kistler's sensor offsets and the depth of the sensor plane (``az0 ≤ 0``). Writers
that store the opposite sign are read by the rule of :func:`origin_by_rule` with a W503 warning.

The wrench about C is ``M_C = M_O − ORIGIN × F``; W (§5.6) has its origin at C, so rotating F and
M_C by the plate axes and reversing them (action and reaction) gives §14.1's total wrench — the load's
on the plate — in W. Haptify's ``plate_wrench`` stream holds
four corner sensors' readings (§2.6), which a platform does not provide: :func:`equivalent_corners`
writes the readings whose §14.1 sum is exactly the platform's wrench (each corner carries a quarter of
it), so every consumer of the plate (COP, natural frequency, rig checks) reads the platform unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptify.codes import Code
from haptify.errors import Finding, fail

# channels each platform type records (spec §5.6.1); other types (5, 6, 7, 11, 12, 21) are not imported
PLATFORM_CHANNELS = {1: 6, 2: 6, 3: 8, 4: 6}
# the dimension of each channel of a type (after its calibration matrix): force, length or torque
CHANNEL_DIMENSIONS = {
    1: ("force", "force", "force", "length", "length", "torque"),
    2: ("force", "force", "force", "torque", "torque", "torque"),
    3: ("force",) * 8,
    4: ("force", "force", "force", "torque", "torque", "torque"),
}


@dataclass(frozen=True)
class PlatformGeometry:
    """The sensing origin relative to the top surface (spec §5.6.1), SI: ``origin`` = O → C in the
    platform frame (m, z ≤ 0); for type 3 ``sensor_offsets`` = (a, b) in m."""

    origin: np.ndarray
    sensor_offsets: tuple[float, float] | None = None


def origin_by_rule(kind: int, origin_m: np.ndarray, *, number: int, file: str) -> tuple[PlatformGeometry, list[Finding]]:
    """``FORCE_PLATFORM:ORIGIN`` (m) read by spec §5.6.1's sign rule, with a W503 finding where the
    writer used the other convention.

    Types 1, 2, 4: the vector O → C has ``z ≤ 0``; a positive z means the writer stored C → O, and the
    whole vector is negated. Type 3: ``(a, b, az0)`` with ``a, b > 0`` and ``az0 ≤ 0``: magnitudes are
    used (a sign on a or b only names the same sensor square). E506 for a type-3 offset of zero (no
    moment can be formed) or a non-finite origin.
    """
    o = np.asarray(origin_m, dtype=np.float64)
    if o.shape != (3,) or not np.isfinite(o).all():
        raise fail(
            Code.IMPORT_PLATFORM_WRENCH_UNREADABLE,
            f"force platform {number}: FORCE_PLATFORM:ORIGIN is not three finite numbers",
            file=file,
            pointer="/FORCE_PLATFORM/ORIGIN",
            expected="3 finite numbers",
            found=np.ravel(o).tolist(),
        )
    notes = []
    if kind == 3:
        a, b = abs(float(o[0])), abs(float(o[1]))
        if min(a, b) == 0.0:
            raise fail(
                Code.IMPORT_PLATFORM_WRENCH_UNREADABLE,
                f"force platform {number} (type 3): the sensor offsets a, b in FORCE_PLATFORM:ORIGIN "
                "must be non-zero to form a moment",
                file=file,
                pointer="/FORCE_PLATFORM/ORIGIN",
                expected="a > 0 and b > 0",
                found=o.tolist(),
            )
        read = np.array([0.0, 0.0, -abs(float(o[2]))])
        if o[0] < 0 or o[1] < 0 or o[2] > 0:
            notes.append(
                _sign_note(
                    number,
                    file,
                    o,
                    np.array([a, b, read[2]]),
                    "Kistler's (a, b, az0) has a, b > 0 and az0 ≤ 0; the magnitudes are used",
                )
            )
        return PlatformGeometry(read, (a, b)), notes
    if o[2] > 0:
        notes.append(
            _sign_note(
                number,
                file,
                o,
                -o,
                "the vector from the sensing origin to the top surface has "
                "z ≤ 0; this one is read as written from the surface to the origin and negated",
            )
        )
        o = -o
    return PlatformGeometry(o), notes


def _sign_note(number: int, file: str, written: np.ndarray, used: np.ndarray, why: str) -> Finding:
    return Finding(
        Code.IMPORT_PLATE_ORIGIN_SIGN,
        f"force platform {number}: FORCE_PLATFORM:ORIGIN {np.round(written * 1000, 6).tolist()} mm "
        f"follows the other sign convention ({why})",
        file=file,
        pointer="/FORCE_PLATFORM/ORIGIN",
        expected=np.round(used * 1000, 6).tolist(),
        found=np.round(written * 1000, 6).tolist(),
    )


def calibrated(kind: int, channels: np.ndarray, cal: np.ndarray | None, *, number: int, file: str) -> np.ndarray:
    """The platform's outputs ``(n_channels, N)``: ``CAL · channels`` for type 4 (required) and for a
    type 3 with a calibration matrix; the channels themselves otherwise (spec §5.6.1)."""
    x = np.asarray(channels, dtype=np.float64)
    if kind == 4 and cal is None:
        raise fail(
            Code.IMPORT_PLATFORM_WRENCH_UNREADABLE,
            f"force platform {number} is type 4 but the file has no FORCE_PLATFORM:CAL_MATRIX for it",
            file=file,
            pointer="/FORCE_PLATFORM/CAL_MATRIX",
            expected="a 6 × 6 matrix",
            found=None,
        )
    if kind not in (3, 4) or cal is None:
        return x
    if cal.shape != (x.shape[0], x.shape[0]):
        raise fail(
            Code.IMPORT_PLATFORM_WRENCH_UNREADABLE,
            f"force platform {number}: its CAL_MATRIX is {cal.shape[0]} × {cal.shape[1]}, its type records {x.shape[0]} channels",
            file=file,
            pointer="/FORCE_PLATFORM/CAL_MATRIX",
            expected=f"{x.shape[0]} × {x.shape[0]}",
            found=list(cal.shape),
        )
    return cal @ x


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a × b`` for vectors stored as rows of ``(3, N)`` arrays (or a ``(3,)`` constant): component by
    component, which is several times faster than ``np.cross`` on long signals."""
    a = a.reshape(3, -1) if a.ndim == 1 else a
    b = b.reshape(3, -1) if b.ndim == 1 else b
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def wrench_at_origin(kind: int, out: np.ndarray, geometry: PlatformGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Force (N) and moment about the sensing origin O (N·m), ``(3, N)`` each (rows x, y, z), platform
    frame, from a platform's SI outputs ``(n_channels, N)`` (spec §5.6.1)."""
    if kind in (2, 4):
        return out[0:3], out[3:6]
    if kind == 1:
        force = out[0:3]
        cop = np.stack([out[3], out[4], np.full(out.shape[1], geometry.origin[2])])  # on the top surface
        moment = cross(cop, force)
        moment[2] += out[5]
        return force, moment
    assert geometry.sensor_offsets is not None  # platform_geometry gives a type-3 platform its offsets
    a, b = geometry.sensor_offsets
    fx12, fx34, fy14, fy23, fz1, fz2, fz3, fz4 = out
    force = np.stack([fx12 + fx34, fy14 + fy23, fz1 + fz2 + fz3 + fz4])
    moment = np.stack([b * (fz1 + fz2 - fz3 - fz4), a * (-fz1 + fz2 + fz3 - fz4), b * (-fx12 + fx34) + a * (fy14 - fy23)])
    return force, moment


def wrench_at_surface(force: np.ndarray, moment_o: np.ndarray, geometry: PlatformGeometry) -> np.ndarray:
    """The moment about the top surface's centre C: ``M_C = M_O − ORIGIN × F`` (N·m, ``(3, N)``; spec §5.6.1)."""
    out: np.ndarray = moment_o - cross(geometry.origin, force)
    return out


def equivalent_corners(force_w: np.ndarray, moment_w: np.ndarray, positions: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """Four corner readings ``(24, N)`` (c1_fx … c4_tz, sensor frames) whose total wrench by §14.1 is
    ``force_w`` and ``moment_w`` (``(3, N)``, about W's origin, in W): each corner carries ``F/4`` and the
    moment ``(M − p̄ × F)/4`` with ``p̄`` the corners' mean position, both rotated into its frame (§5.6.1)."""
    share_f = force_w / 4.0
    share_m = (moment_w - cross(positions.mean(axis=0), force_w)) / 4.0
    return np.concatenate([block for r in rotations for block in (r.T @ share_f, r.T @ share_m)])
