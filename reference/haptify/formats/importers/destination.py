"""Where an import goes (spec §5.8–5.9): a new session, or one more trial appended atomically to an
existing one; the device, the rig merged, the trial and what the import wrote."""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail
from haptify.formats.importers.import_map import ImportMap, LoadedMap, load_map, sanitize_id
from haptify.formats.session_format import (
    Device,
    Session,
)
from haptify.formats.storage import (
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


def _resolve_device(m: ImportMap, base: Path, label: str) -> tuple[Device, dict[str, Any], dict[str, str]]:
    """The device, the manifest's device member and the extra files (device.json) to write with it."""
    dev = m.session.device
    if isinstance(dev, Device):
        return dev, dev.model_dump(mode="json", exclude_none=True), {}
    path = (base / dev.file) if not Path(dev.file).is_absolute() else Path(dev.file)
    where = {"file": label, "pointer": "/session/device/file"}
    if not path.is_file():
        raise fail(
            Code.IMPORT_MAP_INVALID,
            f"device file {str(path)!r} does not exist",
            expected="a device.json",
            found=dev.file,
            **where,
        )
    data = parse_json_file(path, Code.IMPORT_MAP_INVALID, str(path))
    try:
        model = Device.model_validate(data)
    except ValidationError as exc:
        raise HaptifyError(*pydantic_findings(exc, Code.IMPORT_MAP_INVALID, str(path))) from None
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
                raise fail(Code.USAGE, "append and overwrite exclude each other", expected="one of them", found="both")
            return cls(out, existing=open_session(out))
        if out.exists() and not overwrite:
            raise fail(
                Code.OUTPUT_EXISTS,
                f"{str(out)!r} already exists",
                file=str(out),
                expected="a new path or --overwrite",
                found="exists",
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
                    Code.IMPORT_MAP_INVALID,
                    f"the map's session.{key} differs from the session it appends to",
                    file=label,
                    pointer=f"/session/{key}",
                    expected=_plain(theirs),
                    found=_plain(mine),
                )
        if device != self.existing.device():
            raise fail(
                Code.IMPORT_MAP_INVALID,
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
                Code.DUPLICATE_ID,
                f"the session already has a trial {trial_id!r}",
                file=MANIFEST,
                pointer="/trials",
                expected="a new trial id (--trial-id)",
                found=trial_id,
            )
        return append_trial(writer, self.existing)

    def finish(
        self,
        writer: SessionWriter,
        trial_id: str,
        written: list[dict[str, Any]],
        world_frame: str,
        source: dict[str, Any],
        warnings: list[Finding] | None = None,
    ) -> ImportResult:
        """Write (:meth:`write`) and say what was written: the streams' manifest entries ``written``, how W
        was chosen and the source's description (spec §5.8)."""
        self.write(writer, trial_id)
        return ImportResult(
            self.out,
            writer.manifest["session_id"],
            trial_id,
            [_stream_summary(s) for s in written],
            world_frame,
            source,
            warnings if warnings is not None else [],
        )


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
            Code.IMPORT_MAP_INVALID,
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
                Code.IMPORT_MAP_INVALID,
                f"rig.{key} of this import differs from the session's",
                file=label,
                pointer=pointer,
                expected=old[key],
                found=part,
            )
        elif key == "force_plate" and key not in old and world_streams:
            raise fail(
                Code.IMPORT_MAP_INVALID,
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
                Code.IMPORT_MAP_INVALID,
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
                Code.IMPORT_MAP_INVALID,
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
                    Code.DUPLICATE_ID,
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
            raise HaptifyError(*pydantic_findings(exc, Code.SCHEMA_VIOLATION, MANIFEST)) from None
        atomic_write_json(build / MANIFEST, manifest)
        replace_folder_atomically(build, target, overwrite=True)
    except BaseException:
        shutil.rmtree(build, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


def add_trial(writer: SessionWriter, m: ImportMap, stem: str, source: Path, provenance: str) -> str:
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


def prepare(
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
