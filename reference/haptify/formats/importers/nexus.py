"""Vicon Nexus CSV exports as a :class:`~haptify.formats.importers.recording.Recording` (spec §5.10): Trajectories
and length-unit Model Outputs as markers, Segments as 6-DoF bodies, Devices as analog channels. E501 names the
file and the line when the file is not a Nexus export."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.importers.recording import Recording
from haptify.formats.importers.text_export import empty_recording, number_table, read_text
from haptify.formats.importers.units import UNITS

NEXUS_SECTIONS = ("Devices", "Joints", "Model Outputs", "Segments", "Trajectories")


def _nexus_sections(lines: list[str], path: Path) -> dict[str, tuple[float, list[str], list[str], list[str], int, list[str]]]:
    """Each section: rate, label line, column line, unit line, first data line number, data lines."""
    out = {}
    i = 0
    while i < len(lines):
        name = lines[i].strip().strip(",")
        if name not in NEXUS_SECTIONS:
            i += 1
            continue
        if i + 4 >= len(lines):
            raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{path.name}: section {name!r} ends before its data", file=str(path))
        rate = float(lines[i + 1].split(",")[0])
        labels, columns, units = ([c.strip() for c in lines[i + k].split(",")] for k in (2, 3, 4))
        j = i + 5
        while j < len(lines) and lines[j].strip() and lines[j].strip().strip(",") not in NEXUS_SECTIONS:
            j += 1
        out[name] = (rate, labels, columns, units, i + 6, lines[i + 5 : j])
        i = j
    if not out:
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE,
            f"{path.name} is not a Nexus CSV export: no section ({', '.join(NEXUS_SECTIONS)})",
            file=str(path),
        )
    return out


def _groups(labels: list[str], columns: list[str]) -> list[tuple[str, dict[str, int]]]:
    """(label, {column name: index}) for each labelled group of columns after Frame and Sub Frame."""
    groups: list[tuple[str, dict[str, int]]] = []
    for j in range(2, len(columns)):
        if j < len(labels) and labels[j]:
            groups.append((labels[j], {}))
        if groups and columns[j]:
            groups[-1][1][columns[j]] = j
    return groups


def rotation_vector_matrix(v: np.ndarray) -> np.ndarray:
    """Rotation matrices (…, 3, 3) of rotation vectors (…, 3) in rad (Rodrigues)."""
    angle = np.linalg.norm(v, axis=-1)
    axis = v / np.where(angle > 0, angle, 1.0)[..., None]
    x, y, z = np.moveaxis(axis, -1, 0)
    c, s = np.cos(angle), np.sin(angle)
    C = 1 - c
    return np.stack(
        [
            np.stack([c + x * x * C, x * y * C - z * s, x * z * C + y * s], -1),
            np.stack([y * x * C + z * s, c + y * y * C, y * z * C - x * s], -1),
            np.stack([z * x * C - y * s, z * y * C + x * s, c + z * z * C], -1),
        ],
        -2,
    )


NexusSections = dict[str, tuple[float, list[str], list[str], list[str], int, list[str]]]


def read_nexus_csv(path: str | Path) -> Recording:
    """A Vicon Nexus CSV export (spec §5.10): sections (name, rate, label, column and unit lines,
    data). ``Trajectories`` and the ``Model Outputs`` in a length unit become markers; ``Segments``
    (RX, RY, RZ a rotation vector in the unit line's angle unit; TX, TY, TZ) 6-DoF bodies; ``Devices``
    analog channels labelled ``<device> - <column>`` at the device rate. The first Frame number sets
    the clock (Nexus counts from 1)."""
    p = Path(path)
    sections = _nexus_sections(read_text(p).splitlines(), p)
    rec = empty_recording(p, "nexus", "Vicon Nexus")
    point_labels, point_cols, point_rate, unit, frames = _nexus_points(sections, p)
    if point_labels:
        rec.update(point_labels=point_labels, points=np.stack(point_cols, axis=1), point_units=unit)
    if "Segments" in sections:
        segment_rate, segment_frames = _nexus_segments(sections, p, rec, unit)
        if segment_frames is not None:
            point_rate, frames = segment_rate, segment_frames
    if frames is not None and len(frames):
        rec.update(point_rate=point_rate, point_first_frame=int(frames[0]) - 1)
    if "Devices" in sections:
        rec.update(_nexus_devices(sections, p, point_rate))
    return Recording(**rec)


def _nexus_points(sections: NexusSections, p: Path) -> tuple[list[str], list[np.ndarray], float, str | None, np.ndarray | None]:
    """The markers of a Nexus export's ``Trajectories`` and length-unit ``Model Outputs`` (spec §5.10): labels,
    (frames, 3) columns, the rate (Hz), their common unit (E504 when they differ) and the Frame numbers."""
    point_labels: list[str] = []
    point_cols: list[np.ndarray] = []
    point_rate, unit, frames = 0.0, None, None
    for name in ("Trajectories", "Model Outputs"):
        if name not in sections:
            continue
        rate, labels, columns, units, first, body = sections[name]
        data = number_table(body, ",", p, first, len(columns))
        for label, cols in _groups(labels, columns):
            if (
                not all(a in cols for a in "XYZ")
                or UNITS.get(units[cols["X"]], None) is None
                or UNITS[units[cols["X"]]].dimension != "length"
            ):
                continue
            if unit is not None and units[cols["X"]] != unit:
                raise fail(
                    Code.IMPORT_UNIT_UNKNOWN,
                    f"{p.name}: {label!r} is in {units[cols['X']]}, other points in {unit}",
                    file=str(p),
                    expected=unit,
                    found=units[cols["X"]],
                )
            unit = units[cols["X"]]
            point_labels.append(label)
            point_cols.append(data[:, [cols[a] for a in "XYZ"]])
        point_rate, frames = rate, data[:, 0]
    return point_labels, point_cols, point_rate, unit, frames


def _nexus_segments(sections: NexusSections, p: Path, rec: dict[str, Any], unit: str | None) -> tuple[float, np.ndarray | None]:
    """The 6-DoF bodies of a Nexus export's ``Segments`` into ``rec`` (spec §5.10; E504 for a rotation unit that
    is not an angle or a length unit other than the points', E501 for a frame count other than theirs); their
    rate (Hz) and Frame numbers, None when no segment has all six columns."""
    rate, labels, columns, units, first, body = sections["Segments"]
    data = number_table(body, ",", p, first, len(columns))
    names, pos, rot = [], [], []
    for label, cols in _groups(labels, columns):
        if not all(c in cols for c in ("RX", "RY", "RZ", "TX", "TY", "TZ")):
            continue
        angle = UNITS.get(units[cols["RX"]])
        if angle is None or angle.dimension != "angle":
            raise fail(
                Code.IMPORT_UNIT_UNKNOWN,
                f"{p.name}: segment {label!r} rotation unit {units[cols['RX']]!r} is not an angle",
                file=str(p),
                expected=["deg", "rad"],
                found=units[cols["RX"]],
            )
        if unit is not None and units[cols["TX"]] != unit:
            raise fail(
                Code.IMPORT_UNIT_UNKNOWN,
                f"{p.name}: segment {label!r} is in {units[cols['TX']]}, points in {unit}",
                file=str(p),
                expected=unit,
                found=units[cols["TX"]],
            )
        unit = units[cols["TX"]]
        names.append(label)
        pos.append(data[:, [cols[c] for c in ("TX", "TY", "TZ")]])
        rot.append(rotation_vector_matrix(angle.to_si(data[:, [cols[c] for c in ("RX", "RY", "RZ")]])))
    if not names:
        return rate, None
    n_frames = len(data)
    has_points = bool(rec.get("point_labels"))
    if has_points and n_frames != rec["points"].shape[0]:
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE,
            f"{p.name}: Segments hold {n_frames} frames, Trajectories {rec['points'].shape[0]}",
            file=str(p),
            expected=rec["points"].shape[0],
            found=n_frames,
        )
    rec.update(body_labels=names, body_positions=np.stack(pos, axis=1), body_rotations=np.stack(rot, axis=1), point_units=unit)
    if not has_points:
        rec["points"] = np.zeros((n_frames, 0, 3))
    frames: np.ndarray = data[:, 0]
    return rate, frames


def _nexus_devices(sections: NexusSections, p: Path, point_rate: float) -> dict[str, Any]:
    """The analog channels of a Nexus export's ``Devices`` (spec §5.10), labelled ``<device> - <column>``, with
    their rate (Hz) and first sample on the analog clock (frames count from 1, sub-frames from 0)."""
    rate, labels, columns, units, first, body = sections["Devices"]
    data = number_table(body, ",", p, first, len(columns))
    an_labels, an_units, values = [], [], []
    for label, cols in _groups(labels, columns):
        for column, j in cols.items():
            an_labels.append(f"{label} - {column}")
            an_units.append(units[j] if j < len(units) else "")
            values.append(data[:, j])
    per_frame = int(round(rate / point_rate)) if point_rate else 1
    first_sample = (int(data[0, 0]) - 1) * per_frame + int(data[0, 1]) if len(data) else 0
    return {
        "analog_labels": an_labels,
        "analog_units": an_units,
        "analog_rate": rate,
        "analog_first_sample": first_sample,
        "analogs": np.array(values) if values else np.zeros((0, len(data))),
    }
