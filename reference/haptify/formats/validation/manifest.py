"""The first phase of validation: session.json and device.json (spec §4.3.1–4.3.3) — well-formedness,
JSON Schema, the device file, unique ids and cross references, static quaternions, calendar date, nulls,
the rig's corner ids, the device's kinematic chain, then each trial (:mod:`haptify.formats.validation.trials`)."""

from __future__ import annotations

import datetime
import math
from pathlib import PurePosixPath
from typing import Any, Iterable

from pydantic import BaseModel, ValidationError

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError
from haptify.formats.conventions import QUATERNION_NORM_TOLERANCE
from haptify.formats.session_format import ClockOffset, Device, Rig, Session, Stream, Trial
from haptify.formats.storage import MANIFEST, parse_json_file, pydantic_findings, resolve_inside
from haptify.formats.validation.base import StreamEntry, ValidatorBase
from haptify.formats.validation.device import kinematics_findings
from haptify.formats.validation.files import DEVICE_MAX_BYTES, MANIFEST_MAX_BYTES, regular_file
from haptify.formats.validation.report import short
from haptify.formats.validation.schema import schema_findings
from haptify.formats.validation.trials import check_trial
from haptify.versions import SPEC_VERSION


class ManifestChecks(ValidatorBase):
    """Phase 1 of the validator: session.json, device.json and the trials (spec §4.3.1–4.3.3); it parses the
    manifest into :attr:`manifest`, :attr:`rig`, :attr:`trials`, :attr:`offsets` and the stream
    :attr:`entries` phase 2 checks."""

    def check_manifest(self) -> None:
        """Folder, session.json, schema, device, ids, references, trials (spec §4.3.1–4.3.3)."""
        if not self.root.is_dir():
            self.add(
                Finding(
                    Code.SESSION_NOT_FOUND,
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
                self._guard(lambda: check_trial(index, trial, lambda f: self.add(f, trial.id)), trial=trial.id, file=MANIFEST)

    def _load_manifest(self) -> None:
        path = resolve_inside(self.root, MANIFEST)
        regular_file(path, MANIFEST, Code.MANIFEST_MISSING, f"no {MANIFEST} in {str(self.root)!r}", MANIFEST_MAX_BYTES)
        raw = parse_json_file(path, Code.MANIFEST_MALFORMED_JSON, MANIFEST)
        if isinstance(raw, dict) and "spec_version" in raw and raw["spec_version"] != SPEC_VERSION:
            raise HaptifyError(
                Finding(
                    Code.SPEC_VERSION_UNSUPPORTED,
                    f"spec version {raw['spec_version']!r} is not supported",
                    file=MANIFEST,
                    pointer="/spec_version",
                    expected=SPEC_VERSION,
                    found=short(raw["spec_version"]),
                )
            )
        self.raw = raw

    def _check_schema(self) -> None:
        findings = schema_findings(self.raw, "session", Code.SCHEMA_VIOLATION, MANIFEST)
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
                self.add_all(pydantic_findings(exc, Code.SCHEMA_VIOLATION, MANIFEST))
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
            regular_file(path, label, Code.DEVICE_FILE_INVALID, f"device file {label!r} does not exist", DEVICE_MAX_BYTES)
            data = parse_json_file(path, Code.DEVICE_FILE_INVALID, label)
        except HaptifyError as err:
            for f in err.findings:
                if f.file == label and f.pointer is None and f.code in (Code.UNSAFE_PATH, Code.SYMLINK_ESCAPE):
                    f.pointer = "/device/file"
            self.add_all(err.findings)
            return
        findings = schema_findings(data, "device", Code.DEVICE_FILE_INVALID, label)
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
        judged = {
            f.pointer
            for f in self.report.findings
            if f.file == label
            and f.code in (Code.SCHEMA_VIOLATION, Code.DEVICE_FILE_INVALID, Code.DECLARED_SIZE_ABSURD, Code.PROTOCOL_UNKNOWN)
        }
        for pointer, _, value in _json_members(self.raw if document is None else document):
            if value is None and pointer not in judged:
                self.add(
                    Finding(
                        Code.NULL_MEMBER,
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
                    Code.SCHEMA_VIOLATION,
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
                        Code.DUPLICATE_ID,
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
                        Code.DUPLICATE_ID,
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
                        Code.DUPLICATE_ID,
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
                        Code.DUPLICATE_ID,
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
                        Code.REFERENCE_UNKNOWN,
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
                        Code.REFERENCE_UNKNOWN,
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
                        Code.QUATERNION_NOT_UNIT,
                        f"quaternion has norm {norm:.6g}",
                        file=label,
                        pointer=pointer,
                        expected=f"norm 1 ± {QUATERNION_NORM_TOLERANCE}",
                        found=q,
                    )
                )


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
