"""Readers of the common motion-capture text exports (spec §5.10): Qualisys TSV, OptiTrack Motive CSV
and Vicon Nexus CSV, each into a :class:`~haptify.importers.Recording`, so that they import through the
same map rules as a C3D file (markers, 6-DoF bodies, analog channels; W of §5.6).

Occlusion follows each format: an empty cell or ``NaN``, and in a Qualisys 3-D export a marker at
exactly (0, 0, 0) (how QTM writes a gap). E501 names the file and the line when the file is not of
its format.
"""

from __future__ import annotations

import io
import math
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import pandas as pd

from haptify.conventions import quat_to_matrix
from haptify.errors import Finding, fail
from haptify.c3d_stream import STREAM_ABOVE_BYTES
from haptify.importers import UNITS, Destination, ImportResult, LoadedMap, Recording, _prepare, import_recording

FORMATS = ("tsv", "motive", "nexus")


def _text(path: Path) -> str:
    label = str(path)
    if not path.is_file():
        raise fail("E501", f"{label!r} does not exist or is not a file", file=label)
    try:
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise fail("E501", f"{label!r} cannot be read as UTF-8 text: {exc}", file=label) from None


def _table(lines: list[str], sep: str, path: Path, first_line: int, width: int | None = None) -> np.ndarray:
    """The numeric block of ``lines`` (empty cells → NaN); E501 naming the line of a non-number."""
    if not lines:
        return np.zeros((0, width or 0))
    try:
        frame = pd.read_csv(
            io.StringIO("\n".join(lines)),
            sep=sep,
            header=None,
            dtype=np.float64,
            na_values=["", "NaN", "nan"],
            keep_default_na=False,
            skipinitialspace=True,
            names=range(width) if width else None,
            engine="c",
        )
    except ValueError as exc:
        for i, line in enumerate(lines):
            for cell in line.split(sep):
                cell = cell.strip()
                if cell and cell.lower() != "nan":
                    try:
                        float(cell)
                    except ValueError:
                        raise fail(
                            "E501",
                            f"{path.name} line {first_line + i}: {cell!r} is not a number",
                            file=str(path),
                            expected="a number",
                            found=cell,
                        ) from None
        raise fail("E501", f"{path.name} cannot be read: {exc}", file=str(path)) from None
    return frame.to_numpy(dtype=np.float64)


def detect_format(path: Path) -> str | None:
    """The export a file is, from its first line: ``tsv`` (QTM: ``NO_OF_FRAMES``), ``motive``
    (``Format Version``), ``nexus`` (a section name such as ``Trajectories`` or ``Devices``), ``c3d``
    (second byte 0x50), else None (spec §5.8)."""
    try:
        head = path.read_bytes()[:512]
    except OSError:
        return None
    if len(head) >= 2 and head[1] == 0x50:
        return "c3d"
    first = head.decode("utf-8", "replace").lstrip("\ufeff").splitlines()[0] if head else ""
    if first.startswith("NO_OF_FRAMES"):
        return "tsv"
    if first.startswith("Format Version"):
        return "motive"
    if first.strip().strip(",") in NEXUS_SECTIONS:
        return "nexus"
    return None


def _empty(path: Path, fmt: str, manufacturer: str) -> dict[str, Any]:
    return {
        "path": path,
        "manufacturer": manufacturer,
        "format": fmt,
        "point_labels": [],
        "point_units": "mm",
        "point_rate": 0.0,
        "point_first_frame": 0,
        "points": np.zeros((0, 0, 3)),
        "analog_labels": [],
        "analog_units": [],
        "analog_rate": 0.0,
        "analog_first_sample": 0,
        "analogs": np.zeros((0, 0)),
    }


# --- Qualisys TSV (QTM "Export to TSV": 3D and 6D files) -----------------------------------------


def qtm_rotation(cells: np.ndarray) -> np.ndarray:
    """QTM's Rot[0]…Rot[8] (column by column: r11, r21, r31, r12, …) as (…, 3, 3) matrices."""
    return np.swapaxes(cells.reshape(*cells.shape[:-1], 3, 3), -1, -2)


def _qtm_head(lines: list[str], p: Path) -> dict[str, Any]:
    """A QTM TSV's header (spec §5.10): the ``KEY<TAB>value…`` lines, the optional ``Frame`` column
    line, the line where the data start, the markers, bodies and the width of a data row."""
    meta: dict[str, list[str]] = {}
    i = 0
    while i < len(lines) and lines[i] and not _is_number(lines[i].split("\t")[0]) and lines[i].split("\t")[0] != "Frame":
        cells = lines[i].split("\t")
        meta[cells[0].strip()] = [c.strip() for c in cells[1:]]
        i += 1
    has_columns = i < len(lines) and lines[i].split("\t")[0] == "Frame"
    if "FREQUENCY" not in meta:
        raise fail(
            "E501", f"{p.name} is not a QTM TSV export: no FREQUENCY line", file=str(p), expected="FREQUENCY", found=sorted(meta)
        )
    markers = [m for m in meta.get("MARKER_NAMES", []) if m]
    bodies = [b for b in meta.get("BODY_NAMES", []) if b]
    lead = 2 if has_columns else 0
    return {
        "meta": meta,
        "has_columns": has_columns,
        "data_start": i + 1 if has_columns else i,
        "markers": markers,
        "bodies": bodies,
        "lead": lead,
        "width": lead + 3 * len(markers) + QTM_PER_BODY * len(bodies),
        "rate": float(meta["FREQUENCY"][0]),
    }


QTM_PER_BODY = 16  # X, Y, Z, Roll, Pitch, Yaw, Residual, Rot[0]…Rot[8]


def _qtm_part(p: Path, head: dict[str, Any], data: np.ndarray, first_frame: int) -> Recording:
    """The recording held by rows ``data`` of a QTM TSV (the whole file, or one chunk of it)."""
    markers, bodies, lead = head["markers"], head["bodies"], head["lead"]
    rec = _empty(p, "tsv", "Qualisys Track Manager")
    rec.update(point_rate=head["rate"], point_first_frame=first_frame, point_labels=markers)
    pts = data[:, lead : lead + 3 * len(markers)].reshape(len(data), len(markers), 3)
    gap = (pts == 0.0).all(axis=2) | ~np.isfinite(pts).all(axis=2)
    pts[gap] = np.nan
    rec["points"] = pts
    if bodies:
        b = data[:, lead + 3 * len(markers) :].reshape(len(data), len(bodies), QTM_PER_BODY)
        rec.update(
            body_labels=bodies,
            body_positions=b[:, :, 0:3].copy(),
            body_residuals=b[:, :, 6].copy(),
            body_rotations=qtm_rotation(b[:, :, 7:16]),
        )
    return Recording(**rec)


def read_qualisys_tsv(path: str | Path, *, stream: bool | None = None) -> Recording:
    """A QTM TSV export (spec §5.10): header lines ``KEY<TAB>value…`` up to the data; ``MARKER_NAMES``
    give markers (X, Y, Z in mm), ``BODY_NAMES`` 6-DoF bodies (X, Y, Z, Roll, Pitch, Yaw, Residual,
    Rot[0]–Rot[8]). ``FREQUENCY`` is the rate; a ``Frame``/``Time`` column pair, when present, is
    skipped, and the first frame number sets the clock. A large file (or any with ``stream=True``)
    is read in chunks (§5.5.1)."""
    p = Path(path)
    if _stream_wanted(p, stream):
        head = _qtm_head(_head_lines(p), p)
        rec, rows = _streamed(
            p, "\t", head, _qtm_part, lambda first: int(first[0]) - 1 if head["has_columns"] and math.isfinite(first[0]) else 0
        )
    else:
        lines = _text(p).splitlines()
        head = _qtm_head(lines, p)
        data = _table([ln for ln in lines[head["data_start"] :] if ln.strip()], "\t", p, head["data_start"] + 1, head["width"])
        first = int(data[0, 0]) - 1 if head["has_columns"] and len(data) and math.isfinite(data[0, 0]) else 0
        rec, rows = _qtm_part(p, head, data, first), len(data)
    meta = head["meta"]
    expected = int(meta["NO_OF_FRAMES"][0]) if meta.get("NO_OF_FRAMES") else rows
    if expected != rows:
        rec.warnings.append(
            Finding(
                "W501",
                f"{p.name}: NO_OF_FRAMES is {expected}, the file holds {rows} frames; the {rows} frames read are imported",
                file=str(p),
                pointer="/NO_OF_FRAMES",
                expected=expected,
                found=rows,
            )
        )
    return rec


# --- streaming a text export (spec §5.5.1) ---------------------------------------------------------

HEAD_LINES = 64  # a text export's header is within its first lines
STREAM_CHUNK_ROWS = 50_000


def _stream_wanted(p: Path, stream: bool | None) -> bool:
    return bool(stream) or (stream is None and p.is_file() and p.stat().st_size > STREAM_ABOVE_BYTES)


def _head_lines(p: Path) -> list[str]:
    """The first ``HEAD_LINES`` lines of a text file (E501 when it is unreadable)."""
    try:
        with open(p, encoding="utf-8-sig") as fh:
            return [line.rstrip("\r\n") for line, _ in zip(fh, range(HEAD_LINES))]
    except (OSError, UnicodeDecodeError) as exc:
        raise fail("E501", f"{str(p)!r} cannot be read as UTF-8 text: {exc}", file=str(p)) from None


def _data_chunks(p: Path, sep: str, head: dict[str, Any], rows: int) -> Iterator[np.ndarray]:
    """The numeric rows after the header, ``rows`` at a time, parsed as :func:`_table` parses them."""
    try:
        reader = pd.read_csv(
            p,
            sep=sep,
            header=None,
            skiprows=head["data_start"],
            chunksize=rows,
            dtype=np.float64,
            na_values=["", "NaN", "nan"],
            keep_default_na=False,
            skipinitialspace=True,
            names=range(head["width"]),
            engine="c",
            encoding="utf-8-sig",
            skip_blank_lines=True,
        )
        for frame in reader:
            yield frame.to_numpy(dtype=np.float64)
    except ValueError as exc:
        raise fail("E501", f"{p.name} cannot be read after line {head['data_start']}: {exc}", file=str(p)) from None


def _streamed(
    p: Path,
    sep: str,
    head: dict[str, Any],
    part: Callable[[Path, dict[str, Any], np.ndarray, int], Recording],
    first_frame_of: Callable[[np.ndarray], int],
) -> tuple[Recording, int]:
    """A text export opened for streaming: the recording with shape-only frames (NaN views) (their count from one
    pass over the lines) and its chunk reader; also the row count."""
    rows, first = 0, None
    with open(p, "rb") as fh:
        for k, line in enumerate(fh):
            if k >= head["data_start"] and line.strip():
                rows += 1
                if first is None:
                    first = line
    first_frame = (
        first_frame_of(_table([first.decode("utf-8")], sep, p, head["data_start"] + 1, head["width"])[0])
        if first is not None
        else 0
    )
    shape = part(p, head, np.zeros((0, head["width"])), first_frame)

    def shape_only(value: np.ndarray | None) -> np.ndarray | None:
        """A NaN view with ``rows`` frames of ``value``'s shape (None stays None)."""
        return None if value is None else np.broadcast_to(np.float64(np.nan), (rows, *value.shape[1:]))

    def chunked(chunk: int | None) -> Iterator[tuple[int, Recording]]:
        start = 0
        for data in _data_chunks(p, sep, head, chunk or STREAM_CHUNK_ROWS):
            yield start, part(p, head, data, first_frame + start)
            start += len(data)

    points = np.broadcast_to(np.float64(np.nan), (rows, *shape.points.shape[1:]))
    return replace(
        shape,
        chunked=chunked,
        points=points,
        body_positions=shape_only(shape.body_positions),
        body_rotations=shape_only(shape.body_rotations),
        body_residuals=shape_only(shape.body_residuals),
    ), rows


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


# --- OptiTrack Motive CSV ------------------------------------------------------------------------

MOTIVE_UNITS = {"Millimeters": "mm", "Centimeters": "cm", "Meters": "m"}


def _motive_head(lines: list[str], p: Path) -> dict[str, Any]:
    """A Motive CSV's header (spec §5.10): the metadata line, the Type, Name, ID, quantity and axis
    lines, the markers and bodies they name, and where the data start."""
    first = [c.strip() for c in lines[0].split(",")] if lines else []
    meta = dict(zip(first[0::2], first[1::2]))
    if "Format Version" not in meta:
        raise fail("E501", f"{p.name} is not a Motive CSV export: no 'Format Version'", file=str(p))
    if meta.get("Rotation Type", "Quaternion") != "Quaternion":
        raise fail(
            "E501",
            f"{p.name} holds rotations as {meta['Rotation Type']}: export with Rotation Type Quaternion",
            file=str(p),
            pointer="/Rotation Type",
            expected="Quaternion",
            found=meta["Rotation Type"],
        )
    units = MOTIVE_UNITS.get(meta.get("Length Units", "Meters"))
    if units is None:
        raise fail(
            "E504",
            f"{p.name}: Length Units {meta['Length Units']!r} is not known",
            file=str(p),
            expected=sorted(MOTIVE_UNITS),
            found=meta["Length Units"],
        )
    k = 1
    while k < len(lines) and not lines[k].strip():
        k += 1
    rows = [[c.strip() for c in lines[k + j].split(",")] for j in range(5)] if len(lines) >= k + 5 else []
    if len(rows) < 5 or rows[4][:1] != ["Frame"]:
        raise fail(
            "E501",
            f"{p.name}: the Type, Name, ID, quantity and axis lines are missing",
            file=str(p),
            expected="Frame, Time, …",
            found=rows[-1][:2] if rows else None,
        )
    types, names, _, quantity, axes = rows
    width = len(axes)
    return {
        "meta": meta,
        "units": units,
        "rate": float(meta.get("Export Frame Rate") or meta.get("Capture Frame Rate") or 0),
        "data_start": k + 5,
        "width": width,
        "col": {(types[j], names[j], quantity[j], axes[j]): j for j in range(2, width)},
        "markers": list(dict.fromkeys(names[j] for j in range(2, width) if types[j] == "Marker" and quantity[j] == "Position")),
        "bodies": list(dict.fromkeys(names[j] for j in range(2, width) if types[j] == "Rigid Body")),
    }


def _motive_part(p: Path, head: dict[str, Any], data: np.ndarray, first_frame: int) -> Recording:
    """The recording held by rows ``data`` of a Motive CSV (the whole file, or one chunk of it)."""
    col, markers, bodies = head["col"], head["markers"], head["bodies"]
    rec = _empty(p, "motive", f"OptiTrack Motive (format {head['meta']['Format Version']})")
    n = len(data)
    pts = np.full((n, len(markers), 3), np.nan)
    for i, name in enumerate(markers):
        for a, axis in enumerate("XYZ"):
            pts[:, i, a] = data[:, col[("Marker", name, "Position", axis)]]
    rec.update(
        point_rate=head["rate"], point_units=head["units"], point_labels=markers, points=pts, point_first_frame=first_frame
    )
    if bodies:
        pos = np.full((n, len(bodies), 3), np.nan)
        quat = np.full((n, len(bodies), 4), np.nan)
        res = np.full((n, len(bodies)), np.nan)
        for i, name in enumerate(bodies):
            try:
                for a, axis in enumerate("XYZ"):
                    pos[:, i, a] = data[:, col[("Rigid Body", name, "Position", axis)]]
                for a, axis in enumerate("WXYZ"):
                    quat[:, i, a] = data[:, col[("Rigid Body", name, "Rotation", axis)]]
            except KeyError as exc:
                raise fail(
                    "E501",
                    f"{p.name}: rigid body {name!r} lacks column {exc.args[0][2:]}",
                    file=str(p),
                    expected="Rotation X, Y, Z, W and Position X, Y, Z",
                    found=None,
                ) from None
            err = col.get(("Rigid Body", name, "Mean Marker Error", ""))
            if err is not None:
                res[:, i] = data[:, err]
        valid = np.isfinite(quat).all(axis=2)
        rot = np.full((n, len(bodies), 3, 3), np.nan)
        rot[valid] = quat_to_matrix(quat[valid])
        norm_err = np.abs(np.linalg.norm(np.where(valid[..., None], quat, [1.0, 0.0, 0.0, 0.0]), axis=2) - 1.0)
        if (norm_err > 1e-3).any():
            f, b = np.argwhere(norm_err > 1e-3)[0]
            raise fail(
                "E501",
                f"{p.name}: rigid body {bodies[b]!r} holds no unit quaternion at frame {first_frame + f}",
                file=str(p),
                expected="|q| = 1",
                found=float(np.linalg.norm(quat[f, b])),
            )
        has_residuals = any(("Rigid Body", name, "Mean Marker Error", "") in col for name in bodies)
        rec.update(
            body_labels=bodies,
            body_positions=pos,
            body_rotations=rot,
            body_residuals=np.where(np.isnan(res) & valid, 0.0, res) if has_residuals else None,
        )
    return Recording(**rec)


def read_motive_csv(path: str | Path, *, stream: bool | None = None) -> Recording:
    """A Motive CSV export (spec §5.10): a metadata line (``Format Version``, ``Export Frame Rate``,
    ``Rotation Type``, ``Length Units``), a blank line, then the Type, Name, ID, quantity and axis
    lines. ``Marker`` columns (Position X, Y, Z) become markers; ``Rigid Body`` columns (Rotation X, Y,
    Z, W quaternion, Position X, Y, Z, Mean Marker Error) 6-DoF bodies, their mean marker error the
    residual. Only quaternion exports are read (an Euler export's axis order is not in the file). A
    large file (or any with ``stream=True``) is read in chunks (§5.5.1)."""
    p = Path(path)
    if _stream_wanted(p, stream):
        head = _motive_head(_head_lines(p), p)
        return _streamed(p, ",", head, _motive_part, lambda first: int(first[0]) if math.isfinite(first[0]) else 0)[0]
    lines = _text(p).splitlines()
    head = _motive_head(lines, p)
    data = _table([ln for ln in lines[head["data_start"] :] if ln.strip()], ",", p, head["data_start"] + 1, head["width"])
    return _motive_part(p, head, data, int(data[0, 0]) if len(data) and math.isfinite(data[0, 0]) else 0)


# --- Vicon Nexus CSV -----------------------------------------------------------------------------

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
            raise fail("E501", f"{path.name}: section {name!r} ends before its data", file=str(path))
        rate = float(lines[i + 1].split(",")[0])
        labels, columns, units = ([c.strip() for c in lines[i + k].split(",")] for k in (2, 3, 4))
        j = i + 5
        while j < len(lines) and lines[j].strip() and lines[j].strip().strip(",") not in NEXUS_SECTIONS:
            j += 1
        out[name] = (rate, labels, columns, units, i + 6, lines[i + 5 : j])
        i = j
    if not out:
        raise fail("E501", f"{path.name} is not a Nexus CSV export: no section ({', '.join(NEXUS_SECTIONS)})", file=str(path))
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
    sections = _nexus_sections(_text(p).splitlines(), p)
    rec = _empty(p, "nexus", "Vicon Nexus")
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
        data = _table(body, ",", p, first, len(columns))
        for label, cols in _groups(labels, columns):
            if (
                not all(a in cols for a in "XYZ")
                or UNITS.get(units[cols["X"]], None) is None
                or UNITS[units[cols["X"]]].dimension != "length"
            ):
                continue
            if unit is not None and units[cols["X"]] != unit:
                raise fail(
                    "E504",
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
    data = _table(body, ",", p, first, len(columns))
    names, pos, rot = [], [], []
    for label, cols in _groups(labels, columns):
        if not all(c in cols for c in ("RX", "RY", "RZ", "TX", "TY", "TZ")):
            continue
        angle = UNITS.get(units[cols["RX"]])
        if angle is None or angle.dimension != "angle":
            raise fail(
                "E504",
                f"{p.name}: segment {label!r} rotation unit {units[cols['RX']]!r} is not an angle",
                file=str(p),
                expected=["deg", "rad"],
                found=units[cols["RX"]],
            )
        if unit is not None and units[cols["TX"]] != unit:
            raise fail(
                "E504",
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
            "E501",
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
    data = _table(body, ",", p, first, len(columns))
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


READERS: dict[str, Callable[..., Recording]] = {"tsv": read_qualisys_tsv, "motive": read_motive_csv, "nexus": read_nexus_csv}


def read_export(fmt: str, path: str | Path, *, stream: bool | None = None) -> Recording:
    """The recording in a ``tsv``, ``motive`` or ``nexus`` export (spec §5.10); Qualisys and Motive files
    stream when large (or with ``stream=True``, §5.5.1); Nexus files are read whole."""
    return READERS[fmt](path) if fmt == "nexus" else READERS[fmt](path, stream=stream)


def import_export(
    fmt: str,
    path: str | Path,
    out: str | Path | Destination,
    mapping: str | Path | LoadedMap | None = None,
    *,
    overrides: dict[str, Any] | None = None,
    overwrite: bool = False,
    append: bool = False,
    stream: bool | None = None,
    chunk_frames: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ImportResult:
    """Import a Qualisys TSV, Motive CSV or Nexus CSV export as one trial (spec §5.10), through the
    map rules of a C3D file (:func:`~haptify.importers.import_recording`); ``stream``, ``chunk_frames``
    and ``progress`` as for a C3D file (§5.5.1)."""
    dest, loaded, _, device, extra = _prepare(out, mapping, fmt, overrides, overwrite, append)
    return import_recording(
        read_export(fmt, path, stream=stream), dest, loaded, device, extra, chunk_frames=chunk_frames, progress=progress
    )
