"""Qualisys TSV exports (QTM "Export to TSV": 3D and 6D files) as a
:class:`~haptify.formats.importers.recording.Recording` (spec §5.10). A marker at exactly (0, 0, 0) is a gap (how
QTM writes one); E501 names the file and the line when the file is not a QTM export."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from haptify.codes import Code
from haptify.errors import Finding, fail
from haptify.formats.importers.recording import Recording
from haptify.formats.importers.text_export import (
    empty_recording,
    head_lines,
    is_number,
    number_table,
    open_streamed,
    read_text,
    stream_wanted,
)


def qtm_rotation(cells: np.ndarray) -> np.ndarray:
    """QTM's Rot[0]…Rot[8] (column by column: r11, r21, r31, r12, …) as (…, 3, 3) matrices."""
    return np.swapaxes(cells.reshape(*cells.shape[:-1], 3, 3), -1, -2)


def _qtm_head(lines: list[str], p: Path) -> dict[str, Any]:
    """A QTM TSV's header (spec §5.10): the ``KEY<TAB>value…`` lines, the optional ``Frame`` column
    line, the line where the data start, the markers, bodies and the width of a data row."""
    meta: dict[str, list[str]] = {}
    i = 0
    while i < len(lines) and lines[i] and not is_number(lines[i].split("\t")[0]) and lines[i].split("\t")[0] != "Frame":
        cells = lines[i].split("\t")
        meta[cells[0].strip()] = [c.strip() for c in cells[1:]]
        i += 1
    has_columns = i < len(lines) and lines[i].split("\t")[0] == "Frame"
    if "FREQUENCY" not in meta:
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE,
            f"{p.name} is not a QTM TSV export: no FREQUENCY line",
            file=str(p),
            expected="FREQUENCY",
            found=sorted(meta),
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
    rec = empty_recording(p, "tsv", "Qualisys Track Manager")
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
    if stream_wanted(p, stream):
        head = _qtm_head(head_lines(p), p)
        rec, rows = open_streamed(
            p, "\t", head, _qtm_part, lambda first: int(first[0]) - 1 if head["has_columns"] and math.isfinite(first[0]) else 0
        )
    else:
        lines = read_text(p).splitlines()
        head = _qtm_head(lines, p)
        data = number_table(
            [ln for ln in lines[head["data_start"] :] if ln.strip()], "\t", p, head["data_start"] + 1, head["width"]
        )
        first = int(data[0, 0]) - 1 if head["has_columns"] and len(data) and math.isfinite(data[0, 0]) else 0
        rec, rows = _qtm_part(p, head, data, first), len(data)
    meta = head["meta"]
    expected = int(meta["NO_OF_FRAMES"][0]) if meta.get("NO_OF_FRAMES") else rows
    if expected != rows:
        rec.warnings.append(
            Finding(
                Code.IMPORT_SOURCE_DISAGREES,
                f"{p.name}: NO_OF_FRAMES is {expected}, the file holds {rows} frames; the {rows} frames read are imported",
                file=str(p),
                pointer="/NO_OF_FRAMES",
                expected=expected,
                found=rows,
            )
        )
    return rec
