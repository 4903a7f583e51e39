"""A motion-capture recording (C3D, Qualisys TSV, Motive or Nexus CSV) as one trial (spec §5.5, §5.10):
markers, 6-DoF bodies and analog channels, in W (§5.6)."""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import numpy as np

from haptify.codes import Code
from haptify.errors import Finding, fail
from haptify.formats.conventions import matrix_to_quat
from haptify.formats.importers.destination import Destination, ImportResult, add_trial
from haptify.formats.importers.import_map import ImportMap, LoadedMap, MarkerMap, sanitize_id
from haptify.formats.importers.recording import Recording, recording_chunks
from haptify.formats.importers.streams import SourceReader, check_trial_streams, mapped_streams
from haptify.formats.importers.units import Unit, unit_conversion
from haptify.formats.importers.world_frame import WorldFrame, plate_description, platform_plate_wrench, pose_frame
from haptify.formats.session_format import RigidBody
from haptify.formats.storage import SessionWriter
from haptify.versions import PACKAGE_VERSION


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
                    Code.IMPORT_CHANNEL_UNKNOWN,
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
                Code.IMPORT_CHANNEL_UNKNOWN,
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
                Code.IMPORT_CHANNEL_UNKNOWN,
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
                Code.IMPORT_CHANNEL_UNKNOWN,
                f"{c3d.path.name} has {why} analog channel {name!r}",
                file=label,
                expected=c3d.analog_labels,
                found=name,
            )
        i = hits[0]
        return c3d.analogs[i], c3d.analog_units[i] or None

    return read


MocapStreams = dict[str, tuple[dict[str, np.ndarray], list[str] | None]]  # kind → (columns, entities or None)
StreamColumns = dict[str, dict[str, np.ndarray]]  # kind → columns (``t`` first)
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
            Code.IMPORT_SOURCE_UNREADABLE,
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
            Code.IMPORT_CHANNEL_UNKNOWN,
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
) -> MocapStreams:
    """handle_pose and link_poses from the map's ``bodies`` (spec §5.5): kind → (columns, entities)."""
    bm = m.bodies
    if bm is None or (bm.handle is None and not bm.links):
        return {}
    out: MocapStreams = {}
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
                    Code.IMPORT_MAP_INVALID,
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


def _plate_number(rec: Recording, m: ImportMap, label: str) -> int | None:
    """The force platform that defines W (spec §5.6): the map's number, or 1 for ``auto`` when the file
    has platforms and the map gives no ``lab_to_world``; E503 for a number the file lacks, E502 for both."""
    plate_number = None
    if isinstance(m.force_plate, int):
        if m.force_plate > len(rec.platforms):
            raise fail(
                Code.IMPORT_CHANNEL_UNKNOWN,
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
            Code.IMPORT_MAP_INVALID,
            "give either a force platform or lab_to_world: the platform defines W",
            file=label,
            pointer="/lab_to_world",
            expected="one of them",
            found="both",
        )
    return plate_number


def _world_frame(
    rec: Recording, m: ImportMap, rig: dict[str, Any], plate_number: int | None, point_unit: Unit | None, label: str
) -> tuple[WorldFrame | None, list[Finding]]:
    """W (spec §5.6): from the chosen platform, whose description becomes ``rig["force_plate"]`` (W502
    findings returned), or from ``lab_to_world``; None when W is the file's lab frame."""
    if plate_number is not None:
        if "force_plate" in rig:
            raise fail(
                Code.IMPORT_MAP_INVALID,
                "the map's rig has a force_plate and the C3D platform would replace it; set force_plate to 'none' or remove one",
                file=label,
                pointer="/session/rig/force_plate",
                expected="one plate description",
                found="two",
            )
        assert point_unit is not None  # converted whenever a platform defines W
        world, rig["force_plate"], plate_warnings = plate_description(
            rec.platforms[plate_number - 1], point_unit, file=str(rec.path)
        )
        return world, plate_warnings
    if m.lab_to_world is not None:
        return pose_frame(m.lab_to_world), []
    return None, []


def _motion_capture_rig(
    rec: Recording, mm: MarkerMap, chosen: list[int], entities: list[str], rig: dict[str, Any], label: str
) -> dict[str, Any]:
    """The rig's ``motion_capture`` of a recording whose markers or bodies are imported (spec §5.5): its
    system, rate, rigid bodies and marker entities. E205 for fewer than two frames, E502 when the map's rig
    already has one, E503 for a rigid body naming a marker that is not imported."""
    if rec.frames < 2:
        raise fail(
            Code.STREAM_EMPTY,
            f"{rec.path.name} holds {rec.frames} frame(s); a stream needs two",
            file=str(rec.path),
            expected="≥ 2 frames",
            found=rec.frames,
        )
    if "motion_capture" in rig:
        raise fail(
            Code.IMPORT_MAP_INVALID,
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
                    Code.IMPORT_CHANNEL_UNKNOWN,
                    f"rigid body {body.name!r} names markers that are not imported: {unknown}",
                    file=label,
                    pointer=f"/markers/rigid_bodies/{j}/markers",
                    expected=entities,
                    found=unknown,
                )
    system = mm.system or rec.manufacturer or None
    return {
        **({"system": system} if system is not None else {}),
        "rate_hz": rec.point_rate,
        "rigid_bodies": [b.model_dump() for b in mm.rigid_bodies],
        "markers": entities,
    }


def _analog_wanted(rec: Recording, m: ImportMap, plate_number: int | None, label: str) -> bool:
    """Whether analog channels are imported (mapped streams or the platform's wrench, spec §5.3, §5.6.1),
    checked: E502 for a platform wrench without the platform that defines W or mapped twice, or a stream
    rate other than the file's analog rate; E205 for fewer than two analog samples."""
    if m.platform_wrench is not None:
        if plate_number is None:
            raise fail(
                Code.IMPORT_MAP_INVALID,
                "platform_wrench needs the force platform that defines W (force_plate)",
                file=label,
                pointer="/platform_wrench",
                expected="a force platform",
                found=m.force_plate,
            )
        if "plate_wrench" in m.streams:
            raise fail(
                Code.IMPORT_MAP_INVALID,
                "plate_wrench is both mapped from channels and taken from the platform; keep one",
                file=label,
                pointer="/streams/plate_wrench",
                expected="one source",
                found="two",
            )
    if not m.streams and m.platform_wrench is None:
        return False
    n = rec.analogs.shape[1]
    if n < 2:
        raise fail(
            Code.STREAM_EMPTY,
            f"{rec.path.name} holds {n} analog sample(s); a stream needs two",
            file=str(rec.path),
            expected="≥ 2 analog samples",
            found=n,
        )
    for kind, smap in m.streams.items():
        if smap.rate_hz is not None and smap.rate_hz != rec.analog_rate:
            raise fail(
                Code.IMPORT_MAP_INVALID,
                f"{kind} rate_hz {smap.rate_hz} differs from the file's analog rate {rec.analog_rate}",
                file=label,
                pointer=f"/streams/{kind}/rate_hz",
                expected=rec.analog_rate,
                found=smap.rate_hz,
            )
    return True


@dataclass
class _Plan:
    """A recording's import, checked before its frames are read (spec §5.5): the map, the rig so far, the
    platform and point unit, W, the imported markers (indices and entity ids), whether bodies and analog
    channels are wanted, and the warnings found."""

    rec: Recording
    m: ImportMap
    label: str
    markers: MarkerMap
    rig: dict[str, Any]
    plate_number: int | None
    point_unit: Unit | None
    world: WorldFrame | None
    chosen: list[int]
    entities: list[str]
    wants_points: bool
    analog_wanted: bool
    warnings: list[Finding]

    @property
    def frame_note(self) -> str:
        """How W was chosen, as the trial's notes and the result say it (§5.6)."""
        if self.world:
            return self.world.description
        return f"W: the {self.rec.format.upper()} lab frame as recorded (no force platform, no lab_to_world)"

    @property
    def world_rule(self) -> str | None:
        """What defines W of the point streams (``plate``, ``pose`` or ``lab``; None without them), for §5.9's merge."""
        if not self.wants_points:
            return None
        return "plate" if self.plate_number is not None else "pose" if self.world is not None else "lab"

    def streams_of(self, part: Recording) -> tuple[MocapStreams, StreamColumns, list[Finding]]:
        """The trial's streams from the frames of ``part`` (the whole recording, or one chunk of it), and the
        platform wrench's W503 findings."""
        mocap = self._point_streams(part) if self.wants_points else {}
        analog, notes = self._analog_streams(part) if self.analog_wanted else ({}, [])
        return mocap, analog, notes

    def _point_streams(self, part: Recording) -> MocapStreams:
        """markers, handle_pose and link_poses on the point clock, in W (spec §5.5, §2.7)."""
        m, point_unit = self.m, self.point_unit
        assert point_unit is not None  # converted whenever markers or bodies are wanted
        t = (part.point_first_frame + np.arange(part.frames)) / self.rec.point_rate + m.time_offset_s
        out: MocapStreams = {}
        if self.chosen:
            pos = point_unit.to_si(part.points[:, self.chosen, :])
            pos[~np.isfinite(pos).all(axis=2)] = np.nan  # a marker is seen or occluded as a whole (§2.7)
            if self.world is not None:
                pos = self.world.apply(pos)
            marker_data = {"t": t}
            for j, ent in enumerate(self.entities):
                for k, axis in enumerate("xyz"):
                    marker_data[f"{ent}_{axis}"] = pos[:, j, k]
            out["markers"] = (marker_data, self.entities)
        out.update(_pose_streams(part, m, self.world, point_unit, t, self.markers.rigid_bodies, self.label))
        return out

    def _analog_streams(self, part: Recording) -> tuple[StreamColumns, list[Finding]]:
        """The mapped analog streams and the platform's wrench on the analog clock (spec §5.3, §5.6.1)."""
        m, label = self.m, self.label
        n = part.analogs.shape[1]
        t_an = (part.analog_first_sample + np.arange(n)) / self.rec.analog_rate + m.time_offset_s
        read = _analog_reader(part, label)
        mapped = mapped_streams(m, n, read, label=label, source_file=str(self.rec.path), unit_required=False)
        notes: list[Finding] = []
        if m.platform_wrench is not None:
            # a platform wrench without a platform is E502 (_analog_wanted); a platform's geometry needs the POINT unit
            assert self.plate_number is not None and self.point_unit is not None
            mapped["plate_wrench"], notes = platform_plate_wrench(
                part,
                part.platforms[self.plate_number - 1],
                m.platform_wrench,
                self.rig["force_plate"],
                self.point_unit,
                label=label,
            )
        return {kind: {"t": t_an, **cols} for kind, cols in mapped.items()}, notes


def _plan(rec: Recording, loaded: LoadedMap) -> _Plan:
    """Every check of a recording's import that needs no frames, in the order of spec §5.5–5.6."""
    m, label = loaded.map, loaded.label
    mm = m.markers or MarkerMap()
    plate_number = _plate_number(rec, m, label)
    rig = m.session.rig.model_dump(mode="json", exclude_none=True)
    chosen, entities = _select_markers(rec, mm, label)
    wants_bodies = m.bodies is not None and (m.bodies.handle is not None or bool(m.bodies.links))
    point_unit = None
    if chosen or wants_bodies or plate_number is not None:
        point_unit = unit_conversion(rec.point_units, "m", file=str(rec.path), pointer="/POINT/UNITS")
    world, plate_warnings = _world_frame(rec, m, rig, plate_number, point_unit, label)
    wants_points = bool(chosen) or wants_bodies
    if wants_points:
        rig["motion_capture"] = _motion_capture_rig(rec, mm, chosen, entities, rig, label)
    analog_wanted = _analog_wanted(rec, m, plate_number, label)
    return _Plan(
        rec=rec,
        m=m,
        label=label,
        markers=mm,
        rig=rig,
        plate_number=plate_number,
        point_unit=point_unit,
        world=world,
        chosen=chosen,
        entities=entities,
        wants_points=wants_points,
        analog_wanted=analog_wanted,
        warnings=[*rec.warnings, *plate_warnings],
    )


def _check_kinds(plan: _Plan, kinds: list[str]) -> None:
    """Something to import, and the protocol's required streams (spec §2.5): E502 otherwise."""
    if not kinds:
        raise fail(
            Code.IMPORT_MAP_INVALID,
            f"nothing to import from {plan.rec.path.name}: no markers selected, no bodies and no streams mapped",
            file=plan.label,
            pointer="/streams",
            expected="markers, bodies or mapped analog streams",
            found=None,
        )
    check_trial_streams(plan.m, kinds, plan.label)


def _provenance(plan: _Plan) -> str:
    """The trial's notes: the source, the version, how W was chosen and the import's warnings."""
    provenance = f"Imported from {plan.rec.path.name} by haptify {PACKAGE_VERSION}. {plan.frame_note}."
    if plan.warnings:
        provenance += " Import warnings: " + " ".join(f"{w.code} {w.message}." for w in plan.warnings)
    return provenance


def _add_streams(
    writer: SessionWriter, trial_id: str, plan: _Plan, mocap: MocapStreams, analog: StreamColumns
) -> list[dict[str, Any]]:
    """Declare the trial's streams in ``writer`` (whole, or chunked for a streamed recording, §5.5.1),
    each in the format and frame its map asks for; returns their manifest entries."""
    m, rec = plan.m, plan.rec
    written = []

    def add(kind: str, cols: dict[str, np.ndarray], **kw: Any) -> None:
        if rec.streamed:
            written.append(writer.add_chunked_stream(trial_id, kind, list(cols), **kw))
        else:
            written.append(writer.add_stream(trial_id, kind, cols, **kw))

    for kind, (cols, ents) in mocap.items():
        if kind == "markers":
            fmt = plan.markers.format
        else:
            assert m.bodies is not None  # _pose_streams makes the pose streams from the map's bodies
            fmt = m.bodies.format
        add(kind, cols, rate_hz=rec.point_rate, fmt=fmt, entities=ents)
    for kind, cols in analog.items():
        stream_map = m.streams.get(kind)
        if stream_map is not None:
            fmt, frame = stream_map.format, stream_map.frame
        else:
            assert m.platform_wrench is not None  # the one analog stream without a stream map: the platform's wrench
            fmt, frame = m.platform_wrench.format, None
        add(kind, cols, rate_hz=rec.analog_rate, fmt=fmt, frame=frame)
    return written


def _chunk_source(
    plan: _Plan,
    first: Recording,
    pieces: Iterator[tuple[int, Recording]],
    mocap: MocapStreams,
    analog: StreamColumns,
    progress: Callable[[int, int], None] | None,
) -> Callable[[], Iterator[StreamColumns]]:
    """The chunks of a streamed recording's streams (spec §5.5.1): the first chunk's, already built, then
    one per remaining piece; ``progress(frames done, frames)`` after each."""
    rec = plan.rec

    def chunks() -> Iterator[StreamColumns]:
        done = first.frames
        yield {**{k: c for k, (c, _) in mocap.items()}, **analog}
        if progress:
            progress(done, rec.frames)
        for _, part in pieces:
            part_mocap, part_analog, _ = plan.streams_of(part)
            yield {**{k: c for k, (c, _) in part_mocap.items()}, **part_analog}
            done += part.frames
            if progress:
                progress(done, rec.frames)

    return chunks


def import_recording(
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
    plan = _plan(rec, loaded)
    pieces = recording_chunks(rec, chunk_frames)
    first = next(pieces)[1] if rec.frames or rec.analogs.shape[1] else rec
    mocap_streams, analog_streams, origin_notes = plan.streams_of(first)
    plan.warnings += origin_notes
    _check_kinds(plan, list(mocap_streams) + list(analog_streams))
    rig = dest.rig(plan.rig, plan.world_rule, loaded.label)
    recorder = f"haptify {PACKAGE_VERSION} import {rec.format}" + (f" ({rec.manufacturer})" if rec.manufacturer else "")
    writer, stem = dest.writer(loaded.map, rec.path, rig, device, extra, recorder)
    trial_id = add_trial(writer, loaded.map, stem, rec.path, _provenance(plan))
    written = _add_streams(writer, trial_id, plan, mocap_streams, analog_streams)
    if rec.streamed:
        writer.chunks = _chunk_source(plan, first, pieces, mocap_streams, analog_streams, progress)
    return dest.finish(writer, trial_id, written, plan.frame_note, rec.summary(), plan.warnings)
