"""Importers: motion-capture files and column-mapped CSV logs into sessions (spec chapter 5).

A C3D file (Vicon, Qualisys, …; read with ezc3d), a Qualisys TSV, Motive CSV or Nexus CSV export, or a CSV
log (an ATI-style F/T log, a CHAI3D log of commanded force) becomes one trial of a new session. What the
source does not hold — the device, the lab and examiner ids, the recording date, the trial's protocol —
comes from an **import map** (:class:`ImportMap`, JSON; ``schemas/1.0/import-map.schema.json``), which also
says which source channel fills which stream column and in which unit. Units are converted to SI by the
table of §5.3; the session is written atomically through :class:`~haptify.formats.storage.SessionWriter`, or the
trial is appended atomically to an existing session (:class:`Destination`, §5.9).

One module per step of chapter 5 and one per source format:

- :mod:`.units` (§5.3), :mod:`.import_map` (§5.2, ids §5.4), :mod:`.streams` (columns from channels, §5.3),
  :mod:`.destination` (new session or appended trial, §5.8–5.9);
- :mod:`.recording` (what every motion-capture reader gives, §5.5, §5.10), :mod:`.world_frame` (W and the
  platform's wrench, §5.6), :mod:`.motion_capture` (a recording as one trial, §5.5);
- the formats: :mod:`.c3d` (§5.5), :mod:`.qualisys`, :mod:`.motive`, :mod:`.nexus` (§5.10, their shared
  text reading in :mod:`.text_export`, format detection in :mod:`.exports`), :mod:`.csv_log` (§5.7).

Errors (spec §5.1–5.2): E501 the source cannot be read, E502 the map is malformed or invalid, E503 the
map names a label, column or platform the source does not have (the message lists those it has), E504
a unit cannot be converted; E901 the output exists. Every check runs before anything is written.
"""

from __future__ import annotations

from haptify.formats.importers.c3d import import_c3d, read_c3d
from haptify.formats.importers.csv_log import import_csv
from haptify.formats.importers.destination import Destination, ImportResult
from haptify.formats.importers.exports import detect_format, import_export, read_export
from haptify.formats.importers.import_map import MOCAP_SOURCES, SOURCES, ImportMap, LoadedMap, load_map, sanitize_id
from haptify.formats.importers.motion_capture import import_recording
from haptify.formats.importers.recording import C3DPlatform, Recording, recording_chunks
from haptify.formats.importers.units import UNITS, Unit, unit_conversion

__all__ = [
    "C3DPlatform",
    "Destination",
    "ImportMap",
    "ImportResult",
    "LoadedMap",
    "MOCAP_SOURCES",
    "Recording",
    "SOURCES",
    "UNITS",
    "Unit",
    "detect_format",
    "import_c3d",
    "import_csv",
    "import_export",
    "import_recording",
    "load_map",
    "read_c3d",
    "read_export",
    "recording_chunks",
    "sanitize_id",
    "unit_conversion",
]
