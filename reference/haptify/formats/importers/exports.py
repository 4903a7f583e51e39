"""The motion-capture text exports (spec §5.10): which format a file is, its reader, and its import
through the map rules of a C3D file (markers, 6-DoF bodies, analog channels; W of §5.6)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from haptify.formats.importers.destination import Destination, ImportResult, prepare
from haptify.formats.importers.import_map import LoadedMap
from haptify.formats.importers.motion_capture import import_recording
from haptify.formats.importers.motive import read_motive_csv
from haptify.formats.importers.nexus import NEXUS_SECTIONS, read_nexus_csv
from haptify.formats.importers.qualisys import read_qualisys_tsv
from haptify.formats.importers.recording import Recording

FORMATS = ("tsv", "motive", "nexus")


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
    map rules of a C3D file (:func:`~haptify.formats.importers.motion_capture.import_recording`); ``stream``, ``chunk_frames``
    and ``progress`` as for a C3D file (§5.5.1)."""
    dest, loaded, _, device, extra = prepare(out, mapping, fmt, overrides, overwrite, append)
    return import_recording(
        read_export(fmt, path, stream=stream), dest, loaded, device, extra, chunk_frames=chunk_frames, progress=progress
    )
