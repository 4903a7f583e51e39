"""Writing a session (spec §3.6, §5.5.1): :class:`SessionWriter` builds the manifest and its streams, writes them
into a temporary sibling folder and renames it into place, so an interrupted write never leaves a half session.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np
import pandas as pd
from pydantic import ValidationError

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.session_format import Session, default_stream_file, expected_columns, kind_table
from haptify.formats.storage.atomic import atomic_write_json, atomic_write_text, replace_folder_atomically
from haptify.formats.storage.json_documents import pydantic_findings
from haptify.formats.storage.paths import MANIFEST, resolve_inside, sha256_file
from haptify.formats.storage.stream_files import TableSink, write_table
from haptify.versions import SPEC_VERSION


def _stream_columns(trial_id: str, kind: str, entities: list[str] | None, present: list[str]) -> list[tuple[str, str]]:
    """The columns (name, unit) a ``kind`` stream must have (:func:`haptify.formats.session_format.expected_columns`);
    E201 when ``present`` lacks one (spec §2.6)."""
    cols = expected_columns(kind, entities, present)
    missing = [c for c, _ in cols if c not in present]
    if missing:
        raise fail(
            Code.COLUMN_MISMATCH,
            f"{kind} stream of trial {trial_id!r} lacks columns {missing}",
            column=missing[0],
            expected=[c for c, _ in cols],
            found=present,
        )
    return cols


@dataclass
class _PendingStream:
    trial_id: str
    stream: dict[str, Any]
    frame: pd.DataFrame | None  # None: a chunked stream, written from :attr:`SessionWriter.chunks`


@dataclass
class SessionWriter:
    """Build a session in memory and write it atomically (spec §3.6).

    ``manifest`` holds every session-level field of :class:`Session` except ``trials``; trials and
    streams are added with :meth:`add_trial` and :meth:`add_stream`; :meth:`write` fills in rows and
    checksums, validates the manifest against the model, and renames the finished folder into place.
    """

    manifest: dict[str, Any]
    extra_files: dict[str, str] = field(default_factory=dict)
    compact: bool = False  # Parquet streams: float32 + BYTE_STREAM_SPLIT for every column but t (spec §3.2.1)
    _trials: list[dict[str, Any]] = field(default_factory=list)
    _streams: list[_PendingStream] = field(default_factory=list)
    chunks: Callable[[], Iterable[Mapping[str, Mapping[str, Any]]]] | None = None  # rows of the chunked streams

    def add_trial(
        self,
        trial_id: str,
        protocol: str,
        *,
        powered: bool,
        repetition: int = 1,
        label: str | None = None,
        rendering: Mapping[str, Any] | None = None,
        notes: str | None = None,
    ) -> dict[str, Any]:
        trial = {"id": trial_id, "protocol": protocol, "repetition": repetition, "powered": powered, "streams": []}
        for key, val in (("label", label), ("rendering", rendering), ("notes", notes)):
            if val is not None:
                trial[key] = dict(val) if isinstance(val, Mapping) else val
        self._trials.append(trial)
        return trial

    def add_stream(
        self,
        trial_id: str,
        kind: str,
        data: Mapping[str, Any] | pd.DataFrame,
        *,
        rate_hz: float,
        frame: str | None = None,
        fmt: str = "parquet",
        entities: list[str] | None = None,
        file: str | None = None,
    ) -> dict[str, Any]:
        """Add a stream; ``data`` maps every expected column name (``t`` first) to a 1-D array."""
        trial = next(t for t in self._trials if t["id"] == trial_id)
        present = list(data.keys()) if isinstance(data, Mapping) else list(data.columns)
        cols = _stream_columns(trial_id, kind, entities, present)
        table = pd.DataFrame({c: np.asarray(data[c], dtype=np.float64) for c, _ in cols})
        stream = {
            "kind": kind,
            "file": file or default_stream_file(trial_id, kind, fmt),
            "format": fmt,
            "rate_hz": float(rate_hz),
            "frame": frame or kind_table(kind)["frames"][0],
            "columns": [{"name": c, "unit": u} for c, u in cols],
            "rows": int(len(table)),
            "sha256": "0" * 64,
        }
        if entities is not None:
            stream["entities"] = list(entities)
        trial["streams"].append(stream)
        self._streams.append(_PendingStream(trial_id, stream, table))
        return stream

    def add_chunked_stream(
        self,
        trial_id: str,
        kind: str,
        columns: list[str],
        *,
        rate_hz: float,
        frame: str | None = None,
        fmt: str = "parquet",
        entities: list[str] | None = None,
    ) -> dict[str, Any]:
        """Add a stream whose rows come from :attr:`chunks` at :meth:`write` time (spec §5.5.1): each item
        of ``chunks()`` maps stream kinds to their columns for the next rows (``t`` first)."""
        cols = _stream_columns(trial_id, kind, entities, columns)
        stream = self.add_stream(
            trial_id, kind, {c: np.zeros(0) for c, _ in cols}, rate_hz=rate_hz, frame=frame, fmt=fmt, entities=entities
        )
        self._streams[-1].frame = None
        return stream

    def _write_chunks(self, build: Path) -> None:
        """Write every chunked stream from one pass over :attr:`chunks` (spec §5.5.1)."""
        pending = {p.stream["kind"]: p for p in self._streams if p.frame is None}
        if not pending:
            return
        sinks = {}
        for kind, p in pending.items():
            path = resolve_inside(build, p.stream["file"])
            path.parent.mkdir(parents=True, exist_ok=True)
            sinks[kind] = TableSink(path, p.stream["format"], self.compact)
        order = {kind: [c["name"] for c in p.stream["columns"]] for kind, p in pending.items()}
        if self.chunks is None:
            raise ValueError("add_chunked_stream was called, but SessionWriter.chunks is not set")
        for piece in self.chunks():
            for kind, data in piece.items():
                sinks[kind].write(pd.DataFrame({c: np.asarray(data[c], dtype=np.float64) for c in order[kind]}))
        for kind, p in pending.items():
            p.stream["rows"] = sinks[kind].close()
            p.stream["sha256"] = sha256_file(sinks[kind].path)

    def build_manifest(self) -> dict[str, Any]:
        return {**self.manifest, "spec_version": SPEC_VERSION, "trials": self._trials}

    def write(self, target: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write the session folder atomically and return its path."""
        target = Path(target)
        if target.exists() and not overwrite:
            raise fail(Code.OUTPUT_EXISTS, f"{str(target)!r} already exists", file=str(target))
        target.parent.mkdir(parents=True, exist_ok=True)
        build = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=target.parent))
        try:
            self._write_chunks(build)
            for pending in self._streams:
                if pending.frame is None:  # a chunked stream: written above
                    continue
                path = resolve_inside(build, pending.stream["file"])
                path.parent.mkdir(parents=True, exist_ok=True)
                write_table(path, pending.frame, pending.stream["format"], compact=self.compact)
                pending.stream["sha256"] = sha256_file(path)
            for rel, text in self.extra_files.items():
                atomic_write_text(resolve_inside(build, rel), text)
            manifest = self.build_manifest()
            try:
                Session.model_validate(manifest)
            except ValidationError as exc:
                raise HaptifyError(*pydantic_findings(exc, Code.SCHEMA_VIOLATION, MANIFEST)) from None
            atomic_write_json(build / MANIFEST, manifest)
            replace_folder_atomically(build, target, overwrite)
        except BaseException:
            shutil.rmtree(build, ignore_errors=True)
            raise
        return target
