"""Reading a C3D file's data block in chunks, for large files (spec §5.5.1).

ezc3d reads a whole file into memory (several times its size); a 2 GB recording must not need that.
The header and the parameter section are read by ezc3d from a copy of the file's first blocks (the
parameters end where the data begin), so every parameter is interpreted exactly as for a small file;
the data block is then read here, ``chunk_frames`` frames at a time, with numpy, in the two standard
encodings — REAL (``POINT:SCALE < 0``: IEEE float32) and INTEGER (int16, points times ``|POINT:SCALE|``)
— in Intel byte order. A frame holds, per point, x, y, z and a fourth word whose sign marks an
invalid sample (its low byte times ``|POINT:SCALE|`` is the residual), then the analog samples of the
frame, sample by sample, each channel scaled as ``(raw − |OFFSET|) · SCALE · GEN_SCALE`` (ezc3d
subtracts the offset's magnitude). Files in DEC or
MIPS byte order, and files with a ROTATION group (a separate data section), are read whole by ezc3d.

The frames read are the ones ezc3d reads: those ``POINT:FRAMES`` declares (the header's count when the
parameter is missing; every complete frame when it holds the long-file mark 65535, as for a file longer
than 65535 frames), and never more than the file holds.
"""

from __future__ import annotations

import shutil
import struct
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Iterator

import numpy as np

C3D_BLOCK = 512
LONG_FILE_MARK = 0xFFFF  # header last frame / POINT:FRAMES of a file longer than 65535 frames
PROCESSOR_ORDER = {84: "<"}  # Intel; DEC (85) and MIPS (86) files are left to ezc3d
STREAM_CHUNK_BYTES = 32 * 2**20  # about this much of the data block per chunk
STREAM_ABOVE_BYTES = 128 * 2**20  # a larger C3D file is imported in chunks (§5.5.1)


@dataclass(frozen=True)
class C3DLayout:
    """Where and how a C3D file's frames are stored (spec §5.5.1)."""

    path: Path
    data_offset: int  # bytes from the start of the file to frame 0
    order: str  # "<" Intel
    real: bool  # float32 words (else int16)
    points: int
    channels: int
    per_frame: int  # analog samples per frame
    frames: int  # frames read (see the module docstring)
    point_scale: float
    analog_scale: np.ndarray  # (channels,) ANALOG:SCALE
    analog_offset: np.ndarray  # (channels,) |ANALOG:OFFSET|, as ezc3d subtracts it
    gen_scale: float
    unsigned: bool  # ANALOG:FORMAT UNSIGNED (INTEGER files)

    @property
    def frame_words(self) -> int:
        return 4 * self.points + self.channels * self.per_frame

    @property
    def frame_bytes(self) -> int:
        return self.frame_words * (4 if self.real else 2)


PARAM_TYPES = {-1: "S1", 1: "i1", 2: "<i2", 4: "<f4"}  # C3D parameter element types (Intel byte order)


def parameter_records(data: bytes) -> dict[tuple[str, str], tuple[int, str, tuple[int, ...]]]:
    """Every parameter of an Intel C3D file's parameter section: ``(GROUP, NAME)`` → (byte offset of its
    data, numpy dtype, dimensions). The section is a chain of records (name length, group id, name,
    offset to the next record; for a parameter: type, dimensions, data)."""
    start = (data[0] - 1) * C3D_BLOCK + 4
    groups: dict[int, str] = {}
    params: dict[int, list[tuple[str, int, str, tuple[int, ...]]]] = {}
    pos = start
    while True:
        n_chars, gid = struct.unpack_from("<bb", data, pos)
        if n_chars == 0:
            break
        name = data[pos + 2 : pos + 2 + abs(n_chars)].decode("ascii").upper()
        here = pos + 2 + abs(n_chars)
        (step,) = struct.unpack_from("<h", data, here)
        if gid < 0:
            groups[-gid] = name
        else:
            kind, ndim = struct.unpack_from("<bB", data, here + 2)
            dims = tuple(data[here + 4 : here + 4 + ndim])
            params.setdefault(gid, []).append((name, here + 4 + ndim, PARAM_TYPES[kind], dims))
        if step == 0:
            break
        pos = here + step
    return {(groups[g], name): (off, dtype, dims) for g, rows in params.items() for name, off, dtype, dims in rows}


def read_head(path: Path) -> tuple[Any, int]:
    """ezc3d's reading of the header and parameters alone (a copy of the blocks before the data), and
    the first data block (1-based). Raises what ezc3d raises for an unreadable file."""
    import ezc3d

    with open(path, "rb") as fh:
        head = fh.read(C3D_BLOCK)
        data_start = int.from_bytes(head[16:18], "little")
    with tempfile.TemporaryDirectory(prefix="haptify-c3d-") as tmp:
        copy = Path(tmp) / "head.c3d"
        with open(path, "rb") as src, open(copy, "wb") as dst:
            shutil.copyfileobj(_limited(src, (data_start - 1) * C3D_BLOCK), dst)
        c = ezc3d.c3d(str(copy), extract_forceplat_data=False)
        with open(path, "rb") as fh:  # ezc3d sets POINT:FRAMES to the frames it read (none): the file's own
            section = fh.read((data_start - 1) * C3D_BLOCK)
        where = parameter_records(section).get(("POINT", "FRAMES"))
        if where is not None and "POINT" in c["parameters"] and "FRAMES" in c["parameters"]["POINT"]:
            offset, dtype, dims = where
            c["parameters"]["POINT"]["FRAMES"]["value"] = np.frombuffer(section, dtype, max(1, int(np.prod(dims))), offset)
    return c, data_start


class _limited:
    def __init__(self, fh: BinaryIO, n: int) -> None:
        self.fh, self.left = fh, n

    def read(self, size: int = -1) -> bytes:
        size = self.left if size < 0 else min(size, self.left)
        out = self.fh.read(size)
        self.left -= len(out)
        result: bytes = out
        return result


def _values(params: Any, group: str, name: str, n: int, default: float) -> np.ndarray:
    try:
        v = np.asarray(params[group][name]["value"], dtype=np.float64).ravel()
    except (KeyError, TypeError, ValueError):
        v = np.zeros(0)
    return np.concatenate([v, np.full(max(0, n - v.size), default)])[:n] if n else np.zeros(0)


def declared_frames(params: Any, header_frames: int, header_long: bool) -> int | None:
    """The frames a file declares, as ezc3d counts them: ``POINT:FRAMES`` (16 bits, unsigned) when
    present, else the header's count; None for the long-file mark 65535 (every complete frame)."""
    try:
        value = float(np.asarray(params["POINT"]["FRAMES"]["value"], dtype=np.float64).ravel()[0])
    except (KeyError, TypeError, IndexError, ValueError):
        return None if header_long else header_frames
    frames = int(value) % 0x10000 if value < 0 else int(value)
    return None if frames == LONG_FILE_MARK else frames


def c3d_layout(
    path: Path, c: Any, data_start: int, analog_values: int, header_frames: int, header_long: bool
) -> C3DLayout | None:
    """The data layout of a C3D file from ezc3d's header and parameters and the header's analog values
    per frame (word 3) and frame count; None when the file is not read here (DEC or MIPS byte order, a
    ROTATION group)."""
    params, head = c["parameters"], c["header"]
    with open(path, "rb") as fh:
        first = fh.read(1)[0]
        fh.seek(3 + (first - 1) * C3D_BLOCK)
        processor = fh.read(1)[0]
    if processor not in PROCESSOR_ORDER or "ROTATION" in params:
        return None
    points = int(head["points"]["size"])
    channels = int(head["analogs"]["size"])
    per_frame = analog_values // channels if channels else 0
    scale = float(_values(params, "POINT", "SCALE", 1, -1.0)[0])
    real = scale < 0
    fmt = params.get("ANALOG", {}).get("FORMAT", {}).get("value", ["SIGNED"]) if "ANALOG" in params else ["SIGNED"]
    unsigned = bool(fmt) and str(fmt[0]).strip().upper() == "UNSIGNED"
    gen = float(_values(params, "ANALOG", "GEN_SCALE", 1, 1.0)[0])
    layout = C3DLayout(
        path,
        (data_start - 1) * C3D_BLOCK,
        PROCESSOR_ORDER[processor],
        real,
        points,
        channels,
        per_frame,
        0,
        abs(scale),
        _values(params, "ANALOG", "SCALE", channels, 1.0),
        np.abs(_values(params, "ANALOG", "OFFSET", channels, 0.0)),
        gen,
        unsigned,
    )
    held = max(0, (path.stat().st_size - layout.data_offset) // layout.frame_bytes) if layout.frame_bytes else 0
    declared = declared_frames(params, header_frames, header_long)
    frames = held if declared is None else min(declared, held)
    return C3DLayout(**{**layout.__dict__, "frames": int(frames)})


def read_frames(layout: C3DLayout, start: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Frames ``start … start + count − 1``: points ``(count, points, 3)`` (NaN where invalid) and analog
    samples ``(channels, count · per_frame)``, both float64 as ezc3d gives them (spec §5.5.1)."""
    word = np.dtype(f"{layout.order}{'f4' if layout.real else 'i2'}")
    with open(layout.path, "rb") as fh:
        fh.seek(layout.data_offset + start * layout.frame_bytes)
        raw = np.fromfile(fh, dtype=word, count=count * layout.frame_words)
    raw = raw.reshape(count, layout.frame_words)
    n_pt = 4 * layout.points
    quad = raw[:, :n_pt].reshape(count, layout.points, 4)
    xyz = quad[:, :, :3].astype(np.float64)
    if not layout.real:
        xyz *= layout.point_scale
    fourth = np.trunc(quad[:, :, 3].astype(np.float64)) if layout.real else quad[:, :, 3].astype(np.float64)
    with np.errstate(invalid="ignore"):
        invalid = (fourth < 0) | ~np.isfinite(xyz).all(axis=2)
    xyz[invalid] = np.nan
    an = raw[:, n_pt:].reshape(count * layout.per_frame, layout.channels)
    if not layout.real and layout.unsigned:
        an = an.view(np.dtype(f"{layout.order}u2"))
    analogs = (an.T.astype(np.float64) - layout.analog_offset[:, None]) * layout.analog_scale[:, None] * layout.gen_scale
    return xyz, analogs


def chunk_frames_for(layout: C3DLayout, budget_bytes: int = STREAM_CHUNK_BYTES) -> int:
    """Frames per chunk: about ``budget_bytes`` of the data block, at least one frame."""
    return max(1, budget_bytes // max(layout.frame_bytes, 1))


def iter_frames(layout: C3DLayout, chunk: int) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """``(first frame, points, analogs)`` for consecutive chunks of ``chunk`` frames (spec §5.5.1)."""
    for start in range(0, layout.frames, chunk):
        points, analogs = read_frames(layout, start, min(chunk, layout.frames - start))
        yield start, points, analogs
