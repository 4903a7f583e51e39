"""C3D files (spec §5.5): the header, the parameters and the data as ezc3d reads them, their
disagreements (W501), the force platforms and 6-DoF bodies; the C3D import."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from haptify.codes import Code
from haptify.errors import Finding, fail
from haptify.formats.c3d_stream import STREAM_ABOVE_BYTES, c3d_layout, read_head
from haptify.formats.importers.destination import Destination, ImportResult, prepare
from haptify.formats.importers.import_map import LoadedMap
from haptify.formats.importers.motion_capture import import_recording
from haptify.formats.importers.recording import C3DPlatform, Recording


def _param(params: Any, group: str, name: str, default: Any = None) -> Any:
    try:
        return params[group][name]["value"]
    except (KeyError, TypeError):
        return default


def _strings(values: Any, n: int) -> list[str]:
    vals = [str(v).strip() for v in (values if values is not None else [])]
    return (vals + [""] * n)[:n]


def _number(params: Any, group: str, name: str) -> float | None:
    """A numeric parameter's first value, or None when absent or empty."""
    arr = np.asarray(_param(params, group, name, []), dtype=np.float64).ravel()
    return float(arr[0]) if arr.size else None


C3D_BLOCK = 512  # bytes per C3D block
C3D_LONG_FILE_LAST_FRAME = 0xFFFF  # header word 5 of a file longer than 65535 frames (the count is elsewhere)
RATE_AGREEMENT = 1e-6  # relative: a header rate and a parameter rate closer than this agree


@dataclass(frozen=True)
class C3DHeader:
    """The header words the importer compares with the data (spec §5.5): point count, analog values
    per frame, first and last frame (as stored), frame rate. Byte order from the processor type."""

    points: int
    analog_values: int
    first_frame: int
    last_frame: int
    rate: float

    @property
    def frames(self) -> int:
        """Frames the header declares: last − first + 1 (both 1-based, or both 0-based as some writers
        store them); none when both words are 0 or the last precedes the first."""
        return self.last_frame - self.first_frame + 1 if self.last_frame >= max(self.first_frame, 1) else 0


def read_c3d_header(path: Path) -> C3DHeader:
    """The header of a C3D file (16-bit words 2–5, float word 11–12). E501 when too short."""
    with open(path, "rb") as fh:
        head = fh.read(C3D_BLOCK)
        if len(head) < 24 or head[0] == 0:
            raise fail(
                Code.IMPORT_SOURCE_UNREADABLE,
                f"{str(path)!r} is too short for a C3D header",
                file=str(path),
                expected=f"≥ {C3D_BLOCK} bytes",
                found=len(head),
            )
        fh.seek((head[0] - 1) * C3D_BLOCK + 3)
        processor = fh.read(1)
    order = ">" if processor == bytes([86]) else "<"
    words = struct.unpack(f"{order}9H", head[:18])
    rate = struct.unpack(f"{order}f", head[20:24])[0] if processor != bytes([85]) else float("nan")
    return C3DHeader(words[1], words[2], words[3], words[4], float(rate))


def _disagreement(path: Path, what: str, header: Any, other: Any, followed: str, pointer: str) -> Finding:
    return Finding(
        Code.IMPORT_SOURCE_DISAGREES,
        f"{path.name}: {what}; {followed}",
        file=str(path),
        pointer=pointer,
        expected=header,
        found=other,
    )


def c3d_disagreements(
    path: Path,
    header: C3DHeader,
    params: Any,
    frames_read: int,
    analog_per_frame: int,
    point_rate: float,
    analog_rate: float,
    header_analog_rate: float,
) -> list[Finding]:
    """W501 findings: where the header, the POINT/ANALOG parameters and the data as read disagree
    (spec §5.5). The data as read, and the rates chosen by §5.5's rule, are what is imported."""
    out = []
    long_file = header.last_frame == C3D_LONG_FILE_LAST_FRAME and frames_read >= header.frames
    if header.frames != frames_read and not long_file:
        out.append(
            _disagreement(
                path,
                f"the header declares {header.frames} frames, the data hold {frames_read}",
                header.frames,
                frames_read,
                f"the {frames_read} frames read are imported",
                "/header/last_frame",
            )
        )
    frames_param = _number(params, "POINT", "FRAMES")
    if frames_param is not None and frames_param >= 0 and int(frames_param) != frames_read and not long_file:
        out.append(
            _disagreement(
                path,
                f"POINT:FRAMES is {int(frames_param)}, the data hold {frames_read} frames",
                int(frames_param),
                frames_read,
                f"the {frames_read} frames read are imported",
                "/POINT/FRAMES",
            )
        )
    used = _number(params, "POINT", "USED")
    if used is not None and int(used) != header.points:
        out.append(
            _disagreement(
                path,
                f"POINT:USED is {int(used)}, the header holds {header.points} points",
                header.points,
                int(used),
                "the header's points are read",
                "/POINT/USED",
            )
        )
    rate_param = _number(params, "POINT", "RATE")
    if (
        rate_param is not None
        and header.rate > 0
        and rate_param > 0
        and abs(rate_param - header.rate) > RATE_AGREEMENT * header.rate
    ):
        out.append(
            _disagreement(
                path,
                f"POINT:RATE is {rate_param:g} Hz, the header says {header.rate:g} Hz",
                header.rate,
                rate_param,
                f"{point_rate:g} Hz is used",
                "/POINT/RATE",
            )
        )
    an_param = _number(params, "ANALOG", "RATE")
    if (
        analog_per_frame
        and an_param is not None
        and header_analog_rate > 0
        and an_param > 0
        and abs(an_param - header_analog_rate) > RATE_AGREEMENT * header_analog_rate
    ):
        out.append(
            _disagreement(
                path,
                f"ANALOG:RATE is {an_param:g} Hz, the header implies {header_analog_rate:g} Hz",
                header_analog_rate,
                an_param,
                f"{analog_rate:g} Hz is used",
                "/ANALOG/RATE",
            )
        )
    return out


def _platforms(params: Any, n_analogs: int, path: Path) -> tuple[list[C3DPlatform], list[Finding]]:
    """The FORCE_PLATFORM entries (spec §5.6): corners, origin, type, channels, calibration matrix."""
    used = np.asarray(_param(params, "FORCE_PLATFORM", "USED", []), dtype=np.int64).ravel()
    n_plates = int(used[0]) if used.size else 0
    corners = np.asarray(_param(params, "FORCE_PLATFORM", "CORNERS", []), dtype=np.float64)
    origins = np.asarray(_param(params, "FORCE_PLATFORM", "ORIGIN", []), dtype=np.float64)
    types = np.asarray(_param(params, "FORCE_PLATFORM", "TYPE", []), dtype=np.int64).ravel()
    channel = np.asarray(_param(params, "FORCE_PLATFORM", "CHANNEL", []), dtype=np.int64)
    cal = np.asarray(_param(params, "FORCE_PLATFORM", "CAL_MATRIX", []), dtype=np.float64)
    corners = corners.reshape(3, 4, -1) if corners.size and corners.size % 12 == 0 else corners
    origins = origins.reshape(3, -1) if origins.size and origins.size % 3 == 0 else origins
    channel = channel.reshape(channel.shape[0], -1) if channel.ndim >= 1 and channel.size else channel
    out, notes = [], []
    for i in range(n_plates):
        cor = corners[:, :, i].T.copy() if corners.ndim == 3 and corners.shape[2] > i else None
        org = origins[:, i].copy() if origins.ndim == 2 and origins.shape[1] > i else None
        chans = [int(c) - 1 for c in channel[:, i]] if channel.ndim == 2 and channel.shape[1] > i else []
        chans = [c for c in chans if c >= 0]
        if any(c >= n_analogs for c in chans):
            notes.append(
                Finding(
                    Code.IMPORT_SOURCE_DISAGREES,
                    f"{path.name}: FORCE_PLATFORM:CHANNEL of platform {i + 1} names analog "
                    f"channels beyond the {n_analogs} the file holds; its channels are not used",
                    file=str(path),
                    pointer="/FORCE_PLATFORM/CHANNEL",
                    expected=f"≤ {n_analogs}",
                    found=[c + 1 for c in chans],
                )
            )
            chans = []
        matrix = None
        if cal.ndim == 3 and cal.shape[2] > i and cal.shape[0] == cal.shape[1] and cal[:, :, i].any():
            matrix = cal[:, :, i].copy()  # CAL_MATRIX(output, channel, plate), as ezc3d applies it
        out.append(C3DPlatform(i + 1, int(types[i]) if types.size > i else None, cor, org, chans, matrix))
    return out, notes


def _rotations(
    c: Any, params: Any, n_frames: int, path: Path
) -> tuple[list[str], np.ndarray | None, np.ndarray | None, list[Finding]]:
    """The ROTATION group's 6-DoF bodies (spec §5.5): labels, positions (POINT units) and rotation
    matrices (body → lab) per point frame; NaN where the writer marked a sample invalid."""
    rot = np.asarray(c["data"].get("rotations", np.zeros((4, 4, 0, 0))), dtype=np.float64)
    if rot.ndim != 4 or rot.shape[2] == 0 or rot.shape[3] == 0:
        return [], None, None, []
    notes = []
    ratio = max(1, int(_number(params, "ROTATION", "RATIO") or 1))
    if ratio > 1:  # several rotation samples per point frame: the point clock keeps the first of each
        notes.append(
            Finding(
                Code.IMPORT_SOURCE_DISAGREES,
                f"{path.name}: ROTATION:RATIO is {ratio}; one rotation sample per point frame (the first) is imported",
                file=str(path),
                pointer="/ROTATION/RATIO",
                expected=1,
                found=ratio,
            )
        )
        rot = rot[:, :, :, ::ratio]
    labels = _strings(_param(params, "ROTATION", "LABELS"), rot.shape[2])
    m = rot.transpose(3, 2, 0, 1)  # (frames, bodies, 4, 4)
    return labels, m[:, :, :3, 3].copy(), m[:, :, :3, :3].copy(), notes


def read_c3d(path: str | Path, *, stream: bool | None = None) -> Recording:
    """Read a C3D file with ezc3d (spec §5.5). E501 only when it is missing, not a C3D, or ezc3d cannot
    read it; every disagreement between the header, the parameters and the data is a W501 finding in
    ``warnings``, and the data as ezc3d reads them are what the recording holds.

    A file larger than ``STREAM_ABOVE_BYTES`` (or any file with ``stream=True``; never with ``False``)
    is opened for streaming (§5.5.1) when its encoding allows: the recording then holds only its
    header facts, ``layout`` says where its frames are, and :func:`recording_chunks` reads them."""
    import ezc3d

    p = Path(path)
    label = str(p)
    if not p.is_file():
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{label!r} does not exist or is not a file", file=label)
    with open(p, "rb") as fh:
        head = fh.read(2)
    if len(head) < 2 or head[1] != 0x50:
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE,
            f"{label!r} is not a C3D file (its second byte is not 0x50)",
            file=label,
            expected="0x50",
            found=head[1:2].hex() or "end of file",
        )
    header = read_c3d_header(p)
    layout = None
    try:
        if stream or (stream is None and p.stat().st_size > STREAM_ABOVE_BYTES):
            c, data_start = read_head(p)
            layout = c3d_layout(
                p, c, data_start, header.analog_values, header.frames, header.last_frame == C3D_LONG_FILE_LAST_FRAME
            )
        if layout is None:
            c = ezc3d.c3d(str(p), extract_forceplat_data=False)
    except (OSError, RuntimeError, ValueError, IndexError) as exc:
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{label!r} cannot be read as C3D: {exc}", file=label) from None
    params, head_info, data = c["parameters"], c["header"], c["data"]
    if layout is not None:  # the frames stay in the file; broadcast NaN views carry only the shapes (§5.5.1)
        xyz = np.broadcast_to(np.float64(np.nan), (layout.frames, layout.points, 3))
        analogs = np.broadcast_to(np.float64(0.0), (layout.channels, layout.frames * layout.per_frame))
        n_markers, n_frames = layout.points, layout.frames
    else:
        pts = np.asarray(data["points"], dtype=np.float64)  # (4, n_markers, n_frames)
        n_markers, n_frames = pts.shape[1], pts.shape[2]
        xyz = pts[:3].transpose(2, 1, 0).copy()  # (n_frames, n_markers, 3)
        residuals = np.asarray(data["meta_points"]["residuals"], dtype=np.float64)[0].T if n_markers else np.zeros((n_frames, 0))
        invalid = (residuals < 0) | ~np.isfinite(xyz).all(axis=2)
        xyz[invalid] = np.nan
        an = np.asarray(data["analogs"], dtype=np.float64)
        analogs = an[0] if an.ndim == 3 and an.shape[0] == 1 else an.reshape(an.shape[-2], -1)
    n_ch = analogs.shape[0]
    per_frame = analogs.shape[1] // n_frames if n_frames else 0
    # rates (spec §5.5): the header's as ezc3d reads it; a writer that leaves it 0 (analog-only files)
    # has the parameter's
    point_rate = float(head_info["points"]["frame_rate"]) or (_number(params, "POINT", "RATE") or 0.0)
    header_analog_rate = float(head_info["analogs"]["frame_rate"])
    analog_rate = header_analog_rate or (_number(params, "ANALOG", "RATE") or 0.0)
    warnings = c3d_disagreements(p, header, params, n_frames, per_frame, point_rate, analog_rate, header_analog_rate)
    if n_ch and analog_rate <= 0:
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE,
            f"{label!r} holds {n_ch} analog channels but states no analog rate",
            file=label,
            pointer="/ANALOG/RATE",
            expected="a rate > 0",
            found=analog_rate,
        )
    company = _strings(_param(params, "MANUFACTURER", "COMPANY"), 1)[0]
    software = _strings(_param(params, "MANUFACTURER", "SOFTWARE"), 1)[0]
    if software.startswith(company):
        company = ""
    units = _strings(_param(params, "POINT", "UNITS"), 1)[0] or None
    platforms, notes = _platforms(params, n_ch, p)
    body_labels, body_pos, body_rot, rot_notes = _rotations(c, params, n_frames, p)
    if body_labels and point_rate <= 0:
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE,
            f"{label!r} holds 6-DoF bodies but states no frame rate",
            file=label,
            pointer="/POINT/RATE",
            expected="a rate > 0",
            found=point_rate,
        )
    if n_markers and point_rate <= 0:
        raise fail(
            Code.IMPORT_SOURCE_UNREADABLE,
            f"{label!r} holds {n_markers} points but states no point rate",
            file=label,
            pointer="/POINT/RATE",
            expected="a rate > 0",
            found=point_rate,
        )
    return Recording(
        path=p,
        manufacturer=" ".join(s for s in (company, software) if s),
        point_labels=_strings(_param(params, "POINT", "LABELS"), n_markers),
        point_units=units,
        point_rate=point_rate,
        point_first_frame=int(head_info["points"]["first_frame"]),
        points=xyz,
        analog_labels=_strings(_param(params, "ANALOG", "LABELS"), n_ch),
        analog_units=_strings(_param(params, "ANALOG", "UNITS"), n_ch),
        analog_rate=analog_rate,
        analog_first_sample=int(head_info["points"]["first_frame"]) * max(per_frame, 1),
        analogs=analogs,
        platforms=platforms,
        body_labels=body_labels,
        body_positions=body_pos,
        body_rotations=body_rot,
        warnings=warnings + notes + rot_notes,
        layout=layout,
    )


def import_c3d(
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
    """Import a C3D file as one trial of a new session at ``out`` (spec §5.5), or append it as one
    more trial to the session at ``out`` (``append``, §5.9). See :func:`import_recording`; ``stream``
    as :func:`read_c3d`."""
    dest, loaded, _, device, extra = prepare(out, mapping, "c3d", overrides, overwrite, append)
    return import_recording(
        read_c3d(path, stream=stream), dest, loaded, device, extra, chunk_frames=chunk_frames, progress=progress
    )
