"""OptiTrack Motive CSV exports as a :class:`~haptify.formats.importers.recording.Recording` (spec §5.10): markers
and quaternion rigid bodies, their mean marker error the residual. E501 names the file and the line when the
file is not a Motive export."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.conventions import quat_to_matrix
from haptify.formats.importers.recording import Recording
from haptify.formats.importers.text_export import (
    empty_recording,
    head_lines,
    number_table,
    open_streamed,
    read_text,
    stream_wanted,
)

MOTIVE_UNITS = {"Millimeters": "mm", "Centimeters": "cm", "Meters": "m"}


def _motive_head(lines: list[str], p: Path) -> dict[str, Any]:
    """A Motive CSV's header (spec §5.10): the metadata line, the Type, Name, ID, quantity and axis
    lines, the markers and bodies they name, and where the data start."""
    first = [c.strip() for c in lines[0].split(",")] if lines else []
    meta = dict(zip(first[0::2], first[1::2]))
    if "Format Version" not in meta:
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{p.name} is not a Motive CSV export: no 'Format Version'", file=str(p))
    if meta.get("Rotation Type", "Quaternion") != "Quaternion":
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE,
            f"{p.name} holds rotations as {meta['Rotation Type']}: export with Rotation Type Quaternion",
            file=str(p),
            pointer="/Rotation Type",
            expected="Quaternion",
            found=meta["Rotation Type"],
        )
    units = MOTIVE_UNITS.get(meta.get("Length Units", "Meters"))
    if units is None:
        raise fail(
            Code.IMPORT_UNIT_UNKNOWN,
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
            Code.IMPORT_SOURCE_UNREADABLE,
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
    rec = empty_recording(p, "motive", f"OptiTrack Motive (format {head['meta']['Format Version']})")
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
                    Code.IMPORT_SOURCE_UNREADABLE,
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
                Code.IMPORT_SOURCE_UNREADABLE,
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
    if stream_wanted(p, stream):
        head = _motive_head(head_lines(p), p)
        return open_streamed(p, ",", head, _motive_part, lambda first: int(first[0]) if math.isfinite(first[0]) else 0)[0]
    lines = read_text(p).splitlines()
    head = _motive_head(lines, p)
    data = number_table([ln for ln in lines[head["data_start"] :] if ln.strip()], ",", p, head["data_start"] + 1, head["width"])
    return _motive_part(p, head, data, int(data[0, 0]) if len(data) and math.isfinite(data[0, 0]) else 0)
