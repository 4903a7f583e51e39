"""Session storage: folders, stream files, checksums and atomic writes (spec chapter 3).

Reading is lazy: :func:`open_session` parses and checks ``session.json`` only; each stream is read
when asked for. Writing goes through :class:`SessionWriter`, which writes the whole session into a
temporary sibling folder and renames it into place, so an interrupted write never leaves a half
session. Nothing outside the session folder is ever read or written (§3.3).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import tempfile
import uuid
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Callable, Iterable, Iterator, Literal, Mapping, TypedDict, TypeVar

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import BaseModel, ValidationError

from haptify.errors import Finding, HaptifyError, fail
from haptify.session_format import (
    Device,
    DeviceRef,
    Session,
    Stream,
    Trial,
    default_stream_file,
    expected_columns,
    is_safe_relative_path,
    kind_table,
)
from haptify.versions import SPEC_VERSION

MANIFEST = "session.json"
MAX_SYMLINK_HOPS = 40  # as POSIX SYMLOOP_MAX
HASH_CHUNK = 1 << 20


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file's bytes (spec §3.4)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(HASH_CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


def resolve_inside(root: Path, relative: str, *, label: str | None = None) -> Path:
    """The path of ``relative`` inside ``root`` with every symbolic link resolved lexically (spec §3.3).

    Each component is examined with ``lstat`` inside the folder; a link's target is read with
    ``readlink`` and resolved against the folder, never against the file system, so nothing outside
    ``root`` is ever touched. Raises E108 for an unsafe declared path, E109 when a link leads out.
    """
    label = label or relative
    if not is_safe_relative_path(relative):
        raise HaptifyError(
            Finding(
                "E108",
                f"path {relative!r} is absolute or leaves the session folder",
                file=label,
                expected="a relative POSIX path inside the session folder",
                found=relative,
            )
        )
    current: list[str] = []
    pending = relative.split("/")
    hops = 0
    link = last_target = ""

    def escape(target: str) -> HaptifyError:
        return HaptifyError(
            Finding(
                "E109",
                f"{relative!r} passes through the symbolic link {link!r} → {target!r}, which leads outside the session folder",
                file=label,
                expected="a link target inside the session folder",
                found=target,
            )
        )

    while pending:
        part = pending.pop(0)
        if part in ("", "."):
            continue
        if part == "..":
            if not current:
                raise escape(last_target)
            current.pop()
            continue
        candidate = root.joinpath(*current, part)
        if candidate.is_symlink():
            hops += 1
            link = "/".join([*current, part])
            last_target = os.readlink(candidate)
            if hops > MAX_SYMLINK_HOPS or PurePosixPath(last_target).is_absolute() or "\\" in last_target:
                raise escape(last_target)
            pending = last_target.split("/") + pending
            continue
        current.append(part)
    return root.joinpath(*current)


def pointer_of(loc: Iterable[Any]) -> str:
    """A JSON pointer (RFC 6901) from a pydantic/jsonschema location tuple (spec §4.6)."""
    parts = [str(p).replace("~", "~0").replace("/", "~1") for p in loc]
    return "/" + "/".join(parts) if parts else ""


class _NonFinite(ValueError):
    pass


class _DuplicateKey(ValueError):
    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key


def _unique_members(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's members; a name given twice is an error (spec §3.1), not a silent overwrite."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def _reject_constant(name: str) -> float:
    raise _NonFinite(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _NonFinite(f"the number {text} overflows a 64-bit float")
    return value


def parse_json_file(path: Path, code: str, label: str) -> Any:
    """Parse a JSON file strictly: UTF-8, no NaN/Infinity literals, no numbers that overflow, no member
    name twice in one object (E117) (spec §3.1, §4.3)."""
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise HaptifyError(
            Finding(
                code,
                f"{label} is not UTF-8 text: {exc.reason} at byte {exc.start}",
                file=label,
                expected="UTF-8 JSON",
                found=f"byte 0x{exc.object[exc.start]:02x}",
            )
        ) from None
    except OSError as exc:
        raise HaptifyError(Finding(code, f"{label} cannot be read: {exc.strerror}", file=label)) from None
    try:
        return json.loads(text, parse_constant=_reject_constant, parse_float=_finite_float, object_pairs_hook=_unique_members)
    except json.JSONDecodeError as exc:
        raise HaptifyError(
            Finding(
                code,
                f"{label} is not well-formed JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})",
                file=label,
                expected="JSON",
                found=text[max(0, exc.pos - 20) : exc.pos + 20],
            )
        ) from None
    except _DuplicateKey as exc:
        raise HaptifyError(
            Finding(
                "E117",
                f"{label} names the member {_short_text(exc.key)!r} twice in one object",
                file=label,
                expected="unique member names",
                found=_short_text(exc.key),
            )
        ) from None
    except _NonFinite as exc:
        raise HaptifyError(
            Finding(code, f"{label} is not well-formed JSON: {exc}", file=label, expected="a finite JSON number")
        ) from None
    except RecursionError:
        raise HaptifyError(Finding(code, f"{label} nests too deeply to be a Haptify document", file=label)) from None


def pydantic_findings(exc: ValidationError, code: str, label: str) -> list[Finding]:
    """One finding per pydantic error, with JSON pointer and expected/found (spec §4.6)."""
    out = []
    for err in exc.errors(include_url=False):
        found = err.get("input")
        if isinstance(found, (dict, list)):
            found = f"<{type(found).__name__}>"
        out.append(
            Finding(
                code,
                f"{err['msg']}",
                file=label,
                pointer=pointer_of(err["loc"]),
                expected=err.get("ctx", {}).get("expected", err["type"]),
                found=found,
            )
        )
    return out


M = TypeVar("M", bound=BaseModel)


def read_json_model(path: str | os.PathLike[str], model: type[M], code: str) -> M:
    """Read a JSON file into a pydantic ``model``; a missing, malformed or invalid file is ``code``.
    Spec §0.4.

    Used for every standalone document (results files, model parameter files): the finding names the
    file, the JSON pointer of each invalid field, what was expected and what was found.
    """
    p = Path(path)
    if not p.is_file():
        raise fail(code, f"{str(p)!r} does not exist or is not a file", file=str(p))
    data = parse_json_file(p, code, str(p))
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise HaptifyError(*pydantic_findings(exc, code, str(p))) from None


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
            "E903",
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
                raise fail("E106", f"device file {dev.file!r} does not exist", file=dev.file)
            data = parse_json_file(path, "E106", dev.file)
            try:
                return Device.model_validate(data)
            except ValidationError as exc:
                raise HaptifyError(*pydantic_findings(exc, "E106", dev.file)) from None
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
            raise fail("E110", f"stream file {stream.file!r} does not exist", file=stream.file)
        if verify:
            digest = sha256_file(path)
            if digest != stream.sha256:
                raise fail(
                    "E111",
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
            raise fail("E302", f"trial {trial_id!r} has no {kind} stream", file=MANIFEST, expected=kind, found=None)
        return self.read_stream(s, **kw)


def read_table(path: Path, fmt: str, columns: list[str], *, label: str) -> pd.DataFrame:
    """Read a stream file as float64 columns without hashing it (spec §3.2); the codes are those of
    :func:`read_stream_file`."""
    if fmt != "parquet":
        return read_stream_file(path, fmt, columns, label=label)[0]
    try:
        frame = arrow_frame(pq.read_table(path))
    except MemoryError:  # Arrow's allocation failure is the reader's, not the file's (never E112)
        raise
    except (OSError, pa.ArrowException, ValueError) as exc:
        raise fail("E112", f"{label!r} cannot be read as {fmt}: {exc}", file=label) from None
    return as_float64(frame, label)


def read_stream_file(path: Path, fmt: str, columns: list[str], *, label: str) -> tuple[pd.DataFrame, str]:
    """Read a stream file once: its table as float64 columns and the sha256 of its bytes (spec §3.2, §3.4).

    The whole-table case of :func:`read_stream_chunks` (one chunk): the bytes are hashed as they are
    read, so verifying a checksum costs no second pass. The codes are those of :func:`read_stream_chunks`.
    """
    digest, chunks = read_stream_chunks(path, fmt, columns, label=label)
    return next(chunks), digest


def read_stream_chunks(
    path: Path, fmt: str, columns: list[str], *, label: str, chunk_rows: int | None = None
) -> tuple[str, Iterator[pd.DataFrame]]:
    """The sha256 of a stream file's bytes and its table as consecutive float64 chunks of at most
    ``chunk_rows`` rows — at least one chunk, the first possibly empty (spec §3.2, §3.4).

    ``chunk_rows=None`` reads the whole table as one chunk; a Parquet file is then read once, hashed as it
    is read. Otherwise the file is hashed in a first pass of :data:`HASH_CHUNK` blocks and decoded batch by
    batch (Parquet, ``ParquetFile.iter_batches``) or ``chunk_rows`` lines at a time (CSV,
    ``pandas.read_csv(chunksize=…)``), so memory holds one chunk whatever the file's size. A CSV file is
    checked against the grammar of §3.2 in bounded memory before it is parsed (a header or a line longer
    than :func:`csv_line_limit` is E112 at once). Unreadable files raise E112 (also from the iterator, when
    a later part of the file is damaged), a wrong CSV header E211, a column whose stored type is neither
    float64 nor (except ``t``) float32 E212 — judged on the file's schema, before any row is read, so the
    verdict never depends on the chunking; float32 columns are widened to float64 exactly.
    """
    try:
        if fmt == "parquet":
            if chunk_rows is None:
                data = path.read_bytes()
                digest = hashlib.sha256(data).hexdigest()
                source: Any = pa.BufferReader(data)
                del data
            else:
                digest, source = sha256_file(path), path
            # pre-buffering would fetch every row group's bytes at once: memory would grow with the file
            parquet = pq.ParquetFile(source, pre_buffer=chunk_rows is None)
            # the columns are the data (spec §3.2); pandas' own metadata is neither needed nor trusted
            as_float64(arrow_frame(parquet.schema_arrow.empty_table()), label)
            return digest, _checked_chunks(_parquet_chunks(parquet, chunk_rows), fmt, label)
        digest = check_csv_grammar(path, columns, label)
    except (HaptifyError, MemoryError):  # out of memory is the reader's failure, not the file's (never E112)
        raise
    except _READ_ERRORS as exc:
        raise fail("E112", f"{label!r} cannot be read as {fmt}: {exc}", file=label) from None
    return digest, _checked_chunks(_csv_chunks(path, chunk_rows), fmt, label)


_READ_ERRORS = (OSError, pa.ArrowException, ValueError, pd.errors.ParserError, UnicodeDecodeError)


def _parquet_chunks(parquet: pq.ParquetFile, chunk_rows: int | None) -> Iterator[pd.DataFrame]:
    """A Parquet file's table whole, or batch by batch; an empty file yields its empty table."""
    if chunk_rows is None:
        yield arrow_frame(parquet.read())
        return
    empty = True
    for batch in parquet.iter_batches(batch_size=chunk_rows, use_pandas_metadata=False):
        empty = False
        yield arrow_frame(pa.Table.from_batches([batch]))
    if empty:
        yield arrow_frame(parquet.schema_arrow.empty_table())


def arrow_frame(table: pa.Table) -> pd.DataFrame:
    """A decoded Parquet table as the float64 frame of spec §3.2: every column copied once into one
    (columns × rows) float64 block, float32 columns widened exactly, nulls as NaN — what
    ``to_pandas`` then :func:`as_float64` give, without pandas' per-call conversion machinery. A table
    with a column of any other type (or a float32 ``t``) goes through ``to_pandas``, so that
    :func:`as_float64` reports it (E212)."""
    if not all(pa.types.is_float64(f.type) or (pa.types.is_float32(f.type) and f.name != "t") for f in table.schema):
        return table.to_pandas(ignore_metadata=True)
    block = np.empty((table.num_columns, table.num_rows))
    for row, column in zip(block, table.columns):
        row[:] = column.to_numpy()
    return pd.DataFrame(block.T, columns=table.column_names, copy=False)


def _csv_chunks(path: Path, chunk_rows: int | None) -> Iterator[pd.DataFrame]:
    """A CSV stream's table whole, or ``chunk_rows`` lines at a time (a header-only file: one empty chunk)."""
    options: dict[str, Any] = {"dtype": "float64", "na_values": ["NaN"], "keep_default_na": False, "engine": "c"}
    if chunk_rows is None:
        yield pd.read_csv(path, **options)
    else:
        with pd.read_csv(path, chunksize=chunk_rows, **options) as reader:
            yield from reader


def _checked_chunks(chunks: Iterator[pd.DataFrame], fmt: str, label: str) -> Iterator[pd.DataFrame]:
    """``chunks`` as float64 frames (:func:`as_float64`); a read failure on the way is E112."""
    try:
        for chunk in chunks:
            yield as_float64(chunk, label)
    except (HaptifyError, MemoryError):
        raise
    except _READ_ERRORS as exc:
        raise fail("E112", f"{label!r} cannot be read as {fmt}: {exc}", file=label) from None


def as_float64(frame: pd.DataFrame, label: str) -> pd.DataFrame:
    """The stream table as float64 columns (spec §3.2): ``t`` must be float64; any other column may also
    be a compact float32 column, widened exactly. Any other type is E212."""
    dtypes = list(zip(frame.columns.tolist(), frame.dtypes.tolist()))
    for name, dtype in dtypes:
        if dtype == np.float64 or (dtype == np.float32 and name != "t"):
            continue
        expected = "float64" if name == "t" else "float64 or float32"
        raise fail(
            "E212",
            f"column {name!r} of {label!r} is {dtype}, not {expected}",
            file=label,
            column=str(name),
            expected=expected,
            found=str(dtype),
        )
    narrow = [name for name, dtype in dtypes if dtype == np.float32]
    return frame.astype({name: np.float64 for name in narrow}) if narrow else frame


# --- CSV grammar (spec §3.2) --------------------------------------------------------------------------

CSV_FIELD = re.compile(rb"(?<![^,\n])(?:NaN|-?[0-9]+(?:\.[0-9]*)?(?:[eE][+-]?[0-9]+)?)(?![^,\r\n])")
CSV_FIELD_TEXT = re.compile(r"NaN|-?[0-9]+(?:\.[0-9]*)?(?:[eE][+-]?[0-9]+)?")
CSV_CHUNK_BYTES = 8 * 2**20
CSV_FIELD_MAX_CHARS = 32  # the longest field §3.2 allows: 17 significant digits, sign, point, exponent


def csv_line_limit(columns: list[str]) -> int:
    """The longest line (bytes, line end included) a CSV stream with ``columns`` can hold (spec §3.2):
    ``n`` fields of at most :data:`CSV_FIELD_MAX_CHARS`, ``n − 1`` commas and CR LF — or the header's
    names, commas and line end when they are longer."""
    n = len(columns)
    names = sum(len(c.encode("utf-8")) for c in columns)
    return max(names, CSV_FIELD_MAX_CHARS * n) + n + 1


def check_csv_grammar(path: Path, columns: list[str], label: str) -> str:
    r"""Check a CSV stream against the grammar of spec §3.2 and return the sha256 of its bytes.

    The header must list ``columns`` (E211). Every line after it holds exactly ``len(columns)`` fields,
    each ``NaN`` or a decimal number ``-?[0-9]+(\.[0-9]*)?([eE][+-]?[0-9]+)?`` — no sign '+', quotes,
    spaces, empty fields, ``inf`` or blank lines — and ends in ``\n`` or ``\r\n`` (the last line's end
    optional); the first line that does not is E112. The file is scanned in chunks of whole lines (every
    valid field is replaced by ``x``, so a sound line reads ``x,x,…,x``); a line longer than
    :func:`csv_line_limit` is E112 as soon as it is seen, so memory stays bounded whatever the content.
    """
    sound = b",".join([b"x"] * len(columns))
    allowed = {sound, sound + b"\r"}
    limit = csv_line_limit(columns)
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        header = fh.readline(limit + 1)
        digest.update(header)
        _check_csv_header(header, columns, label, limit)
        line_no, rest = 1, b""
        while True:
            block = fh.read(CSV_CHUNK_BYTES)
            digest.update(block)
            data = rest + block
            if block:
                cut = data.rfind(b"\n") + 1
                data, rest = data[:cut], data[cut:]
                if len(rest) > limit:
                    long_line = line_no + data.count(b"\n") + 1
                    raise fail(
                        "E112",
                        f"line {long_line} of {label!r} is longer than the {limit} bytes "
                        f"a line of {len(columns)} numbers can take",
                        file=label,
                        expected=f"at most {limit} bytes per line",
                        found=f"more than {len(rest)} bytes",
                    )
            else:
                rest = b""
            if data:
                lines = CSV_FIELD.sub(b"x", data).split(b"\n")
                if data.endswith(b"\n"):
                    lines.pop()
                if not set(lines) <= allowed:
                    k = next(i for i, line in enumerate(lines) if line not in allowed)
                    _csv_line_error(data.split(b"\n")[k], line_no + k + 1, columns, label)
                line_no += len(lines)
            if not block:
                return digest.hexdigest()


def _check_csv_header(header: bytes, columns: list[str], label: str, limit: int) -> None:
    r"""The header line names exactly ``columns`` and ends in ``\n`` or ``\r\n`` (E211, E112; spec §3.2)."""
    if len(header) > limit:
        raise fail(
            "E211",
            f"the header line of {label!r} is longer than the {limit} bytes its columns take",
            file=label,
            expected=columns,
            found=f"more than {limit} bytes",
        )
    body = header.removesuffix(b"\n").removesuffix(b"\r")
    if b"\r" in body:
        raise fail(
            "E112",
            f"{label!r} ends a line with a lone carriage return",
            file=label,
            expected="lines ending in \\n or \\r\\n",
            found="\\r",
        )
    found = body.decode("utf-8", errors="replace").split(",")
    if found != columns:
        raise fail(
            "E211",
            f"CSV header of {label!r} differs from the declared columns",
            file=label,
            expected=columns,
            found=[_short_text(f) for f in found[: len(columns) + 2]],
        )


def _csv_line_error(raw: bytes, line_no: int, columns: list[str], label: str) -> None:
    """Raise E112 naming the line, the column and the first field of ``raw`` outside the grammar."""
    text = raw.decode("utf-8", errors="replace").removesuffix("\r")
    fields = text.split(",")
    if text == "":
        raise fail(
            "E112",
            f"line {line_no} of {label!r} is blank",
            file=label,
            expected="one sample per line, no blank lines",
            found="a blank line",
        )
    if len(fields) != len(columns):
        raise fail(
            "E112",
            f"line {line_no} of {label!r} has {len(fields)} fields, not {len(columns)}",
            file=label,
            expected=len(columns),
            found=len(fields),
        )
    k = next((i for i, f in enumerate(fields) if not CSV_FIELD_TEXT.fullmatch(f)), 0)
    raise fail(
        "E112",
        f"line {line_no} of {label!r}: field {_short_text(fields[k])!r} is not a number as spec §3.2 writes it",
        file=label,
        column=columns[k],
        expected="NaN or -?[0-9]+(.[0-9]*)?([eE][+-]?[0-9]+)?",
        found=_short_text(fields[k]),
    )


def _short_text(text: str) -> str:
    """``text`` cut to 80 characters for a finding's ``found``."""
    return text if len(text) <= 80 else text[:77] + "..."


def open_session(path: str | os.PathLike[str]) -> SessionFolder:
    """Open a session folder and parse its manifest (E101–E105); streams are read lazily (spec §3.1)."""
    root = Path(path)
    if not root.is_dir():
        raise fail("E101", f"{str(root)!r} is not a session folder", file=str(root))
    manifest_path = root / MANIFEST
    if not manifest_path.is_file():
        raise fail("E102", f"no {MANIFEST} in {str(root)!r}", file=MANIFEST)
    raw = parse_json_file(manifest_path, "E103", MANIFEST)
    if isinstance(raw, dict) and raw.get("spec_version") not in (None, SPEC_VERSION):
        raise fail(
            "E105",
            f"spec version {raw.get('spec_version')!r} is not supported",
            file=MANIFEST,
            pointer="/spec_version",
            expected=SPEC_VERSION,
            found=raw.get("spec_version"),
        )
    try:
        manifest = Session.model_validate(raw)
    except ValidationError as exc:
        raise HaptifyError(*pydantic_findings(exc, "E104", MANIFEST)) from None
    return SessionFolder(root, manifest, raw)


# --- writing -----------------------------------------------------------------------------------


def write_table(path: Path, frame: pd.DataFrame, fmt: str, *, compact: bool = False) -> None:
    """Write a float64 table as Parquet (zstd) or CSV (shortest round-trip decimal, NaN as 'NaN'), spec §3.2.

    Parquet columns are PLAIN-encoded: dictionary encoding never pays off for measured floats and makes
    files larger and reading slower (benchmarks/RESULTS.md, session I/O). ``compact`` (Parquet only, spec §3.2.1)
    stores every column but ``t`` as float32 with the BYTE_STREAM_SPLIT encoding, which zstd compresses
    far better than interleaved bytes (sizes in benchmarks/RESULTS.md).
    """
    if fmt == "parquet":
        table, narrow = _arrow_table(frame, compact)
        # pyarrow-stubs type this argument bool; pyarrow takes a list of columns too (its docstring)
        pq.write_table(table, path, **_PARQUET_OPTIONS, use_byte_stream_split=narrow or False)  # type: ignore[arg-type]
    else:
        frame.to_csv(path, index=False, na_rep="NaN", float_format=None, lineterminator="\n")


class _ParquetOptions(TypedDict):
    compression: Literal["zstd"]
    use_dictionary: bool


_PARQUET_OPTIONS: _ParquetOptions = {"compression": "zstd", "use_dictionary": False}


def _arrow_table(frame: pd.DataFrame, compact: bool) -> tuple[pa.Table, list[str]]:
    """The Arrow table :func:`write_table` writes, and its narrowed (float32) columns."""
    table = pa.Table.from_pandas(frame, preserve_index=False)
    narrow = [c for c in table.column_names if c != "t"] if compact else []
    if narrow:
        table = table.cast(pa.schema([pa.field(c, pa.float32() if c in narrow else pa.float64()) for c in table.column_names]))
    return table, narrow


class TableSink:
    """A stream file written in pieces (spec §3.2, §5.5.1): each :meth:`write` appends rows — one Parquet
    row group, or CSV lines after the header the first piece writes — with the encoding of
    :func:`write_table`; :meth:`close` finishes the file and returns its row count."""

    def __init__(self, path: Path, fmt: str, compact: bool = False) -> None:
        self.path, self.fmt, self.compact, self.rows = Path(path), fmt, compact, 0
        self._parquet: pq.ParquetWriter | None = None

    def write(self, frame: pd.DataFrame) -> None:
        if self.fmt == "parquet":
            table, narrow = _arrow_table(frame, self.compact)
            if self._parquet is None:
                self._parquet = pq.ParquetWriter(
                    self.path, table.schema, **_PARQUET_OPTIONS, use_byte_stream_split=narrow or False
                )
            self._parquet.write_table(table)
        else:
            frame.to_csv(
                self.path,
                mode="a" if self.rows else "w",
                header=not self.rows,
                index=False,
                na_rep="NaN",
                float_format=None,
                lineterminator="\n",
            )
        self.rows += len(frame)

    def close(self) -> int:
        if self._parquet is not None:
            self._parquet.close()
        return self.rows


def write_atomically(path: Path, writer: Callable[[str], Any]) -> None:
    """Run ``writer(tmp_path)`` on a temporary file beside ``path``, then rename it onto ``path`` (spec §3.6).

    An exception (or an interruption) leaves ``path`` as it was and removes the temporary file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent)
    os.close(fd)
    try:
        writer(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """Write a text file atomically, flushed to disk before the rename (spec §3.6)."""

    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())

    write_atomically(path, write)


def atomic_write_json(path: Path, payload: Any) -> None:
    """Write ``payload`` as UTF-8 JSON (2-space indent, final newline) atomically (spec §3.6; via :func:`atomic_write_text`)."""
    atomic_write_text(path, json.dumps(payload, indent=2, ensure_ascii=False) + "\n")


def replace_folder_atomically(build: Path, target: Path, overwrite: bool) -> None:
    """Move a fully written ``build`` folder to ``target`` (E901 when it exists and not ``overwrite``).
    Spec §3.6."""
    if target.exists():
        if not overwrite:
            shutil.rmtree(build, ignore_errors=True)
            raise fail("E901", f"{str(target)!r} already exists", file=str(target))
        old = target.parent / f".{target.name}.old-{uuid.uuid4().hex[:8]}"
        os.replace(target, old)
        os.replace(build, target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(build, target)


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
        cols = expected_columns(kind, entities, present)
        missing = [c for c, _ in cols if c not in present]
        if missing:
            raise fail(
                "E201",
                f"{kind} stream of trial {trial_id!r} lacks columns {missing}",
                column=missing[0],
                expected=[c for c, _ in cols],
                found=present,
            )
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
        cols = expected_columns(kind, entities, columns)
        missing = [c for c, _ in cols if c not in columns]
        if missing:
            raise fail(
                "E201",
                f"{kind} stream of trial {trial_id!r} lacks columns {missing}",
                column=missing[0],
                expected=[c for c, _ in cols],
                found=columns,
            )
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
            raise fail("E901", f"{str(target)!r} already exists", file=str(target))
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
                raise HaptifyError(*pydantic_findings(exc, "E104", MANIFEST)) from None
            atomic_write_json(build / MANIFEST, manifest)
            replace_folder_atomically(build, target, overwrite)
        except BaseException:
            shutil.rmtree(build, ignore_errors=True)
            raise
        return target
