"""C3D files as other systems write them, built with ezc3d's own writer (spec §5.5–5.6; tests, benchmarks).

Every variant the importer must read is made here from known values, never edited by hand: markers
in any unit and at any rate, analog-only files (no point, point rate 0), 6-DoF bodies in the ROTATION
group with or without markers, force platforms of types 1–4 (calibration matrices, Kistler's
eight-channel type 3), and the header/data disagreements some writers leave (:func:`patch_header`
rewrites the header words after ezc3d has written a consistent file, as those writers do).

ezc3d's Python ``write`` needs at least one point; :func:`write_c3d` therefore uses its SWIG layer,
which writes any combination (the same C++ writer).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from haptify.formats.c3d_stream import parameter_records

C3D_BLOCK = 512


@dataclass
class Platform:
    """One FORCE_PLATFORM entry as a vendor writes it: corners (4 × 3, POINT units, lab frame, C3D
    order +x+y, −x+y, −x−y, +x−y of the platform), origin (3), its analog channels (1-based), and a
    calibration matrix (n × n, row = output) for types 3 and 4."""

    type: int
    corners: np.ndarray
    origin: np.ndarray
    channels: list[int]
    cal_matrix: np.ndarray | None = None


@dataclass
class C3DSpec:
    """Everything one synthetic C3D file holds; arrays as the importer reads them back (float32-exact)."""

    point_rate: float = 100.0
    point_units: str = "mm"
    labels: list[str] = field(default_factory=list)
    points: np.ndarray | None = None  # (n_frames, n_markers, 3)
    residuals: np.ndarray | None = None  # (n_frames, n_markers); negative = invalid
    analog_rate: float = 0.0
    analog_labels: list[str] = field(default_factory=list)
    analog_units: list[str] = field(default_factory=list)
    analogs: np.ndarray | None = None  # (n_channels, n_samples), already scaled
    rotation_labels: list[str] = field(default_factory=list)
    rotations: np.ndarray | None = None  # (n_frames, n_bodies, 4, 4) homogeneous, NaN = invalid
    platforms: list[Platform] = field(default_factory=list)
    first_frame: int = 0  # 0-based
    company: str = ""
    software: str = ""
    frames: int = 0  # frames when there is no point and no rotation (analog-only: samples / ratio)


def _param(c, group: str, name: str, values, kind: str = "float", dims: list[int] | None = None) -> None:
    from ezc3d import ezc3d as E  # type: ignore[import-untyped]  # ezc3d ships no type information

    p = E.Parameter(name)
    if kind == "str":
        p.set(E.VecString([str(v) for v in values]), dims or [len(values)])
    elif kind == "int":
        p.set(E.VecInt([int(v) for v in np.ravel(values, order="F")]), dims or [int(np.size(values))])
    else:
        p.set(E.VecDouble([float(v) for v in np.ravel(values, order="F")]), dims or [int(np.size(values))])
    if not c.parameters().isGroup(group):
        c.parameters().group(E.Group(group))
    c.parameter(group, p)


def float32(values: np.ndarray) -> np.ndarray:
    """Values as a C3D file stores them (IEEE float32), back in float64: what a reader gets."""
    return np.asarray(values, dtype=np.float64).astype(np.float32).astype(np.float64)


def _point_arrays(spec: C3DSpec, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The marker points ``(4, markers, frames)`` (homogeneous) and residuals ``(1, markers, frames)`` as ezc3d takes them."""
    n_markers = len(spec.labels)
    points = np.zeros((4, n_markers, n_frames))
    residuals = np.zeros((1, n_markers, n_frames))
    if n_markers:
        if spec.points is None:
            raise ValueError(f"{n_markers} marker labels but no points")
        points[:3] = spec.points.transpose(2, 1, 0)
        points[3] = 1.0
        if spec.residuals is not None:
            residuals[0] = spec.residuals.T
    return points, residuals


def write_c3d(path: Path, spec: C3DSpec) -> Path:
    """Write ``spec`` as a C3D file with ezc3d (float data, Intel byte order)."""
    from ezc3d import ezc3d as E  # type: ignore[import-untyped]  # ezc3d ships no type information

    c = E.c3d()
    n_frames = (
        spec.points.shape[0]
        if spec.points is not None
        else spec.rotations.shape[0]
        if spec.rotations is not None
        else spec.frames
    )
    for label in spec.labels:
        c.point(label)
    for label in spec.analog_labels:
        c.analog(label)
    _param(c, "POINT", "RATE", [spec.point_rate])
    _param(c, "POINT", "UNITS", [spec.point_units], "str")
    _param(c, "ANALOG", "RATE", [spec.analog_rate or spec.point_rate or 1.0])
    if spec.analog_labels:
        _param(c, "ANALOG", "UNITS", spec.analog_units or [""] * len(spec.analog_labels), "str")
    if spec.company or spec.software:
        _param(c, "MANUFACTURER", "COMPANY", [spec.company], "str")
        _param(c, "MANUFACTURER", "SOFTWARE", [spec.software], "str")
    if spec.rotation_labels:
        _param(c, "ROTATION", "USED", [len(spec.rotation_labels)], "int")
        _param(c, "ROTATION", "LABELS", spec.rotation_labels, "str")
        _param(c, "ROTATION", "RATE", [spec.point_rate])
        _param(c, "ROTATION", "RATIO", [1], "int")
    if spec.platforms:
        n = len(spec.platforms)
        width = max(len(p.channels) for p in spec.platforms)
        _param(c, "FORCE_PLATFORM", "USED", [n], "int")
        _param(c, "FORCE_PLATFORM", "TYPE", [p.type for p in spec.platforms], "int")
        _param(c, "FORCE_PLATFORM", "CORNERS", np.stack([p.corners.T for p in spec.platforms], axis=2), dims=[3, 4, n])
        _param(c, "FORCE_PLATFORM", "ORIGIN", np.stack([p.origin for p in spec.platforms], axis=1), dims=[3, n])
        chan = np.zeros((width, n), dtype=int)
        for i, p in enumerate(spec.platforms):
            chan[: len(p.channels), i] = p.channels
        _param(c, "FORCE_PLATFORM", "CHANNEL", chan, "int", dims=[width, n])
        cals = [p.cal_matrix for p in spec.platforms if p.cal_matrix is not None]
        if cals:
            size = max(m.shape[0] for m in cals)
            cal = np.zeros((size, size, n))
            for i, p in enumerate(spec.platforms):
                if p.cal_matrix is not None:
                    k = p.cal_matrix.shape[0]
                    cal[:k, :k, i] = p.cal_matrix  # first index = output row, as ezc3d applies it
            _param(c, "FORCE_PLATFORM", "CAL_MATRIX", cal, dims=[size, size, n])
    n_markers = len(spec.labels)
    points, residuals = _point_arrays(spec, n_frames)
    n_ch = len(spec.analog_labels)
    analogs = np.zeros((1, n_ch, 0 if spec.analogs is None else spec.analogs.shape[1]))
    if n_ch:
        analogs[0] = spec.analogs
    rotations = None if spec.rotations is None else spec.rotations.transpose(2, 3, 1, 0)
    if spec.first_frame:  # ezc3d keeps TRIAL:ACTUAL_START_FIELD/END_FIELD in step with the header
        _param(c, "TRIAL", "ACTUAL_START_FIELD", [spec.first_frame + 1, 0], "int")
        _param(c, "TRIAL", "ACTUAL_END_FIELD", [spec.first_frame + n_frames, 0], "int")
        c.header().firstFrame(spec.first_frame)
    c.import_numpy_data(points, residuals, np.zeros((7, n_markers, n_frames), dtype=bool), analogs, rotations)
    c.write(str(path), E.WriteOptions(True, False))
    return path


def header_words(path: Path) -> tuple[int, ...]:
    """The first nine 16-bit header words (Intel order)."""
    return struct.unpack("<9H", path.read_bytes()[:18])


def patch_header(path: Path, *, first_frame: int | None = None, last_frame: int | None = None, rate: float | None = None) -> Path:
    """Rewrite header words 4–5 (first and last frame, as stored) and the header frame rate of a file
    ezc3d wrote: the disagreements other writers leave between the header and the data."""
    data = bytearray(path.read_bytes())
    if first_frame is not None:
        data[6:8] = struct.pack("<H", first_frame)
    if last_frame is not None:
        data[8:10] = struct.pack("<H", last_frame)
    if rate is not None:
        data[20:24] = struct.pack("<f", rate)
    path.write_bytes(bytes(data))
    return path


def rectangle_corners(centre, size_x: float, size_y: float, x_axis=(1.0, 0.0, 0.0), z_down=(0.0, 0.0, -1.0)) -> np.ndarray:
    """The four C3D corners (+x+y, −x+y, −x−y, +x−y of the platform) of a size_x × size_y plate whose
    x axis and (downward) z axis are given in the lab frame."""
    x = np.asarray(x_axis, float) / np.linalg.norm(x_axis)
    z = np.asarray(z_down, float) / np.linalg.norm(z_down)
    y = np.cross(z, x)
    c = np.asarray(centre, float)
    return np.array([c + sx * size_x / 2 * x + sy * size_y / 2 * y for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))])


# --- force platforms carrying a known load (spec §5.6.1) -------------------------------------------

PLATFORM_UNITS = {
    1: ["N", "N", "N", "mm", "mm", "Nmm"],
    2: ["N", "N", "N", "Nmm", "Nmm", "Nmm"],
    3: ["N"] * 8,
    4: ["N", "N", "N", "Nmm", "Nmm", "Nmm"],
}


def unimodular(seed: int, n: int = 6) -> np.ndarray:
    """An integer n × n calibration matrix with an integer inverse (determinant 1: unit lower times unit
    upper triangular), so that channels = CAL⁻¹ · outputs are integers a C3D file stores exactly."""
    rng = np.random.default_rng(seed)
    lower = np.tril(rng.integers(-2, 3, (n, n)), -1) + np.eye(n, dtype=int)
    upper = np.triu(rng.integers(-2, 3, (n, n)), 1) + np.eye(n, dtype=int)
    return (lower @ upper).astype(np.float64)


def known_load_channels(
    kind: int,
    force,
    point,
    free_moment: np.ndarray,
    origin,
    cal: np.ndarray | None = None,
    split: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """The channels ``(n_channels, N)`` a platform of ``kind`` records for a load, all in the platform
    frame (x, y in the top surface, z down; N, mm, N·mm): ``force (N, 3)`` acting at ``point (N, 2)``
    of the top surface (measured from its centre) with the free moment ``free_moment (N,)`` about the
    vertical there. The channels hold the platform's reaction — the negated force and moments, as
    platforms write them (a load pressing down, +z, reads a negative Fz). ``origin`` is FORCE_PLATFORM:ORIGIN as the standard writes it (the sensing origin →
    the surface centre; type 3: ``(a, b, az0)``). Type 3's two statically free shares — how the vertical
    load twists among the four sensors, how Fy divides between the sensor pairs — are ``split`` (default
    zero); type 4 records ``CAL⁻¹ · [F, M]``. Raises ValueError when a channel value would not be stored
    exactly as float32 (choose integers, and for type 3 offsets that are powers of two)."""
    f = -np.asarray(force, np.float64)  # the reaction
    p = np.asarray(point, np.float64)
    o = np.asarray(origin, np.float64)
    n = len(f)
    tz = -np.asarray(free_moment, np.float64)
    surface = np.zeros(3) if kind == 3 else o  # the point from the sensing origin: O → C, then C → P
    r = np.column_stack([p, np.zeros(n)]) + (np.array([0.0, 0.0, o[2]]) if kind == 3 else surface)
    moment = np.cross(r, f)
    moment[:, 2] += tz
    if kind == 1:
        ch = np.vstack([f.T, p[:, 0] + o[0], p[:, 1] + o[1], tz])
    elif kind in (2, 4):
        ch = np.vstack([f.T, moment.T])
        if kind == 4:
            if cal is None:
                raise ValueError("a type-4 platform records CAL⁻¹ · [F, M]: give its calibration matrix")
            ch = np.rint(np.linalg.inv(cal)) @ ch
    else:
        a, b = o[0], o[1]
        twist, shift = (np.zeros(n), np.zeros(n)) if split is None else map(np.asarray, split)
        s, u, v = f[:, 2], moment[:, 0] / b, moment[:, 1] / a
        fz = [(s + u - v + twist) / 4, (s + u + v - twist) / 4, (s - u + v + twist) / 4, (s - u - v - twist) / 4]
        fy14, fy23 = f[:, 1] / 2 + shift, f[:, 1] / 2 - shift
        dx = (moment[:, 2] - a * (fy14 - fy23)) / b
        ch = np.vstack([(f[:, 0] - dx) / 2, (f[:, 0] + dx) / 2, fy14, fy23, *fz])
    if not np.array_equal(float32(ch), ch):
        raise ValueError("a channel value is not exactly a float32; choose integer loads")
    return ch


# --- large files (benchmarks/bench_import.py, the streamed import's tests) --------------------------


def patch_parameter(path: Path, group: str, name: str, values) -> Path:
    """Overwrite the values of an existing parameter in place (same count, its own element type): the
    scale factors and offsets other writers set (ezc3d writes 1 and 0)."""
    data = bytearray(path.read_bytes())
    offset, dtype, dims = parameter_records(bytes(data))[(group, name)]
    vals = np.asarray(values, dtype=dtype).ravel()
    count = int(np.prod(dims)) if dims else 1
    if vals.size != count:
        raise ValueError(f"{group}:{name} holds {count} values, not {vals.size}")
    data[offset : offset + vals.nbytes] = vals.tobytes()
    path.write_bytes(bytes(data))
    return path


def to_integer(src: Path, dst: Path, point_scale: float) -> Path:
    """The same recording in the INTEGER format (int16 words; points stored as value / point_scale, the
    fourth word as int16, analog words as they were): POINT:SCALE and the header's scale factor become
    ``point_scale`` > 0. Every stored value must be an integer in that encoding (ValueError otherwise)."""
    data = bytearray(src.read_bytes())
    recs = parameter_records(bytes(data))
    (start,) = np.frombuffer(bytes(data), "<i2", 1, recs[("POINT", "DATA_START")][0])
    points = struct.unpack_from("<H", data, 2)[0]
    body = np.frombuffer(bytes(data[(start - 1) * C3D_BLOCK :]), "<f4").astype(np.float64)
    analog_values = struct.unpack_from("<H", data, 4)[0]
    frame = 4 * points + analog_values
    words = body[: len(body) // frame * frame].reshape(-1, frame).copy()
    xyz = words[:, : 4 * points].reshape(len(words), points, 4)
    xyz[:, :, :3] /= point_scale
    if not np.array_equal(np.rint(words), words) or np.abs(words).max(initial=0) > 32767:
        raise ValueError("a value is not an int16 in the INTEGER encoding")
    out = data[: (start - 1) * C3D_BLOCK] + words.astype("<i2").tobytes()
    out += bytes(-len(out) % C3D_BLOCK)
    struct.pack_into("<f", out, 12, point_scale)
    dst.write_bytes(bytes(out))
    return patch_parameter(dst, "POINT", "SCALE", [point_scale])


def grow_c3d(path: Path, template: C3DSpec, frames: int, fill, chunk: int = 20_000) -> Path:
    """A C3D file of ``frames`` frames without holding them: ezc3d writes ``template``'s header and
    parameters (its own frames are dropped), the frame counts are set as ezc3d sets them (header last
    frame and POINT:FRAMES; the long-file mark 65535 / −1 past 65535 frames), and the frames are
    appended ``chunk`` at a time from ``fill(first, count)`` → (points ``(count, markers, 3)``, analog
    samples ``(channels, count · per frame)``), REAL words, every point valid."""
    write_c3d(path, template)
    data = path.read_bytes()
    (start,) = np.frombuffer(data, "<i2", 1, parameter_records(data)[("POINT", "DATA_START")][0])
    head = bytearray(data[: (start - 1) * C3D_BLOCK])
    first = struct.unpack_from("<H", head, 6)[0]
    struct.pack_into("<H", head, 8, min(first + frames - 1, 0xFFFF))
    path.write_bytes(bytes(head))
    patch_parameter(path, "POINT", "FRAMES", [frames if frames <= 32767 else frames - 65536 if frames <= 65535 else -1])
    markers = len(template.labels)
    with open(path, "ab") as fh:
        for at in range(0, frames, chunk):
            n = min(chunk, frames - at)
            points, analogs = fill(at, n)
            quad = np.ones((n, markers, 4), np.float32)
            quad[:, :, :3] = points
            samples = np.asarray(analogs, np.float32).T.reshape(n, -1)  # sample by sample, channels inside
            fh.write(np.hstack([quad.reshape(n, -1), samples]).astype("<f4").tobytes())
        fh.write(bytes(-fh.tell() % C3D_BLOCK))
    return path
