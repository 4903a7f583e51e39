"""What the readers of the motion-capture text exports share (spec §5.10): the file as text, numeric blocks
(E501 naming the line of a non-number), an empty recording, and a large export read in chunks (§5.5.1).

Occlusion follows each format: an empty cell or ``NaN`` (and in a Qualisys 3-D export a marker at exactly
(0, 0, 0), :mod:`~haptify.formats.importers.qualisys`).
"""

from __future__ import annotations

import io
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import pandas as pd

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.c3d_stream import STREAM_ABOVE_BYTES
from haptify.formats.importers.recording import Recording


def read_text(path: Path) -> str:
    label = str(path)
    if not path.is_file():
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{label!r} does not exist or is not a file", file=label)
    try:
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{label!r} cannot be read as UTF-8 text: {exc}", file=label) from None


def number_table(lines: list[str], sep: str, path: Path, first_line: int, width: int | None = None) -> np.ndarray:
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
                            Code.IMPORT_SOURCE_UNREADABLE,
                            f"{path.name} line {first_line + i}: {cell!r} is not a number",
                            file=str(path),
                            expected="a number",
                            found=cell,
                        ) from None
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{path.name} cannot be read: {exc}", file=str(path)) from None
    return frame.to_numpy(dtype=np.float64)


def empty_recording(path: Path, fmt: str, manufacturer: str) -> dict[str, Any]:
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


# --- streaming a text export (spec §5.5.1) ---------------------------------------------------------

HEAD_LINES = 64  # a text export's header is within its first lines
STREAM_CHUNK_ROWS = 50_000


def stream_wanted(p: Path, stream: bool | None) -> bool:
    return bool(stream) or (stream is None and p.is_file() and p.stat().st_size > STREAM_ABOVE_BYTES)


def head_lines(p: Path) -> list[str]:
    """The first ``HEAD_LINES`` lines of a text file (E501 when it is unreadable)."""
    try:
        with open(p, encoding="utf-8-sig") as fh:
            return [line.rstrip("\r\n") for line, _ in zip(fh, range(HEAD_LINES))]
    except (OSError, UnicodeDecodeError) as exc:
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{str(p)!r} cannot be read as UTF-8 text: {exc}", file=str(p)) from None


def _data_chunks(p: Path, sep: str, head: dict[str, Any], rows: int) -> Iterator[np.ndarray]:
    """The numeric rows after the header, ``rows`` at a time, parsed as :func:`number_table` parses them."""
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
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE, f"{p.name} cannot be read after line {head['data_start']}: {exc}", file=str(p)
        ) from None


def open_streamed(
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
        first_frame_of(number_table([first.decode("utf-8")], sep, p, head["data_start"] + 1, head["width"])[0])
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


def is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False
