"""The logical content of a fixture tree and its digest (spec §16.7): what ``haptify-conform --lint`` checks a
fixture against, and what the fixture builders record.

A fixture's bytes depend on the Parquet writer's version and on timestamps; its logical content does not:
:func:`logical_snapshot` describes a tree by parsed JSON, table values, symlink targets and other files'
bytes, :func:`snapshot_digest` hashes it, and :func:`trees_agree` compares two trees with numbers up to
:data:`AGREEMENT_RTOL`. The judge reads fixtures as data only: this module needs neither the reference nor
the tools.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

#: The file beside each fixture set recording every fixture's digest (written by the builders).
DIGESTS = "digests.json"
#: A session's manifest (spec §3.1).
MANIFEST = "session.json"


def snapshot_digest(folder: Path) -> str:
    """sha256 of a fixture's logical content (what the builders' ``--check`` and the linter compare)."""
    return hashlib.sha256(json.dumps(logical_snapshot(folder), sort_keys=True).encode()).hexdigest()


def _file_sha256(path: Path) -> str:
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def _inside(relative: str) -> bool:
    """Whether a manifest's file name stays inside the session (relative, '/', no '..'; spec §3.3)."""
    return (
        bool(relative)
        and not re.match(r"^([/\\]|[A-Za-z]:)", relative)
        and "\\" not in relative
        and all(part not in ("", ".", "..") for part in relative.split("/"))
    )


def _parquet_digest(path: Path, values: bool = False) -> Any:
    """Column names, types and value bits (or, with ``values``, the values) of a Parquet file; unreadable
    files are only marked so."""
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError, ValueError):
        return {"unreadable parquet": True}
    cols = {}
    for name, col in zip(table.column_names, table.columns):
        column = col.to_numpy(zero_copy_only=False)
        if column.dtype.kind not in "fiub":
            cols[name] = [str(col.type), column.tolist()]
        else:
            cols[name] = [str(col.type), column if values else hashlib.sha256(np.ascontiguousarray(column).tobytes()).hexdigest()]
    return {"parquet": cols, "rows": table.num_rows}


def _csv_tokens(raw: bytes) -> Any:
    """A CSV file as lines of fields, numbers parsed; bytes that are not UTF-8 only by their digest."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        return {"bytes": hashlib.sha256(raw).hexdigest()}

    def field(token: str) -> Any:
        try:
            return float(token)
        except ValueError:
            return token

    return {"csv": [[field(t) for t in line.split(",")] for line in text.split("\n")]}


def logical_snapshot(root: Path, values: bool = False) -> dict[str, Any]:
    """The content of a fixture tree independent of timestamps and of the Parquet writer's version.

    JSON files are parsed (each Parquet ``sha256`` replaced by whether it matches its file), Parquet files
    are described by their columns' types and value bits, symlinks by their target, other files by their
    bytes. With ``values`` the snapshot holds the numbers themselves (Parquet columns as arrays, CSV
    files as parsed fields, every stream ``sha256`` as whether it matches) for :func:`trees_agree`.
    """
    snap: dict[str, Any] = {}
    for path in sorted(root.rglob("*")):
        rel = path.relative_to(root).as_posix()
        if path.is_symlink():
            snap[rel] = {"symlink": os.readlink(path)}
        elif path.is_dir():
            continue
        elif path.suffix == ".json":
            raw = path.read_bytes()
            try:
                data = json.loads(raw.decode("utf-8"))
            except UnicodeDecodeError:  # the deliberately non-UTF-8 manifest
                try:
                    data = {"latin-1": json.loads(raw.decode("latin-1"))}
                except json.JSONDecodeError:
                    data = None
            except json.JSONDecodeError:
                data = None
            if data is None:
                snap[rel] = {"bytes": hashlib.sha256(raw).hexdigest()}
                continue
            snap[rel] = _checksums_as_matches(data, path.parent, every_format=values) if path.name == MANIFEST else data
        elif path.suffix == ".parquet":
            snap[rel] = _parquet_digest(path, values)
        elif path.suffix == ".csv" and values:
            snap[rel] = _csv_tokens(path.read_bytes())
        else:
            snap[rel] = {"bytes": hashlib.sha256(path.read_bytes()).hexdigest()}
    return snap


#: How far two builds' floating-point numbers may differ and still be the same fixture: relative to the
#: number (or to the largest finite magnitude of its table column). numpy's vectorised sin, exp and log
#: round differently on different CPUs, a few units in the last place that filters and sums carry on.
AGREEMENT_RTOL = 1e-9


def values_agree(x: Any, y: Any) -> bool:
    """Whether two snapshot values are equal, floating-point numbers and float arrays within AGREEMENT_RTOL."""
    if isinstance(x, dict) and isinstance(y, dict):
        return x.keys() == y.keys() and all(values_agree(x[k], y[k]) for k in x)
    if isinstance(x, list) and isinstance(y, list):
        return len(x) == len(y) and all(values_agree(a, b) for a, b in zip(x, y))
    if isinstance(x, np.ndarray) and isinstance(y, np.ndarray):
        if x.shape != y.shape or x.dtype != y.dtype:
            return False
        if x.dtype.kind != "f":
            return bool(np.array_equal(x, y))
        finite = np.isfinite(y)
        scale = float(np.max(np.abs(y[finite]), initial=0.0))
        return bool(
            np.array_equal(finite, np.isfinite(x))
            and np.array_equal(x[~finite], y[~finite], equal_nan=True)
            and np.all(np.abs(x[finite] - y[finite]) <= AGREEMENT_RTOL * scale)
        )
    if isinstance(x, float) and isinstance(y, float):
        return x == y or (math.isnan(x) and math.isnan(y)) or math.isclose(x, y, rel_tol=AGREEMENT_RTOL)
    return type(x) is type(y) and x == y


def trees_agree(a: Path, b: Path) -> bool:
    """Whether two fixture trees hold the same content, numbers up to AGREEMENT_RTOL (see logical_snapshot)."""
    return values_agree(logical_snapshot(a, values=True), logical_snapshot(b, values=True))


def _checksums_as_matches(manifest_data: Any, folder: Path, every_format: bool = False) -> Any:
    """Replace the sha256 of Parquet streams (whose bytes depend on the writer's version) by whether it
    matches the file; CSV bytes are deterministic and keep their checksum unless ``every_format``."""
    if not isinstance(manifest_data, dict):
        return manifest_data
    data = json.loads(json.dumps(manifest_data))
    if "latin-1" in data:
        return {"latin-1": _checksums_as_matches(data["latin-1"], folder, every_format)}
    for trial in data.get("trials", []) if isinstance(data.get("trials"), list) else []:
        for s in trial.get("streams", []) if isinstance(trial, dict) else []:
            if not (isinstance(s, dict) and isinstance(s.get("sha256"), str) and isinstance(s.get("file"), str)):
                continue
            path = folder / s["file"]
            readable = _inside(s["file"]) and not path.is_symlink() and path.is_file()
            replaced = every_format or s.get("format") == "parquet"
            if readable and replaced:
                s["sha256"] = "matches" if _file_sha256(path) == s["sha256"] else "differs"
            elif replaced:
                s["sha256"] = "no readable file"
    return data
