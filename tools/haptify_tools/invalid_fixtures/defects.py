"""The deliberate defects of the bad-input fixtures (spec §4.7): each function breaks one thing of a written
session folder (or extends a session writer) so that validation must report the codes its case states —
truncated or re-encoded files, wrong types and missing keys, disordered or jittered times, bad quaternions,
wrong columns, broken CSV text, duplicated trials or streams, a missing or invalid device file, NaN markers
and a sync stream."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Callable, TypeVar

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from haptify.formats.storage import MANIFEST, SessionWriter, atomic_write_json
from haptify_tools.invalid_fixtures.session_edits import (
    DURATION_S,
    TRIAL,
    _pose,
    _t,
    _wrench,
    edit,
    manifest,
    rehash,
    rewrite_data,
    save_manifest,
    set_column,
    stream_of,
    trial_of,
)

_On = TypeVar("_On")


def _in_turn(*steps: Callable[[_On], object]) -> Callable[[_On], None]:
    """One mutation (or extension) made of ``steps`` applied in order to the same folder (or writer)."""

    def run(target: _On) -> None:
        for step in steps:
            step(target)

    return run


def _truncate(folder: Path, kind: str, keep: float) -> None:
    m = manifest(folder)
    path = folder / stream_of(m, kind)["file"]
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    rehash(folder, kind)


def _replace_text(folder: Path, rel: str, old: str, new: str, count: int = 1) -> None:
    path = folder / rel
    text = path.read_text(encoding="utf-8")
    assert old in text, (rel, old)
    path.write_text(text.replace(old, new, count), encoding="utf-8")


def _symlink_stream(folder: Path, kind: str, target: str) -> None:
    m = manifest(folder)
    path = folder / stream_of(m, kind)["file"]
    path.unlink()
    os.symlink(target, path)


def _manifest_malformed(folder: Path) -> None:
    text = (folder / MANIFEST).read_text(encoding="utf-8")
    (folder / MANIFEST).write_text(text[: len(text) // 2], encoding="utf-8")


def _manifest_latin1(folder: Path) -> None:
    text = (folder / MANIFEST).read_text(encoding="utf-8").replace('"ex-01"', '"ex-\u00e901"')
    (folder / MANIFEST).write_bytes(text.encode("latin-1"))


def _wrong_types(m: dict) -> None:
    t = trial_of(m)
    t["repetition"] = "one"
    t["powered"] = "yes"
    stream_of(m, "handle_wrench")["rate_hz"] = "fast"


def _drop_keys(m: dict) -> None:
    del m["session_id"]
    del m["examiner"]


def _swap_times(df: pd.DataFrame) -> pd.DataFrame:
    t = df["t"].to_numpy().copy()
    t[50], t[51] = t[51], t[50]
    df["t"] = t
    return df


def _jitter(df: pd.DataFrame) -> pd.DataFrame:
    t = df["t"].to_numpy().copy()
    t[50] += 0.0006  # the intervals around it become 1.6 ms and 0.4 ms: outside [0.5, 1.5] ms
    t[120] -= 0.0006
    df["t"] = t
    return df


def _retime(rate: float) -> Callable[[pd.DataFrame], pd.DataFrame]:
    def fn(df: pd.DataFrame) -> pd.DataFrame:
        df["t"] = np.arange(len(df)) / rate
        return df

    return fn


def _shift_time(seconds: float) -> Callable[[pd.DataFrame], pd.DataFrame]:
    def fn(df: pd.DataFrame) -> pd.DataFrame:
        df["t"] = df["t"].to_numpy() + seconds
        return df

    return fn


def _scale_quaternions(df: pd.DataFrame) -> pd.DataFrame:
    for c in ("qw", "qx", "qy", "qz"):
        v = df[c].to_numpy().copy()
        v[5:10] *= 1.1
        df[c] = v
    return df


def _int_column(folder: Path) -> None:
    m = manifest(folder)
    s = stream_of(m, "handle_wrench")
    path = folder / s["file"]
    table = pq.read_table(path)
    fx = pa.array(np.round(table.column("fx").to_numpy() * 100).astype(np.int64))
    pq.write_table(table.set_column(table.schema.get_field_index("fx"), "fx", fx), path, compression="zstd")
    rehash(folder, "handle_wrench")


def _drop_file_column(folder: Path) -> None:
    m = manifest(folder)
    s = stream_of(m, "handle_wrench")
    path = folder / s["file"]
    table = pq.read_table(path)
    pq.write_table(table.drop(["tz"]), path, compression="zstd")
    rehash(folder, "handle_wrench")


def _drop_declared_and_file_column(folder: Path) -> None:
    _drop_file_column(folder)
    edit(folder, lambda m: stream_of(m, "handle_wrench")["columns"].pop())


def _csv_header(folder: Path) -> None:
    rel = stream_of(manifest(folder), "handle_wrench")["file"]
    _replace_text(folder, rel, "t,fx,fy,fz,tx,ty,tz\n", "time,Fx,Fy,Fz,Tx,Ty,Tz\n")
    rehash(folder, "handle_wrench")


def _csv_text_value(folder: Path) -> None:
    rel = stream_of(manifest(folder), "handle_accel")["file"]
    lines = (folder / rel).read_text(encoding="utf-8").split("\n")
    fields = lines[7].split(",")
    fields[3] = "nine point eight"
    lines[7] = ",".join(fields)
    (folder / rel).write_text("\n".join(lines), encoding="utf-8")
    rehash(folder, "handle_accel")


def _csv_edit_line(kind: str, row: int, fn: Callable[[str], str]) -> Callable[[Path], None]:
    """Replace data line ``row`` (0 = first sample) of a CSV stream by ``fn(line)`` and rehash the file."""

    def edit_line(folder: Path) -> None:
        rel = stream_of(manifest(folder), kind)["file"]
        lines = (folder / rel).read_text(encoding="utf-8").split("\n")
        lines[1 + row] = fn(lines[1 + row])
        (folder / rel).write_text("\n".join(lines), encoding="utf-8")
        rehash(folder, kind)

    return edit_line


def _csv_nul_bytes(folder: Path) -> None:
    """handle_pose's CSV file replaced by NUL bytes with no line end, as much as its declared rows allow."""
    rel = stream_of(manifest(folder), "handle_pose")["file"]
    path = folder / rel
    path.write_bytes(b"\0" * path.stat().st_size * 4)
    rehash(folder, "handle_pose")


def _oversized(folder: Path) -> None:
    """A CSV handle_pose declared with 20 rows whose file is padded far beyond what 20 rows need."""
    rel = stream_of(manifest(folder), "handle_pose")["file"]
    path = folder / rel
    text = path.read_text(encoding="utf-8")
    path.write_text(text + "# padding\n" * 4000, encoding="utf-8")
    rehash(folder, "handle_pose")


def _empty(rows: int) -> Callable[[pd.DataFrame], pd.DataFrame]:
    return lambda df: df.iloc[:rows].reset_index(drop=True)


def _duplicate_trial_writer(w: SessionWriter) -> None:
    w.add_trial("free_space-2", "free_space", powered=False, repetition=2)
    n = int(DURATION_S * 1000)
    w.add_stream("free_space-2", "handle_wrench", _wrench(n), rate_hz=1000)
    accel = {"t": _t(2 * n, 2000.0), "ax": np.zeros(2 * n), "ay": np.zeros(2 * n), "az": np.full(2 * n, 9.81)}
    w.add_stream("free_space-2", "handle_accel", accel, rate_hz=2000)
    w.add_stream("free_space-2", "handle_pose", _pose(int(DURATION_S * 100)), rate_hz=100)
    plate = {"t": _t(n, 1000.0), **{f"c{i}_{c}": np.zeros(n) for i in range(1, 5) for c in ("fx", "fy", "fz", "tx", "ty", "tz")}}
    w.add_stream("free_space-2", "plate_wrench", plate, rate_hz=1000)


def _second_wrench(folder: Path) -> None:
    m = manifest(folder)
    s = dict(stream_of(m, "handle_wrench"))
    copy = "trials/free_space-1/handle_wrench-2.parquet"
    shutil.copyfile(folder / s["file"], folder / copy)
    s["file"] = copy
    trial_of(m)["streams"].append(s)
    save_manifest(folder, m)


def _several(folder: Path) -> None:
    rewrite_data(folder, "handle_wrench", _swap_times)
    rewrite_data(folder, "handle_accel", set_column("handle_accel", "ax", slice(10, 12), float("nan")))
    (folder / stream_of(manifest(folder), "handle_pose")["file"]).unlink()
    m = manifest(folder)
    s = stream_of(m, "plate_wrench")
    trial_of(m)["streams"].remove(s)
    (folder / s["file"]).unlink()
    save_manifest(folder, m)


def _device_file(content: dict | None, ref: str = "device.json") -> Callable[[Path], None]:
    def fn(folder: Path) -> None:
        m = manifest(folder)
        device = m["device"]
        m["device"] = {"file": ref}
        save_manifest(folder, m)
        if content is not None:
            atomic_write_json(folder / "device.json", {**device, **content})

    return fn


def _markers_nan(rows: slice, columns: list[str]) -> Callable[[Path], None]:
    def fn(folder: Path) -> None:
        for c in columns:
            rewrite_data(folder, "markers", set_column("markers", c, rows, float("nan")), trial_id="workspace-1")

    return fn


def _joint(m: dict, name: str) -> dict:
    return next(j for j in m["device"]["kinematics"]["joints"] if j["name"] == name)


def _sync_trial(values: Callable[[np.ndarray], np.ndarray]) -> Callable[[SessionWriter], None]:
    """Add a 1 kHz ``sync`` stream with ``trigger = values(t)`` to the free-space trial."""

    def fn(w: SessionWriter) -> None:
        t = _t(int(DURATION_S * 1000), 1000.0)
        w.add_stream(TRIAL, "sync", {"t": t, "trigger": values(t)}, rate_hz=1000)

    return fn
