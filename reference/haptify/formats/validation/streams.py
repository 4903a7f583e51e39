"""The second phase of validation: every stream (spec §4.3.5, §4.4) — what session.json declares of it
(columns, units, entities, frame, rate), its file (path safety, size, checksum, readability, columns,
rows), its data chunk by chunk (:mod:`haptify.formats.validation.times`, :mod:`haptify.formats.validation.values`), and
last the time overlap of the streams of each trial (§4.3.6)."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError
from haptify.formats.session_format import SensorRange, Stream, expected_columns, kind_table
from haptify.formats.storage import MANIFEST, read_stream_chunks, resolve_inside, sha256_file
from haptify.formats.validation.base import StreamEntry, ValidatorBase, collect
from haptify.formats.validation.files import parquet_footer, regular_file, stream_size_limit
from haptify.formats.validation.times import TimeScan
from haptify.formats.validation.values import ValueScan

STREAM_CHUNK_BYTES = 32 * 2**20  # a stream is validated in chunks of about this many float64 bytes


class StreamChecks(ValidatorBase):
    """Phase 2 of the validator: every stream of :attr:`entries`, then the time overlap per trial
    (spec §4.3.5–4.3.6)."""

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
        raised = collect(lambda: self._check_declaration(entry, found.append), entry.stream.file)
        self.add_all(found + raised, entry.trial)

    def check_stream(self, entry: StreamEntry, *, keep: bool = False) -> pd.DataFrame | None:
        """Check one stream's declaration, file and data (spec §4.3.5); the findings go into the report.

        With ``keep`` the file is read whole and its table as read (stream clock) is returned, or None when
        the file could not be read; without, it is read in chunks, in bounded memory (:meth:`reads_whole`),
        and None is returned."""
        self.check_declaration(entry)
        kept: list[pd.DataFrame] = []
        path = entry.path
        if path is not None:
            found: list[Finding] = []
            raised = collect(
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
                        Code.COLUMN_MISMATCH,
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
                        Code.DUPLICATE_ID,
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
                                Code.ENTITY_UNKNOWN,
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
                    Code.ENTITIES_NOT_ALLOWED,
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
                    Code.COLUMN_MISMATCH,
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
                            Code.WRONG_UNIT,
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
                    Code.WRONG_FRAME,
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
                    Code.RATE_BELOW_RECOMMENDED,
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
            regular_file(path, label, Code.STREAM_FILE_MISSING, missing, stream_size_limit(len(declared), s.rows, max(1, s.rows)))
            groups, entry.footer_rows = parquet_footer(path, label, s.rows)
            regular_file(path, label, Code.STREAM_FILE_MISSING, missing, stream_size_limit(len(declared), s.rows, groups))
        else:
            regular_file(path, label, Code.STREAM_FILE_MISSING, missing, stream_size_limit(len(declared), s.rows))
        entry.path = path

    def _check_contents(
        self, entry: StreamEntry, path: Path, add: Callable[[Finding], None], keep: Callable[[pd.DataFrame], Any] | None
    ) -> None:
        """Checksum, readability, columns, rows and data of a stream file whose declaration was checked.

        The file is read chunk by chunk (:func:`~haptify.formats.storage.read_stream_chunks`, :meth:`chunk_rows_for`)
        and every check of spec §4.4 carries its state across chunk borders, so memory holds one chunk and
        the findings are those of the whole table. With ``keep`` (the gate, which computes from the table)
        the table is read whole — the one-chunk case — and handed to ``keep``.
        """
        s, label = entry.stream, entry.stream.file
        declared = [c.name for c in s.columns]
        try:
            whole = keep is not None or self.reads_whole(entry)
            digest, chunks = read_stream_chunks(
                path, s.format, declared, label=label, chunk_rows=None if whole else self.chunk_rows_for(len(declared))
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
        times = TimeScan(s.rate_hz)
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
                    Code.COLUMN_MISMATCH,
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
                Finding(
                    Code.ROW_COUNT_MISMATCH,
                    f"{label!r} holds {n} rows, session.json declares {s.rows}",
                    file=label,
                    expected=s.rows,
                    found=n,
                )
            )
        if n < 2:
            add(
                Finding(
                    Code.STREAM_EMPTY,
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

    def reads_whole(self, entry: StreamEntry) -> bool:
        """Whether a stream is read in one piece, hashed as it is read (no first hashing pass): a Parquet
        file whose footer's rows (fixed-width float columns) fit in one chunk, unless chunks are forced."""
        rows = entry.footer_rows
        return self.chunk_rows is None and rows is not None and rows <= self.chunk_rows_for(len(entry.stream.columns))

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
                    Code.CHECKSUM_MISMATCH,
                    f"checksum of {s.file!r} does not match session.json",
                    file=s.file,
                    expected=s.sha256,
                    found=digest,
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

    def _value_scan(self, s: Stream, cols: list[str]) -> ValueScan:
        """The value checks of one stream (spec §4.4), with the rig's sensor range of its kind."""
        rng_spec = kind_table(s.kind).get("range")
        return ValueScan(s, cols, self._rig_range(rng_spec["rig_field"]) if rng_spec else None)

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
                        Code.STREAMS_DO_NOT_OVERLAP,
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
