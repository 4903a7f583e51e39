"""Edits of a written fixture session folder and the extra trials some fixtures add (spec §4.7 fixtures).

Read and write ``session.json``, find a trial or a stream, replace a stream's table (updating rows and
sha256 unless told otherwise), drop a stream or set a column; build the small stream tables (wrench, pose,
markers, link poses) and add an active stiffness trial (with its rendering, spec §2.5) or a workspace trial
with markers to an example session writer."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from haptify.formats.storage import MANIFEST, SessionWriter, atomic_write_json, read_table, sha256_file, write_table

DURATION_S = 0.2
TRIAL = "free_space-1"


def manifest(folder: Path) -> dict:
    return json.loads((folder / MANIFEST).read_text(encoding="utf-8"))


def save_manifest(folder: Path, m: dict) -> None:
    atomic_write_json(folder / MANIFEST, m)


def edit(folder: Path, fn: Callable[[dict], Any]) -> None:
    """Apply ``fn`` to the parsed session.json and write it back."""
    m = manifest(folder)
    fn(m)
    save_manifest(folder, m)


def trial_of(m: dict, trial_id: str = TRIAL) -> dict:
    return next(t for t in m["trials"] if t["id"] == trial_id)


def stream_of(m: dict, kind: str, trial_id: str = TRIAL) -> dict:
    return next(s for s in trial_of(m, trial_id)["streams"] if s["kind"] == kind)


def rewrite_data(
    folder: Path, kind: str, fn: Callable[[pd.DataFrame], pd.DataFrame], *, rehash: bool = True, trial_id: str = TRIAL
) -> None:
    """Replace a stream's table by ``fn(table)``; update rows and sha256 unless ``rehash`` is False."""
    m = manifest(folder)
    s = stream_of(m, kind, trial_id)
    path = folder / s["file"]
    table = fn(read_table(path, s["format"], [c["name"] for c in s["columns"]], label=s["file"]).copy())
    write_table(path, table, s["format"])
    if rehash:
        s["rows"] = int(len(table))
        s["sha256"] = sha256_file(path)
    save_manifest(folder, m)


def rehash(folder: Path, kind: str, trial_id: str = TRIAL) -> None:
    """Set a stream's sha256 to its file's current checksum (so only the intended defect shows)."""
    edit(folder, lambda m: stream_of(m, kind, trial_id).update(sha256=sha256_file(folder / stream_of(m, kind, trial_id)["file"])))


def drop_stream(folder: Path, kind: str, trial_id: str = TRIAL) -> None:
    m = manifest(folder)
    t = trial_of(m, trial_id)
    s = stream_of(m, kind, trial_id)
    t["streams"].remove(s)
    (folder / s["file"]).unlink()
    save_manifest(folder, m)


def set_column(kind: str, column: str, rows: slice | list[int], value: float) -> Callable[[pd.DataFrame], pd.DataFrame]:
    def fn(df: pd.DataFrame) -> pd.DataFrame:
        values = df[column].to_numpy().copy()
        values[rows] = value
        df[column] = values
        return df

    return fn


def _t(n: int, rate: float) -> np.ndarray:
    return np.arange(n) / rate


def _wrench(n: int, rate: float = 1000.0) -> dict:
    t = _t(n, rate)
    return {"t": t, "fx": 0.1 * np.sin(2 * np.pi * 5 * t), "fy": 0 * t, "fz": -2.0 + 0 * t, "tx": 0 * t, "ty": 0 * t, "tz": 0 * t}


def _pose(n: int, rate: float = 100.0) -> dict:
    t = _t(n, rate)
    return {"t": t, "px": 0.01 * t, "py": 0 * t, "pz": 0.08 + 0 * t, "qw": 1 + 0 * t, "qx": 0 * t, "qy": 0 * t, "qz": 0 * t}


def _markers(entities: list[str], n: int = 20, rate: float = 100.0) -> dict:
    t = _t(n, rate)
    cols: dict = {"t": t}
    for k, ent in enumerate(entities):
        cols[f"{ent}_x"] = 0.01 * k + 0 * t
        cols[f"{ent}_y"] = 0.02 + 0 * t
        cols[f"{ent}_z"] = 0.1 + 0.001 * t
    return cols


def _link_poses(links: list[str], n: int = 20, rate: float = 100.0) -> dict:
    t = _t(n, rate)
    cols: dict = {"t": t}
    for k, link in enumerate(links):
        ang = 0.2 * np.sin(2 * np.pi * t) + 0.1 * k
        cols.update(
            {
                f"{link}_px": 0.05 * k + 0 * t,
                f"{link}_py": 0 * t,
                f"{link}_pz": 0.1 + 0 * t,
                f"{link}_qw": np.cos(ang / 2),
                f"{link}_qx": 0 * t,
                f"{link}_qy": np.sin(ang / 2),
                f"{link}_qz": 0 * t,
            }
        )
    return cols


RENDERING = {
    "surface_point_m": [0.0, 0.0, 0.05],
    "surface_normal": [0.0, 0.0, 1.0],
    "stiffness_N_per_m": 750.0,
    "static_friction": 0.0,
    "dynamic_friction": 0.0,
    "software": "CHAI3D 3.2",
    "loop_rate_hz": 1000.0,
}


def add_active_trial(
    w: SessionWriter, trial_id: str = "stiffness-1", rendering: dict | None = RENDERING, fmt: str = "parquet"
) -> None:
    """A short stiffness trial with its three required streams."""
    w.add_trial(trial_id, "stiffness", powered=True, rendering=rendering)
    n = int(DURATION_S * 1000)
    w.add_stream(trial_id, "handle_wrench", _wrench(n), rate_hz=1000, fmt=fmt)
    w.add_stream(trial_id, "handle_pose", _pose(int(DURATION_S * 100)), rate_hz=100, fmt=fmt)
    w.add_stream(trial_id, "commanded_wrench", _wrench(n), rate_hz=1000, fmt=fmt)


def add_markers_trial(w: SessionWriter, entities: list[str], trial_id: str = "workspace-1", fmt: str = "parquet") -> None:
    """A short workspace trial with handle_pose and a markers stream of ``entities``."""
    w.add_trial(trial_id, "workspace", powered=False)
    w.add_stream(trial_id, "handle_pose", _pose(int(DURATION_S * 100)), rate_hz=100, fmt=fmt)
    w.add_stream(trial_id, "markers", _markers(entities), rate_hz=100, fmt=fmt, entities=entities)
