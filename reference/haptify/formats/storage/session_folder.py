"""A session opened for reading (spec §3.1): the manifest parsed and checked, streams read on demand."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pandas as pd
from pydantic import ValidationError

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.session_format import Device, DeviceRef, Session, Stream, Trial
from haptify.formats.storage.json_documents import parse_json_file, pydantic_findings
from haptify.formats.storage.paths import MANIFEST, resolve_inside, sha256_file
from haptify.formats.storage.stream_files import read_table
from haptify.versions import SPEC_VERSION


class SessionFolder:
    """A session opened for reading (spec §3.1): the manifest, and streams on demand."""

    def __init__(self, root: Path, manifest: Session, raw: dict[str, Any]) -> None:
        self.root = root
        self.manifest = manifest
        self.raw = raw

    # -- manifest navigation ------------------------------------------------------------------
    @property
    def session_id(self) -> str:
        return self.manifest.session_id

    @property
    def trials(self) -> list[Trial]:
        return self.manifest.trials

    def trial(self, trial_id: str) -> Trial:
        for t in self.manifest.trials:
            if t.id == trial_id:
                return t
        raise fail(
            Code.USAGE,
            f"no trial {trial_id!r} in session {self.session_id}",
            file=MANIFEST,
            expected=[t.id for t in self.manifest.trials],
            found=trial_id,
        )

    def trials_of(self, protocol: str) -> list[Trial]:
        """Trials of one protocol, ordered by repetition."""
        return sorted((t for t in self.manifest.trials if t.protocol == protocol), key=lambda t: (t.repetition, t.id))

    def stream(self, trial_id: str, kind: str) -> Stream | None:
        """The trial's stream of ``kind``, or None when it has none."""
        return next((s for s in self.trial(trial_id).streams if s.kind == kind), None)

    def device(self) -> Device:
        """The device description, reading ``device.json`` when the manifest refers to one."""
        dev = self.manifest.device
        if isinstance(dev, DeviceRef):
            path = resolve_inside(self.root, dev.file)
            if not path.is_file():
                raise fail(Code.DEVICE_FILE_INVALID, f"device file {dev.file!r} does not exist", file=dev.file)
            data = parse_json_file(path, Code.DEVICE_FILE_INVALID, dev.file)
            try:
                return Device.model_validate(data)
            except ValidationError as exc:
                raise HaptifyError(*pydantic_findings(exc, Code.DEVICE_FILE_INVALID, dev.file)) from None
        return dev

    # -- stream data ----------------------------------------------------------------------------
    def stream_path(self, stream: Stream) -> Path:
        return resolve_inside(self.root, stream.file)

    def clock_offset(self, stream: Stream) -> float:
        """Seconds to add to the stream's ``t`` to put it on the session clock (spec §2.8)."""
        return sum(c.offset_s for c in self.manifest.calibration if c.kind == "clock_offset" and c.stream_file == stream.file)

    def read_stream(self, stream: Stream, *, verify: bool = False, session_clock: bool = True) -> pd.DataFrame:
        """The stream's table: ``t`` then the kind's columns, float64 (spec §3.2).

        ``verify`` checks the sha256 first (E111); ``session_clock`` applies clock-offset records.
        """
        path = self.stream_path(stream)
        if not path.is_file():
            raise fail(Code.STREAM_FILE_MISSING, f"stream file {stream.file!r} does not exist", file=stream.file)
        if verify:
            digest = sha256_file(path)
            if digest != stream.sha256:
                raise fail(
                    Code.CHECKSUM_MISMATCH,
                    f"checksum of {stream.file!r} does not match the manifest",
                    file=stream.file,
                    expected=stream.sha256,
                    found=digest,
                )
        table = read_table(path, stream.format, [c.name for c in stream.columns], label=stream.file)
        if session_clock:
            offset = self.clock_offset(stream)
            if offset:
                table["t"] = table["t"] + offset
        return table

    def read(self, trial_id: str, kind: str, **kw: Any) -> pd.DataFrame:
        """Shortcut: the table of the trial's stream of ``kind`` (E302 when the trial has none)."""
        s = self.stream(trial_id, kind)
        if s is None:
            raise fail(
                Code.REQUIRED_STREAM_MISSING, f"trial {trial_id!r} has no {kind} stream", file=MANIFEST, expected=kind, found=None
            )
        return self.read_stream(s, **kw)


def open_session(path: str | os.PathLike[str]) -> SessionFolder:
    """Open a session folder and parse its manifest (E101–E105); streams are read lazily (spec §3.1)."""
    root = Path(path)
    if not root.is_dir():
        raise fail(Code.SESSION_NOT_FOUND, f"{str(root)!r} is not a session folder", file=str(root))
    manifest_path = root / MANIFEST
    if not manifest_path.is_file():
        raise fail(Code.MANIFEST_MISSING, f"no {MANIFEST} in {str(root)!r}", file=MANIFEST)
    raw = parse_json_file(manifest_path, Code.MANIFEST_MALFORMED_JSON, MANIFEST)
    if isinstance(raw, dict) and raw.get("spec_version") not in (None, SPEC_VERSION):
        raise fail(
            Code.SPEC_VERSION_UNSUPPORTED,
            f"spec version {raw.get('spec_version')!r} is not supported",
            file=MANIFEST,
            pointer="/spec_version",
            expected=SPEC_VERSION,
            found=raw.get("spec_version"),
        )
    try:
        manifest = Session.model_validate(raw)
    except ValidationError as exc:
        raise HaptifyError(*pydantic_findings(exc, Code.SCHEMA_VIOLATION, MANIFEST)) from None
    return SessionFolder(root, manifest, raw)
