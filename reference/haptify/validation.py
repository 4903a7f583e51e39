"""Validation of a session folder (spec chapter 4).

:func:`validate_session` checks a session folder against chapters 1–3 and reports **every** problem
it finds as a coded :class:`~haptify.errors.Finding` (codes from ``schemas/<v>/codes.json``), grouped by
trial and file. It never raises for bad input and never reads anything outside the session folder:
paths are resolved lexically, symbolic link by symbolic link, and a path that would leave the folder is
reported (E108/E109) before anything is opened (spec §4.2).

The checks run in the order of spec §4.3: the manifest (well-formedness, JSON Schema with all errors,
device file, ids, cross references), then the trials (protocol requirements, rendering, label,
powered flag), then every stream (path safety, file, size limits, checksum, readability, columns and
units, frame, rows, time, rate, NaN policy, infinities, quaternion norms, sensor ranges), and last the
time overlap of the streams of each trial.
"""

from __future__ import annotations

import datetime
import itertools
import json
import math
import os
import stat
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path, PurePosixPath
from typing import Any, Callable, Iterable, Literal

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from jsonschema import Draft202012Validator
from jsonschema.exceptions import ValidationError as SchemaError
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from haptify import schemas
from haptify.conventions import QUATERNION_NORM_TOLERANCE
from haptify.errors import Finding, HaptifyError
from haptify.kinematics import empty_joint_range, limit_order_violations
from haptify.session_format import (
    ALLOWED_VALUES,
    ClockOffset,
    Device,
    Kinematics,
    Rig,
    SensorRange,
    Session,
    Stream,
    Trial,
    expected_columns,
    kind_table,
    quaternion_groups,
    values_outside_set,
)
from haptify.storage import (
    MANIFEST,
    parse_json_file,
    pointer_of,
    pydantic_findings,
    read_stream_chunks,
    resolve_inside,
    sha256_file,
)
from haptify.versions import PACKAGE_VERSION, SPEC_VERSION

# --- tolerances and limits of spec chapter 4 (§4.4, §4.5) ----------------------------------------
RATE_TOLERANCE = 0.01  # |actual mean rate / rate_hz − 1| allowed (E206)
INTERVAL_LOW, INTERVAL_HIGH = 0.5, 1.5  # an interval outside [0.5, 1.5] / rate_hz is irregular (W402)
OCCLUSION_WARNING_SHARE = 0.20  # share of occluded samples above which W405 is raised
NORMAL_NORM_TOLERANCE = QUATERNION_NORM_TOLERANCE  # |‖n‖ − 1| allowed in a rendering's surface_normal (E307, spec §2.5)
MANIFEST_MAX_BYTES = 16 * 2**20  # session.json larger than this is not read (E113)
DEVICE_MAX_BYTES = 4 * 2**20  # device.json larger than this is not read (E113)
STREAM_MAX_BYTES = 8 * 2**30  # spec §3.5: no stream file exceeds 8 GiB (E113)
STREAM_BYTES_BASE = 16 * 2**10  # plausibility bound of a stream file's size from its declared
STREAM_BYTES_PER_COLUMN = 2**10  # rows and columns: base + per column + per value (E113), so a
STREAM_BYTES_PER_VALUE = 32  # tiny declared stream never makes the validator read gigabytes
STREAM_CHUNK_BYTES = 32 * 2**20  # a stream is validated in chunks of about this many float64 bytes

MOCAP_KINDS = frozenset(k for k, v in schemas.load("stream-kinds.json")["kinds"].items() if v.get("nan_allowed"))
EXIT_VALID, EXIT_INVALID, EXIT_CANNOT_RUN = 0, 1, 2


# --- the report ----------------------------------------------------------------------------------


@dataclass
class ReportItem:
    """A finding and the trial it belongs to (None for session-level findings)."""

    finding: Finding
    trial: str | None = None


@dataclass
class ValidationReport:
    """Everything validation found in one session folder (spec §4.6)."""

    session: str
    items: list[ReportItem] = field(default_factory=list)
    streams_checked: int = 0

    @property
    def findings(self) -> list[Finding]:
        return [i.finding for i in self.items]

    @property
    def codes(self) -> list[str]:
        """The distinct codes found, sorted."""
        return sorted({f.code for f in self.findings})

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.is_error]

    @property
    def warnings(self) -> list[Finding]:
        return [f for f in self.findings if not f.is_error]

    @property
    def valid(self) -> bool:
        """True when no finding is an error (warnings allowed)."""
        return not self.errors

    @property
    def exit_code(self) -> int:
        """0 valid, 1 invalid, 2 validation could not run (no session folder, internal error) — spec §4.6."""
        if any(f.code in ("E101", "E999") for f in self.findings):
            return EXIT_CANNOT_RUN
        return EXIT_VALID if self.valid else EXIT_INVALID

    def groups(self) -> list[tuple[str | None, str, list[Finding]]]:
        """Findings grouped as ``(trial, file, findings)``: session-level first, then trial by trial."""
        order: dict[tuple[str | None, str], list[Finding]] = {}
        for item in self.items:
            order.setdefault((item.trial, item.finding.file or MANIFEST), []).append(item.finding)
        trial_rank = {t: n for n, t in enumerate(dict.fromkeys(i.trial for i in self.items))}
        keys = sorted(order, key=lambda k: (k[0] is not None, trial_rank[k[0]], k[1] != MANIFEST))
        return [(trial, file, order[(trial, file)]) for trial, file in keys]

    def to_model(self) -> "ValidationReportModel":
        """The machine-readable report (``validation-report.schema.json``)."""
        return ValidationReportModel(
            spec_version=SPEC_VERSION,
            haptify_version=PACKAGE_VERSION,
            session=self.session,
            valid=self.valid,
            exit_code=self.exit_code,
            errors=len(self.errors),
            warnings=len(self.warnings),
            streams_checked=self.streams_checked,
            findings=[FindingModel(trial=i.trial, **_jsonable(i.finding.to_dict())) for i in self.items],
        )


class FindingModel(BaseModel):
    """One finding of a validation report (spec §4.6)."""

    model_config = ConfigDict(extra="forbid")

    code: str = Field(pattern=r"^[EW][0-9]{3}$", description="Stable code from codes.json.")
    name: str = Field(description="The code's short name, e.g. 'time-not-increasing'.")
    severity: Literal["error", "warning"]
    message: str
    hint: str
    spec_section: str = Field(description="The spec section the rule comes from, e.g. '2.6'.")
    trial: str | None = Field(None, description="The trial the finding belongs to; absent for session-level findings.")
    file: str | None = Field(None, description="Path of the file, relative to the session folder.")
    pointer: str | None = Field(None, description="JSON pointer (RFC 6901) into that file when it is JSON.")
    column: str | None = Field(None, description="The stream column concerned.")
    time_range: list[float] | None = Field(
        None, min_length=2, max_length=2, description="First and last affected sample time, s."
    )
    expected: Any = None
    found: Any = None


class ValidationReportModel(BaseModel):
    """The ``--json`` output of ``haptify validate`` (spec §4.6)."""

    model_config = ConfigDict(extra="forbid")

    spec_version: Literal[SPEC_VERSION]  # type: ignore[valid-type]
    haptify_version: str
    session: str = Field(description="The session folder as given on the command line.")
    valid: bool = Field(description="True when no finding is an error.")
    exit_code: Literal[0, 1, 2]
    errors: int = Field(ge=0)
    warnings: int = Field(ge=0)
    streams_checked: int = Field(ge=0)
    findings: list[FindingModel] = Field(description="Every finding, grouped: session-level first, then by trial and file.")


def _jsonable(value: Any) -> Any:
    """A JSON-safe copy: numpy scalars to Python, tuples to lists, non-finite floats to strings."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return str(value)


def _short(value: Any) -> Any:
    """A short printable stand-in for a found value (containers summarised, long text cut)."""
    if isinstance(value, dict):
        return "<object>"
    if isinstance(value, list):
        return f"<array of {len(value)}>"
    if isinstance(value, str) and len(value) > 80:
        return value[:77] + "..."
    return value


# --- schema validation (spec §4.3.1) -------------------------------------------------------------


@lru_cache(maxsize=None)
def _schema_validator(name: str) -> Draft202012Validator:
    """The Draft 2020-12 validator of ``<name>.schema.json``; from the pydantic model when not yet generated."""
    try:
        schema = schemas.schema(name)
    except FileNotFoundError:
        models: dict[str, type[BaseModel]] = {"session": Session, "device": Device}
        schema = models[name].model_json_schema()
    return Draft202012Validator(schema)


def _branch_errors(err: SchemaError) -> list[SchemaError]:
    """The leaf errors of the branch of an ``anyOf``/``oneOf`` that the instance was meant to match.

    A ``discriminator`` (pydantic's tagged unions) names the branch; otherwise branches whose type
    does not fit the instance are dropped and the one with the fewest errors is taken.
    """
    if err.validator not in ("anyOf", "oneOf") or not err.context:
        return [err]
    by_branch: dict[str | int, list[SchemaError]] = {}
    for sub in err.context:
        by_branch.setdefault(sub.relative_schema_path[0], []).append(sub)
    options = err.validator_value
    assert isinstance(options, list)  # the value of an anyOf / oneOf is its list of branches (JSON Schema §10.2.1)
    disc = err.schema.get("discriminator") if isinstance(err.schema, dict) else None
    if disc and isinstance(err.instance, dict):
        tag = err.instance.get(disc.get("propertyName"))
        target = disc.get("mapping", {}).get(tag) if isinstance(tag, str) else None
        if target is None:
            return [err]
        chosen = [i for i, o in enumerate(options) if o.get("$ref") == target]
        if not chosen or chosen[0] not in by_branch:
            return [err]
        branch = by_branch[chosen[0]]
    else:
        fitting = {
            i: errs for i, errs in by_branch.items() if not any(e.validator == "type" and not e.relative_path for e in errs)
        }
        if not fitting:
            return [err]
        branch = min(fitting.values(), key=len)
    out: list[SchemaError] = []
    for sub in branch:
        out.extend(_branch_errors(sub))
    return out


_SIZE_FIELDS = {"rows", "rate_hz", "loop_rate_hz"}


def _code_for(err: SchemaError, default: str) -> str:
    """Map a schema error to its catalogue code: E301 unknown protocol, E113 absurd size, else ``default``."""
    path = list(err.absolute_path)
    if default != "E104":
        return default
    if len(path) == 3 and path[0] == "trials" and path[2] == "protocol" and err.validator == "enum":
        return "E301"
    if path and path[-1] in _SIZE_FIELDS and err.validator in ("maximum", "exclusiveMaximum"):
        return "E113"
    return default


def schema_findings(instance: Any, schema_name: str, code: str, label: str) -> list[Finding]:
    """Every JSON Schema error of ``instance`` against ``<schema_name>.schema.json`` as findings (spec §4.3.1)."""
    validator = _schema_validator(schema_name)
    out: list[Finding] = []
    for top in validator.iter_errors(instance):
        for err in _branch_errors(top):
            expected = err.validator_value if err.validator not in ("anyOf", "oneOf", "$ref", "additionalProperties") else None
            if isinstance(expected, (dict, list)) and len(json.dumps(expected, default=str)) > 200:
                expected = None
            message = err.message if len(err.message) <= 300 else err.message[:297] + "..."
            out.append(
                Finding(
                    _code_for(err, code),
                    f"{schema_name}.schema.json: {message}",
                    file=label,
                    pointer=pointer_of(err.absolute_path),
                    expected=_jsonable(expected) if expected is not None else err.validator,
                    found=_jsonable(_short(err.instance)),
                )
            )
    out.sort(key=lambda f: f.pointer or "")
    return out


# --- the device's kinematic chain (spec §2.3) ------------------------------------------------------


def kinematics_findings(kin: Kinematics, file: str, base: str) -> list[Finding]:
    """The rules of spec §2.3 on a DH chain, as findings located at ``file`` + ``base`` (a JSON pointer).

    E116: the joints are named ``q1 … qn`` in chain order, and a limit names only earlier joints.
    E115: every joint's range is non-empty — ``upper ≥ lower`` — at some configuration of the lattice of
    spec §8.3 step 1 (``RANGE_LATTICE_POINTS`` per joint, joint by joint within the earlier joints' coupled
    limits; :func:`haptify.kinematics.empty_joint_range`); for constant limits simply ``upper ≥ lower``.
    It is the very lattice the modeled workspace samples, so a session that validates never fails
    ``workspace.modeled_volume`` for its limits.
    """
    out = [
        Finding(
            "E116",
            f"joint {i + 1} of the chain is named {joint.name!r}",
            file=file,
            pointer=f"{base}/joints/{i}/name",
            expected=f"q{i + 1}",
            found=joint.name,
        )
        for i, joint in enumerate(kin.joints)
        if joint.name != f"q{i + 1}"
    ]
    if out:
        return out
    names = [j.name for j in kin.joints]
    out = [
        Finding(
            "E116",
            f"the {side} limit of {names[i]} depends on {other}, which is not an earlier joint",
            file=file,
            pointer=f"{base}/joints/{i}/{side}/coefficients/{other}",
            expected=names[:i],
            found=other,
        )
        for i, side, other in limit_order_violations(kin)
    ]
    if out:
        return out
    empty = empty_joint_range(kin)
    if empty is not None:
        joint = kin.joints[empty.joint]
        out.append(
            Finding(
                "E115",
                f"the upper limit of {joint.name} lies below its lower limit (by at least "
                f"{-empty.widest_rad:.6g} rad) for every configuration of the earlier joints",
                file=file,
                pointer=f"{base}/joints/{empty.joint}",
                expected="upper ≥ lower for some configuration",
                found={"lower": joint.lower.model_dump(), "upper": joint.upper.model_dump()},
            )
        )
    return out


# --- files inside the folder (spec §4.2) ---------------------------------------------------------


def _regular_file(path: Path, label: str, missing_code: str, missing_text: str, limit: int) -> int:
    """``lstat`` a resolved path: its size when it is a regular file within ``limit``; coded errors otherwise."""
    try:
        st = os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise HaptifyError(Finding(missing_code, missing_text, file=label)) from None
    except OSError as exc:
        raise HaptifyError(Finding("E112", f"{label!r} cannot be examined: {exc.strerror}", file=label)) from None
    if not stat.S_ISREG(st.st_mode):
        raise HaptifyError(
            Finding(
                "E112",
                f"{label!r} is not a regular file",
                file=label,
                expected="a regular file",
                found="a folder" if stat.S_ISDIR(st.st_mode) else "a special file",
            )
        )
    if st.st_size > limit:
        raise HaptifyError(
            Finding(
                "E113",
                f"{label!r} is {st.st_size} bytes, more than the {limit} bytes allowed",
                file=label,
                expected=f"at most {limit} bytes",
                found=st.st_size,
            )
        )
    return st.st_size


def stream_size_limit(columns: int, rows: int, row_groups: int = 1) -> int:
    """The largest plausible size (bytes) of a stream file with ``columns`` × ``rows`` declared values
    and ``row_groups`` Parquet row groups (1 for CSV): min(8 GiB, 16 KiB + C · (1 KiB · G + 32 B · R)),
    spec §4.2 (E113)."""
    return min(
        STREAM_MAX_BYTES, STREAM_BYTES_BASE + columns * (STREAM_BYTES_PER_COLUMN * row_groups + STREAM_BYTES_PER_VALUE * rows)
    )


def _parquet_row_groups(path: Path, label: str, rows: int) -> int:
    """The number of row groups a Parquet file's footer declares (E112 unreadable; E113 more row groups
    than declared rows, since every row group but an empty file's holds a row; spec §4.2)."""
    try:
        groups = pq.read_metadata(path).num_row_groups
    except MemoryError:
        raise
    except (OSError, pa.ArrowException, ValueError) as exc:
        raise HaptifyError(Finding("E112", f"{label!r} cannot be read as parquet: {exc}", file=label)) from None
    if groups > max(1, rows):
        raise HaptifyError(
            Finding(
                "E113",
                f"{label!r} declares {groups} row groups for {rows} rows",
                file=label,
                expected=f"at most {max(1, rows)} row groups",
                found=groups,
            )
        )
    return max(1, groups)


# --- the validator -------------------------------------------------------------------------------


@dataclass
class StreamEntry:
    """One stream of the manifest as the validator checks it: where it is declared, and what its checks found."""

    trial: str | None
    pointer: str
    stream: Stream
    span: tuple[float, float] | None = None  # first and last time on the session clock, when its time is sound
    declared: bool = False  # its declaration has been checked
    names_ok: bool = False  # its declared columns are its kind's, each once
    path: Path | None = None  # its file, once found inside the folder within its size bound


@dataclass
class _Tally:
    """The samples a mask selects, over consecutive chunks of a stream: how many, and the first and last
    finite time among them (a finding's ``time_range``)."""

    count: int = 0
    first: float | None = None
    last: float | None = None

    def add(self, t: np.ndarray, mask: np.ndarray) -> None:
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return
        self.count += int(idx.size)
        times = t[idx]
        times = times[np.isfinite(times)]
        if times.size:
            if self.first is None:
                self.first = float(times[0])
            self.last = float(times[-1])

    @property
    def span(self) -> tuple[float, float] | None:
        return None if self.first is None or self.last is None else (self.first, self.last)


@dataclass
class _TimeScan:
    """The time column of a stream, chunk by chunk (spec §4.4: finite, strictly increasing, mean rate,
    regular intervals). The interval across a chunk border is judged with the previous chunk's last time,
    so the findings are those of the whole column."""

    rate_hz: float
    rows: int = 0
    first: float = math.nan  # t of the first and of the last sample
    last: float = math.nan
    non_finite: int = 0
    last_finite: float | None = None
    gap: list[float | None] | None = None  # finite times before and after the first non-finite one
    gap_open: bool = False  # no finite time seen yet after the first non-finite one
    reversals: int = 0
    first_reversal: tuple[int, float, float] | None = None  # row k, t[k], t[k+1]
    odd: int = 0  # intervals outside [INTERVAL_LOW, INTERVAL_HIGH] / rate_hz
    odd_span: list[float] = field(default_factory=list)  # start of the first, end of the last
    dt_max: float = -math.inf
    dt_min: float = math.inf

    def feed(self, t: np.ndarray) -> None:
        tt = t if self.rows == 0 else np.concatenate(([self.last], t))
        base = self.rows - (tt.size - t.size)  # row of tt[0]
        if self.rows == 0 and t.size:
            self.first = float(t[0])
        finite = np.isfinite(t)
        if self.gap_open and finite.any():
            assert self.gap is not None  # the gap is open only once it was found
            self.gap[1], self.gap_open = float(t[finite][0]), False
        if not finite.all():
            bad = np.flatnonzero(~finite)
            self.non_finite += int(bad.size)
            if self.gap is None:
                k = int(bad[0])
                before, after = t[:k][finite[:k]], t[k + 1 :][finite[k + 1 :]]
                self.gap = [float(before[-1]) if before.size else self.last_finite, float(after[0]) if after.size else None]
                self.gap_open = not after.size
        if finite.any():
            self.last_finite = float(t[finite][-1])
        if t.size:
            self.rows += int(t.size)
            self.last = float(t[-1])
        dt = np.diff(tt)
        bad_dt = ~(dt > 0) & np.isfinite(dt)
        if bad_dt.any():
            j = int(np.flatnonzero(bad_dt)[0])
            self.reversals += int(bad_dt.sum())
            if self.first_reversal is None:
                self.first_reversal = (base + j, float(tt[j]), float(tt[j + 1]))
        nominal = 1.0 / self.rate_hz
        odd = np.flatnonzero((dt < INTERVAL_LOW * nominal) | (dt > INTERVAL_HIGH * nominal))
        if odd.size:
            self.odd += int(odd.size)
            self.odd_span = [self.odd_span[0] if self.odd_span else float(tt[odd[0]]), float(tt[odd[-1] + 1])]
        if dt.size:
            self.dt_max, self.dt_min = max(self.dt_max, float(dt.max())), min(self.dt_min, float(dt.min()))

    def findings(self, label: str, add: Callable[[Finding], None]) -> bool:
        """Add the time findings (E203, E206, W402); True when the time column is sound (finite, increasing)."""
        if self.non_finite:
            add(
                Finding(
                    "E203",
                    f"time column holds {self.non_finite} non-finite values",
                    file=label,
                    column="t",
                    time_range=self._gap_span(),
                    expected="finite seconds",
                    found="NaN or infinity",
                )
            )
        if self.first_reversal is not None:  # noted with the first of the reversals
            k, a, b = self.first_reversal
            add(
                Finding(
                    "E203",
                    f"time does not strictly increase at {self.reversals} intervals (first at row {k + 1})",
                    file=label,
                    column="t",
                    time_range=(min(a, b), max(a, b)),
                    expected="t[i+1] > t[i]",
                    found=f"t[{k}]={a!r}, t[{k + 1}]={b!r}",
                )
            )
        if self.non_finite or self.reversals:
            return False
        actual = (self.rows - 1) / (self.last - self.first)
        if abs(actual / self.rate_hz - 1.0) > RATE_TOLERANCE:
            add(
                Finding(
                    "E206",
                    f"actual mean rate {actual:.6g} Hz differs from the declared {self.rate_hz:g} Hz by more than "
                    f"{RATE_TOLERANCE:.0%}",
                    file=label,
                    column="t",
                    time_range=(self.first, self.last),
                    expected=self.rate_hz,
                    found=round(actual, 6),
                )
            )
        if self.odd:
            nominal = 1.0 / self.rate_hz
            add(
                Finding(
                    "W402",
                    f"{self.odd} sample intervals lie outside [{INTERVAL_LOW}, {INTERVAL_HIGH}] × {nominal:.6g} s "
                    f"(largest {self.dt_max:.6g} s, smallest {self.dt_min:.6g} s)",
                    file=label,
                    column="t",
                    time_range=(self.odd_span[0], self.odd_span[1]),
                    expected=nominal,
                    found=self.odd,
                )
            )
        return True

    def _gap_span(self) -> tuple[float, float] | None:
        """The finite times around the first non-finite one (either alone when the other does not exist)."""
        before, after = self.gap if self.gap is not None else (None, None)
        if before is None:
            return None if after is None else (after, after)
        return (before, after if after is not None else before)


class _ValueScan:
    """The value columns of a stream, chunk by chunk (spec §2.7, §4.4): infinities (E210), the NaN policy
    (E204, occlusion W405), closed value sets (E214), quaternion norms (E207) and sensor ranges (W401).
    Each check keeps counts, first/last times and extremes only, so the findings are those of the whole
    table whatever the chunking — and memory holds one chunk."""

    def __init__(self, s: Stream, cols: list[str], rng: SensorRange | None) -> None:
        self.stream, self.cols = s, cols
        self.inf = [_Tally() for _ in cols]
        self.nan = [_Tally() for _ in cols]
        spec = kind_table(s.kind)
        self.mocap = s.kind in MOCAP_KINDS
        if "entity_columns" in spec:
            width = len(spec["entity_columns"])
            groups = [(ent, list(range(k * width, (k + 1) * width))) for k, ent in enumerate(s.entities or [])]
        else:
            groups = [(s.kind, list(range(len(cols))))]
        self.groups = [
            (name, idx, _Tally(), _Tally()) for name, idx in groups if idx and idx[-1] < len(cols)
        ]  # partial, occluded
        self.sets: list[tuple[int, _Tally, list[np.ndarray]]] = [
            (k, _Tally(), []) for k, c in enumerate(cols) if values_outside_set(s.kind, c, np.empty(0)) is not None
        ]
        index = {c: k for k, c in enumerate(cols)}
        self.quats: list[tuple[list[str], list[int], _Tally, list[float | None]]] = [
            (list(g), [index[c] for c in g], _Tally(), [None])
            for g in quaternion_groups(s.kind, s.entities)
            if all(c in index for c in g)
        ]
        limits = [(k, _range_limit(c, rng)) for k, c in enumerate(cols)] if rng is not None else []
        self.ranges = [(k, limit, _Tally(), [0.0]) for k, limit in limits if limit is not None]

    def feed(self, t: np.ndarray, values: np.ndarray) -> None:
        if not np.isfinite(values).all():  # the column-by-column account only when something is not finite
            nan, inf = np.isnan(values), np.isinf(values)
            for col in np.flatnonzero(inf.any(axis=0)):
                self.inf[col].add(t, inf[:, col])
            for col in np.flatnonzero(nan.any(axis=0)):
                self.nan[col].add(t, nan[:, col])
            for _, idx, partial, occluded in self.groups:
                g = nan[:, idx]
                some, every = g.any(axis=1), g.all(axis=1)
                partial.add(t, some & ~every)
                occluded.add(t, every)
        for k, tally, seen in self.sets:
            outside = values_outside_set(self.stream.kind, self.cols[k], values[:, k])
            assert outside is not None  # self.sets holds the columns with a closed value set only
            other, _ = outside
            if other.any():
                tally.add(t, other)
                seen[:] = [np.union1d(seen[0], values[other, k]) if seen else np.unique(values[other, k])]
        for _, idx, tally, worst in self.quats:
            q = values[:, idx]
            norm = np.sqrt(np.einsum("ij,ij->i", q, q))
            off = np.isfinite(q).all(axis=1) & (np.abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE)
            if off.any():
                tally.add(t, off)
                local = float(norm[off][np.argmax(np.abs(norm[off] - 1.0))])
                if worst[0] is None or abs(local - 1.0) > abs(worst[0] - 1.0):  # ties keep the first, as argmax
                    worst[0] = local
        for k, limit, tally, peak in self.ranges:
            with np.errstate(invalid="ignore"):
                over = np.isfinite(values[:, k]) & (np.abs(values[:, k]) > limit)
            if over.any():
                tally.add(t, over)
                peak[0] = max(peak[0], float(np.max(np.abs(values[over, k]))))

    def findings(self, rows: int, add: Callable[[Finding], None]) -> None:
        """Add the value findings in the order of spec §4.4: E210, E204/W405, E214, E207, W401."""
        s, cols, label = self.stream, self.cols, self.stream.file
        for k, tally in enumerate(self.inf):
            if tally.count:
                add(
                    Finding(
                        "E210",
                        f"column {cols[k]!r} holds {tally.count} infinite values",
                        file=label,
                        column=cols[k],
                        time_range=tally.span,
                        expected="finite values",
                        found="inf",
                    )
                )
        if self.mocap:  # mocap NaN policy (spec §2.7): whole entities NaN together; warn above the occlusion share
            for name, idx, partial, occluded in self.groups:
                if partial.count:
                    add(
                        Finding(
                            "E204",
                            f"{name}: {partial.count} samples have some but not all of {[cols[i] for i in idx]} NaN",
                            file=label,
                            column=cols[idx[0]],
                            time_range=partial.span,
                            expected="all columns of an occluded entity NaN together",
                            found="partial NaN",
                        )
                    )
                share = occluded.count / rows
                if share > OCCLUSION_WARNING_SHARE:
                    add(
                        Finding(
                            "W405",
                            f"{name} is occluded in {share:.0%} of the samples",
                            file=label,
                            column=cols[idx[0]],
                            time_range=occluded.span,
                            expected=f"at most {OCCLUSION_WARNING_SHARE:.0%}",
                            found=round(share, 4),
                        )
                    )
        else:
            for k, tally in enumerate(self.nan):
                if tally.count:
                    add(
                        Finding(
                            "E204",
                            f"column {cols[k]!r} holds {tally.count} NaN values; {s.kind} allows none",
                            file=label,
                            column=cols[k],
                            time_range=tally.span,
                            expected="no NaN",
                            found="NaN",
                        )
                    )
        for k, tally, seen in self.sets:
            if tally.count:
                col = cols[k]
                outside = values_outside_set(s.kind, col, np.empty(0))
                assert outside is not None  # self.sets holds the columns with a closed value set only
                add(
                    Finding(
                        "E214",
                        f"column {col!r} holds {tally.count} values other than {outside[1]} "
                        f"({seen[0].size} distinct, e.g. {float(seen[0][0])!r})",
                        file=label,
                        column=col,
                        time_range=tally.span,
                        expected=list(ALLOWED_VALUES[(s.kind, col)]),
                        found=[float(v) for v in seen[0][:5]],
                    )
                )
        for group, _, tally, worst in self.quats:
            if tally.count:
                add(
                    Finding(
                        "E207",
                        f"{tally.count} quaternions ({', '.join(group)}) are not unit; worst norm {worst[0]:.6g}",
                        file=label,
                        column=group[0],
                        time_range=tally.span,
                        expected=f"norm 1 ± {QUATERNION_NORM_TOLERANCE}",
                        found=worst[0],
                    )
                )
        for k, limit, tally, peak in self.ranges:
            if tally.count:
                add(
                    Finding(
                        "W401",
                        f"column {cols[k]!r} exceeds the declared ±{limit:g} range at {tally.count} samples (peak {peak[0]:.6g})",
                        file=label,
                        column=cols[k],
                        time_range=tally.span,
                        expected=f"|value| ≤ {limit:g}",
                        found=peak[0],
                    )
                )


def _range_limit(column: str, rng: SensorRange) -> float | None:
    """The symmetric range (stream units) of a wrench/accel column, from the rig's SensorRange (spec §2.4)."""
    base = column.split("_")[-1]
    axis = "xyz".find(base[-1:]) if len(base) == 2 else -1
    if axis < 0:
        return None
    table = {"f": rng.force_N, "t": rng.torque_Nm, "a": rng.accel_m_per_s2}.get(base[0])
    return None if table is None else float(table[axis])


class SessionValidator:
    """Validate one session folder in two phases: :meth:`check_manifest`, then :meth:`check_streams`.

    The split lets a caller show progress over the streams (their number is known after the first
    phase); :func:`validate_session` runs both. ``chunk_rows`` forces the rows per chunk in which stream
    files are read (:meth:`chunk_rows_for`); the findings do not depend on it.
    """

    def __init__(self, path: str | os.PathLike[str], chunk_rows: int | None = None) -> None:
        self.root = Path(path)
        self.chunk_rows = chunk_rows
        self.report = ValidationReport(session=str(path))
        self.raw: Any = None
        self.manifest: Session | None = None  # the parsed session.json, when it validates whole
        self.rig: Rig | None = None
        self.trials: list[tuple[int, dict[str, Any], Trial | None]] = []
        self.entries: list[StreamEntry] = []
        self.offsets: dict[str, float] = {}
        self._manifest_ok = False

    # -- bookkeeping --------------------------------------------------------------------------
    def add(self, finding: Finding, trial: str | None = None) -> None:
        """Record one finding, attributed to ``trial`` (None: the session as a whole)."""
        self.report.items.append(ReportItem(finding, trial))

    def add_all(self, findings: Iterable[Finding], trial: str | None = None) -> None:
        for f in findings:
            self.add(f, trial)

    @property
    def stream_count(self) -> int:
        return len(self.entries)

    def _guard(self, step: Callable[[], None], trial: str | None = None, file: str | None = None) -> None:
        """Run one check; coded errors become findings, anything unexpected becomes E999 (never a traceback)."""
        self.add_all(_collect(step, file), trial)

    # -- phase 1: the manifest ------------------------------------------------------------------
    def check_manifest(self) -> None:
        """Folder, session.json, schema, device, ids, references, trials (spec §4.3.1–4.3.3)."""
        if not self.root.is_dir():
            self.add(
                Finding(
                    "E101",
                    f"{str(self.root)!r} is not a session folder",
                    file=str(self.root),
                    expected="a folder holding session.json",
                    found="missing" if not self.root.exists() else "not a folder",
                )
            )
            return
        self._guard(self._load_manifest, file=MANIFEST)
        if self.raw is None:
            return
        self._guard(self._check_schema, file=MANIFEST)
        if not self._manifest_ok:
            return
        self._guard(self._check_device, file=MANIFEST)
        self._guard(self._check_ids, file=MANIFEST)
        self._guard(self._check_static_quaternions, file=MANIFEST)
        self._guard(self._check_date, file=MANIFEST)
        self._guard(self._check_nulls, file=MANIFEST)
        self._guard(self._check_rig, file=MANIFEST)
        self._guard(self._check_inline_device, file=MANIFEST)
        for index, raw_trial, trial in self.trials:
            if trial is not None:
                self._guard(lambda: self._check_trial(index, trial), trial=trial.id, file=MANIFEST)

    def _load_manifest(self) -> None:
        path = resolve_inside(self.root, MANIFEST)
        _regular_file(path, MANIFEST, "E102", f"no {MANIFEST} in {str(self.root)!r}", MANIFEST_MAX_BYTES)
        raw = parse_json_file(path, "E103", MANIFEST)
        if isinstance(raw, dict) and "spec_version" in raw and raw["spec_version"] != SPEC_VERSION:
            raise HaptifyError(
                Finding(
                    "E105",
                    f"spec version {raw['spec_version']!r} is not supported",
                    file=MANIFEST,
                    pointer="/spec_version",
                    expected=SPEC_VERSION,
                    found=_short(raw["spec_version"]),
                )
            )
        self.raw = raw

    def _check_schema(self) -> None:
        findings = schema_findings(self.raw, "session", "E104", MANIFEST)
        raw = self.raw
        for f in findings:
            self.add(f, _trial_of_pointer(raw, f.pointer))
        if not isinstance(raw, dict):
            return
        self._manifest_ok = True
        if not findings:
            try:
                manifest = Session.model_validate(raw)
            except ValidationError as exc:  # the model is stricter than its schema somewhere
                self.add_all(pydantic_findings(exc, "E104", MANIFEST))
                manifest = None
            if manifest is not None:
                self.manifest = manifest
                self.rig = manifest.rig
                self.trials = [(i, raw["trials"][i], t) for i, t in enumerate(manifest.trials)]
                self.offsets = self._offsets(manifest.calibration)
                self._collect_streams()
                return
        # Partial manifest: validate what can be validated piece by piece, so that every stream whose
        # own description is sound is still checked (spec §4.1: report everything).
        self.rig = _try(Rig, raw.get("rig"))
        trials = raw.get("trials")
        self.trials = []
        if isinstance(trials, list):
            for i, t in enumerate(trials):
                self.trials.append((i, t, _try(Trial, t)))
        calib = raw.get("calibration")
        records = []
        if isinstance(calib, list):
            for rec in calib:
                if isinstance(rec, dict) and rec.get("kind") == "clock_offset":
                    parsed = _try(ClockOffset, rec)
                    if parsed is not None:
                        records.append(parsed)
        self.offsets = self._offsets(records)
        self._collect_streams()

    @staticmethod
    def _offsets(records: Iterable[Any]) -> dict[str, float]:
        out: dict[str, float] = {}
        for rec in records:
            if getattr(rec, "kind", None) == "clock_offset":
                out[rec.stream_file] = out.get(rec.stream_file, 0.0) + rec.offset_s
        return out

    def _collect_streams(self) -> None:
        for index, raw_trial, trial in self.trials:
            trial_id = trial.id if trial is not None else _str_or_none(raw_trial, "id")
            raw_streams = (
                trial.streams if trial is not None else (raw_trial.get("streams") if isinstance(raw_trial, dict) else None)
            )
            if not isinstance(raw_streams, list):
                continue
            for j, s in enumerate(raw_streams):
                stream = s if isinstance(s, Stream) else _try(Stream, s)
                if stream is not None:
                    self.entries.append(StreamEntry(trial_id, f"/trials/{index}/streams/{j}", stream))

    def _check_device(self) -> None:
        dev = self.raw.get("device")
        if not (isinstance(dev, dict) and set(dev) == {"file"} and isinstance(dev["file"], str)):
            return
        label = dev["file"]
        try:
            path = resolve_inside(self.root, label)
            _regular_file(path, label, "E106", f"device file {label!r} does not exist", DEVICE_MAX_BYTES)
            data = parse_json_file(path, "E106", label)
        except HaptifyError as err:
            for f in err.findings:
                if f.file == label and f.pointer is None and f.code in ("E108", "E109"):
                    f.pointer = "/device/file"
            self.add_all(err.findings)
            return
        findings = schema_findings(data, "device", "E106", label)
        self.add_all(findings)
        self._check_static_quaternions(data, label)
        self._check_nulls(data, label)
        device = _try(Device, data) if not findings else None
        if device is not None and device.kinematics is not None:
            self.add_all(kinematics_findings(device.kinematics, label, "/kinematics"))

    def _check_inline_device(self) -> None:
        """The kinematic chain of a device given inline in session.json (spec §2.3)."""
        dev = self.raw.get("device")
        device = _try(Device, dev) if isinstance(dev, dict) and "file" not in dev else None
        if device is not None and device.kinematics is not None:
            self.add_all(kinematics_findings(device.kinematics, MANIFEST, "/device/kinematics"))

    def _check_nulls(self, document: Any = None, label: str = MANIFEST) -> None:
        """W407 at every ``null`` the schema tolerated: writers omit members without a value (spec §2.1)."""
        judged = {f.pointer for f in self.report.findings if f.file == label and f.code in ("E104", "E106", "E113", "E301")}
        for pointer, _, value in _json_members(self.raw if document is None else document):
            if value is None and pointer not in judged:
                self.add(
                    Finding(
                        "W407",
                        "a member is written as null; omit it instead",
                        file=label,
                        pointer=pointer,
                        expected="the member omitted",
                        found=None,
                    ),
                    _trial_of_pointer(self.raw, pointer) if document is None else None,
                )

    def _check_date(self) -> None:
        """``date`` is a calendar date, not only ``YYYY-MM-DD``-shaped (spec §2.1)."""
        date = self.raw.get("date")
        if not isinstance(date, str) or len(date) != 10:
            return  # absent or not of the pattern: the schema has said so (E104)
        try:
            datetime.date.fromisoformat(date)
        except ValueError:
            self.add(
                Finding(
                    "E104",
                    f"date {date!r} is not a calendar date",
                    file=MANIFEST,
                    pointer="/date",
                    expected="an existing date YYYY-MM-DD",
                    found=date,
                )
            )

    def _check_rig(self) -> None:
        """The rig's corner sensors have distinct ids c1…c4 (spec §2.4, E107)."""
        plate = self.rig.force_plate if self.rig is not None else None
        if plate is None:
            return
        ids = [c.id for c in plate.corners]
        for k, cid in enumerate(ids):
            if cid in ids[:k]:
                missing = sorted({"c1", "c2", "c3", "c4"} - set(ids))
                self.add(
                    Finding(
                        "E107",
                        f"force-plate corner sensor id {cid!r} is used twice (missing: {', '.join(missing)})",
                        file=MANIFEST,
                        pointer=f"/rig/force_plate/corners/{k}/id",
                        expected="the four distinct ids c1, c2, c3, c4",
                        found=ids,
                    )
                )

    def _check_ids(self) -> None:
        raw = self.raw
        seen: dict[str, str] = {}
        for index, raw_trial, trial in self.trials:
            tid = trial.id if trial is not None else _str_or_none(raw_trial, "id")
            if tid is None:
                continue
            if tid in seen:
                self.add(
                    Finding(
                        "E107",
                        f"trial id {tid!r} is used twice",
                        file=MANIFEST,
                        pointer=f"/trials/{index}/id",
                        expected="a unique trial id",
                        found=tid,
                    ),
                    tid,
                )
            seen.setdefault(tid, f"/trials/{index}")
        calib = raw.get("calibration") if isinstance(raw.get("calibration"), list) else []
        cids: set[str] = set()
        for i, rec in enumerate(calib):
            cid = _str_or_none(rec, "id")
            if cid is not None and cid in cids:
                self.add(
                    Finding(
                        "E107",
                        f"calibration id {cid!r} is used twice",
                        file=MANIFEST,
                        pointer=f"/calibration/{i}/id",
                        expected="a unique calibration id",
                        found=cid,
                    )
                )
            if cid is not None:
                cids.add(cid)
        files: dict[str, str] = {}
        for e in self.entries:
            key = PurePosixPath(e.stream.file).as_posix()
            if key in files:
                self.add(
                    Finding(
                        "E107",
                        f"stream file {e.stream.file!r} is named twice (also at {files[key]})",
                        file=MANIFEST,
                        pointer=f"{e.pointer}/file",
                        expected="one stream per file",
                        found=e.stream.file,
                    ),
                    e.trial,
                )
            files.setdefault(key, e.pointer)
        stream_files = set(files)
        for i, rec in enumerate(calib):
            if not isinstance(rec, dict):
                continue
            src = rec.get("source_trial")
            if isinstance(src, str) and src not in seen:
                self.add(
                    Finding(
                        "E114",
                        f"calibration {rec.get('id')!r} names trial {src!r}, which the session does not hold",
                        file=MANIFEST,
                        pointer=f"/calibration/{i}/source_trial",
                        expected=sorted(seen),
                        found=src,
                    )
                )
            sf = rec.get("stream_file")
            if rec.get("kind") == "clock_offset" and isinstance(sf, str) and sf not in stream_files:
                self.add(
                    Finding(
                        "E114",
                        f"clock offset {rec.get('id')!r} names stream file {sf!r}, which no stream uses",
                        file=MANIFEST,
                        pointer=f"/calibration/{i}/stream_file",
                        expected="a stream file of this session",
                        found=sf,
                    )
                )

    def _check_static_quaternions(self, document: Any = None, label: str = MANIFEST) -> None:
        """Unit norm of the quaternions inside session.json (or device.json) itself (spec §1.3, §4.3.3)."""
        for pointer, q in _quaternions_in(self.raw if document is None else document, ""):
            if not (
                isinstance(q, list) and len(q) == 4 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in q)
            ):
                continue
            try:
                norm = math.hypot(*(float(v) for v in q))  # hypot: no overflow for components near 1e308
            except OverflowError:  # an integer beyond the float range
                norm = math.inf
            if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
                self.add(
                    Finding(
                        "E207",
                        f"quaternion has norm {norm:.6g}",
                        file=label,
                        pointer=pointer,
                        expected=f"norm 1 ± {QUATERNION_NORM_TOLERANCE}",
                        found=q,
                    )
                )

    def _check_trial(self, index: int, trial: Trial) -> None:
        """Protocol requirements, rendering, label, powered flag, one stream per kind (spec §4.3.3)."""
        where = f"/trials/{index}"
        proto = schemas.load("protocols.json")["protocols"][trial.protocol]
        kinds = [s.kind for s in trial.streams]
        for j, kind in enumerate(kinds):
            if kind in kinds[:j]:
                self.add(
                    Finding(
                        "E306",
                        f"trial {trial.id!r} has two {kind} streams",
                        file=MANIFEST,
                        pointer=f"{where}/streams/{j}/kind",
                        expected=f"one {kind} stream",
                        found=kinds.count(kind),
                    ),
                    trial.id,
                )
        for kind in proto["required"]:
            if kind not in kinds:
                self.add(
                    Finding(
                        "E302",
                        f"{trial.protocol} trial {trial.id!r} has no {kind} stream",
                        file=MANIFEST,
                        pointer=f"{where}/streams",
                        expected=proto["required"],
                        found=kinds,
                    ),
                    trial.id,
                )
        for kind in proto["recommended"]:
            if kind not in kinds:
                self.add(
                    Finding(
                        "W404",
                        f"{trial.protocol} trial {trial.id!r} has no {kind} stream",
                        file=MANIFEST,
                        pointer=f"{where}/streams",
                        expected=proto["recommended"],
                        found=kinds,
                    ),
                    trial.id,
                )
        passive = proto["passive"]
        if passive is False and trial.rendering is None:
            self.add(
                Finding(
                    "E303",
                    f"active {trial.protocol} trial {trial.id!r} has no rendering parameters",
                    file=MANIFEST,
                    pointer=f"{where}/rendering",
                    expected="a rendering object",
                    found=None,
                ),
                trial.id,
            )
        if trial.rendering is not None:
            n = trial.rendering.surface_normal
            try:
                norm = math.hypot(*n)  # hypot: no overflow for components near 1e308
            except OverflowError:
                norm = math.inf
            if not abs(norm - 1.0) <= NORMAL_NORM_TOLERANCE:
                self.add(
                    Finding(
                        "E307",
                        f"trial {trial.id!r}: the rendering's surface_normal has norm {norm:.6g}",
                        file=MANIFEST,
                        pointer=f"{where}/rendering/surface_normal",
                        expected=f"norm 1 ± {NORMAL_NORM_TOLERANCE}",
                        found=list(n),
                    ),
                    trial.id,
                )
        if trial.protocol == "other" and not (trial.label or "").strip():
            self.add(
                Finding(
                    "E304",
                    f"trial {trial.id!r} of protocol 'other' has no label",
                    file=MANIFEST,
                    pointer=f"{where}/label",
                    expected="a label such as 'figure_eight'",
                    found=trial.label,
                ),
                trial.id,
            )
        if passive is not None and trial.powered == passive:
            self.add(
                Finding(
                    "W403",
                    f"{'passive' if passive else 'active'} protocol {trial.protocol!r} recorded with powered={str(trial.powered).lower()}",
                    file=MANIFEST,
                    pointer=f"{where}/powered",
                    expected=not passive,
                    found=trial.powered,
                ),
                trial.id,
            )

    # -- phase 2: the streams --------------------------------------------------------------------
    def check_streams(self, advance: Callable[[int], Any] | None = None) -> None:
        """Check every stream's file and data, then the time overlap per trial (spec §4.3.5–4.3.6)."""
        for entry in self.entries:
            self.check_stream(entry)
            if advance is not None:
                advance(1)
        self.check_overlap()

    def check_declaration(self, entry: StreamEntry) -> None:
        """Check what session.json declares of one stream and that its file is there, inside the folder and
        within its size bound — nothing of the file is read but a Parquet footer (spec §4.2, §4.3.5)."""
        if entry.declared:
            return
        entry.declared = True
        found: list[Finding] = []
        raised = _collect(lambda: self._check_declaration(entry, found.append), entry.stream.file)
        self.add_all(found + raised, entry.trial)

    def check_stream(self, entry: StreamEntry, *, keep: bool = False) -> pd.DataFrame | None:
        """Check one stream's declaration, file and data (spec §4.3.5); the findings go into the report.

        With ``keep`` the file is read whole and its table as read (stream clock) is returned, or None when
        the file could not be read; without, it is read in chunks, in bounded memory, and None is returned."""
        self.check_declaration(entry)
        kept: list[pd.DataFrame] = []
        path = entry.path
        if path is not None:
            found: list[Finding] = []
            raised = _collect(
                lambda: self._check_contents(entry, path, found.append, kept.append if keep else None), entry.stream.file
            )
            self.add_all(found + raised, entry.trial)
        self.report.streams_checked += 1
        return kept[0] if kept else None

    def check_overlap(self) -> None:
        """The last check, once every stream has been checked: time overlap per trial (spec §4.3.6)."""
        self._guard(self._check_overlap, file=MANIFEST)

    def _check_declaration(self, entry: StreamEntry, add: Callable[[Finding], None]) -> None:
        s, label = entry.stream, entry.stream.file
        spec = kind_table(s.kind)
        # declared metadata: columns, units, entities, frame, rate
        declared = [c.name for c in s.columns]
        if "entity_columns" in spec:
            entities = s.entities or []
            if not entities:
                add(
                    Finding(
                        "E201",
                        f"{s.kind} stream names no entities",
                        file=MANIFEST,
                        pointer=f"{entry.pointer}/entities",
                        expected="the marker or link names, in column order",
                        found=s.entities,
                    )
                )
            dups = sorted({e for e in entities if entities.count(e) > 1})
            if dups:
                add(
                    Finding(
                        "E107",
                        f"{s.kind} stream lists entities {dups} more than once",
                        file=MANIFEST,
                        pointer=f"{entry.pointer}/entities",
                        expected="distinct entities",
                        found=dups,
                    )
                )
            known = self._known_entities(s.kind)
            if known is not None:
                for k, ent in enumerate(entities):
                    if ent not in known:
                        add(
                            Finding(
                                "E213",
                                f"{s.kind} stream names {ent!r}, which the rig does not describe",
                                file=MANIFEST,
                                pointer=f"{entry.pointer}/entities/{k}",
                                expected=sorted(known),
                                found=ent,
                            )
                        )
        elif s.entities is not None:
            add(
                Finding(
                    "E215",
                    f"{s.kind} stream declares entities, which only markers and link_poses have",
                    file=MANIFEST,
                    pointer=f"{entry.pointer}/entities",
                    expected="no 'entities' member",
                    found=s.entities,
                )
            )
        expected = expected_columns(s.kind, s.entities, declared)
        entry.names_ok = [n for n, _ in expected] == declared and len(set(declared)) == len(declared)
        if [n for n, _ in expected] != declared:
            add(
                Finding(
                    "E201",
                    f"{s.kind} stream declares columns that differ from its kind's",
                    file=MANIFEST,
                    pointer=f"{entry.pointer}/columns",
                    expected=[n for n, _ in expected],
                    found=declared,
                )
            )
        else:
            for k, ((name, unit), col) in enumerate(zip(expected, s.columns)):
                if col.unit != unit:
                    add(
                        Finding(
                            "E202",
                            f"column {name!r} is declared in {col.unit!r}",
                            file=MANIFEST,
                            pointer=f"{entry.pointer}/columns/{k}/unit",
                            column=name,
                            expected=unit,
                            found=col.unit,
                        )
                    )
        if s.frame not in spec["frames"]:
            add(
                Finding(
                    "E209",
                    f"{s.kind} stream is declared in frame {s.frame!r}",
                    file=MANIFEST,
                    pointer=f"{entry.pointer}/frame",
                    expected=spec["frames"],
                    found=s.frame,
                )
            )
        if s.rate_hz < spec["recommended_rate_hz"]:
            add(
                Finding(
                    "W406",
                    f"{s.kind} stream at {s.rate_hz:g} Hz is below the recommended {spec['recommended_rate_hz']} Hz",
                    file=MANIFEST,
                    pointer=f"{entry.pointer}/rate_hz",
                    expected=spec["recommended_rate_hz"],
                    found=s.rate_hz,
                )
            )
        # the file: path safety, existence, size
        path = resolve_inside(self.root, s.file)
        missing = f"stream file {label!r} does not exist"
        if s.format == "parquet":  # the footer says how many row groups the file may spend metadata on
            _regular_file(path, label, "E110", missing, stream_size_limit(len(declared), s.rows, max(1, s.rows)))
            groups = _parquet_row_groups(path, label, s.rows)
            _regular_file(path, label, "E110", missing, stream_size_limit(len(declared), s.rows, groups))
        else:
            _regular_file(path, label, "E110", missing, stream_size_limit(len(declared), s.rows))
        entry.path = path

    def _check_contents(
        self, entry: StreamEntry, path: Path, add: Callable[[Finding], None], keep: Callable[[pd.DataFrame], Any] | None
    ) -> None:
        """Checksum, readability, columns, rows and data of a stream file whose declaration was checked.

        The file is read chunk by chunk (:func:`~haptify.storage.read_stream_chunks`, :meth:`chunk_rows_for`)
        and every check of spec §4.4 carries its state across chunk borders, so memory holds one chunk and
        the findings are those of the whole table. With ``keep`` (the gate, which computes from the table)
        the table is read whole — the one-chunk case — and handed to ``keep``.
        """
        s, label = entry.stream, entry.stream.file
        declared = [c.name for c in s.columns]
        try:
            digest, chunks = read_stream_chunks(
                path, s.format, declared, label=label, chunk_rows=None if keep is not None else self.chunk_rows_for(len(declared))
            )
        except HaptifyError:
            self._check_digest(s, sha256_file(path), add)
            raise
        self._check_digest(s, digest, add)
        first = next(chunks)
        if keep is not None:
            keep(first)
        names = first.columns.tolist()
        columns = [str(c) for c in names]
        same = names == declared
        times = _TimeScan(s.rate_hz)
        values = self._value_scan(s, columns[1:]) if same and entry.names_ok else None  # else the columns' meaning is unknown
        chunks = itertools.chain([first], chunks)
        del first  # hold no chunk but the current one
        for chunk in chunks:  # every chunk is read: a damaged later part is E112
            if values is None:
                times.rows += len(chunk)
                continue
            block = chunk.to_numpy(dtype=np.float64, copy=False)  # one block: no per-column frame; t first (names_ok)
            times.feed(block[:, 0])
            values.feed(block[:, 0], block[:, 1:])
        if not same:
            add(
                Finding(
                    "E201",
                    "the file's columns differ from the columns declared in session.json",
                    file=label,
                    expected=declared,
                    found=columns,
                )
            )
            return
        n = times.rows
        if n != s.rows:
            add(
                Finding("E208", f"{label!r} holds {n} rows, session.json declares {s.rows}", file=label, expected=s.rows, found=n)
            )
        if n < 2:
            add(
                Finding(
                    "E205",
                    f"{s.kind} stream holds {n} sample{'s' if n != 1 else ''}",
                    file=label,
                    expected="at least 2 samples",
                    found=n,
                )
            )
            return
        if values is None:
            return  # the columns' meaning is unknown (E201/E107 above): data checks would mislead
        if times.findings(label, add):
            offset = self.offsets.get(s.file, 0.0)
            entry.span = (times.first + offset, times.last + offset)
        values.findings(n, add)

    def chunk_rows_for(self, columns: int) -> int:
        """Rows per chunk when a stream of ``columns`` columns is validated: :attr:`chunk_rows` when set (the
        tests force tiny chunks), else as many float64 rows as fit in :data:`STREAM_CHUNK_BYTES`."""
        return self.chunk_rows or max(2, STREAM_CHUNK_BYTES // (8 * max(1, columns)))

    @staticmethod
    def _check_digest(s: Stream, digest: str, add: Callable[[Finding], None]) -> None:
        """The file's sha256 matches the manifest's (E111, spec §3.4)."""
        if digest != s.sha256:
            add(
                Finding(
                    "E111", f"checksum of {s.file!r} does not match session.json", file=s.file, expected=s.sha256, found=digest
                )
            )

    def _known_entities(self, kind: str) -> set[str] | None:
        mocap = self.rig.motion_capture if self.rig is not None else None
        if mocap is None:
            return set()
        if kind == "markers":
            return set(mocap.markers) | {m for rb in mocap.rigid_bodies for m in rb.markers}
        if kind == "link_poses":
            return {rb.name for rb in mocap.rigid_bodies}
        return None

    def _value_scan(self, s: Stream, cols: list[str]) -> _ValueScan:
        """The value checks of one stream (spec §4.4), with the rig's sensor range of its kind."""
        rng_spec = kind_table(s.kind).get("range")
        return _ValueScan(s, cols, self._rig_range(rng_spec["rig_field"]) if rng_spec else None)

    def _rig_range(self, dotted: str) -> SensorRange | None:
        node: Any = self.rig
        for part in dotted.split("."):
            node = getattr(node, part, None) if node is not None else None
        return node if isinstance(node, SensorRange) else None

    def _check_overlap(self) -> None:
        """The streams of one trial share a time interval of positive length (spec §4.3.5)."""
        by_trial: dict[str | None, list[tuple[StreamEntry, tuple[float, float]]]] = {}
        for e in self.entries:
            if e.span is not None:
                by_trial.setdefault(e.trial, []).append((e, e.span))
        for trial, entries in by_trial.items():
            if len(entries) < 2:
                continue
            late, late_span = max(entries, key=lambda es: es[1][0])
            early, early_span = min(entries, key=lambda es: es[1][1])
            if late_span[0] >= early_span[1]:
                self.add(
                    Finding(
                        "E305",
                        f"{early.stream.kind} ends at t={early_span[1]:.6g} s before {late.stream.kind} starts at "
                        f"t={late_span[0]:.6g} s (session clock)",
                        file=late.stream.file,
                        column="t",
                        time_range=(early_span[1], late_span[0]),
                        expected="overlapping time spans",
                        found={early.stream.kind: list(early_span), late.stream.kind: list(late_span)},
                    ),
                    trial,
                )

    def finish(self) -> ValidationReport:
        """The report of everything checked so far (spec §4.6)."""
        return self.report


def _collect(step: Callable[[], None], file: str | None) -> list[Finding]:
    """Run ``step``; the findings of a coded error it raises, E112 when the input exhausts memory or
    nesting, E999 for anything else (a validator bug, reported rather than raised)."""
    try:
        step()
    except HaptifyError as err:
        return list(err.findings)
    except (MemoryError, RecursionError) as exc:
        return [
            Finding("E112", f"{file or 'the input'} is too large or too deeply nested to check: {type(exc).__name__}", file=file)
        ]
    except Exception as exc:  # a bug in the validator: report it, coded, and go on
        return [Finding("E999", f"{type(exc).__name__}: {exc}", file=file)]
    return []


def _json_members(node: Any, pointer: str = "") -> Iterable[tuple[str, Any, Any]]:
    """Every ``(pointer, key, value)`` inside a JSON tree, depth first (object keys and array indices)."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        p = f"{pointer}/{str(k).replace('~', '~0').replace('/', '~1')}"
        yield p, k, v
        yield from _json_members(v, p)


def _quaternions_in(node: Any, pointer: str) -> Iterable[tuple[str, Any]]:
    """Every ``quaternion`` member inside a JSON tree, with its pointer."""
    return ((p, v) for p, k, v in _json_members(node, pointer) if k == "quaternion")


def _trial_of_pointer(raw: Any, pointer: str | None) -> str | None:
    """The id of the trial a manifest pointer (``/trials/<i>/…``) lies in, when it has a string id."""
    parts = (pointer or "").split("/")
    if (
        len(parts) > 2
        and parts[1] == "trials"
        and parts[2].isdigit()
        and isinstance(raw, dict)
        and isinstance(raw.get("trials"), list)
    ):
        i = int(parts[2])
        if i < len(raw["trials"]):
            return _str_or_none(raw["trials"][i], "id")
    return None


def _try(model: type[BaseModel], value: Any) -> Any:
    try:
        return model.model_validate(value)
    except ValidationError:
        return None


def _str_or_none(node: Any, key: str) -> str | None:
    value = node.get(key) if isinstance(node, dict) else None
    return value if isinstance(value, str) else None


def validate_session(
    path: str | os.PathLike[str], advance: Callable[[int], Any] | None = None, chunk_rows: int | None = None
) -> ValidationReport:
    """Validate a session folder and return every finding (spec chapter 4); never raises for bad input.

    ``advance(n)`` is called after each stream (for a progress bar). Stream files are read in chunks
    (``chunk_rows`` rows each when given), so memory does not grow with a stream's length. The report's
    ``exit_code`` is 0 when valid (warnings allowed), 1 when invalid, 2 when validation could not run.
    """
    v = SessionValidator(path, chunk_rows)
    try:
        v.check_manifest()
        v.check_streams(advance)
    except Exception as exc:  # the last guard: a validator bug is a coded finding, never a traceback
        v.add(Finding("E999", f"{type(exc).__name__}: {exc}"))
    return v.finish()
