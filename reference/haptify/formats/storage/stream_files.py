"""Stream files (spec §3.2, §3.2.1, §3.4): reading a Parquet or CSV stream as float64 columns, whole or chunk by
chunk and hashed as it is read, and writing one, whole or in pieces.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, Iterator, Literal, TypedDict

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.storage.csv_grammar import check_csv_grammar
from haptify.formats.storage.paths import sha256_file


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
        raise fail(Code.STREAM_UNREADABLE, f"{label!r} cannot be read as {fmt}: {exc}", file=label) from None
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
        raise fail(Code.STREAM_UNREADABLE, f"{label!r} cannot be read as {fmt}: {exc}", file=label) from None
    return digest, _checked_chunks(_csv_chunks(path, chunk_rows), fmt, label)


_READ_ERRORS = (OSError, pa.ArrowException, ValueError, pd.errors.ParserError, UnicodeDecodeError)


def _parquet_chunks(parquet: pq.ParquetFile, chunk_rows: int | None) -> Iterator[pd.DataFrame]:
    """A Parquet file's table whole, or batch by batch; an empty file yields its empty table."""
    if chunk_rows is None:
        yield arrow_frame(parquet.read(use_threads=False))
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
        raise fail(Code.STREAM_UNREADABLE, f"{label!r} cannot be read as {fmt}: {exc}", file=label) from None


def as_float64(frame: pd.DataFrame, label: str) -> pd.DataFrame:
    """The stream table as float64 columns (spec §3.2): ``t`` must be float64; any other column may also
    be a compact float32 column, widened exactly. Any other type is E212."""
    dtypes = list(zip(frame.columns.tolist(), frame.dtypes.tolist()))
    for name, dtype in dtypes:
        if dtype == np.float64 or (dtype == np.float32 and name != "t"):
            continue
        expected = "float64" if name == "t" else "float64 or float32"
        raise fail(
            Code.COLUMN_NOT_NUMERIC,
            f"column {name!r} of {label!r} is {dtype}, not {expected}",
            file=label,
            column=str(name),
            expected=expected,
            found=str(dtype),
        )
    narrow = [name for name, dtype in dtypes if dtype == np.float32]
    return frame.astype({name: np.float64 for name in narrow}) if narrow else frame


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
