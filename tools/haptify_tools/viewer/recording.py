"""A Haptify session as a rerun recording (.rrd): scene graph, time series, blueprints (spec chapter 2 streams).

:func:`build` streams the recording straight to the .rrd: the file sink is set before
anything is logged, each trial's streams are read one at a time (each read is also the stream's
validation when the session came through the gate, spec §4.8), turned into
:class:`~haptify_tools.viewer.plan.Entry` objects (:mod:`haptify_tools.viewer.trial_planner`) —
an entity path, its static archetypes and its time-indexed fields — and each entry is sent with bulk
``send_columns`` in chunks of at most ``CHUNK_ROWS`` rows and dropped; only its metadata (path,
series, stream, rows) stays in the :class:`~haptify_tools.viewer.plan.Plan`. The blueprint is derived
from that metadata (:mod:`haptify_tools.viewer.blueprints`) and sent last. :func:`plan_recording` +
:func:`write_rrd` keep every entry in memory first, for callers that add entries of their own (the
discrepancy overlay). The ``/session`` and ``/results`` documents come from
:mod:`haptify_tools.viewer.documents`.

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
    /world/<trial>/<role>/hand_force/calibrated  hand force (haptify.processing.signals), arrow at the handle
    /world/<trial>/<role>/hand_force/raw      without calibration: raw F/T force rotated to W
    /world/<trial>/<role>/plate_force         plate force (haptify.processing.force_plate), arrow ending at the COP
    /world/<trial>/<role>/markers/<link>      the motion-capture markers of a link, labelled, one colour per link
    /world/<trial>/<role>/links/<link>        link frames from link_poses
    /world/<trial>/<role>/force_field         free space: mean force per bin (haptify.metrics.free_space)
    /world/<trial>/<role>/workspace/points    workspace: the measured point cloud
    /world/<trial>/<role>/workspace/measured  workspace: the measured workspace (volume operator) as a mesh
    /world/<trial>/<role>/workspace/modeled   workspace: the modeled workspace (DH model) as a mesh
    /world/<trial>/<role>/virtual_surface     active trials: the rendered plane
    /series/<trial>/<role>/...                time series (see ``SERIES`` in :mod:`haptify_tools.viewer.plan`)
    /session, /results                        markdown documents
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Collection
from pathlib import Path
from typing import TYPE_CHECKING, Any

import rerun as rr

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.session_format import Trial
from haptify.formats.storage import SessionFolder
from haptify_tools.viewer.arrays import xyzw
from haptify_tools.viewer.documents import results_markdown, session_markdown
from haptify_tools.viewer.plan import (
    APP_ID,
    CHUNK_ROWS,
    DEFAULT_DERIVED,
    DERIVED_MODES,
    PLATE_THICKNESS_M,
    Entry,
    Plan,
    RrdWriter,
    TrialPlan,
    time_ns,
)
from haptify_tools.viewer.trial_planner import CachedStreams, TrialPlanner

if TYPE_CHECKING:  # imported where used: a raw-only recording needs neither (start-up time)
    from haptify.pipeline.compute import ComputeContext
    from haptify.pipeline.results import ResultsFile


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
        raise fail(Code.USAGE, f"unknown derived-signal mode {derived!r}", expected=list(DERIVED_MODES), found=derived)

    def context(folder: SessionFolder) -> tuple[CachedStreams, ComputeContext | None]:
        cached = CachedStreams(folder)
        if derived == "off":
            return cached, None
        from haptify.pipeline.compute import ComputeContext

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
