"""The files a simulated dossier is written with (design §4): a folder built beside its target and renamed in
one step, and the truth arrays as a compressed ``.npz`` (float32 except the time base) with plain-JSON values."""

from __future__ import annotations

import os
import shutil
import tempfile
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np


@contextmanager
def built_in_place(out: Path) -> Iterator[Path]:
    """A fresh folder beside ``out`` to build in; when the block ends normally it replaces ``out`` in one rename,
    otherwise it is removed, so an interrupted run leaves nothing half-written (spec §3.6)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    build = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    try:
        yield build
        if out.exists():
            shutil.rmtree(out)
        os.replace(build, out)
    except BaseException:
        shutil.rmtree(build, ignore_errors=True)
        raise


def write_npz(path: Path, arrays: dict[str, np.ndarray], level: int = 1) -> None:
    """Write arrays as a deflate-compressed ``.npz`` (readable by ``numpy.load``) at a fast compression level."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=level) as zf:
        for name, arr in arrays.items():
            with zf.open(name + ".npy", "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.asarray(arr), allow_pickle=False)


def _truth_array(key: str, value) -> np.ndarray:
    """Truth arrays in float32 (ample for SI signals of this size: 0.1 µm at 1 m), except the time base."""
    arr = np.asarray(value)
    return arr.astype(np.float32) if arr.dtype == np.float64 and key != "t" else arr


def _jsonable(obj):
    """Numbers and arrays as plain JSON values (NaN never occurs in the truth)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    return obj
