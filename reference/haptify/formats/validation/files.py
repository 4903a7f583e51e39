"""Files inside the session folder (spec §4.2, §3.5): a path is a regular file within its size bound
(E110/E102/E106 missing, E112 not a regular file or unreadable footer, E113 too large) before anything of
it is read."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError

# --- size limits of spec §4.2 and §3.5 (E113) ----------------------------------------------------
MANIFEST_MAX_BYTES = 16 * 2**20  # session.json larger than this is not read (E113)
DEVICE_MAX_BYTES = 4 * 2**20  # device.json larger than this is not read (E113)
STREAM_MAX_BYTES = 8 * 2**30  # spec §3.5: no stream file exceeds 8 GiB (E113)
STREAM_BYTES_BASE = 16 * 2**10  # plausibility bound of a stream file's size from its declared
STREAM_BYTES_PER_COLUMN = 2**10  # rows and columns: base + per column + per value (E113), so a
STREAM_BYTES_PER_VALUE = 32  # tiny declared stream never makes the validator read gigabytes


def regular_file(path: Path, label: str, missing_code: Code, missing_text: str, limit: int) -> int:
    """``lstat`` a resolved path: its size when it is a regular file within ``limit``; coded errors otherwise."""
    try:
        st = os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise HaptifyError(Finding(missing_code, missing_text, file=label)) from None
    except OSError as exc:
        raise HaptifyError(Finding(Code.STREAM_UNREADABLE, f"{label!r} cannot be examined: {exc.strerror}", file=label)) from None
    if not stat.S_ISREG(st.st_mode):
        raise HaptifyError(
            Finding(
                Code.STREAM_UNREADABLE,
                f"{label!r} is not a regular file",
                file=label,
                expected="a regular file",
                found="a folder" if stat.S_ISDIR(st.st_mode) else "a special file",
            )
        )
    if st.st_size > limit:
        raise HaptifyError(
            Finding(
                Code.DECLARED_SIZE_ABSURD,
                f"{label!r} is {st.st_size} bytes, more than the {limit} bytes allowed",
                file=label,
                expected=f"at most {limit} bytes",
                found=st.st_size,
            )
        )
    return st.st_size


def stream_size_limit(columns: int, rows: int, row_groups: int = 1) -> int:
    """The largest plausible size (bytes) of a stream file with ``columns`` × ``rows`` declared values
    and ``row_groups`` Parquet row groups (1 for CSV): min(8 GiB, 16 KiB + C · (1 KiB · G + 32 B · R)),
    spec §4.2 (E113)."""
    return min(
        STREAM_MAX_BYTES, STREAM_BYTES_BASE + columns * (STREAM_BYTES_PER_COLUMN * row_groups + STREAM_BYTES_PER_VALUE * rows)
    )


def parquet_footer(path: Path, label: str, rows: int) -> tuple[int, int]:
    """The numbers of row groups and rows a Parquet file's footer declares (E112 unreadable; E113 more row
    groups than declared rows, since every row group but an empty file's holds a row; spec §4.2). The
    row count bounds what decoding the file can hold (its columns are fixed-width)."""
    try:
        footer = pq.read_metadata(path)
        groups = footer.num_row_groups
    except MemoryError:
        raise
    except (OSError, pa.ArrowException, ValueError) as exc:
        raise HaptifyError(Finding(Code.STREAM_UNREADABLE, f"{label!r} cannot be read as parquet: {exc}", file=label)) from None
    if groups > max(1, rows):
        raise HaptifyError(
            Finding(
                Code.DECLARED_SIZE_ABSURD,
                f"{label!r} declares {groups} row groups for {rows} rows",
                file=label,
                expected=f"at most {max(1, rows)} row groups",
                found=groups,
            )
        )
    return max(1, groups), footer.num_rows
