"""The viewer recording's data model (spec chapter 2 streams as rerun entities): the constants (timeline,
roles, derived-signal modes, display scales and colours, the time series ``SERIES``), the :class:`Entry` /
:class:`TrialPlan` / :class:`Plan` records, the :class:`RrdWriter` that sends entries in chunks, exact
nanosecond times on the session clock (spec §1.4) and the ``compact`` form of derived entries."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rerun as rr

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.session_format import Trial

APP_ID = "haptify"
TIMELINE = "time"
ROLES = ("measured", "compare")
DERIVED_MODES = ("off", "compact", "full")  # how derived signals are recorded (haptify_tools.viewer.recording docstring)
DEFAULT_DERIVED = "off"
CHUNK_ROWS = 100_000  # rows per send_columns call: bounds the SDK's per-call buffers on long streams
COMPACT_RATE_HZ = 100.0  # compact derived signals: at most this rate (the default signal grid of spec §7.3)

# Display constants (visual only; no metric depends on them).
HAND_FORCE_M_PER_N = 0.02  # arrow length per newton of hand force
PLATE_FORCE_M_PER_N = 0.005  # arrow length per newton of plate force
HANDLE_AXIS_M = 0.03  # length of the handle's frame axes
LINK_AXIS_M = 0.02  # length of each link frame's axes
PLATE_THICKNESS_M = 0.02  # drawn thickness when the rig gives no corner-sensor depth
SURFACE_MARGIN_M = 0.02  # margin of the virtual-surface rectangle around the trajectory
SURFACE_MIN_HALF_M = 0.05  # smallest half side of the virtual-surface rectangle

# Per-axis line colours (x, y, z, then more) of the measured and the compared session.
SERIES_COLORS = {
    "measured": [(214, 39, 40), (44, 160, 44), (31, 119, 180), (148, 103, 189), (140, 86, 75), (227, 119, 194)],
    "compare": [(255, 152, 150), (152, 223, 138), (174, 199, 232), (197, 176, 213), (196, 156, 148), (247, 182, 210)],
}
ROLE_COLORS = {"measured": (31, 119, 180), "compare": (255, 127, 14)}
MODELED_COLOR = (44, 160, 44)
MESH_ALPHA = 70  # translucency of the workspace meshes (0–255)
FORCE_COLORS = {"measured": (214, 39, 40), "compare": (255, 152, 150)}
PLATE_FORCE_COLOR = (148, 103, 189)
LINK_PALETTE = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
]

# Time series the viewer can show: relative path under /series/<trial>/<role> → (title, unit).
SERIES = {
    "handle/position": ("handle position in W", "m"),
    "handle/force_raw": ("handle F/T force, raw, sensor frame", "N"),
    "handle/torque_raw": ("handle F/T torque, raw, sensor frame", "N*m"),
    "hand_force/raw_world": ("raw F/T force rotated to W (bias and weight not removed)", "N"),
    "hand_force/calibrated": ("force the device applies to the hand, W (calibrated)", "N"),
    "hand_torque/calibrated": ("torque on the hand about the gimbal centre, W (calibrated)", "N*m"),
    "accel/raw": ("accelerometer specific force, raw, sensor frame", "m/s^2"),
    "accel/world": ("handle acceleration, W, bias and gravity removed", "m/s^2"),
    "accel/dft321": ("DFT321 of the high-passed raw acceleration (spec §10.3)", "m/s^2"),
    "contact/normal_force": ("force along the surface normal: commanded vs felt (spec §12.2)", "N"),
    "contact/penetration": ("penetration on the signal grid, (p0 − p)·n (spec §13.2)", "m"),
    "contact/state": ("contact (commanded rule) and guarded samples used by the metrics", "1"),
    "plate/force": ("force the load exerts on the plate, W", "N"),
    "plate/cop": ("centre of pressure on the plate, W", "m"),
    "plate/corner_force_raw": ("plate corner forces, raw, corner-sensor frames", "N"),
    "plate/corner_torque_raw": ("plate corner torques, raw, corner-sensor frames", "N*m"),
    "commanded/force": ("commanded force in W", "N"),
    "commanded/torque": ("commanded torque in W", "N*m"),
    "penetration": ("handle depth below the virtual surface (+ inside)", "m"),
    "device/joint_angles": ("joint angles reported by the device", "rad"),
    "sync/trigger": ("synchronisation trigger", "1"),
}


@dataclass
class Entry:
    """One entity of the recording: static archetypes and/or time-indexed fields of one archetype.

    ``archetype.columns(**fields)`` builds the component columns, one row per entry of ``times_ns``
    (so any row range can be sent on its own). Once written, only the metadata stays (``rows``).
    """

    path: str
    static: list[Any] = field(default_factory=list)
    times_ns: np.ndarray | None = None  # int64 ns on the session clock
    archetype: Any = None  # rr.Scalars, rr.Transform3D, rr.Points3D or rr.Arrows3D
    fields: dict[str, np.ndarray] = field(default_factory=dict)  # that archetype's fields, first axis = rows
    series: str | None = None  # for time series: the relative series key (a key of SERIES)
    stream: str | None = None  # the stream kind whose samples are the rows, or the derivation ("handle_signals", "vibration")
    derived: bool = False  # computed by the reference's processing from the raw streams (recorded per ``derived`` mode)
    written_rows: int | None = None  # set when the entry was written and its data dropped

    @property
    def rows(self) -> int:
        if self.written_rows is not None:
            return self.written_rows
        return 0 if self.times_ns is None else int(len(self.times_ns))

    def columns(self, start: int = 0, stop: int | None = None) -> Any:
        """The component columns of rows ``start:stop``; positions of shape (rows, points, 3) make rows of
        several points each."""
        fields = {k: v[start:stop] for k, v in self.fields.items()}
        points = fields.get("positions")
        if points is not None and points.ndim == 3:
            fields["positions"] = points.reshape(-1, 3)
            return self.archetype.columns(**fields).partition(np.full(len(points), points.shape[1]))
        return self.archetype.columns(**fields)


@dataclass
class TrialPlan:
    """The trial shown, its protocol and the roles (measured/compare) that have data for it."""

    trial: Trial
    key: str
    counterpart: dict[str, str] = field(default_factory=dict)  # role → trial id in that role's session


@dataclass
class Plan:
    """What the recording holds: the entries (only their metadata once written), trials, notes.

    With a ``writer`` (:func:`build`), :meth:`add` writes each entry at once; without one
    (:func:`plan_recording`), entries are kept whole until :func:`write_rrd`.
    """

    recording_id: str
    entries: list[Entry] = field(default_factory=list)
    trials: list[TrialPlan] = field(default_factory=list)
    has_results: bool = False
    notes: list[str] = field(default_factory=list)  # what could not be shown, and why (coded)
    derived: str = DEFAULT_DERIVED  # a member of DERIVED_MODES
    writer: RrdWriter | None = None
    shift_ns: int = 0  # added to the times of the entries added now (a compared trial's alignment)

    def paths(self) -> set[str]:
        return {e.path for e in self.entries}

    def add(self, entry: Entry) -> None:
        if entry.derived and self.derived == "off":
            return
        if self.shift_ns and entry.times_ns is not None:
            entry.times_ns = entry.times_ns + self.shift_ns
        if entry.derived and self.derived == "compact":
            entry = compact(entry)
        if self.writer is not None:
            self.writer.write(entry)
            entry = Entry(entry.path, series=entry.series, stream=entry.stream, derived=entry.derived, written_rows=entry.rows)
        self.entries.append(entry)


class RrdWriter:
    """Sends entries to a recording stream whose file sink is already set: static archetypes once,
    temporal rows with ``send_columns`` in chunks of at most ``chunk_rows`` rows (strict mode)."""

    def __init__(self, rec: rr.RecordingStream, chunk_rows: int = CHUNK_ROWS) -> None:
        if chunk_rows < 1:
            raise fail(Code.USAGE, f"chunk_rows must be at least 1, not {chunk_rows}", expected=">= 1", found=chunk_rows)
        self.rec = rec
        self.chunk_rows = chunk_rows

    def write(self, e: Entry) -> None:
        bad = {k: len(v) for k, v in e.fields.items() if len(v) != e.rows}
        if bad:  # a programming error, raised before anything of the entry is sent
            raise ValueError(f"{e.path}: {e.rows} timestamps but field lengths {bad}")
        if e.static:
            self.rec.log(e.path, *e.static, static=True, strict=True)
        if e.times_ns is None:  # static only
            return
        for start in range(0, e.rows, self.chunk_rows):
            stop = min(start + self.chunk_rows, e.rows)
            self.rec.send_columns(e.path, [time_column(e.times_ns[start:stop])], e.columns(start, stop), strict=True)


def time_ns(t: np.ndarray) -> np.ndarray:
    """Session-clock seconds → exact integer nanoseconds (int64), ``round(t · 10⁹)`` (spec §1.4)."""
    ns = np.asarray(t, dtype=np.float64) * 1e9
    return np.rint(ns, out=ns).astype(np.int64)


def time_column(ns: np.ndarray) -> rr.TimeColumn:
    """The ``time`` timeline column from integer nanoseconds (no float truncation).
    The session clock of spec §1.4."""
    return rr.TimeColumn(TIMELINE, duration=np.ascontiguousarray(ns, dtype=np.int64).view("timedelta64[ns]"))


def decimation_factor(times_ns: np.ndarray, max_rate_hz: float = COMPACT_RATE_HZ) -> int:
    """The whole number of samples per bin that brings a series' median rate to at most ``max_rate_hz`` (≥ 1)."""
    if len(times_ns) < 2:
        return 1
    dt = float(np.median(np.diff(times_ns)))
    if dt <= 0:
        return 1
    return max(1, math.ceil(1e9 / dt / max_rate_hz - 1e-6))


def envelope(times_ns: np.ndarray, values: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Min/max envelope of ``values (n, c)`` over bins of ``k`` consecutive rows: per bin two rows, each
    column's minimum at the bin's first time and its maximum at the time of its middle row (NaN only when
    the whole bin is NaN). A line through them covers every sample's value range at bin resolution."""
    n = len(times_ns)
    starts = np.arange(0, n, k)
    values = np.asarray(values).reshape(n, -1)
    with np.errstate(invalid="ignore"):
        lo = np.fmin.reduceat(values, starts, axis=0)
        hi = np.fmax.reduceat(values, starts, axis=0)
    ends = np.append(starts[1:], n)
    mid = starts + (ends - starts) // 2
    t = np.column_stack([times_ns[starts], times_ns[mid]]).reshape(-1)
    return t, np.stack([lo, hi], axis=1).reshape(-1, values.shape[1])


def compact(entry: Entry) -> Entry:
    """A derived entry as the ``compact`` mode records it: fields as float32 and at most ``COMPACT_RATE_HZ``
    — a time series as its :func:`envelope`, other archetypes (arrows) point-sampled every k-th row."""
    fields = {name: np.asarray(v, dtype=np.float32) for name, v in entry.fields.items()}
    times = entry.times_ns
    k = 1 if times is None else decimation_factor(times)
    if times is not None and k > 1:
        if entry.archetype is rr.Scalars:
            times, fields["scalars"] = envelope(times, fields["scalars"], k)
        else:
            times = times[::k]
            fields = {name: v[::k] for name, v in fields.items()}
    return Entry(
        entry.path,
        static=entry.static,
        times_ns=times,
        archetype=entry.archetype,
        fields=fields,
        series=entry.series,
        stream=entry.stream,
        derived=True,
    )
