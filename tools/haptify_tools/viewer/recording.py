"""A Haptify session as a rerun recording (.rrd): scene graph, time series, blueprints (spec chapter 2 streams).

:func:`build` streams the recording straight to the .rrd: the file sink is set before
anything is logged, each trial's streams are read one at a time (each read is also the stream's
validation when the session came through the gate, spec §4.8), turned into :class:`Entry` objects —
an entity path, its static archetypes and its time-indexed fields — and each entry is sent with bulk
``send_columns`` in chunks of at most ``CHUNK_ROWS`` rows and dropped; only its metadata (path,
series, stream, rows) stays in the :class:`Plan`. The blueprint is derived from that metadata
(:mod:`haptify_tools.viewer.blueprints`) and sent last. :func:`plan_recording` + :func:`write_rrd`
keep every entry in memory first, for callers that add entries of their own (the discrepancy overlay).

What is derived from the raw streams by the reference's processing (calibrated hand signals, plate
force and COP, DFT321, contact signals, force arrows, workspace meshes, the force field) is recorded
according to ``derived`` (:data:`DERIVED_MODES`): ``off`` (the default: raw streams only, exact),
``compact`` (float32, at most ``COMPACT_RATE_HZ`` — time series above it as a min/max envelope, 3-D
arrows point-sampled) or ``full`` (every derived sample, float64).

Every sample is placed on one timeline, ``time`` (a duration on the session clock, spec §1.4), at
its exact integer-nanosecond timestamp ``round(t · 10⁹)``. Time series hold one row per stream
sample; NaN samples (motion-capture occlusions, spec §2.7) stay as NaN rows. 3-D entities skip
samples whose pose is unknown.

Entity paths (``<trial>`` is the escaped trial id, ``<role>`` is ``measured`` or ``compare``)::

    /world                                    ViewCoordinates RIGHT_HAND_Z_UP (world frame W)
    /world/plate                              the force plate as a box (top surface at z = 0)
    /world/plate/corners                      the four corner sensors
    /world/device                             the device base frame (device_placement)
    /world/<trial>/<role>/handle              handle pose (Transform3D) with axes
    /world/<trial>/<role>/trajectory          the gimbal-centre path
    /world/<trial>/<role>/hand_force/calibrated  hand force (haptify.signals), arrow at the handle
    /world/<trial>/<role>/hand_force/raw      without calibration: raw F/T force rotated to W
    /world/<trial>/<role>/plate_force         plate force (haptify.force_plate), arrow ending at the COP
    /world/<trial>/<role>/markers/<link>      the motion-capture markers of a link, labelled, one colour per link
    /world/<trial>/<role>/links/<link>        link frames from link_poses
    /world/<trial>/<role>/force_field         free space: mean force per bin (haptify.free_space)
    /world/<trial>/<role>/workspace/points    workspace: the measured point cloud
    /world/<trial>/<role>/workspace/measured  workspace: the measured workspace (volume operator) as a mesh
    /world/<trial>/<role>/workspace/modeled   workspace: the modeled workspace (DH model) as a mesh
    /world/<trial>/<role>/virtual_surface     active trials: the rendered plane
    /series/<trial>/<role>/...                time series (see ``SERIES`` below)
    /session, /results                        markdown documents
"""

from __future__ import annotations

import functools
import math
import os
import uuid
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike
import rerun as rr

from haptify.conventions import quat_multiply, quat_rotate
from haptify.errors import HaptifyError, fail
from haptify.session_format import Kinematics, Stream, Trial
from haptify.storage import SessionFolder
from haptify_tools.viewer.voxel_mesh import boundary_mesh

if TYPE_CHECKING:  # imported where used: a raw-only recording needs neither (start-up time)
    from haptify.compute import ComputeContext
    from haptify.results import ResultsFile

APP_ID = "haptify"
TIMELINE = "time"
ROLES = ("measured", "compare")
DERIVED_MODES = ("off", "compact", "full")  # how derived signals are recorded (module docstring)
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
            raise fail("E903", f"chunk_rows must be at least 1, not {chunk_rows}", expected=">= 1", found=chunk_rows)
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


class CachedStreams(SessionFolder):
    """A session whose stream tables are read once per trial (spec §3.2 reading, unchanged).

    Reads go through the wrapped session (so a checked session validates each stream on its first
    read, spec §4.8). The planner and the reference functions it calls (``haptify.signals``,
    ``haptify.force_plate``) read the same streams; each caller gets a shallow copy, so replacing a
    column never leaks. :meth:`forget` drops the tables once a trial is written, so at most one
    trial's tables are in memory.
    """

    def __init__(self, session: SessionFolder) -> None:
        super().__init__(session.root, session.manifest, session.raw)
        self._inner = session
        self._tables: dict[tuple, pd.DataFrame] = {}

    def read_stream(self, stream: Stream, *, verify: bool = False, session_clock: bool = True) -> pd.DataFrame:
        key = (stream.file, verify, session_clock)
        if key not in self._tables:
            self._tables[key] = self._inner.read_stream(stream, verify=verify, session_clock=session_clock)
        return self._tables[key].copy(deep=False)

    def forget(self) -> None:
        self._tables.clear()


# --- small numeric helpers -----------------------------------------------------------------------


def time_ns(t: np.ndarray) -> np.ndarray:
    """Session-clock seconds → exact integer nanoseconds (int64), ``round(t · 10⁹)`` (spec §1.4)."""
    ns = np.asarray(t, dtype=np.float64) * 1e9
    return np.rint(ns, out=ns).astype(np.int64)


def time_column(ns: np.ndarray) -> rr.TimeColumn:
    """The ``time`` timeline column from integer nanoseconds (no float truncation).
    The session clock of spec §1.4."""
    return rr.TimeColumn(TIMELINE, duration=np.ascontiguousarray(ns, dtype=np.int64).view("timedelta64[ns]"))


def xyzw(q_wxyz: ArrayLike) -> np.ndarray:
    """Our quaternions [w, x, y, z] (spec §1.3) → rerun's [x, y, z, w]."""
    q = np.asarray(q_wxyz, dtype=np.float64)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def raw_pose_at(t_pose: np.ndarray, p: np.ndarray, q: np.ndarray, t: np.ndarray) -> Any:
    """The unfiltered pose stream at times ``t`` (s): linear in position, slerp in orientation (spec §7.4).

    Every finite sample counts as one segment, so a time is valid only between two finite samples;
    nothing is bridged or filtered (the viewer's "raw" quantities stay raw). A ``preprocessing.PoseOnGrid``.
    """
    from haptify import preprocessing

    ok = finite_rows(p, q)
    nan3 = np.full((len(t_pose), 3), np.nan)
    track = preprocessing.MocapTrack(
        t=np.asarray(t_pose, dtype=np.float64),
        position=p,
        quaternion=q,
        velocity=nan3,
        angular_velocity=nan3,
        segment=np.where(ok, 0, -1),
    )
    return preprocessing.resample_track(track, t)


def columns_of(frame: pd.DataFrame, names: list[str]) -> np.ndarray:
    """The columns ``names`` of a stream table as one float64 array (rows × names), built column by column
    (selecting a list of columns through pandas builds an index each time and costs more than the copy)."""
    return np.column_stack([frame[name].to_numpy(dtype=np.float64) for name in names]) if names else np.empty((len(frame), 0))


def finite_rows(*arrays: np.ndarray) -> np.ndarray:
    """Boolean mask of rows where every given array is finite."""
    mask = np.ones(len(arrays[0]), dtype=bool)
    for a in arrays:
        mask &= np.all(np.isfinite(np.asarray(a).reshape(len(a), -1)), axis=1)
    return mask


def nan_split(points: np.ndarray) -> list[np.ndarray]:
    """Split a polyline at NaN rows into runs of at least two finite points."""
    ok = finite_rows(points)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return [points[a:b] for a, b in zip(edges[::2], edges[1::2]) if b - a >= 2]


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


def plane_rectangle(point: np.ndarray, normal: np.ndarray, around: np.ndarray | None) -> np.ndarray:
    """Four corners (m, W) of a rectangle in the plane through ``point`` with ``normal``.
    The trial's ``rendering`` plane, spec §2.5.

    Centred on the projection of the finite points ``around`` (else on ``point``), large enough to
    hold their projections plus ``SURFACE_MARGIN_M``, at least ``2·SURFACE_MIN_HALF_M`` a side.
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    point = np.asarray(point, dtype=np.float64)
    centre = point
    hu = hv = SURFACE_MIN_HALF_M
    if around is not None and len(around):
        rel = around - point
        centre = point + rel.mean(axis=0) @ np.outer(u, u) + rel.mean(axis=0) @ np.outer(v, v)
        d = around - centre
        hu = max(hu, float(np.max(np.abs(d @ u))) + SURFACE_MARGIN_M)
        hv = max(hv, float(np.max(np.abs(d @ v))) + SURFACE_MARGIN_M)
    return np.array([centre - hu * u - hv * v, centre + hu * u - hv * v, centre + hu * u + hv * v, centre - hu * u + hv * v])


# --- entries ---------------------------------------------------------------------------------------


def series_entry(
    path: str, key: str, t: np.ndarray, values: np.ndarray, names: list[str], role: str, stream: str, derived: bool = False
) -> Entry:
    """A time series: one row of ``len(names)`` scalars per sample, at the samples' exact times.
    ``t`` in s on the session clock, spec §1.4.

    Legend entries read ``name [unit]`` (unit from ``SERIES``), with ``(compare)`` for the compared session.
    """
    values = np.asarray(values, dtype=np.float64).reshape(len(t), len(names))
    palette = SERIES_COLORS[role]
    suffix = f" [{SERIES[key][1]}]" + ("" if role == "measured" else f" ({role})")
    lines = rr.SeriesLines(names=[f"{n}{suffix}" for n in names], colors=[palette[i % len(palette)] for i in range(len(names))])
    return Entry(
        path,
        static=[lines],
        times_ns=time_ns(t),
        archetype=rr.Scalars,
        fields={"scalars": values},
        series=key,
        stream=stream,
        derived=derived,
    )


class TrialPlanner:
    """Turns one trial of one session (one role) into entries (spec chapter 2 streams)."""

    def __init__(self, session: CachedStreams, ctx: ComputeContext | None, trial: Trial, role: str, key: str, plan: Plan) -> None:
        self.ctx = ctx  # shares calibration, handle and plate signals between the reference functions (None: derived off)
        self.session = session
        self.trial = trial
        self.role = role
        self.plan = plan
        self.world = f"/world/{key}/{role}"
        self.series = f"/series/{key}/{role}"
        self.kinds = {s.kind for s in trial.streams}
        self.rig = self.session.manifest.rig
        self._signals: Any = None  # signals.HandleSignals
        self._signals_tried = False

    def read(self, kind: str) -> pd.DataFrame | None:
        if kind not in self.kinds:
            return None
        return self.session.read(self.trial.id, kind)

    @property
    def derive(self) -> bool:
        """Whether derived signals are computed at all (``derived`` is not ``off``)."""
        return self.plan.derived != "off"

    def add_series(
        self, key: str, t: np.ndarray, values: np.ndarray, names: list[str], stream: str, derived: bool = False
    ) -> None:
        self.plan.add(series_entry(f"{self.series}/{key}", key, t, values, names, self.role, stream, derived))

    def run(self) -> None:
        pose = self.read("handle_pose")
        p = q = t_pose = None
        if pose is not None:
            t_pose = pose["t"].to_numpy()
            p = columns_of(pose, ["px", "py", "pz"])
            q = columns_of(pose, ["qw", "qx", "qy", "qz"])
            self.handle(t_pose, p, q)
        self.wrench(t_pose, p, q)
        self.accel()
        self.plate()
        self.commanded()
        self.device_and_sync()
        self.markers()
        self.links()
        if p is not None and self.trial.protocol == "workspace":
            self.workspace(p[finite_rows(p)])
        self.session.forget()
        if self.trial.rendering is not None:
            self.surface(t_pose, p)

    def workspace(self, points: np.ndarray) -> None:
        """The measured cloud, and the measured and modeled workspaces as meshes (spec §8.2–8.4)."""
        self.plan.add(
            Entry(f"{self.world}/workspace/points", static=[rr.Points3D(points, radii=0.0015, colors=ROLE_COLORS[self.role])])
        )
        if not self.derive:
            return
        from haptify import workspace

        try:
            solid = workspace.volume_solid(points)
        except HaptifyError as err:
            self.note("measured workspace mesh", err)
        else:
            self.add_solid("measured workspace mesh", f"{self.world}/workspace/measured", solid, ROLE_COLORS[self.role])
        kin = self.session.device().kinematics
        if kin is None:
            self.note("modeled workspace mesh", fail("E311", "the device has no kinematics", pointer="/device/kinematics"))
            return
        place = self.session.manifest.device_placement
        try:
            model = modeled_solid(kin.model_dump_json(), tuple(place.position), tuple(place.quaternion))
        except HaptifyError as err:
            self.note("modeled workspace mesh", err)
        else:
            self.add_solid("modeled workspace mesh", f"{self.world}/workspace/modeled", model, MODELED_COLOR)

    def handle(self, t: np.ndarray, p: np.ndarray, q: np.ndarray) -> None:
        """Handle pose with axes, the gimbal-centre path and the position time series."""
        ok = finite_rows(p, q)
        self.plan.add(
            Entry(
                f"{self.world}/handle",
                static=[rr.TransformAxes3D(HANDLE_AXIS_M)],
                times_ns=time_ns(t[ok]),
                archetype=rr.Transform3D,
                fields={"translation": p[ok], "quaternion": xyzw(q[ok])},
                stream="handle_pose",
            )
        )
        strips = nan_split(p)
        if strips:
            self.plan.add(
                Entry(f"{self.world}/trajectory", static=[rr.LineStrips3D(strips, radii=0.0008, colors=ROLE_COLORS[self.role])])
            )
        self.add_series("handle/position", t, p, ["px", "py", "pz"], "handle_pose")

    def note(self, what: str, err: HaptifyError) -> None:
        """Record why a derived quantity is missing (shown in the /session document)."""
        f = err.findings[0]
        self.plan.notes.append(f"{self.trial.id} ({self.role}): {what} not shown — {f.code} {f.message}")

    def add_solid(self, what: str, path: str, solid: Any, color: tuple[int, int, int]) -> None:
        """A voxel solid as a mesh, or a W410 note when nothing is inside (the sweep did not close)."""
        entry = solid_entry(path, solid, color, compact=self.plan.derived == "compact")
        if entry is None:
            self.plan.notes.append(f"{self.trial.id} ({self.role}): {what} not shown — W410 the points enclose no volume")
        else:
            self.plan.add(entry)

    def handle_signals(self) -> Any:
        """The calibrated handle signals (spec §7.5, ``signals.HandleSignals``), once per trial; None (with a
        note) when unavailable, and None without computing anything when derived signals are off."""
        if not self._signals_tried and self.derive:
            from haptify import signals

            self._signals_tried = True
            if "handle_pose" in self.kinds and self.kinds & {"handle_wrench", "handle_accel"}:
                try:
                    self._signals = signals.handle_signals(self.ctx, self.trial.id)
                except HaptifyError as err:
                    self.note("calibrated handle force and acceleration", err)
        return self._signals

    def force_arrows(self, path: str, t: np.ndarray, origins: np.ndarray, force: np.ndarray, stream: str) -> None:
        ok = finite_rows(origins, force)
        self.plan.add(
            Entry(
                path,
                times_ns=time_ns(t[ok]),
                static=[rr.Arrows3D.from_fields(colors=FORCE_COLORS[self.role], radii=0.001)],
                archetype=rr.Arrows3D,
                fields={"origins": origins[ok], "vectors": force[ok] * HAND_FORCE_M_PER_N},
                stream=stream,
                derived=True,
            )
        )

    def wrench(self, t_pose: np.ndarray | None, p: np.ndarray | None, q: np.ndarray | None) -> None:
        """Raw F/T series (sensor frame), and the hand force in W as series, arrow and free-space field.

        The hand force is the calibrated wrench when the session's calibration allows it (spec §7.5);
        otherwise the raw F/T force rotated to W with the unfiltered pose (bias and weight still in).
        """
        w = self.read("handle_wrench")
        if w is None:
            return
        t = w["t"].to_numpy()
        f = columns_of(w, ["fx", "fy", "fz"])
        self.add_series("handle/force_raw", t, f, ["fx", "fy", "fz"], "handle_wrench")
        self.add_series("handle/torque_raw", t, columns_of(w, ["tx", "ty", "tz"]), ["tx", "ty", "tz"], "handle_wrench")
        hs = self.handle_signals()
        if hs is not None and hs.force is not None:
            self.add_series("hand_force/calibrated", hs.t, hs.force, ["fx", "fy", "fz"], "handle_signals", derived=True)
            self.add_series("hand_torque/calibrated", hs.t, hs.torque, ["tx", "ty", "tz"], "handle_signals", derived=True)
            shown = (hs.t, hs.position, hs.force, "handle_signals", "calibrated")
        elif self.derive and t_pose is not None and p is not None and q is not None and self.rig.handle is not None:
            pose = raw_pose_at(t_pose, p, q, t)
            q_sensor = np.asarray(self.rig.handle.ft_sensor.pose.quaternion, dtype=np.float64)
            with np.errstate(invalid="ignore"):
                f_w = quat_rotate(quat_multiply(pose.quaternion, q_sensor), f)
            self.add_series("hand_force/raw_world", t, f_w, ["fx", "fy", "fz"], "handle_wrench", derived=True)
            shown = (t, pose.position, f_w, "handle_wrench", "raw")
        else:
            shown = None
        if shown is None:
            return
        t_a, origins, force, stream, label = shown
        self.force_arrows(f"{self.world}/hand_force/{label}", t_a, origins, force, stream)
        ok = finite_rows(origins, force)
        if self.trial.protocol == "free_space" and ok.any():
            from haptify import free_space

            field_ = free_space.force_field(origins[ok], force[ok])  # the spec's binning (§9.5)
            if len(field_.centres):
                self.plan.add(
                    Entry(
                        f"{self.world}/force_field",
                        static=[
                            rr.Arrows3D(
                                origins=field_.centres,
                                vectors=field_.mean_force * HAND_FORCE_M_PER_N,
                                colors=FORCE_COLORS[self.role],
                                radii=0.0006,
                            )
                        ],
                        derived=True,
                    )
                )

    def accel(self) -> None:
        a = self.read("handle_accel")
        if a is not None:
            self.add_series("accel/raw", a["t"].to_numpy(), columns_of(a, ["ax", "ay", "az"]), ["ax", "ay", "az"], "handle_accel")
            hs = self.handle_signals()
            if hs is not None and hs.acceleration is not None:
                self.add_series("accel/world", hs.t, hs.acceleration, ["ax", "ay", "az"], "handle_signals", derived=True)
            if not self.derive:
                return
            from haptify import vibration

            try:
                vib = vibration.trial_vibration(self.ctx, self.trial.id)
            except HaptifyError as err:
                self.note("DFT321 vibration signal", err)
            else:
                self.add_series("accel/dft321", vib.t, vib.signal, ["dft321"], "vibration", derived=True)

    def plate(self) -> None:
        w = self.read("plate_wrench")
        if w is None:
            return
        t = w["t"].to_numpy()
        names_f = [f"c{i}_f{a}" for i in range(1, 5) for a in "xyz"]
        names_t = [f"c{i}_t{a}" for i in range(1, 5) for a in "xyz"]
        self.add_series("plate/corner_force_raw", t, columns_of(w, names_f), names_f, "plate_wrench")
        self.add_series("plate/corner_torque_raw", t, columns_of(w, names_t), names_t, "plate_wrench")
        if not self.derive:
            return
        from haptify import force_plate

        try:
            ps = force_plate.plate_signals(self.ctx, self.trial.id)
        except HaptifyError as err:
            self.note("plate total force and COP", err)
            return
        self.add_series("plate/force", ps.t, ps.force, ["Fx", "Fy", "Fz"], "plate_signals", derived=True)
        self.add_series("plate/cop", ps.t, ps.cop, ["x", "y"], "plate_signals", derived=True)
        # The force on the plate drawn as an arrow whose head is at the COP (on the top surface, z = 0).
        ok = ps.cop_valid & finite_rows(ps.force)
        head = np.column_stack([ps.cop[ok], np.zeros(int(ok.sum()))])
        vec = ps.force[ok] * PLATE_FORCE_M_PER_N
        self.plan.add(
            Entry(
                f"{self.world}/plate_force",
                times_ns=time_ns(ps.t[ok]),
                static=[rr.Arrows3D.from_fields(colors=PLATE_FORCE_COLOR, radii=0.002)],
                archetype=rr.Arrows3D,
                fields={"origins": head - vec, "vectors": vec},
                stream="plate_signals",
                derived=True,
            )
        )

    def commanded(self) -> None:
        c = self.read("commanded_wrench")
        if c is None:
            return
        t = c["t"].to_numpy()
        self.add_series("commanded/force", t, columns_of(c, ["fx", "fy", "fz"]), ["fx", "fy", "fz"], "commanded_wrench")
        self.add_series("commanded/torque", t, columns_of(c, ["tx", "ty", "tz"]), ["tx", "ty", "tz"], "commanded_wrench")

    def device_and_sync(self) -> None:
        """The device's own joint angles (diagnostic, spec §2.6) and the sync trigger, as they are."""
        q = self.read("device_joint_angles")
        if q is not None:
            names = [c for c in q.columns if c != "t"]
            self.add_series("device/joint_angles", q["t"].to_numpy(), columns_of(q, names), names, "device_joint_angles")
        s = self.read("sync")
        if s is not None:
            self.add_series("sync/trigger", s["t"].to_numpy(), columns_of(s, ["trigger"]), ["trigger"], "sync")

    def read_entities(self, kind: str) -> tuple[list[str], pd.DataFrame, np.ndarray] | None:
        """Entity names, table and time column of a per-entity stream (markers, link_poses), or None."""
        stream = self.session.stream(self.trial.id, kind)
        if stream is None:
            return None
        frame = self.session.read_stream(stream)
        return list(stream.entities or []), frame, frame["t"].to_numpy()

    def markers(self) -> None:
        """The markers of each rigid body (link) as one labelled point cloud, a colour per link: one row per
        frame where any of them is known, an occluded marker's position NaN (not drawn) in that row."""
        found = self.read_entities("markers")
        if found is None:
            return
        entities, frame, t = found
        owner: dict[str, str] = {}  # marker → its rigid body
        if self.rig.motion_capture is not None:
            for body in self.rig.motion_capture.rigid_bodies:
                for m in body.markers:
                    owner.setdefault(m, body.name)
        groups: dict[str, list[str]] = {}
        for m in entities:
            groups.setdefault(owner.get(m, "unassigned"), []).append(m)
        for i, (link, names) in enumerate(groups.items()):
            xyz = columns_of(frame, [f"{m}_{a}" for m in names for a in "xyz"]).reshape(len(t), len(names), 3)
            ok = np.isfinite(xyz).all(axis=2).any(axis=1)
            self.plan.add(
                Entry(
                    f"{self.world}/markers/{rr.escape_entity_path_part(link)}",
                    static=[rr.Points3D.from_fields(colors=LINK_PALETTE[i % len(LINK_PALETTE)], radii=0.002, labels=names)],
                    times_ns=time_ns(t[ok]),
                    archetype=rr.Points3D,
                    fields={"positions": xyz[ok]},
                    stream="markers",
                )
            )

    def links(self) -> None:
        """Each link's frame from link_poses, with axes."""
        found = self.read_entities("link_poses")
        if found is None:
            return
        entities, frame, t = found
        for link in entities:
            p = columns_of(frame, [f"{link}_p{a}" for a in "xyz"])
            q = columns_of(frame, [f"{link}_q{a}" for a in "wxyz"])
            ok = finite_rows(p, q)
            self.plan.add(
                Entry(
                    f"{self.world}/links/{rr.escape_entity_path_part(link)}",
                    static=[rr.TransformAxes3D(LINK_AXIS_M)],
                    times_ns=time_ns(t[ok]),
                    archetype=rr.Transform3D,
                    fields={"translation": p[ok], "quaternion": xyzw(q[ok])},
                    stream="link_poses",
                )
            )

    def surface(self, t_pose: np.ndarray | None, p: np.ndarray | None) -> None:
        """The rendered plane as a translucent rectangle, and the handle's penetration series."""
        r = self.trial.rendering
        if r is None:  # a trial without a rendered plane has none to draw
            return
        point = np.asarray(r.surface_point_m, dtype=np.float64)
        normal = np.asarray(r.surface_normal, dtype=np.float64)
        norm = float(np.linalg.norm(normal))
        if not (np.isfinite(norm) and norm > 0.0):
            from haptify.surface import unit_normal

            unit_normal(normal, self.trial.id)  # the reference's coded error (E303)
        normal = normal / norm
        around = p[finite_rows(p)] if p is not None else None
        corners = plane_rectangle(point, normal, around)
        self.plan.add(
            Entry(
                f"{self.world}/virtual_surface",
                static=[
                    rr.Mesh3D(
                        vertex_positions=corners,
                        triangle_indices=[[0, 1, 2], [0, 2, 3]],
                        vertex_normals=np.tile(normal, (4, 1)),
                        albedo_factor=(*ROLE_COLORS[self.role], 90),
                    )
                ],
            )
        )
        if t_pose is not None and p is not None:
            depth = (point - p) @ normal
            self.add_series("penetration", t_pose, depth, ["depth"], "handle_pose")
        if self.derive and {"commanded_wrench", "handle_wrench", "handle_pose"} <= self.kinds:
            from haptify import surface

            try:
                cs = surface.contact_signals(self.ctx, self.trial.id)
            except HaptifyError as err:
                self.note("contact signals (normal force, contact)", err)
                return
            self.add_series(
                "contact/normal_force",
                cs.t,
                np.column_stack([cs.commanded_normal, cs.normal_force]),
                ["commanded Fn", "felt Fn"],
                "handle_signals",
                derived=True,
            )
            self.add_series("contact/penetration", cs.t, cs.penetration, ["depth"], "handle_signals", derived=True)
            self.add_series(
                "contact/state",
                cs.t,
                np.column_stack([cs.contact, cs.used]).astype(np.float64),
                ["contact", "used"],
                "handle_signals",
                derived=True,
            )


@functools.lru_cache(maxsize=4)
def modeled_solid(kinematics_json: str, position: tuple, quaternion: tuple) -> Any:
    """``haptify.workspace.modeled_solid`` (spec §8.3, a ``VoxelSolid``), computed once per device model and placement."""
    from haptify import workspace

    kin = Kinematics.model_validate_json(kinematics_json)
    return workspace.modeled_solid(kin, position, quaternion)


def solid_entry(path: str, solid: Any, color: tuple[int, int, int], compact: bool = False) -> Entry | None:
    """A voxel solid's boundary (voxels with fraction ≥ 0.5) as a translucent static mesh; None when empty.
    The fractions of spec §8.4 step 5. ``compact``: each lattice corner once, no normals (``SurfaceMesh.shared``)."""
    mesh = boundary_mesh(solid.fraction >= 0.5, solid.origin, solid.pitch)
    if not len(mesh.triangles):
        return None
    if compact:
        vertices, triangles = mesh.shared(solid.pitch)
        drawn = rr.Mesh3D(vertex_positions=vertices, triangle_indices=triangles, albedo_factor=(*color, MESH_ALPHA))
    else:
        drawn = rr.Mesh3D(
            vertex_positions=mesh.vertices,
            triangle_indices=mesh.triangles,
            vertex_normals=mesh.normals,
            albedo_factor=(*color, MESH_ALPHA),
        )
    return Entry(path, static=[drawn], derived=True)


# --- session level ---------------------------------------------------------------------------------


def rig_entries(session: SessionFolder) -> list[Entry]:
    """World frame, force plate, corner sensors and device base (static).
    From the rig description, spec §1.2, §2.4."""
    m = session.manifest
    out = [Entry("/world", static=[rr.ViewCoordinates.RIGHT_HAND_Z_UP])]
    plate = m.rig.force_plate
    if plate is not None:
        zs = [c.pose.position[2] for c in plate.corners]
        depth = -min(zs) if min(zs) < 0 else PLATE_THICKNESS_M
        sx, sy = plate.size_m
        out.append(
            Entry(
                "/world/plate",
                static=[
                    rr.Boxes3D(
                        centers=[[0.0, 0.0, -depth / 2]],
                        half_sizes=[[sx / 2, sy / 2, depth / 2]],
                        colors=[(160, 160, 160)],
                        fill_mode="solid",
                    )
                ],
            )
        )
        out.append(
            Entry(
                "/world/plate/corners",
                static=[
                    rr.Points3D(
                        [c.pose.position for c in plate.corners],
                        labels=[c.id for c in plate.corners],
                        radii=0.006,
                        colors=(90, 90, 90),
                    )
                ],
            )
        )
    placement = m.device_placement
    out.append(
        Entry(
            "/world/device",
            static=[
                rr.Transform3D(translation=placement.position, quaternion=rr.Quaternion(xyzw=xyzw(placement.quaternion))),
                rr.TransformAxes3D(0.05),
            ],
        )
    )
    return out


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _num(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, list):
        return "[" + ", ".join(_num(x) for x in v) + "]"
    return f"{v:.4g}"


def results_markdown(results: ResultsFile, session_id: str) -> str:
    """The metrics of a results file as markdown tables (spec §15.2)."""
    lines = [
        f"# Results — session `{results.session_id}`",
        f"{results.implementation.name} {results.implementation.version}, spec {results.spec_version}",
        "",
    ]
    if results.session_id != session_id:
        lines += [f"**Warning:** these results are for session `{results.session_id}`, not `{session_id}`.", ""]
    lines += ["| metric | value | unit | n | sd | trials | warnings |", "|---|---:|---|---:|---:|---|---|"]
    for m in results.metrics:
        lines.append(
            f"| {_cell(m.id)} | {_num(m.value)} | {_cell(m.unit)} | {m.n} | {_num(m.sd)} | "
            f"{_cell(', '.join(m.trials))} | {_cell(', '.join(m.warnings))} |"
        )
    if results.unavailable:
        lines += ["", "## Unavailable", "", "| metric | code | reason |", "|---|---|---|"]
        lines += [f"| {_cell(u.id)} | {u.code} | {_cell(u.reason)} |" for u in results.unavailable]
    if results.warnings:
        lines += ["", "## Warnings", "", "| code | metric | trial | message |", "|---|---|---|---|"]
        lines += [
            f"| {w.code} | {_cell(w.metric or '')} | {_cell(w.trial or '')} | {_cell(w.message)} |" for w in results.warnings
        ]
    return "\n".join(lines) + "\n"


def session_markdown(
    session: SessionFolder,
    trials: list[TrialPlan],
    other: SessionFolder | None,
    notes: Collection[str] = (),
    derived: str = "full",
) -> str:
    """A summary of the session (and the compared one) and how to read the 3-D view."""
    m = session.manifest
    dev = session.device()
    lines = [
        f"# Session `{m.session_id}`",
        "",
        f"{dev.manufacturer} {dev.model} · {m.date} · lab `{m.lab.id}` · examiner `{m.examiner.id}`",
        "",
    ]
    if other is not None:
        od = other.device()
        lines += [
            f"Compared with session `{other.session_id}` ({od.manufacturer} {od.model}), drawn in lighter colours "
            "under the `compare` entities.",
            "",
        ]
    lines += ["| trial | protocol | powered | streams | compared with |", "|---|---|---|---|---|"]
    for tp in trials:
        t = tp.trial
        kinds = ", ".join(f"{s.kind} ({s.rows} @ {s.rate_hz:g} Hz)" for s in t.streams)
        lines.append(
            f"| {_cell(t.id)} | {t.protocol} | {'yes' if t.powered else 'no'} | {_cell(kinds)} | "
            f"{_cell(tp.counterpart.get('compare', '—' if other is not None else ''))} |"
        )
    lines += ["", "World frame W: origin at the centre of the plate's top surface, z up, right-handed (spec §1.2)."]
    if derived == "off":
        lines.append(
            "Derived signals (calibrated hand force, plate force and COP, DFT321, contact signals, force arrows, "
            "workspace meshes) are not recorded: `haptify view --derived compact` or `--derived full` adds them."
        )
    else:
        from haptify.metric_definitions import param

        lines += [
            f"Arrows: hand force {HAND_FORCE_M_PER_N * 100:g} cm per N; plate force {PLATE_FORCE_M_PER_N * 100:g} cm per N.",
            f"Free-space force field: mean hand force per {param('free_space', 'force_field_bin_m') * 100:g} cm bin "
            f"holding at least {param('free_space', 'force_field_min_samples')} samples (spec §9.5).",
            "The plate arrow is the force the load exerts on the plate, drawn with its head at the COP.",
        ]
        if derived == "compact":
            lines.append(
                f"Derived signals are compact: float32, at most {COMPACT_RATE_HZ:g} Hz (faster time series as a "
                "min/max envelope, faster arrows point-sampled); `--derived full` records every sample."
            )
    if notes:
        lines += ["", "## Not shown", ""] + [f"- {_cell(n)}" for n in notes]
    return "\n".join(lines) + "\n"


def trial_start_ns(session: SessionFolder, trial: Trial) -> int:
    """The first sample time of a trial over all its streams, integer ns on the session clock (spec §1.4)."""
    return min(int(time_ns(session.read_stream(s)["t"].to_numpy()[:1])[0]) for s in trial.streams if s.rows)


def counterpart(other: SessionFolder, trial: Trial) -> Trial | None:
    """The trial of ``other`` matching ``trial``: same id, else same protocol and repetition."""
    for t in other.trials:
        if t.id == trial.id:
            return t
    return next((t for t in other.trials if t.protocol == trial.protocol and t.repetition == trial.repetition), None)


def plan_recording(
    session: SessionFolder,
    *,
    trial_id: str | None = None,
    results: ResultsFile | None = None,
    other: SessionFolder | None = None,
    trial_ids: Collection[str] | None = None,
    derived: str = DEFAULT_DERIVED,
    writer: RrdWriter | None = None,
) -> Plan:
    """Every entity of the recording of ``session`` (one trial, the trials ``trial_ids`` in session order, or
    all), optionally compared with ``other``; written entry by entry through ``writer`` when given, else
    kept whole in the plan (for :func:`write_rrd`).

    A compared trial is shifted in time by a whole number of nanoseconds so that it starts with the
    measured trial (their first samples coincide); the shift is listed in the session document.
    """
    if derived not in DERIVED_MODES:
        raise fail("E903", f"unknown derived-signal mode {derived!r}", expected=list(DERIVED_MODES), found=derived)

    def context(folder: SessionFolder) -> tuple[CachedStreams, ComputeContext | None]:
        cached = CachedStreams(folder)
        if derived == "off":
            return cached, None
        from haptify.compute import ComputeContext

        return cached, ComputeContext(session=cached)

    streams, ctx = context(session)
    other_streams, other_ctx = context(other) if other is not None else (None, None)
    trials = [session.trial(trial_id)] if trial_id else [t for t in session.trials if trial_ids is None or t.id in trial_ids]
    plan = Plan(
        recording_id=recording_id(session, trial_id, other), has_results=results is not None, derived=derived, writer=writer
    )
    for entry in rig_entries(session):
        plan.add(entry)
    for trial in trials:
        key = rr.escape_entity_path_part(trial.id)
        tp = TrialPlan(trial, key, {"measured": trial.id})
        match = counterpart(other, trial) if other is not None else None
        shift = 0
        if match is not None and other_streams is not None:  # read before the measured trial's tables are dropped
            shift = trial_start_ns(streams, trial) - trial_start_ns(other_streams, match)
        TrialPlanner(streams, ctx, trial, "measured", key, plan).run()
        if ctx is not None:
            ctx.forget_trial(trial.id)  # each trial is visited once: its derived signals can go
        if match is not None and other_streams is not None:  # (a match is looked for only with the other session)
            tp.counterpart["compare"] = match.id
            plan.shift_ns = shift
            TrialPlanner(other_streams, other_ctx, match, "compare", key, plan).run()
            plan.shift_ns = 0
            if other_ctx is not None:
                other_ctx.forget_trial(match.id)
            if shift:
                plan.notes.append(f"{match.id} (compare) shifted by {shift / 1e9:+.9g} s to start with {trial.id} (measured)")
        plan.trials.append(tp)
    plan.add(
        Entry(
            "/session",
            static=[
                rr.TextDocument(
                    session_markdown(session, plan.trials, other, plan.notes, derived), media_type=rr.MediaType.MARKDOWN
                )
            ],
        )
    )
    if results is not None:
        plan.add(
            Entry(
                "/results",
                static=[rr.TextDocument(results_markdown(results, session.session_id), media_type=rr.MediaType.MARKDOWN)],
            )
        )
    return plan


def open_rrd(recording_id: str, tmp: Path) -> rr.RecordingStream:
    """A recording stream whose file sink (``tmp``) is set before anything is logged."""
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id, send_properties=False)
    rec.save(tmp)
    rec.send_recording_name(recording_id)
    return rec


def atomic_rrd(path: str | os.PathLike, recording_id: str, fill: Callable[[rr.RecordingStream], Any]) -> Path:
    """Write an .rrd atomically (temp file + rename, spec §3.6): ``fill(rec)`` logs into a stream whose
    file sink is the temp file, in strict mode; the file is closed (footer written) and renamed only when
    ``fill`` returned."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex[:12]}.tmp"  # created by rerun, with the usual permissions
    previous = rr.strict_mode()
    rr.set_strict_mode(True)
    try:
        rec = open_rrd(recording_id, tmp)
        fill(rec)
        rec.disconnect()
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    finally:
        rr.set_strict_mode(previous)
    return path


def write_rrd(plan: Plan, path: str | os.PathLike, blueprint: Any, *, chunk_rows: int = CHUNK_ROWS) -> Path:
    """Write a plan kept in memory (:func:`plan_recording` without a writer) to an .rrd file atomically,
    with its blueprint."""

    def fill(rec: rr.RecordingStream) -> None:
        writer = RrdWriter(rec, chunk_rows)
        for e in plan.entries:
            writer.write(e)
        if blueprint is not None:
            rec.send_blueprint(blueprint, make_active=True, make_default=True)

    return atomic_rrd(path, plan.recording_id, fill)


def recording_id(session: SessionFolder, trial_id: str | None, other: SessionFolder | None) -> str:
    return session.session_id + (f"/{trial_id}" if trial_id else "") + (f"+{other.session_id}" if other else "")
