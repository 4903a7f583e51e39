"""What the importer uses from a motion-capture file, whatever its format (spec §5.5, §5.10), and its
frames in chunks (§5.5.1)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from haptify.errors import Finding
from haptify.formats.c3d_stream import C3DLayout, chunk_frames_for, iter_frames


@dataclass
class C3DPlatform:
    """One FORCE_PLATFORM entry: number (1-based), type, corners (4 × 3, POINT units, lab), origin (3),
    its analog channels (0-based indices into the analog labels) and calibration matrix (row = output,
    or None). Spec §5.6."""

    number: int
    type: int | None
    corners: np.ndarray | None
    origin: np.ndarray | None
    channels: list[int] = field(default_factory=list)
    cal_matrix: np.ndarray | None = None


@dataclass
class Recording:
    """What the importer uses from a motion-capture file (C3D, Qualisys TSV, Motive CSV, Nexus CSV),
    as the file's reader exposes it (analog values already scaled). Spec §5.5, §5.10.

    Points and 6-DoF bodies share the point clock: sample ``k`` is at ``(point_first_frame + k) /
    point_rate``. ``warnings`` are the coded disagreements found while reading (W501)."""

    path: Path
    manufacturer: str
    point_labels: list[str]
    point_units: str | None
    point_rate: float
    point_first_frame: int
    points: np.ndarray  # (n_frames, n_markers, 3), POINT units, NaN where residual < 0 or invalid
    analog_labels: list[str]
    analog_units: list[str]
    analog_rate: float
    analog_first_sample: int
    analogs: np.ndarray  # (n_channels, n_samples)
    platforms: list[C3DPlatform] = field(default_factory=list)
    body_labels: list[str] = field(default_factory=list)
    body_positions: np.ndarray | None = None  # (n_frames, n_bodies, 3), POINT units, NaN where invalid
    body_rotations: np.ndarray | None = None  # (n_frames, n_bodies, 3, 3), body → lab, NaN where invalid
    body_residuals: np.ndarray | None = None  # (n_frames, n_bodies), POINT units, when the file has them
    format: str = "c3d"
    warnings: list[Finding] = field(default_factory=list)
    layout: C3DLayout | None = None  # a C3D file read in chunks (§5.5.1); points/analogs are then shape-only NaN views
    chunked: Callable[[int | None], Iterator[tuple[int, "Recording"]]] | None = None  # a text export read in chunks

    @property
    def streamed(self) -> bool:
        """Whether the frames stay in the file and are read chunk by chunk (§5.5.1)."""
        return self.layout is not None or self.chunked is not None

    @property
    def frames(self) -> int:
        """Point (and body) frames: the length of the point clock."""
        if self.body_positions is not None and not self.point_labels:
            return int(self.body_positions.shape[0])
        return int(self.points.shape[0])

    def summary(self) -> dict[str, Any]:
        """A JSON-able description of the file (what ``haptify import FORMAT --list`` prints)."""
        return {
            "file": self.path.name,
            "format": self.format,
            "manufacturer": self.manufacturer,
            "markers": {
                "count": len(self.point_labels),
                "rate_hz": self.point_rate,
                "frames": self.frames,
                "units": self.point_units,
                "labels": list(self.point_labels),
            },
            "bodies": {
                "count": len(self.body_labels),
                "labels": list(self.body_labels),
                "residuals": self.body_residuals is not None,
            },
            "analog": {
                "count": len(self.analog_labels),
                "rate_hz": self.analog_rate,
                "samples": int(self.analogs.shape[1]),
                "channels": [{"label": lab, "unit": u} for lab, u in zip(self.analog_labels, self.analog_units)],
            },
            "force_platforms": [
                {
                    "number": p.number,
                    "type": p.type,
                    "corners": None if p.corners is None else p.corners.tolist(),
                    "origin": None if p.origin is None else p.origin.tolist(),
                    "channels": [self.analog_labels[i] for i in p.channels if i < len(self.analog_labels)],
                    "calibrated": p.cal_matrix is not None,
                }
                for p in self.platforms
            ],
            "warnings": [f.to_dict() for f in self.warnings],
        }


def recording_chunks(rec: Recording, chunk_frames: int | None = None) -> Iterator[tuple[int, Recording]]:
    """A recording's frames in chunks (spec §5.5.1): ``(first frame, the recording restricted to the
    chunk)``, its clocks advanced to the chunk's first frame. A recording read whole is one chunk."""
    if rec.chunked is not None:
        yield from rec.chunked(chunk_frames)
        return
    if rec.layout is None:
        yield 0, rec
        return
    per_frame = rec.layout.per_frame
    for start, points, analogs in iter_frames(rec.layout, chunk_frames or chunk_frames_for(rec.layout)):
        yield (
            start,
            replace(
                rec,
                points=points,
                analogs=analogs,
                point_first_frame=rec.point_first_frame + start,
                analog_first_sample=rec.analog_first_sample + start * per_frame,
                layout=None,
            ),
        )
