"""Importers: C3D motion-capture files and column-mapped CSV logs into sessions (spec chapter 5).

A C3D file (Vicon, Qualisys, …; read with ezc3d) or a CSV log (an ATI-style F/T log, a CHAI3D log of
commanded force) becomes one trial of a new session. What the source does not hold — the device, the
lab and examiner ids, the recording date, the trial's protocol — comes from an **import map**
(:class:`ImportMap`, JSON; ``schemas/1.0/import-map.schema.json``), which also says which source
channel fills which stream column and in which unit. Units are converted to SI by the table of §5.3;
the session is written atomically through :class:`~haptify.storage.SessionWriter`, or the trial is
appended atomically to an existing session (:class:`Destination`, §5.9).

Errors (spec §5.1–5.2): E501 the source cannot be read, E502 the map is malformed or invalid, E503 the
map names a label, column or platform the source does not have (the message lists those it has), E504
a unit cannot be converted; E901 the output exists. Every check runs before anything is written.
"""

from __future__ import annotations

import fnmatch
import json
import re
import shutil
import struct
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, Callable, Iterator, Literal, TypedDict, Union

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from haptify import schemas
from haptify.conventions import matrix_to_quat, quat_to_matrix
from haptify.c3d_stream import STREAM_ABOVE_BYTES, C3DLayout, c3d_layout, chunk_frames_for, iter_frames, read_head
from haptify.errors import Finding, HaptifyError, fail
from haptify.force_plate import CORNERS, PLATE_COLUMNS
from haptify.platform_wrench import (
    CHANNEL_DIMENSIONS,
    PLATFORM_CHANNELS,
    calibrated,
    equivalent_corners,
    origin_by_rule,
    wrench_at_origin,
    wrench_at_surface,
)
from haptify.session_format import (
    ALLOWED_VALUES,
    PROTOCOLS,
    Device,
    Id,
    Party,
    Pose,
    Rendering,
    Rig,
    RigidBody,
    Session,
    expected_columns,
    kind_table,
    values_outside_set,
)
from haptify.storage import (
    MANIFEST,
    SessionFolder,
    SessionWriter,
    atomic_write_json,
    open_session,
    parse_json_file,
    pydantic_findings,
    replace_folder_atomically,
    resolve_inside,
)
from haptify.versions import PACKAGE_VERSION

# --- units (spec §5.3) ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Unit:
    """A source unit: its dimension and the conversion ``si = (value · mul) / div`` (spec §5.3)."""

    dimension: str
    mul: float = 1.0
    div: float = 1.0

    def to_si(self, values: np.ndarray) -> np.ndarray:
        """Convert ``values`` to SI: one multiplication, then one division, each skipped when it is by 1."""
        out = np.asarray(values, dtype=np.float64)
        if self.mul != 1.0:
            out = out * self.mul
        if self.div != 1.0:
            out = out / self.div
        return out


def _unit_table() -> tuple[dict[str, Unit], dict[str, str]]:
    table = schemas.load("import-units.json")
    units = {
        name: Unit(row["dimension"], float(row["mul"]), float(row["div"])) for row in table["units"] for name in row["spellings"]
    }
    return units, dict(table["si_units"])


# Every accepted spelling of a source unit, and the dimension of each SI column unit (spec §1.1, §5.3),
# from schemas/<v>/import-units.json. Decimal sub-units divide by an integer power of ten, so a value
# converts to the correctly rounded SI double (mm → m is x / 1000, not x · 0.001).
UNITS, SI_DIMENSION = _unit_table()


def unit_conversion(unit: str | None, target: str, **where: Any) -> Unit:
    """The conversion from source ``unit`` to the SI ``target`` unit of a column (spec §5.3).

    E504 when ``unit`` is not in the table or has another dimension than ``target``; ``where`` names
    the file and column for the error.
    """
    dim = SI_DIMENSION[target]
    spelled = (unit or "").strip()
    known = UNITS.get(spelled)
    accepted = sorted(n for n, u in UNITS.items() if u.dimension == dim)
    if known is None:
        raise fail(
            "E504", f"unit {spelled!r} is not in the conversion table (spec §5.3)", expected=accepted, found=spelled, **where
        )
    if known.dimension != dim:
        raise fail(
            "E504",
            f"unit {spelled!r} is a {known.dimension}, the column needs a {dim} ({target})",
            expected=accepted,
            found=spelled,
            **where,
        )
    return known


# --- the import map (spec §5.2) -------------------------------------------------------------------

FIXED_KINDS: tuple[str, ...] = tuple(
    k for k, v in schemas.load("stream-kinds.json")["kinds"].items() if "entity_columns" not in v
)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ChannelMap(_Strict):
    """Where one stream column comes from (spec §5.2): a source ``source`` channel, or a constant ``value``.

    The SI value is ``convert(scale · raw + offset)`` from ``unit`` (spec §5.3; default for C3D: the channel's
    ANALOG:UNITS; CSV columns and constants must state it). ``threshold`` turns the value into a 0/1
    trigger (1 where value ≥ threshold, in ``unit``) and is allowed only for dimensionless columns.
    """

    source: str | None = Field(None, description="C3D analog label or CSV column header.")
    value: float | None = Field(
        None,
        description="A constant, for a quantity the source does not log because it is zero by construction (e.g. the torque of a 3-DOF force command).",
    )
    unit: str | None = Field(None, description="Unit of scale·raw+offset; one of the spellings of spec §5.3.")
    scale: float = Field(1.0, description="Multiplies the raw value first (e.g. a sensor gain in unit per volt).")
    offset: float = Field(0.0, description="Added after scaling, in `unit`.")
    threshold: float | None = Field(None, description="For the sync trigger only: 1 where the value is ≥ threshold, else 0.")

    @model_validator(mode="after")
    def _one_origin(self) -> "ChannelMap":
        if (self.source is None) == (self.value is None):
            raise ValueError("give exactly one of 'source' and 'value'")
        return self


class StreamMap(_Strict):
    """One output stream (spec §5.2): the kind's columns (``t`` excluded) mapped to source channels; rate in Hz."""

    columns: dict[str, Union[ChannelMap, str]] = Field(
        description='Column name → channel; a string is short for {"source": string}.'
    )
    rate_hz: float | None = Field(
        None,
        gt=0,
        description="Nominal rate; C3D: must equal ANALOG:RATE when given; CSV: default 1/median(Δt) to 6 significant digits.",
    )
    format: Literal["parquet", "csv"] = "parquet"
    frame: str | None = Field(None, description="Default: the kind's frame.")
    from_frame: Literal["device"] | None = Field(
        None,
        description="commanded_wrench only: the log holds the vectors in the device frame D (as CHAI3D logs them); the importer rotates them into W by session.device_placement.",
    )


class MarkerMap(_Strict):
    """Which C3D point labels become markers, and their entity ids (spec §5.4, §5.5)."""

    include: list[str] | None = Field(
        None, description="Labels or shell patterns ('boite:*'); default every label; [] imports no markers."
    )
    exclude: list[str] = Field(default_factory=list, description="Labels or shell patterns to leave out.")
    rename: dict[str, Id] = Field(default_factory=dict, description="C3D label → entity id; other labels are sanitised (§5.4).")
    rigid_bodies: list[RigidBody] = Field(default_factory=list, description="Rigid bodies of the rig, by entity id.")
    system: str | None = Field(None, description="Motion-capture system; default MANUFACTURER:COMPANY and SOFTWARE.")
    format: Literal["parquet", "csv"] = "parquet"


class BodyMap(_Strict):
    """Which 6-DoF bodies (C3D ROTATION group, Qualisys 6DOF, Motive rigid bodies) become pose streams
    (spec §5.5): the handle's pose and the device links' poses."""

    handle: str | None = Field(
        None, description="The body label whose pose becomes handle_pose (its origin must be the gimbal centre)."
    )
    links: dict[Id, str] = Field(
        default_factory=dict,
        description="Link name → body label; each becomes one entity of link_poses (the link must be a rigid body of markers.rigid_bodies).",
    )
    max_residual: float | None = Field(
        None,
        gt=0,
        description="A sample whose residual (in the file's point units) exceeds this is occluded; default: only the file's own invalid samples are.",
    )
    format: Literal["parquet", "csv"] = "parquet"


class PlatformWrenchMap(_Strict):
    """The chosen C3D force platform's channels as the trial's ``plate_wrench`` (spec §5.6.1): the units
    of the platform's outputs (after its calibration matrix), each defaulting to its channel's
    ANALOG:UNITS."""

    force_unit: str | None = Field(None, description="Unit of the force outputs (Fx, Fy, Fz; type 3: all eight).")
    torque_unit: str | None = Field(None, description="Unit of the moment outputs (types 2 and 4: Mx, My, Mz; type 1: Tz).")
    length_unit: str | None = Field(None, description="Type 1 only: unit of the centre of pressure Px, Py.")
    format: Literal["parquet", "csv"] = "parquet"


class DeviceFile(_Strict):
    """The device given as a device.json file beside the map instead of inline (spec §5.2)."""

    file: str = Field(
        description="Path of a device.json, relative to the map file's folder; copied into the session as device.json."
    )


class SessionFields(_Strict):
    """The session-level facts a source file does not hold (spec §5.2)."""

    session_id: Id | None = Field(None, description="Default: the source file's name, sanitised (§5.4).")
    date: str | None = Field(
        None,
        pattern=r"^\d{4}-\d{2}-\d{2}$",
        description="ISO date of the recording; required, but usually given per file on the command line (--date) so that one map serves many recordings.",
    )
    lab: Party
    examiner: Party
    device: Union[Device, DeviceFile]
    device_placement: Pose = Field(description="The device frame in W.")
    rig: Rig = Field(
        default_factory=Rig,
        description="Rig parts the source does not describe (handle sensors, ranges); the importer adds motion_capture and the force plate from a C3D.",
    )


class TrialFields(_Strict):
    """The imported trial (spec §2.5)."""

    id: Id | None = Field(None, description="Default: the source file's name, sanitised (§5.4).")
    protocol: Literal[PROTOCOLS] = Field("other", description="Default 'other'.")  # type: ignore[valid-type]
    label: str | None = Field(None, description="Default for 'other': the source file's name.")
    repetition: int = Field(1, ge=1)
    powered: bool
    rendering: Rendering | None = None
    notes: str | None = None


class CsvTime(_Strict):
    """The time column of a CSV log: its header and unit, s, ms or us (spec §5.2, §5.7)."""

    source: str = Field(description="Header of the time column.")
    unit: str = Field(description="s, ms or us.")


class CsvOptions(_Strict):
    """How a CSV log is read: delimiter, lines before the header, comment character (spec §5.2, §5.7)."""

    delimiter: str = Field(",", min_length=1, max_length=1)
    skip_rows: int = Field(0, ge=0, description="Lines before the header row.")
    comment: str | None = Field(None, min_length=1, max_length=1, description="Lines starting with this character are ignored.")


MOCAP_SOURCES = ("c3d", "tsv", "motive", "nexus")  # motion-capture files: markers, bodies, platforms (§5.5, §5.10)
SOURCES = (*MOCAP_SOURCES, "csv")


class ImportMap(_Strict):
    """An import map (spec §5.2): how one source file becomes one trial of a session."""

    source: Literal[SOURCES] = Field(description="The importer this map is for.")  # type: ignore[valid-type]
    session: SessionFields
    trial: TrialFields
    time_offset_s: float = Field(0.0, description="Added to every imported time, s (puts the source on the session clock).")
    streams: dict[Literal[FIXED_KINDS], StreamMap] = Field(default_factory=dict)  # type: ignore[valid-type]
    markers: MarkerMap | None = Field(None, description="Motion-capture sources only; default: every point label.")
    bodies: BodyMap | None = Field(
        None, description="Motion-capture sources only: 6-DoF bodies that become handle_pose and link_poses; default none."
    )
    force_plate: Union[Annotated[int, Field(ge=1)], Literal["auto", "none"]] = Field(
        "auto",
        description="C3D only: the FORCE_PLATFORM number (1-based) that becomes the rig's plate and defines W; 'auto' = 1 when the file has platforms.",
    )
    platform_wrench: PlatformWrenchMap | None = Field(
        None,
        description="C3D only: the force platform that defines W also gives the trial's plate_wrench, from its channels (types 1–4); default: its channels are not imported.",
    )
    lab_to_world: Pose | None = Field(
        None, description="C3D only, without a force plate: the C3D lab frame in W (default: W is the lab frame)."
    )
    time: CsvTime | None = Field(None, description="CSV only, required: the time column and its unit.")
    csv: CsvOptions | None = Field(None, description="CSV only: parsing options.")


# Members an override replaces as a whole (a device given as a file replaces an inline one).
_REPLACED_WHOLE = {"device"}


def _deep_merge(base: Any, over: Any) -> Any:
    if isinstance(base, dict) and isinstance(over, dict):
        out = dict(base)
        for k, v in over.items():
            out[k] = _deep_merge(base[k], v) if k in base and k not in _REPLACED_WHOLE else v
        return out
    return over


@dataclass
class LoadedMap:
    """A validated import map and the folder its relative paths refer to (spec §5.2)."""

    map: ImportMap
    base_dir: Path
    label: str


def load_map(
    path: str | Path | None, source: str, overrides: dict[str, Any] | None = None, session_facts: dict[str, Any] | None = None
) -> LoadedMap:
    """Read and validate an import map (spec §5.2); ``overrides`` is deep-merged over the file's JSON.

    ``session_facts`` (appending, §5.9) fill the ``session`` members the map leaves out. E502 on a
    missing or malformed file, a schema violation (one finding per problem, with JSON pointer) or a
    map written for the other importer.
    """
    if path is None:
        raw: Any = {"source": source}
        base, label = Path.cwd(), "command line"
    else:
        p = Path(path)
        label = str(p)
        if not p.is_file():
            raise fail("E502", f"import map {label!r} does not exist", file=label)
        raw = parse_json_file(p, "E502", label)
        base = p.resolve().parent
    if not isinstance(raw, dict):
        raise fail("E502", "an import map is a JSON object", file=label, expected="object", found=type(raw).__name__)
    raw = _deep_merge(raw, overrides or {})
    if session_facts is not None:
        given = raw.get("session") if isinstance(raw.get("session"), dict) else {}
        raw["session"] = {**{k: v for k, v in session_facts.items() if k not in given}, **given}
    session = raw.get("session")
    no_date = None
    if not isinstance(session, dict) or session.get("date") is None:
        no_date = fail(
            "E502",
            "the recording date is missing: give session.date in the map or --date",
            file=label,
            pointer="/session/date",
            expected="YYYY-MM-DD",
            found="missing",
        )
    try:
        m = ImportMap.model_validate(raw)
    except ValidationError as exc:
        findings = pydantic_findings(exc, "E502", label)
        if no_date is not None and not any(f.pointer == "/session" for f in findings):
            findings += no_date.findings
        raise HaptifyError(*findings) from None
    if no_date is not None:
        raise no_date
    if m.source != source:
        raise fail(
            "E502",
            f"the map is for the {m.source} importer, not {source}",
            file=label,
            pointer="/source",
            expected=source,
            found=m.source,
        )
    wrong = ("markers", "bodies", "lab_to_world", "platform_wrench") if source == "csv" else ("time", "csv")
    for key in wrong:
        if getattr(m, key) is not None:
            raise fail(
                "E502", f"{key!r} does not apply to {source} imports", file=label, pointer=f"/{key}", expected=None, found=key
            )
    if source == "csv":
        if m.force_plate != "auto":
            raise fail("E502", "'force_plate' does not apply to csv imports", file=label, pointer="/force_plate")
        if m.time is None:
            raise fail(
                "E502",
                "a csv map needs 'time' (the time column and its unit)",
                file=label,
                pointer="/time",
                expected={"source": "<header>", "unit": "s|ms|us"},
                found=None,
            )
    return LoadedMap(m, base, label)


# --- ids (spec §5.4) ------------------------------------------------------------------------------

_ID_BAD = re.compile(r"[^A-Za-z0-9._-]")


def sanitize_id(text: str, fallback: str) -> str:
    """An id (spec §2.2) from a free label: ':' → '.', other characters outside [A-Za-z0-9._-] → '_',
    prefix 'm' when the first character is not a letter or digit, cut to 64 characters; ``fallback``
    for an empty label (spec §5.4)."""
    text = text.strip()
    if not text:
        return fallback
    out = _ID_BAD.sub("_", text.replace(":", "."))
    if not out[0].isalnum() or not out[0].isascii():
        out = "m" + out
    return out[:64]


# --- C3D reading (spec §5.5) ----------------------------------------------------------------------


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
                "E501",
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
    return Finding("W501", f"{path.name}: {what}; {followed}", file=str(path), pointer=pointer, expected=header, found=other)


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
                    "W501",
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
                "W501",
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
        raise fail("E501", f"{label!r} does not exist or is not a file", file=label)
    with open(p, "rb") as fh:
        head = fh.read(2)
    if len(head) < 2 or head[1] != 0x50:
        raise fail(
            "E501",
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
        raise fail("E501", f"{label!r} cannot be read as C3D: {exc}", file=label) from None
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
            "E501",
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
            "E501",
            f"{label!r} holds 6-DoF bodies but states no frame rate",
            file=label,
            pointer="/POINT/RATE",
            expected="a rate > 0",
            found=point_rate,
        )
    if n_markers and point_rate <= 0:
        raise fail(
            "E501",
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


# --- geometry: the world frame from a force platform (spec §5.6) ----------------------------------

PLATE_RECTANGLE_TOLERANCE_M = 0.001  # corners within 1 mm of a flat rectangle: silent (§5.6)
PLATE_SHAPE_LIMIT = 0.1  # a deviation beyond 10 % of the shorter side is no rectangle at all (E505)
PLATE_MIN_SIDE_M = 0.01  # a side shorter than 10 mm: coincident corners (E505)


@dataclass
class WorldFrame:
    """``p_W = R · (p_lab − centre)``; ``description`` says how W was chosen (kept in the trial notes).
    Positions in m; spec §5.6."""

    rotation: np.ndarray
    centre: np.ndarray
    description: str

    def apply(self, p: np.ndarray) -> np.ndarray:
        out: np.ndarray = (p - self.centre) @ self.rotation.T
        return out


def _meaningless(number: int, why: str, file: str, found: Any) -> HaptifyError:
    return fail(
        "E505",
        f"force platform {number}: {why}",
        file=file,
        pointer="/FORCE_PLATFORM/CORNERS",
        expected="four corners of a plate, in C3D order",
        found=found,
    )


def plate_frame(corners_m: np.ndarray, *, file: str, number: int) -> tuple[WorldFrame, np.ndarray, list[float], float]:
    """W from a C3D platform's corners (metres, lab frame), spec §5.6.

    C3D numbers corners by the plate's own quadrants (+x+y, −x+y, −x−y, +x−y) and its z axis points
    into the plate. W's origin is the centre of the four corners, x the plate's x, z up (−plate z),
    y = z × x. Returns W, the plate axes in W (3 × 3, columns x, y, z), the size [x, y] in m and the
    largest deviation of a corner from the flat rectangle of that size (m). E505 when the corners
    cannot define a plate: not finite, coincident (two corners within 10 mm), collinear, crossed (a
    corner outside its quadrant), or further from a rectangle than 10 % of the shorter side.
    """
    c = np.asarray(corners_m, dtype=np.float64)
    if not np.isfinite(c).all():
        raise _meaningless(number, "a corner coordinate is not finite", file, c.tolist())
    gaps = [float(np.linalg.norm(c[i] - c[j])) for i in range(4) for j in range(i + 1, 4)]
    if min(gaps) < PLATE_MIN_SIDE_M:
        raise _meaningless(number, f"its corners coincide (two are {min(gaps) * 1000:.3g} mm apart)", file, c.tolist())
    crossed = "its corners are not in C3D order (the outline crosses itself)"
    x = (c[0] + c[3]) / 2 - (c[1] + c[2]) / 2
    y_raw = (c[0] + c[1]) / 2 - (c[2] + c[3]) / 2
    size = [float(np.linalg.norm(x)), float(np.linalg.norm(y_raw))]
    if min(size) < PLATE_MIN_SIDE_M:
        raise _meaningless(number, crossed, file, c.tolist())
    x /= size[0]
    z_plate = np.cross(x, y_raw)
    if np.linalg.norm(z_plate) < PLATE_MIN_SIDE_M * size[1]:
        raise _meaningless(number, "its corners are collinear", file, c.tolist())
    z_plate /= np.linalg.norm(z_plate)
    y_plate = np.cross(z_plate, x)
    zw = -z_plate
    yw = np.cross(zw, x)
    rotation = np.stack([x, yw, zw])
    centre = c.mean(axis=0)
    local = (c - centre) @ rotation.T
    quadrants = np.array([[1, -1], [-1, -1], [-1, 1], [1, 1]])
    if (np.sign(local[:, :2]) != quadrants).any():
        raise _meaningless(number, crossed, file, c.tolist())
    ideal = quadrants * np.array(size) / 2
    deviation = float(max(np.abs(local[:, :2] - ideal).max(), np.abs(local[:, 2]).max()))
    if deviation > PLATE_SHAPE_LIMIT * min(size):
        raise _meaningless(
            number,
            f"its corners are {deviation * 1000:.3g} mm from a flat rectangle, more than "
            f"{PLATE_SHAPE_LIMIT:.0%} of its shorter side",
            file,
            c.tolist(),
        )
    axes_in_w = rotation @ np.stack([x, y_plate, z_plate], axis=1)
    desc = (
        f"W: centre of C3D force platform {number}'s corners, x along the platform's x axis, z up (opposite to the platform's z)"
    )
    return WorldFrame(rotation, centre, desc), axes_in_w, size, deviation


# Haptify names corner sensors by their quadrant of W (spec §5.6); C3D numbers them in the platform's
# own frame, whose y axis is W's −y, so C3D corner 1 becomes c4, 2 → c3, 3 → c2, 4 → c1.
CORNER_QUADRANTS = {"c1": (1.0, 1.0), "c2": (-1.0, 1.0), "c3": (-1.0, -1.0), "c4": (1.0, -1.0)}


def plate_description(platform: C3DPlatform, to_m: Unit, *, file: str) -> tuple[WorldFrame, dict[str, Any], list[Finding]]:
    """W and the rig's ``force_plate`` from a C3D platform (spec §5.6): one corner sensor at each C3D
    corner, named by its quadrant of W (``CORNER_QUADRANTS``), lowered to the depth |ORIGIN z| of the
    platform's sensing origin and oriented as the platform's frame. A W502 finding gives the corners'
    deviation from a flat rectangle when it exceeds 1 mm."""
    if platform.corners is None:
        raise fail(
            "E503",
            f"force platform {platform.number} has no FORCE_PLATFORM:CORNERS",
            file=file,
            pointer="/FORCE_PLATFORM/CORNERS",
            expected="corners",
            found=None,
        )
    corners = to_m.to_si(platform.corners)
    world, axes, size, deviation = plate_frame(corners, file=file, number=platform.number)
    warnings = []
    if deviation > PLATE_RECTANGLE_TOLERANCE_M:
        warnings.append(
            Finding(
                "W502",
                f"the corners of force platform {platform.number} are {deviation * 1000:.3g} mm "
                "from a flat rectangle; W and the plate size come from the best-fitting rectangle",
                file=file,
                pointer="/FORCE_PLATFORM/CORNERS",
                expected=f"≤ {PLATE_RECTANGLE_TOLERANCE_M * 1000:g} mm",
                found=f"{deviation * 1000:.3g} mm",
            )
        )
    origin = to_m.to_si(platform.origin) if platform.origin is not None else np.zeros(3)
    if not np.isfinite(origin).all():
        raise fail(
            "E505",
            f"force platform {platform.number}: its origin is not finite",
            file=file,
            pointer="/FORCE_PLATFORM/ORIGIN",
            expected="a finite origin",
            found=origin.tolist(),
        )
    depth = float(abs(origin[2]))
    q = [float(v) for v in matrix_to_quat(axes)]
    in_w = world.apply(corners)
    sensors = []
    for cid, (sx, sy) in CORNER_QUADRANTS.items():
        corner = next(c for c in in_w if np.sign(c[0]) == sx and np.sign(c[1]) == sy)
        sensors.append({"id": cid, "pose": {"position": [float(corner[0]), float(corner[1]), -depth], "quaternion": q}})
    return world, {"size_m": size, "corners": sensors}, warnings


def pose_frame(pose: Pose) -> WorldFrame:
    """W from a ``lab_to_world`` pose (the lab frame in W): ``p_W = R · p_lab + position``.
    Spec §5.6 rule 2."""
    rotation = quat_to_matrix(np.asarray(pose.quaternion, dtype=np.float64))
    centre = -rotation.T @ np.asarray(pose.position, dtype=np.float64)
    return WorldFrame(rotation, centre, "W: the C3D lab frame placed in W by the map's lab_to_world pose")


# --- the platform's wrench (spec §5.6.1) ------------------------------------------------------------

_SI_OF_DIMENSION = {"force": "N", "torque": "N*m", "length": "m"}


def platform_plate_wrench(
    rec: Recording, platform: C3DPlatform, pm: PlatformWrenchMap, plate: dict[str, Any], to_m: Unit, *, label: str
) -> tuple[dict[str, np.ndarray], list[Finding]]:
    """The ``plate_wrench`` columns (``t`` excluded) of the platform that defines W (spec §5.6.1): its
    outputs (types 1–4, calibration matrix applied) in SI, the wrench moved to the top surface's
    centre (W's origin), rotated into W and reversed (the channels hold the reaction), shared among the rig's four corner sensors
    (:func:`~haptify.platform_wrench.equivalent_corners`). Returns the columns and W503 findings.

    E506 when the platform's type is not 1–4, its channels are missing or its calibration matrix or
    origin is unusable; E504 for a unit that is not a force, torque or length as the output needs.
    """
    src, number = str(rec.path), platform.number
    kind = platform.type
    if kind not in PLATFORM_CHANNELS:
        raise fail(
            "E506",
            f"force platform {number} is of type {kind}; its wrench is imported for types {sorted(PLATFORM_CHANNELS)}",
            file=src,
            pointer="/FORCE_PLATFORM/TYPE",
            expected=sorted(PLATFORM_CHANNELS),
            found=kind,
        )
    need = PLATFORM_CHANNELS[kind]
    if len(platform.channels) < need:
        raise fail(
            "E506",
            f"force platform {number} (type {kind}) names {len(platform.channels)} of the {need} analog "
            "channels its type records in FORCE_PLATFORM:CHANNEL",
            file=src,
            pointer="/FORCE_PLATFORM/CHANNEL",
            expected=need,
            found=[c + 1 for c in platform.channels],
        )
    if platform.origin is None:
        raise fail(
            "E506",
            f"force platform {number} has no FORCE_PLATFORM:ORIGIN",
            file=src,
            pointer="/FORCE_PLATFORM/ORIGIN",
            expected="3 numbers",
            found=None,
        )
    chans = platform.channels[:need]
    out = calibrated(kind, rec.analogs[chans], platform.cal_matrix, number=number, file=src)
    given = {"force": pm.force_unit, "torque": pm.torque_unit, "length": pm.length_unit}
    si = np.empty_like(out)
    for row, (ch, dim) in enumerate(zip(chans, CHANNEL_DIMENSIONS[kind])):
        unit = given[dim] if given[dim] is not None else (rec.analog_units[ch] or None)
        si[row] = unit_conversion(
            unit,
            _SI_OF_DIMENSION[dim],
            file=label if given[dim] else src,
            pointer=f"/platform_wrench/{dim}_unit" if given[dim] else "/ANALOG/UNITS",
            column=rec.analog_labels[ch],
        ).to_si(out[row])
    bad = ~np.isfinite(si)
    if bad.any():
        row, i = (int(v[0]) for v in np.nonzero(bad))
        raise fail(
            "E204",
            f"force platform {number}: channel {rec.analog_labels[chans[row]]!r} is not finite at sample {i}",
            file=src,
            column=rec.analog_labels[chans[row]],
            expected="finite values",
            found=str(si[row, i]),
        )
    geometry, notes = origin_by_rule(kind, to_m.to_si(platform.origin), number=number, file=src)
    force, moment_o = wrench_at_origin(kind, si, geometry)
    moment_c = wrench_at_surface(force, moment_o, geometry)
    sensors = {c["id"]: c["pose"] for c in plate["corners"]}
    positions = np.array([sensors[c]["position"] for c in CORNERS], dtype=np.float64)
    rotations = quat_to_matrix(np.array([sensors[c]["quaternion"] for c in CORNERS], dtype=np.float64))
    axes = rotations[0]  # every corner sensor is oriented as the platform (§5.6): platform → W
    # the channels are the platform's reaction on the load; §14.1's wrench is the load's on the plate
    readings = equivalent_corners(-(axes @ force), -(axes @ moment_c), positions, rotations)
    return dict(zip(PLATE_COLUMNS, readings)), notes


# --- building streams from channels (spec §5.3) ---------------------------------------------------

SourceReader = Callable[[str], tuple[np.ndarray, str | None]]


def _as_channel(spec: ChannelMap | str) -> ChannelMap:
    return ChannelMap(source=spec) if isinstance(spec, str) else spec


def build_stream_columns(
    kind: str, smap: StreamMap, n: int, read: SourceReader, *, label: str, source_file: str, unit_required: bool
) -> dict[str, np.ndarray]:
    """The SI columns (``t`` excluded) of one mapped stream (spec §5.3).

    ``read(source)`` returns a channel's raw values and its unit as the source states it (None when the
    source states none; raises E503 for an unknown channel).
    """
    pointer = f"/streams/{kind}/columns"
    allowed = [c for c, _ in expected_columns(kind, present=list(smap.columns))][1:]
    unknown = [c for c in smap.columns if c not in allowed]
    if unknown:
        raise fail(
            "E502",
            f"{kind} has no column {unknown[0]!r}",
            file=label,
            pointer=f"{pointer}/{unknown[0]}",
            expected=allowed,
            found=unknown[0],
        )
    missing = [c for c in allowed if c not in smap.columns]
    if missing:
        raise fail(
            "E502",
            f"the {kind} map lacks columns {missing}",
            file=label,
            pointer=pointer,
            expected=allowed,
            found=list(smap.columns),
        )
    units = dict(expected_columns(kind, present=list(smap.columns)))
    nan_allowed = kind_table(kind)["nan_allowed"]
    out: dict[str, np.ndarray] = {}
    for col in allowed:
        ch = _as_channel(smap.columns[col])
        where = {"file": label, "pointer": f"{pointer}/{col}", "column": col}
        if ch.value is not None:
            raw, stated = np.full(n, ch.value, dtype=np.float64), None
        else:
            assert ch.source is not None  # ChannelMap._one_origin: exactly one of source and value
            raw, stated = read(ch.source)
        unit = ch.unit if ch.unit is not None else stated
        if unit is None and (unit_required or ch.value is not None):
            raise fail(
                "E502",
                f"column {col!r} of {kind} needs a 'unit' (this source states none)",
                expected="a unit of spec §5.3",
                found=None,
                **where,
            )
        values = raw if (ch.scale == 1.0 and ch.offset == 0.0) else raw * ch.scale + ch.offset
        target = units[col]
        if ch.threshold is not None:
            if target != "1":
                raise fail(
                    "E502",
                    f"'threshold' applies only to dimensionless columns; {col!r} is in {target}",
                    expected="1",
                    found=target,
                    **where,
                )
            if (unit or "").strip() not in UNITS:
                raise fail(
                    "E504",
                    f"unit {unit!r} is not in the conversion table (spec §5.3)",
                    expected=sorted(UNITS),
                    found=unit,
                    **where,
                )
            values = np.where(values >= ch.threshold, 1.0, 0.0)
        else:
            values = unit_conversion(unit, target, **where).to_si(values)
        if not nan_allowed:
            bad = ~np.isfinite(values)
            if bad.any():
                i = int(np.argmax(bad))
                code = "E204" if np.isnan(values[i]) else "E210"
                raise fail(
                    code,
                    f"{kind} column {col!r} (from {ch.source!r}) holds a non-finite value at sample {i}",
                    file=source_file,
                    column=ch.source,
                    expected="finite values",
                    found=str(values[i]),
                )
        outside = values_outside_set(kind, col, values)
        if outside is not None and outside[0].any():
            other, words = outside
            i = int(np.argmax(other))
            raise fail(
                "E214",
                f"{kind} column {col!r} (from {ch.source!r}) holds {int(other.sum())} values other than "
                f"{words}, first at sample {i}; map it with a 'threshold'",
                file=source_file,
                column=ch.source,
                expected=list(ALLOWED_VALUES[(kind, col)]),
                found=float(values[i]),
            )
        out[col] = values
    return out


VECTOR_TRIPLETS = {"commanded_wrench": (("fx", "fy", "fz"), ("tx", "ty", "tz"))}


def rotate_into_world(kind: str, columns: dict[str, np.ndarray], placement: Pose, *, label: str) -> dict[str, np.ndarray]:
    """Express a stream logged in the device frame D in W (spec §5.2 ``from_frame``): every vector
    triplet of the kind is rotated by the quaternion of ``device_placement`` (D → W). A wrench's
    reference point does not move, so its torque rotates like its force."""
    if kind not in VECTOR_TRIPLETS:
        raise fail(
            "E502",
            f"from_frame applies to {sorted(VECTOR_TRIPLETS)}, not {kind}",
            file=label,
            pointer=f"/streams/{kind}/from_frame",
            expected=sorted(VECTOR_TRIPLETS),
            found=kind,
        )
    rotation = quat_to_matrix(np.asarray(placement.quaternion, dtype=np.float64))
    out = dict(columns)
    for triplet in VECTOR_TRIPLETS[kind]:
        v = np.stack([columns[c] for c in triplet], axis=1) @ rotation.T
        out.update({c: v[:, i] for i, c in enumerate(triplet)})
    return out


def _mapped_streams(
    m: ImportMap, n: int, read: SourceReader, *, label: str, source_file: str, unit_required: bool
) -> dict[str, dict[str, np.ndarray]]:
    """Every mapped stream's SI columns (``t`` excluded), rotated into W where ``from_frame`` asks."""
    out = {}
    for kind, smap in m.streams.items():
        cols = build_stream_columns(kind, smap, n, read, label=label, source_file=source_file, unit_required=unit_required)
        if smap.from_frame == "device":
            cols = rotate_into_world(kind, cols, m.session.device_placement, label=label)
        out[kind] = cols
    return out


def _check_trial_streams(m: ImportMap, kinds: list[str], label: str) -> None:
    """The protocol's required streams and an active protocol's rendering (spec §2.5), checked before writing."""
    proto = schemas.load("protocols.json")["protocols"][m.trial.protocol]
    missing = [k for k in proto["required"] if k not in kinds]
    if missing:
        raise fail(
            "E502",
            f"protocol {m.trial.protocol!r} requires streams {missing} the map does not produce",
            file=label,
            pointer="/streams",
            expected=proto["required"],
            found=sorted(kinds),
        )
    if proto["passive"] is False and m.trial.rendering is None:
        raise fail(
            "E502",
            f"protocol {m.trial.protocol!r} is active: the trial needs 'rendering'",
            file=label,
            pointer="/trial/rendering",
            expected="rendering parameters",
            found=None,
        )


def _resolve_device(m: ImportMap, base: Path, label: str) -> tuple[Device, dict[str, Any], dict[str, str]]:
    """The device, the manifest's device member and the extra files (device.json) to write with it."""
    dev = m.session.device
    if isinstance(dev, Device):
        return dev, dev.model_dump(mode="json", exclude_none=True), {}
    path = (base / dev.file) if not Path(dev.file).is_absolute() else Path(dev.file)
    where = {"file": label, "pointer": "/session/device/file"}
    if not path.is_file():
        raise fail("E502", f"device file {str(path)!r} does not exist", expected="a device.json", found=dev.file, **where)
    data = parse_json_file(path, "E502", str(path))
    try:
        model = Device.model_validate(data)
    except ValidationError as exc:
        raise HaptifyError(*pydantic_findings(exc, "E502", str(path))) from None
    return model, {"file": "device.json"}, {"device.json": path.read_text(encoding="utf-8")}


@dataclass
class ImportResult:
    """What an import wrote: the session path, ids, streams and the source's description (spec §5.8)."""

    session: Path
    session_id: str
    trial_id: str
    streams: list[dict[str, Any]]
    world_frame: str
    source: dict[str, Any]
    warnings: list[Finding] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "ok": True,
            "session": str(self.session),
            "session_id": self.session_id,
            "trial_id": self.trial_id,
            "streams": self.streams,
            "world_frame": self.world_frame,
            "source": self.source,
            "warnings": [w.to_dict() for w in self.warnings],
        }


@dataclass
class Destination:
    """Where an import goes (spec §5.8–5.9): a new session folder, or one more trial of an existing one."""

    out: Path
    overwrite: bool = False
    existing: SessionFolder | None = None

    @classmethod
    def of(cls, out: str | Path, *, overwrite: bool = False, append: bool = False) -> "Destination":
        """Check the output before any work: E901 when a new session's folder exists (unless
        ``overwrite``); when appending, the folder must hold a readable session (E101–E105)."""
        out = Path(out)
        if append:
            if overwrite:
                raise fail("E903", "append and overwrite exclude each other", expected="one of them", found="both")
            return cls(out, existing=open_session(out))
        if out.exists() and not overwrite:
            raise fail(
                "E901", f"{str(out)!r} already exists", file=str(out), expected="a new path or --overwrite", found="exists"
            )
        return cls(out, overwrite=overwrite)

    def session_facts(self) -> dict[str, Any] | None:
        """The existing session's facts, which fill what the map leaves out when appending (§5.9)."""
        if self.existing is None:
            return None
        man = self.existing.manifest
        return {
            "session_id": man.session_id,
            "date": man.date,
            "lab": man.lab.model_dump(),
            "examiner": man.examiner.model_dump(),
            "device": self.existing.device().model_dump(mode="json", exclude_none=True),
            "device_placement": man.device_placement.model_dump(),
        }

    def check_facts(self, m: ImportMap, device: Device, label: str) -> None:
        """Appending: every session fact the map states must be the session's own (E502)."""
        if self.existing is None:
            return
        man = self.existing.manifest
        for key in ("session_id", "date", "lab", "examiner", "device_placement"):
            mine, theirs = getattr(m.session, key), getattr(man, key)
            if mine != theirs:
                raise fail(
                    "E502",
                    f"the map's session.{key} differs from the session it appends to",
                    file=label,
                    pointer=f"/session/{key}",
                    expected=_plain(theirs),
                    found=_plain(mine),
                )
        if device != self.existing.device():
            raise fail(
                "E502",
                "the map's device differs from the session's device",
                file=label,
                pointer="/session/device",
                expected=self.existing.device().model,
                found=device.model,
            )

    def rig(self, new_rig: dict[str, Any], world_rule: str | None, label: str) -> dict[str, Any]:
        """The rig to write: a new session's own, or the existing rig with this import's parts merged."""
        if self.existing is None:
            return new_rig
        return merge_rig(self.existing, new_rig, world_rule, label)

    def writer(
        self, m: ImportMap, source: Path, rig: dict[str, Any], device: dict[str, Any], extra: dict[str, str], recorder: str
    ) -> tuple[SessionWriter, str]:
        """A writer holding the session-level manifest; the trial and streams are added by the caller."""
        stem = sanitize_id(source.stem, "import")
        if self.existing is not None:
            manifest = {k: v for k, v in self.existing.raw.items() if k not in ("spec_version", "trials")}
            return SessionWriter(manifest={**manifest, "rig": rig}), stem
        manifest = {
            "session_id": m.session.session_id or stem,
            "date": m.session.date,
            "lab": m.session.lab.model_dump(),
            "examiner": m.session.examiner.model_dump(),
            "device": device,
            "device_placement": m.session.device_placement.model_dump(),
            "rig": rig,
            "recorder": recorder,
        }
        return SessionWriter(manifest=manifest, extra_files=extra), stem

    def write(self, writer: SessionWriter, trial_id: str) -> Path:
        """Write atomically: a new folder, or the existing one with the trial appended (§3.6, §5.9)."""
        if self.existing is None:
            return writer.write(self.out, overwrite=self.overwrite)
        if any(t.id == trial_id for t in self.existing.trials):
            raise fail(
                "E107",
                f"the session already has a trial {trial_id!r}",
                file=MANIFEST,
                pointer="/trials",
                expected="a new trial id (--trial-id)",
                found=trial_id,
            )
        return append_trial(writer, self.existing)


def _plain(value: Any) -> Any:
    return value.model_dump() if isinstance(value, BaseModel) else value


def merge_rig(existing: SessionFolder, new_rig: dict[str, Any], world_rule: str | None, label: str) -> dict[str, Any]:
    """The existing session's rig with an appended import's rig parts (spec §5.9).

    A part the session already describes must be identical (E502), except ``motion_capture``, whose
    marker lists and rigid bodies are united (same rate and system required). W must not change:
    a platform cannot be added to a session whose trials already hold world-frame streams, and a
    C3D file imported in its lab frame cannot join a session whose W is its force plate (E502).
    """
    old = existing.manifest.rig.model_dump(mode="json", exclude_none=True)
    if "force_plate" in old and world_rule == "lab":
        raise fail(
            "E502",
            "the session's W is the centre of its force plate; this file would be imported in its lab "
            "frame: choose its force platform or give lab_to_world",
            file=label,
            pointer="/force_plate",
            expected="a platform or lab_to_world",
            found="none",
        )
    merged = dict(old)
    world_streams = [s.file for t in existing.trials for s in t.streams if s.frame == "world"]
    for key, part in new_rig.items():
        pointer = f"/session/rig/{key}"
        if key == "motion_capture" and key in old:
            merged[key] = _merge_motion_capture(old[key], part, label)
        elif key in old and old[key] != part:
            raise fail(
                "E502",
                f"rig.{key} of this import differs from the session's",
                file=label,
                pointer=pointer,
                expected=old[key],
                found=part,
            )
        elif key == "force_plate" and key not in old and world_streams:
            raise fail(
                "E502",
                "this import's force platform would define W, but the session's world-frame streams use a W without a plate",
                file=label,
                pointer=pointer,
                expected="force_plate 'none'",
                found=world_streams[0],
            )
        else:
            merged[key] = part
    return merged


def _merge_motion_capture(old: dict[str, Any], new: dict[str, Any], label: str) -> dict[str, Any]:
    pointer = "/session/rig/motion_capture"
    for key in ("rate_hz", "system"):
        if key in old and key in new and old[key] != new[key]:
            raise fail(
                "E502",
                f"motion-capture {key} differs from the session's",
                file=label,
                pointer=f"{pointer}/{key}",
                expected=old[key],
                found=new[key],
            )
    bodies = {b["name"]: b for b in old.get("rigid_bodies", [])}
    for body in new.get("rigid_bodies", []):
        if body["name"] in bodies and bodies[body["name"]] != body:
            raise fail(
                "E502",
                f"rigid body {body['name']!r} differs from the session's",
                file=label,
                pointer="/markers/rigid_bodies",
                expected=bodies[body["name"]],
                found=body,
            )
        bodies.setdefault(body["name"], body)
    markers = list(old.get("markers", []))
    markers += [e for e in new.get("markers", []) if e not in markers]
    return {**new, **old, "markers": markers, "rigid_bodies": list(bodies.values())}


def append_trial(writer: SessionWriter, existing: SessionFolder) -> Path:
    """Append the writer's single trial to ``existing`` atomically (spec §5.9): the new trial is written
    alone to a staging folder (streams, checksums, manifest check), the session is copied beside itself,
    the new stream files are added, the manifest is re-validated and the copy replaces the original."""
    target = existing.root
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.new-", dir=target.parent))
    build = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=target.parent))
    try:
        writer.write(staging / "trial")
        [trial] = json.loads((staging / "trial" / MANIFEST).read_text(encoding="utf-8"))["trials"]
        shutil.copytree(target, build, symlinks=True, dirs_exist_ok=True)
        for stream in trial["streams"]:
            dst = resolve_inside(build, stream["file"])
            if dst.exists():
                raise fail(
                    "E107",
                    f"the session already holds a file {stream['file']!r}",
                    file=stream["file"],
                    expected="a new stream file",
                    found=stream["file"],
                )
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(staging / "trial" / stream["file"], dst)
        manifest = {**existing.raw, "rig": writer.manifest["rig"], "trials": [*existing.raw["trials"], trial]}
        try:
            Session.model_validate(manifest)
        except ValidationError as exc:
            raise HaptifyError(*pydantic_findings(exc, "E104", MANIFEST)) from None
        atomic_write_json(build / MANIFEST, manifest)
        replace_folder_atomically(build, target, overwrite=True)
    except BaseException:
        shutil.rmtree(build, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


def _add_trial(writer: SessionWriter, m: ImportMap, stem: str, source: Path, provenance: str) -> str:
    t = m.trial
    trial_id = t.id or stem
    label = t.label if t.label is not None else (source.stem if t.protocol == "other" else None)
    notes = f"{t.notes}\n{provenance}" if t.notes else provenance
    writer.add_trial(
        trial_id,
        t.protocol,
        powered=t.powered,
        repetition=t.repetition,
        label=label,
        rendering=t.rendering.model_dump(exclude_none=True) if t.rendering else None,
        notes=notes,
    )
    return trial_id


def _stream_summary(stream: dict[str, Any]) -> dict[str, Any]:
    return {
        "kind": stream["kind"],
        "file": stream["file"],
        "rows": stream["rows"],
        "rate_hz": stream["rate_hz"],
        "columns": len(stream["columns"]) - 1,
    }


# --- C3D import (spec §5.5) -----------------------------------------------------------------------


def _select_markers(c3d: Recording, mm: MarkerMap, label: str) -> tuple[list[int], list[str]]:
    """Indices of the imported point labels and their entity ids (spec §5.4)."""
    labels = c3d.point_labels
    where = {"file": label}

    def matches(pattern: str) -> list[int]:
        return [i for i, lab in enumerate(labels) if fnmatch.fnmatchcase(lab, pattern)]

    for key, patterns in (("include", mm.include or []), ("exclude", mm.exclude)):
        for j, pat in enumerate(patterns):
            if not matches(pat):
                raise fail(
                    "E503",
                    f"marker {key} {pat!r} matches no point label of {c3d.path.name}",
                    pointer=f"/markers/{key}/{j}",
                    expected=labels,
                    found=pat,
                    **where,
                )
    chosen = sorted({i for pat in mm.include for i in matches(pat)}) if mm.include is not None else list(range(len(labels)))
    dropped = {i for pat in mm.exclude for i in matches(pat)}
    chosen = [i for i in chosen if i not in dropped]
    for old in mm.rename:
        if old not in [labels[i] for i in chosen]:
            raise fail(
                "E503",
                f"rename names {old!r}, which is not an imported point label",
                pointer=f"/markers/rename/{old}",
                expected=[labels[i] for i in chosen],
                found=old,
                **where,
            )
    ids: list[str] = []
    seen: dict[str, str] = {}
    for i in chosen:
        ent = mm.rename.get(labels[i]) or sanitize_id(labels[i], f"m{i + 1}")
        if ent in seen:
            raise fail(
                "E503",
                f"point labels {seen[ent]!r} and {labels[i]!r} both become entity {ent!r}; rename one",
                pointer="/markers/rename",
                expected="distinct entity ids",
                found=ent,
                **where,
            )
        seen[ent] = labels[i]
        ids.append(ent)
    return chosen, ids


def _analog_reader(c3d: Recording, label: str) -> SourceReader:
    def read(name: str) -> tuple[np.ndarray, str | None]:
        hits = [i for i, lab in enumerate(c3d.analog_labels) if lab == name]
        if len(hits) != 1:
            why = "no" if not hits else f"{len(hits)} channels labelled"
            raise fail(
                "E503", f"{c3d.path.name} has {why} analog channel {name!r}", file=label, expected=c3d.analog_labels, found=name
            )
        i = hits[0]
        return c3d.analogs[i], c3d.analog_units[i] or None

    return read


def _prepare(
    out: str | Path | Destination,
    mapping: str | Path | LoadedMap | None,
    source: str,
    overrides: dict[str, Any] | None,
    overwrite: bool,
    append: bool,
) -> tuple[Destination, LoadedMap, Device, dict[str, Any], dict[str, str]]:
    """Destination, map and device of an import, all checked before the source is read."""
    dest = out if isinstance(out, Destination) else Destination.of(out, overwrite=overwrite, append=append)
    loaded = mapping if isinstance(mapping, LoadedMap) else load_map(mapping, source, overrides, dest.session_facts())
    model, device, extra = _resolve_device(loaded.map, loaded.base_dir, loaded.label)
    dest.check_facts(loaded.map, model, loaded.label)
    return dest, loaded, model, device, extra


ROTATION_TOLERANCE = 1e-3  # |RᵀR − I| and |det R − 1| allowed in a stored rotation (float32 storage)


def body_poses(
    rec: Recording, index: int, world: WorldFrame | None, to_m: Unit, max_residual: float | None, *, label: str
) -> tuple[np.ndarray, np.ndarray]:
    """One 6-DoF body as pose columns (spec §5.5): positions (n × 3, m, in W) and unit quaternions
    (n × 4, body → W, w ≥ 0). A sample the file marks invalid, or whose residual exceeds
    ``max_residual``, is occluded: all seven values NaN. E501 when a valid sample is not a rotation."""
    # every reader that names 6-DoF bodies gives their positions and rotations
    assert rec.body_positions is not None and rec.body_rotations is not None
    pos = to_m.to_si(rec.body_positions[:, index, :])
    rot = rec.body_rotations[:, index, :, :]
    valid = np.isfinite(pos).all(axis=1) & np.isfinite(rot).all(axis=(1, 2))
    if rec.body_residuals is not None:
        res = rec.body_residuals[:, index]
        valid &= ~(res < 0)
        if max_residual is not None:
            valid &= ~(res > max_residual)
    r = np.where(valid[:, None, None], rot, np.eye(3))
    err = np.abs(np.einsum("nji,njk->nik", r, r) - np.eye(3)).max(axis=(1, 2))
    err = np.maximum(err, np.abs(np.linalg.det(r) - 1.0))
    if (err > ROTATION_TOLERANCE).any():
        k = int(np.argmax(err > ROTATION_TOLERANCE))
        raise fail(
            "E501",
            f"6-DoF body {rec.body_labels[index]!r} of {rec.path.name} holds no rotation at frame {k}",
            file=str(rec.path),
            column=rec.body_labels[index],
            expected="an orthonormal matrix, det 1",
            found=np.round(r[k], 6).tolist(),
        )
    if world is not None:
        pos = world.apply(pos)
        r = world.rotation @ r
    quat = matrix_to_quat(r)
    pos = np.where(valid[:, None], pos, np.nan)
    quat = np.where(valid[:, None], quat, np.nan)
    return pos, quat


def _body_index(rec: Recording, body: str, pointer: str, label: str) -> int:
    hits = [i for i, b in enumerate(rec.body_labels) if b == body]
    if len(hits) != 1:
        why = "no" if not hits else f"{len(hits)} bodies labelled"
        raise fail(
            "E503",
            f"{rec.path.name} has {why} 6-DoF body {body!r}",
            file=label,
            pointer=pointer,
            expected=rec.body_labels,
            found=body,
        )
    return hits[0]


def _pose_streams(
    rec: Recording,
    m: ImportMap,
    world: WorldFrame | None,
    to_m: Unit,
    t: np.ndarray,
    rigid_bodies: list[RigidBody],
    label: str,
) -> dict[str, tuple[dict[str, np.ndarray], list[str] | None]]:
    """handle_pose and link_poses from the map's ``bodies`` (spec §5.5): kind → (columns, entities)."""
    bm = m.bodies
    if bm is None or (bm.handle is None and not bm.links):
        return {}
    out: dict[str, tuple[dict[str, np.ndarray], list[str] | None]] = {}
    names = {b.name for b in rigid_bodies}
    if bm.handle is not None:
        pos, quat = body_poses(
            rec, _body_index(rec, bm.handle, "/bodies/handle", label), world, to_m, bm.max_residual, label=label
        )
        cols = {c: pos[:, k] for k, c in enumerate(("px", "py", "pz"))}
        cols.update({c: quat[:, k] for k, c in enumerate(("qw", "qx", "qy", "qz"))})
        out["handle_pose"] = ({"t": t, **cols}, None)
    if bm.links:
        cols = {"t": t}
        for link, body in bm.links.items():
            if link not in names:
                raise fail(
                    "E502",
                    f"link {link!r} of bodies.links is not a rigid body of markers.rigid_bodies",
                    file=label,
                    pointer=f"/bodies/links/{link}",
                    expected=sorted(names),
                    found=link,
                )
            pos, quat = body_poses(
                rec, _body_index(rec, body, f"/bodies/links/{link}", label), world, to_m, bm.max_residual, label=label
            )
            cols.update({f"{link}_{c}": pos[:, k] for k, c in enumerate(("px", "py", "pz"))})
            cols.update({f"{link}_{c}": quat[:, k] for k, c in enumerate(("qw", "qx", "qy", "qz"))})
        out["link_poses"] = (cols, list(bm.links))
    return out


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
    dest, loaded, _, device, extra = _prepare(out, mapping, "c3d", overrides, overwrite, append)
    return import_recording(
        read_c3d(path, stream=stream), dest, loaded, device, extra, chunk_frames=chunk_frames, progress=progress
    )


def import_recording(  # noqa: C901 (over ruff's limit of 15: to be split)
    rec: Recording,
    dest: Destination,
    loaded: LoadedMap,
    device: dict[str, Any],
    extra: dict[str, str],
    *,
    chunk_frames: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ImportResult:
    """One motion-capture recording (C3D, Qualisys TSV, Motive or Nexus CSV) as one trial (spec §5.5, §5.10).

    Markers become a ``markers`` stream (point units → m, invalid → NaN), the map's 6-DoF bodies
    ``handle_pose`` and ``link_poses``, all in W (§5.6); analog channels become the streams the map
    names (§5.3); a chosen force platform becomes the rig's plate. The reader's warnings (W501) and
    the plate's (W502) are returned and written into the trial's notes. Nothing is written when any
    check fails.

    A recording opened for streaming (``rec.streamed``, §5.5.1) is read ``chunk_frames`` frames at a time
    and its streams are written row group by row group; ``progress(frames done, frames)`` follows it.
    """
    m, label = loaded.map, loaded.label
    src = str(rec.path)
    mm = m.markers or MarkerMap()
    warnings = list(rec.warnings)

    # world frame
    plate_number = None
    if isinstance(m.force_plate, int):
        if m.force_plate > len(rec.platforms):
            raise fail(
                "E503",
                f"{rec.path.name} has no force platform {m.force_plate}",
                file=label,
                pointer="/force_plate",
                expected=[p.number for p in rec.platforms],
                found=m.force_plate,
            )
        plate_number = m.force_plate
    elif m.force_plate == "auto" and rec.platforms and m.lab_to_world is None:
        plate_number = 1
    if plate_number is not None and m.lab_to_world is not None:
        raise fail(
            "E502",
            "give either a force platform or lab_to_world: the platform defines W",
            file=label,
            pointer="/lab_to_world",
            expected="one of them",
            found="both",
        )
    rig = m.session.rig.model_dump(mode="json", exclude_none=True)
    point_unit = None
    chosen, entities = _select_markers(rec, mm, label)
    wants_bodies = m.bodies is not None and (m.bodies.handle is not None or bool(m.bodies.links))
    if chosen or wants_bodies or plate_number is not None:
        point_unit = unit_conversion(rec.point_units, "m", file=src, pointer="/POINT/UNITS")
    world: WorldFrame | None = None
    if plate_number is not None:
        if "force_plate" in rig:
            raise fail(
                "E502",
                "the map's rig has a force_plate and the C3D platform would replace it; set force_plate to 'none' or remove one",
                file=label,
                pointer="/session/rig/force_plate",
                expected="one plate description",
                found="two",
            )
        assert point_unit is not None  # converted above when a platform defines W
        world, rig["force_plate"], plate_warnings = plate_description(rec.platforms[plate_number - 1], point_unit, file=src)
        warnings += plate_warnings
    elif m.lab_to_world is not None:
        world = pose_frame(m.lab_to_world)
    frame_note = (
        world.description if world else f"W: the {rec.format.upper()} lab frame as recorded (no force platform, no lab_to_world)"
    )

    # markers and 6-DoF bodies, on the point clock
    mocap_streams: dict[str, tuple[dict[str, np.ndarray], list[str] | None]] = {}
    if chosen or wants_bodies:
        if rec.frames < 2:
            raise fail(
                "E205",
                f"{rec.path.name} holds {rec.frames} frame(s); a stream needs two",
                file=src,
                expected="≥ 2 frames",
                found=rec.frames,
            )
        if "motion_capture" in rig:
            raise fail(
                "E502",
                "the importer writes rig.motion_capture from the source; give rigid bodies and the system under 'markers'",
                file=label,
                pointer="/session/rig/motion_capture",
                expected=None,
                found="motion_capture",
            )
        if chosen:
            for j, body in enumerate(mm.rigid_bodies):
                unknown = [e for e in body.markers if e not in entities]
                if unknown:
                    raise fail(
                        "E503",
                        f"rigid body {body.name!r} names markers that are not imported: {unknown}",
                        file=label,
                        pointer=f"/markers/rigid_bodies/{j}/markers",
                        expected=entities,
                        found=unknown,
                    )
        rig["motion_capture"] = {
            "system": mm.system or rec.manufacturer or None,
            "rate_hz": rec.point_rate,
            "rigid_bodies": [b.model_dump() for b in mm.rigid_bodies],
            "markers": entities,
        }
        if rig["motion_capture"]["system"] is None:
            del rig["motion_capture"]["system"]

    # analog streams, and the platform's wrench (§5.6.1)
    analog_wanted = bool(m.streams) or m.platform_wrench is not None
    if m.platform_wrench is not None:
        if plate_number is None:
            raise fail(
                "E502",
                "platform_wrench needs the force platform that defines W (force_plate)",
                file=label,
                pointer="/platform_wrench",
                expected="a force platform",
                found=m.force_plate,
            )
        if "plate_wrench" in m.streams:
            raise fail(
                "E502",
                "plate_wrench is both mapped from channels and taken from the platform; keep one",
                file=label,
                pointer="/streams/plate_wrench",
                expected="one source",
                found="two",
            )
    if analog_wanted:
        n = rec.analogs.shape[1]
        if n < 2:
            raise fail(
                "E205",
                f"{rec.path.name} holds {n} analog sample(s); a stream needs two",
                file=src,
                expected="≥ 2 analog samples",
                found=n,
            )
        for kind, smap in m.streams.items():
            if smap.rate_hz is not None and smap.rate_hz != rec.analog_rate:
                raise fail(
                    "E502",
                    f"{kind} rate_hz {smap.rate_hz} differs from the file's analog rate {rec.analog_rate}",
                    file=label,
                    pointer=f"/streams/{kind}/rate_hz",
                    expected=rec.analog_rate,
                    found=smap.rate_hz,
                )

    def streams_of(part: Recording) -> tuple[dict[str, Any], dict[str, dict[str, np.ndarray]], list[Finding]]:
        """The trial's streams from the frames of ``part`` (the whole recording, or one chunk of it)."""
        mocap: dict[str, tuple[dict[str, np.ndarray], list[str] | None]] = {}
        analog: dict[str, dict[str, np.ndarray]] = {}
        notes: list[Finding] = []
        if chosen or wants_bodies:
            assert point_unit is not None  # converted above whenever markers or bodies are wanted
            t = (part.point_first_frame + np.arange(part.frames)) / rec.point_rate + m.time_offset_s
            if chosen:
                pos = point_unit.to_si(part.points[:, chosen, :])
                pos[~np.isfinite(pos).all(axis=2)] = np.nan  # a marker is seen or occluded as a whole (§2.7)
                if world is not None:
                    pos = world.apply(pos)
                marker_data = {"t": t}
                for j, ent in enumerate(entities):
                    for k, axis in enumerate("xyz"):
                        marker_data[f"{ent}_{axis}"] = pos[:, j, k]
                mocap["markers"] = (marker_data, entities)
            mocap.update(_pose_streams(part, m, world, point_unit, t, mm.rigid_bodies, label))
        if analog_wanted:
            n = part.analogs.shape[1]
            t_an = (part.analog_first_sample + np.arange(n)) / rec.analog_rate + m.time_offset_s
            mapped = _mapped_streams(m, n, _analog_reader(part, label), label=label, source_file=src, unit_required=False)
            if m.platform_wrench is not None:
                # a platform wrench without a platform is E502 above; a platform's geometry needs the POINT unit
                assert plate_number is not None and point_unit is not None
                mapped["plate_wrench"], notes = platform_plate_wrench(
                    part, part.platforms[plate_number - 1], m.platform_wrench, rig["force_plate"], point_unit, label=label
                )
            analog = {kind: {"t": t_an, **cols} for kind, cols in mapped.items()}
        return mocap, analog, notes

    pieces = recording_chunks(rec, chunk_frames)
    first = next(pieces)[1] if rec.frames or rec.analogs.shape[1] else rec
    mocap_streams, analog_streams, origin_notes = streams_of(first)
    warnings += origin_notes

    kinds = list(mocap_streams) + list(analog_streams)
    if not kinds:
        raise fail(
            "E502",
            f"nothing to import from {rec.path.name}: no markers selected, no bodies and no streams mapped",
            file=label,
            pointer="/streams",
            expected="markers, bodies or mapped analog streams",
            found=None,
        )
    _check_trial_streams(m, kinds, label)
    world_rule = ("plate" if plate_number is not None else "pose" if world is not None else "lab") if mocap_streams else None
    rig = dest.rig(rig, world_rule, label)
    recorder = f"haptify {PACKAGE_VERSION} import {rec.format}" + (f" ({rec.manufacturer})" if rec.manufacturer else "")
    writer, stem = dest.writer(m, rec.path, rig, device, extra, recorder)
    provenance = f"Imported from {rec.path.name} by haptify {PACKAGE_VERSION}. {frame_note}."
    if warnings:
        provenance += " Import warnings: " + " ".join(f"{w.code} {w.message}." for w in warnings)
    trial_id = _add_trial(writer, m, stem, rec.path, provenance)
    written = []
    streamed = rec.streamed

    def add(kind: str, cols: dict[str, np.ndarray], **kw: Any) -> None:
        if streamed:
            written.append(writer.add_chunked_stream(trial_id, kind, list(cols), **kw))
        else:
            written.append(writer.add_stream(trial_id, kind, cols, **kw))

    for kind, (cols, ents) in mocap_streams.items():
        if kind == "markers":
            fmt = mm.format
        else:
            assert m.bodies is not None  # _pose_streams makes the pose streams from the map's bodies
            fmt = m.bodies.format
        add(kind, cols, rate_hz=rec.point_rate, fmt=fmt, entities=ents)
    for kind, cols in analog_streams.items():
        stream_map = m.streams.get(kind)
        if stream_map is not None:
            fmt, frame = stream_map.format, stream_map.frame
        else:
            assert m.platform_wrench is not None  # the one analog stream without a stream map: the platform's wrench
            fmt, frame = m.platform_wrench.format, None
        add(kind, cols, rate_hz=rec.analog_rate, fmt=fmt, frame=frame)
    if streamed:

        def chunks() -> Iterator[dict[str, dict[str, np.ndarray]]]:
            done = first.frames
            yield {**{k: c for k, (c, _) in mocap_streams.items()}, **analog_streams}
            if progress:
                progress(done, rec.frames)
            for _, part in pieces:
                mocap, analog, _ = streams_of(part)
                yield {**{k: c for k, (c, _) in mocap.items()}, **analog}
                done += part.frames
                if progress:
                    progress(done, rec.frames)

        writer.chunks = chunks
    dest.write(writer, trial_id)
    return ImportResult(
        dest.out,
        writer.manifest["session_id"],
        trial_id,
        [_stream_summary(s) for s in written],
        frame_note,
        rec.summary(),
        warnings,
    )


# --- CSV import (spec §5.7) -----------------------------------------------------------------------

RATE_SIGNIFICANT_DIGITS = 6  # a CSV stream's default nominal rate: 1/median(Δt) to 6 significant digits


def _round_significant(x: float, digits: int) -> float:
    return float(f"{x:.{digits}g}")


class _CsvReading(TypedDict, total=False):
    """The options :func:`read_csv_columns` gives pandas' ``read_csv``."""

    sep: str
    skiprows: int
    comment: str | None
    skipinitialspace: bool
    engine: Literal["c"]
    encoding: str
    usecols: list[str]
    na_values: list[str]
    keep_default_na: bool


def read_csv_columns(path: Path, names: list[str], opts: CsvOptions, *, map_label: str) -> dict[str, np.ndarray]:
    """The named columns of a CSV log as float64 arrays (spec §5.7).

    E501 when the file is missing or unreadable or a cell is not a number (row named); E503 when a
    column is not in the header (the header is listed).
    """
    label = str(path)
    if not path.is_file():
        raise fail("E501", f"{label!r} does not exist or is not a file", file=label)
    common: _CsvReading = {
        "sep": opts.delimiter,
        "skiprows": opts.skip_rows,
        "comment": opts.comment,
        "skipinitialspace": True,
        "engine": "c",
        "encoding": "utf-8",
    }
    try:
        raw_header = [str(h) for h in pd.read_csv(path, nrows=0, **common).columns]
    except (OSError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as exc:
        raise fail("E501", f"{label!r} cannot be read as CSV: {exc}", file=label) from None
    header = [h.strip() for h in raw_header]
    for name in names:
        if name not in header:
            raise fail("E503", f"{path.name} has no column {name!r}", file=map_label, expected=header, found=name)
    columns = {raw_header[header.index(name)]: name for name in names}
    numeric: _CsvReading = {"usecols": list(columns), "na_values": ["NaN", "nan"], "keep_default_na": False, **common}
    try:  # the fast path: the C parser, correctly rounded (pandas ≥ 3)
        table = pd.read_csv(path, dtype={c: "float64" for c in columns}, **numeric)
    except (OSError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise fail("E501", f"{label!r} cannot be read as CSV: {exc}", file=label) from None
    except ValueError:  # some cell is not a number: find it for the message
        text = pd.read_csv(path, dtype=str, **numeric)
        first_data_line = opts.skip_rows + 2  # 1-based line of the first data row (comment lines aside)
        for raw_name, name in columns.items():
            cells = text[raw_name].fillna("").str.strip()
            parsed = pd.to_numeric(cells, errors="coerce")
            bad = np.flatnonzero(parsed.isna() & ~cells.str.lower().isin(["nan"]))
            if bad.size:
                i = int(bad[0])
                raise fail(
                    "E501",
                    f"{path.name} column {name!r}, data row {i + 1} (line ≈{first_data_line + i}) is not a number",
                    file=label,
                    column=name,
                    expected="a number",
                    found=cells.iloc[i],
                ) from None
        raise fail("E501", f"{label!r} cannot be read as numbers", file=label) from None
    return {name: table[raw].to_numpy(dtype=np.float64) for raw, name in columns.items()}


def import_csv(
    path: str | Path,
    out: str | Path | Destination,
    mapping: str | Path | LoadedMap,
    *,
    overrides: dict[str, Any] | None = None,
    overwrite: bool = False,
    append: bool = False,
) -> ImportResult:
    """Import a column-mapped CSV log as one trial of a new session at ``out`` (spec §5.7), or append
    it as one more trial to the session at ``out`` (``append``, §5.9).

    One time column (s, ms or us, plus ``time_offset_s``) serves every mapped stream; each column is
    converted to SI by §5.3. Nothing is written when any check fails.
    """
    dest, loaded, _, device, extra = _prepare(out, mapping, "csv", overrides, overwrite, append)
    m, label = loaded.map, loaded.label
    src_path = Path(path)
    src = str(src_path)
    if not m.streams:
        raise fail("E502", "a csv map needs at least one stream", file=label, pointer="/streams", expected="streams", found={})
    opts = m.csv or CsvOptions()
    time = m.time
    assert time is not None  # load_map requires 'time' of a csv map (E502)
    sources = {_as_channel(c).source for s in m.streams.values() for c in s.columns.values()}
    wanted = [time.source] + sorted({named for named in sources if named is not None} - {time.source})
    data = read_csv_columns(src_path, wanted, opts, map_label=label)
    time_unit = unit_conversion(time.unit, "s", file=label, pointer="/time/unit", column=time.source)
    t = time_unit.to_si(data[time.source])
    if m.time_offset_s != 0.0:
        t = t + m.time_offset_s
    if t.size < 2:
        raise fail(
            "E205", f"{src_path.name} holds {t.size} row(s); a stream needs two", file=src, expected="≥ 2 rows", found=int(t.size)
        )
    steps = np.diff(t)
    if not np.isfinite(t).all() or (steps <= 0).any():
        i = int(np.argmax(~np.isfinite(t))) if not np.isfinite(t).all() else int(np.argmax(steps <= 0)) + 1
        raise fail(
            "E203",
            f"time column {time.source!r} of {src_path.name} is not finite and strictly increasing at data row {i + 1}",
            file=src,
            column=time.source,
            expected="strictly increasing",
            found=f"{data[time.source][i - 1] if i else ''} → {data[time.source][i]}",
        )

    def read(name: str) -> tuple[np.ndarray, str | None]:
        return data[name], None

    streams = _mapped_streams(m, t.size, read, label=label, source_file=src, unit_required=True)
    _check_trial_streams(m, list(streams), label)
    rig = dest.rig(m.session.rig.model_dump(mode="json", exclude_none=True), None, label)
    writer, stem = dest.writer(m, src_path, rig, device, extra, f"haptify {PACKAGE_VERSION} import csv")
    trial_id = _add_trial(writer, m, stem, src_path, f"Imported from {src_path.name} by haptify {PACKAGE_VERSION}.")
    default_rate = _round_significant(1.0 / float(np.median(steps)), RATE_SIGNIFICANT_DIGITS)
    written = []
    for kind, cols in streams.items():
        smap = m.streams[kind]
        written.append(
            writer.add_stream(
                trial_id, kind, {"t": t, **cols}, rate_hz=smap.rate_hz or default_rate, fmt=smap.format, frame=smap.frame
            )
        )
    dest.write(writer, trial_id)
    return ImportResult(
        dest.out,
        writer.manifest["session_id"],
        trial_id,
        [_stream_summary(s) for s in written],
        "CSV values are stored as logged (rotated into W only where from_frame says so)",
        {"file": src_path.name, "rows": int(t.size), "columns": wanted},
    )
