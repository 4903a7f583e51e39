"""The import map (spec §5.2): what a source file does not hold and which channel fills which column;
ids from free labels (spec §5.4)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from haptify import schemas
from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.session_format import (
    PROTOCOLS,
    Device,
    Id,
    Party,
    Pose,
    Rendering,
    Rig,
    RigidBody,
)
from haptify.formats.storage import (
    parse_json_file,
    pydantic_findings,
)

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
            raise fail(Code.IMPORT_MAP_INVALID, f"import map {label!r} does not exist", file=label)
        raw = parse_json_file(p, Code.IMPORT_MAP_INVALID, label)
        base = p.resolve().parent
    if not isinstance(raw, dict):
        raise fail(
            Code.IMPORT_MAP_INVALID, "an import map is a JSON object", file=label, expected="object", found=type(raw).__name__
        )
    raw = _deep_merge(raw, overrides or {})
    if session_facts is not None:
        given = raw.get("session") if isinstance(raw.get("session"), dict) else {}
        raw["session"] = {**{k: v for k, v in session_facts.items() if k not in given}, **given}
    session = raw.get("session")
    no_date = None
    if not isinstance(session, dict) or session.get("date") is None:
        no_date = fail(
            Code.IMPORT_MAP_INVALID,
            "the recording date is missing: give session.date in the map or --date",
            file=label,
            pointer="/session/date",
            expected="YYYY-MM-DD",
            found="missing",
        )
    try:
        m = ImportMap.model_validate(raw)
    except ValidationError as exc:
        findings = pydantic_findings(exc, Code.IMPORT_MAP_INVALID, label)
        if no_date is not None and not any(f.pointer == "/session" for f in findings):
            findings += no_date.findings
        raise HaptifyError(*findings) from None
    if no_date is not None:
        raise no_date
    if m.source != source:
        raise fail(
            Code.IMPORT_MAP_INVALID,
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
                Code.IMPORT_MAP_INVALID,
                f"{key!r} does not apply to {source} imports",
                file=label,
                pointer=f"/{key}",
                expected=None,
                found=key,
            )
    if source == "csv":
        if m.force_plate != "auto":
            raise fail(Code.IMPORT_MAP_INVALID, "'force_plate' does not apply to csv imports", file=label, pointer="/force_plate")
        if m.time is None:
            raise fail(
                Code.IMPORT_MAP_INVALID,
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
