"""Build the bad-input fixtures ``fixtures/invalid/`` and the small valid sessions ``fixtures/valid/`` (spec §4.7).

Every invalid fixture is the analytic example session (:mod:`haptify_tools.example_session`, 0.2 s of
data) with ONE deliberate defect (or, for ``several-problems``, a few) applied by a small function
below. Its sidecar ``fixtures/invalid/<name>.expected.json`` states the codes validation must report —
fixed by construction here, never copied from a validator run — the exit code, and what is broken.

    python -m haptify_tools.build_invalid_fixtures [--out FIXTURES_DIR]
    python -m haptify_tools.build_invalid_fixtures --check   # exit 1 when the committed fixtures are stale

The build is deterministic up to the CPU's rounding; :func:`~haptify_conform.fixture_digest.logical_snapshot` describes a built tree by
content (parsed JSON, table values, symlink targets) and :func:`trees_agree` compares two, so a test can
check that the committed fixtures are current without depending on file timestamps, on the Parquet
writer's version string or on the last bits of numpy's vectorised functions.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, TypeVar

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from haptify.storage import MANIFEST, SessionWriter, atomic_write_json, read_table, sha256_file, write_table
from haptify_conform.fixture_digest import trees_agree
from haptify_tools.example_session import TOUCH_DEVICE, example_writer

REPO = Path(__file__).resolve().parents[2]
DURATION_S = 0.2
TRIAL = "free_space-1"


# --- helpers on a written session folder --------------------------------------------------------


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


# --- the cases ------------------------------------------------------------------------------------


@dataclass
class Case:
    """One fixture: its name, the expected codes (by construction), what is broken and how to break it."""

    name: str
    codes: list[str]
    description: str
    mutate: Callable[[Path], object] | None = None  # what it returns is not used
    fmt: str = "parquet"
    extend: Callable[[SessionWriter], object] | None = None

    @property
    def exit_code(self) -> int:
        return 1 if any(c.startswith("E") for c in self.codes) else 0


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


CASES: list[Case] = [
    Case("malformed-json", ["E103"], "session.json is cut off in the middle (not well-formed JSON).", _manifest_malformed),
    Case("manifest-not-utf8", ["E103"], "session.json is Latin-1, not UTF-8 (an accented examiner id).", _manifest_latin1),
    Case(
        "manifest-nan-literal",
        ["E103"],
        "session.json uses the non-JSON literal NaN for a rate.",
        lambda f: _replace_text(f, MANIFEST, '"rate_hz": 1000.0', '"rate_hz": NaN'),
    ),
    Case("manifest-missing", ["E102"], "The folder holds stream files but no session.json.", lambda f: (f / MANIFEST).unlink()),
    Case(
        "manifest-not-object",
        ["E104"],
        "session.json is a JSON array, not an object.",
        lambda f: (f / MANIFEST).write_text("[]\n", encoding="utf-8"),
    ),
    Case(
        "wrong-types",
        ["E104"],
        "A string where an integer, a boolean and a number are required (repetition, powered, rate_hz).",
        lambda f: edit(f, _wrong_types),
    ),
    Case("missing-required-fields", ["E104"], "session_id and examiner are missing.", lambda f: edit(f, _drop_keys)),
    Case("spec-version-unsupported", ["E105"], "spec_version is 2.0.", lambda f: edit(f, lambda m: m.update(spec_version="2.0"))),
    Case(
        "unknown-protocol",
        ["E301"],
        "A trial's protocol is 'juggling'.",
        lambda f: edit(f, lambda m: trial_of(m).update(protocol="juggling")),
    ),
    Case(
        "unknown-stream-kind",
        ["E104"],
        "A stream's kind is 'gyroscope'.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_accel").update(kind="gyroscope")),
    ),
    Case(
        "stream-file-missing",
        ["E110"],
        "The handle_accel file named in session.json was deleted.",
        lambda f: (f / stream_of(manifest(f), "handle_accel")["file"]).unlink(),
    ),
    Case(
        "truncated-parquet",
        ["E112"],
        "handle_wrench.parquet is cut to half its length (checksum updated to the cut file).",
        lambda f: _truncate(f, "handle_wrench", 0.5),
    ),
    Case(
        "csv-wrong-header",
        ["E211"],
        "CSV session whose handle_wrench header reads time,Fx,... instead of t,fx,...",
        _csv_header,
        fmt="csv",
    ),
    Case(
        "csv-text-value",
        ["E112"],
        "CSV session with the text 'nine point eight' in a handle_accel cell.",
        _csv_text_value,
        fmt="csv",
    ),
    Case(
        "csv-plus-sign",
        ["E112"],
        "CSV session whose handle_accel az at row 7 is written '+9.81' (spec §3.2 allows no '+' sign).",
        _csv_edit_line("handle_accel", 7, lambda line: ",".join(line.split(",")[:3] + ["+" + line.split(",")[3]])),
        fmt="csv",
    ),
    Case(
        "csv-blank-line",
        ["E112"],
        "CSV session whose handle_wrench has a blank line after row 10.",
        _csv_edit_line("handle_wrench", 10, lambda line: line + "\n"),
        fmt="csv",
    ),
    Case("column-not-float", ["E212"], "handle_wrench column fx is stored as 64-bit integers.", _int_column),
    Case(
        "time-not-increasing",
        ["E203"],
        "Two handle_wrench samples are swapped, so t decreases once.",
        lambda f: rewrite_data(f, "handle_wrench", _swap_times),
    ),
    Case(
        "time-nan",
        ["E203"],
        "handle_accel's t is NaN at row 10.",
        lambda f: rewrite_data(f, "handle_accel", set_column("handle_accel", "t", [10], float("nan"))),
    ),
    Case(
        "wrong-units",
        ["E202"],
        "handle_wrench declares fx in kN and tx in N*mm.",
        lambda f: edit(
            f,
            lambda m: (
                stream_of(m, "handle_wrench")["columns"][1].update(unit="kN"),
                stream_of(m, "handle_wrench")["columns"][4].update(unit="N*mm"),
            ),
        ),
    ),
    Case(
        "wrong-columns",
        ["E201"],
        "handle_wrench lacks the tz column (both in session.json and in the file).",
        _drop_declared_and_file_column,
    ),
    Case("file-columns-differ", ["E201"], "session.json declares tz but the Parquet file has no tz column.", _drop_file_column),
    Case(
        "non-unit-quaternion",
        ["E207"],
        "handle_pose quaternions of rows 5-9 are scaled by 1.1 (norm 1.1).",
        lambda f: rewrite_data(f, "handle_pose", _scale_quaternions),
    ),
    Case(
        "nan-in-force",
        ["E204"],
        "handle_wrench fx is NaN for rows 20-24 (NaN is allowed only in motion capture).",
        lambda f: rewrite_data(f, "handle_wrench", set_column("handle_wrench", "fx", slice(20, 25), float("nan"))),
    ),
    Case(
        "infinity",
        ["E210"],
        "handle_accel az is +inf at row 3.",
        lambda f: rewrite_data(f, "handle_accel", set_column("handle_accel", "az", [3], float("inf"))),
    ),
    Case(
        "checksum-mismatch",
        ["E111"],
        "handle_wrench data changed after its checksum was taken.",
        lambda f: rewrite_data(f, "handle_wrench", set_column("handle_wrench", "fy", slice(0, 200), 0.3), rehash=False),
    ),
    Case(
        "empty-stream",
        ["E205"],
        "handle_wrench holds a header and no rows (rows: 0).",
        lambda f: rewrite_data(f, "handle_wrench", _empty(0)),
    ),
    Case(
        "single-sample-stream", ["E205"], "handle_wrench holds one sample.", lambda f: rewrite_data(f, "handle_wrench", _empty(1))
    ),
    Case(
        "path-traversal",
        ["E108"],
        "A stream's file is '../../etc/passwd'.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(file="../../etc/passwd")),
    ),
    Case(
        "absolute-path",
        ["E108"],
        "A stream's file is the absolute path '/etc/passwd'.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(file="/etc/passwd")),
    ),
    Case(
        "symlink-absolute",
        ["E109"],
        "handle_wrench.parquet is a symbolic link to /etc/passwd.",
        lambda f: _symlink_stream(f, "handle_wrench", "/etc/passwd"),
    ),
    Case(
        "symlink-relative-escape",
        ["E109"],
        "handle_wrench.parquet is a relative symbolic link into another fixture (a valid file, outside this folder).",
        lambda f: _symlink_stream(
            f, "handle_wrench", "../../../../valid/parquet-basic/trials/free_space-1/handle_wrench.parquet"
        ),
    ),
    Case(
        "symlinked-folder-escape",
        ["E109"],
        "The trials/ folder is a symbolic link to another fixture's trials/ folder.",
        _in_turn(lambda f: shutil.rmtree(f / "trials"), lambda f: os.symlink("../../valid/parquet-basic/trials", f / "trials")),
    ),
    Case(
        "manifest-symlink-escape",
        ["E109"],
        "session.json is a symbolic link to another fixture's session.json.",
        _in_turn(lambda f: (f / MANIFEST).unlink(), lambda f: os.symlink("../../valid/parquet-basic/session.json", f / MANIFEST)),
    ),
    Case(
        "stream-is-folder",
        ["E112"],
        "A stream's file names a folder (trials/free_space-1).",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(file="trials/free_space-1")),
    ),
    Case(
        "absurd-rows",
        ["E113"],
        "handle_wrench declares 10^12 rows.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(rows=10**12)),
    ),
    Case(
        "absurd-rate",
        ["E113"],
        "handle_accel declares a rate of 10^12 Hz.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_accel").update(rate_hz=1e12)),
    ),
    Case(
        "oversized-file",
        ["E113"],
        "A CSV handle_pose declares 20 rows but its file is padded to ~40 kB; it is not read.",
        _oversized,
        fmt="csv",
    ),
    Case(
        "row-count-mismatch",
        ["E208"],
        "handle_wrench declares 150 rows; the file holds 200.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(rows=150)),
    ),
    Case(
        "rate-mismatch",
        ["E206"],
        "handle_wrench is sampled at 950 Hz but declares 1000 Hz (5 % off).",
        lambda f: rewrite_data(f, "handle_wrench", _retime(950.0)),
    ),
    Case(
        "irregular-intervals",
        ["W402"],
        "Two handle_wrench samples are moved by 0.6 ms (warning only; the mean rate is exact).",
        lambda f: rewrite_data(f, "handle_wrench", _jitter),
    ),
    Case(
        "rate-below-recommended",
        ["W406"],
        "handle_accel recorded and declared at 1 kHz; 2 kHz is recommended (warning only).",
        _in_turn(
            lambda f: rewrite_data(f, "handle_accel", lambda df: df.iloc[::2].reset_index(drop=True)),
            lambda f: edit(f, lambda m: stream_of(m, "handle_accel").update(rate_hz=1000.0)),
        ),
    ),
    Case(
        "sensor-range-exceeded",
        ["W401"],
        "handle_wrench fz reaches -170 N; the rig declares ±160 N (warning only).",
        lambda f: rewrite_data(f, "handle_wrench", set_column("handle_wrench", "fz", slice(100, 110), -170.0)),
    ),
    Case(
        "non-overlapping-streams",
        ["E305"],
        "handle_pose starts 10 s after the other streams of its trial ended.",
        lambda f: rewrite_data(f, "handle_pose", _shift_time(10.0)),
    ),
    Case(
        "required-stream-missing",
        ["E302"],
        "The free_space trial has no handle_accel stream.",
        lambda f: drop_stream(f, "handle_accel"),
    ),
    Case(
        "recommended-stream-missing",
        ["W404"],
        "The free_space trial has no plate_wrench stream (warning only).",
        lambda f: drop_stream(f, "plate_wrench"),
    ),
    Case(
        "rendering-missing",
        ["E303"],
        "An active stiffness trial has no rendering parameters.",
        extend=lambda w: add_active_trial(w, rendering=None),
    ),
    Case(
        "other-without-label",
        ["E304"],
        "A trial of protocol 'other' has no label.",
        extend=_in_turn(
            lambda w: w.add_trial("figure8-1", "other", powered=False),
            lambda w: w.add_stream("figure8-1", "handle_pose", _pose(20), rate_hz=100),
        ),
    ),
    Case(
        "powered-flag-unusual",
        ["W403"],
        "The passive free_space trial is marked powered (warning only).",
        lambda f: edit(f, lambda m: trial_of(m).update(powered=True)),
    ),
    Case(
        "duplicate-trial-id",
        ["E107"],
        "Two trials share the id free_space-1.",
        lambda f: edit(f, lambda m: m["trials"][1].update(id="free_space-1")),
        extend=_duplicate_trial_writer,
    ),
    Case(
        "duplicate-stream-file",
        ["E107"],
        "The second trial's handle_wrench names the first trial's file.",
        lambda f: edit(
            f,
            lambda m: stream_of(m, "handle_wrench", "free_space-2").update(
                file=stream_of(m, "handle_wrench")["file"], sha256=stream_of(m, "handle_wrench")["sha256"]
            ),
        ),
        extend=_duplicate_trial_writer,
    ),
    Case("duplicate-stream-kind", ["E306"], "One trial holds two handle_wrench streams (two files).", _second_wrench),
    Case(
        "unknown-marker",
        ["E213"],
        "A markers stream names 'h9', which the rig's motion capture does not list.",
        extend=lambda w: add_markers_trial(w, ["h1", "h9"]),
    ),
    Case(
        "markers-partial-nan",
        ["E204"],
        "Marker h1 has x NaN but y and z present at rows 3-4.",
        _markers_nan(slice(3, 5), ["h1_x"]),
        extend=lambda w: add_markers_trial(w, ["h1", "h2"]),
    ),
    Case(
        "occlusion-high",
        ["W405"],
        "Marker h2 is occluded (x, y, z NaN) in 10 of 20 samples (warning only).",
        _markers_nan(slice(5, 15), ["h2_x", "h2_y", "h2_z"]),
        extend=lambda w: add_markers_trial(w, ["h1", "h2"]),
    ),
    Case(
        "wrong-frame",
        ["E209"],
        "handle_wrench is declared in frame 'world' instead of 'handle_ft_sensor'.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(frame="world")),
    ),
    Case(
        "manifest-duplicate-key",
        ["E117"],
        "session.json names the member 'date' twice at its top level.",
        lambda f: _replace_text(f, MANIFEST, '"date": "2026-11-22",', '"date": "2026-11-22",\n  "date": "2026-11-23",'),
    ),
    Case(
        "device-file-duplicate-key",
        ["E117"],
        "device.json names the member 'dof' twice.",
        _in_turn(_device_file({}), lambda f: _replace_text(f, "device.json", '"dof": 6', '"dof": 6,\n  "dof": 3')),
    ),
    Case(
        "csv-nul-bytes",
        ["E211"],
        "CSV session whose handle_pose file is NUL bytes with no line end (checksum updated).",
        _csv_nul_bytes,
        fmt="csv",
    ),
    Case("device-file-missing", ["E106"], "device refers to device.json, which is absent.", _device_file(None)),
    Case(
        "device-file-escape",
        ["E108"],
        "device refers to '../device.json', outside the folder.",
        _device_file(None, "../device.json"),
    ),
    Case("device-file-invalid", ["E106"], "device.json gives dof as the string 'six'.", _device_file({"dof": "six"})),
    Case(
        "device-file-quaternion-not-unit",
        ["E207"],
        "device.json's DH base quaternion is [0.5, 0, 0, 0] (norm 0.5).",
        _device_file(
            {
                "kinematics": {
                    **TOUCH_DEVICE["kinematics"],
                    "base": {"position": [0.0, 0.0, 0.0], "quaternion": [0.5, 0.0, 0.0, 0.0]},
                }
            }
        ),
    ),
    Case(
        "rig-quaternion-not-unit",
        ["E207"],
        "The handle F/T sensor pose in the rig has quaternion [1, 1, 0, 0].",
        lambda f: edit(f, lambda m: m["rig"]["handle"]["ft_sensor"]["pose"].update(quaternion=[1.0, 1.0, 0.0, 0.0])),
    ),
    Case(
        "clock-offset-unknown-file",
        ["E114"],
        "A clock_offset record names a stream file no stream uses.",
        lambda f: edit(
            f,
            lambda m: m.setdefault("calibration", []).append(
                {"kind": "clock_offset", "id": "sync-1", "stream_file": "trials/free_space-1/mocap.parquet", "offset_s": 0.01}
            ),
        ),
    ),
    Case(
        "calibration-unknown-trial",
        ["E114"],
        "A plate_bias record names source trial 'plate-bias-9', which does not exist.",
        lambda f: edit(
            f,
            lambda m: m.setdefault("calibration", []).append(
                {"kind": "plate_bias", "id": "bias-1", "source_trial": "plate-bias-9", "bias": [0.0] * 24}
            ),
        ),
    ),
    Case(
        "plate-corner-duplicate-id",
        ["E107"],
        "The force plate's third corner sensor has id 'c1' (c1 twice, c3 missing).",
        lambda f: edit(f, lambda m: m["rig"]["force_plate"]["corners"][2].update(id="c1")),
    ),
    Case(
        "rendering-without-stiffness",
        ["E104"],
        "An active stiffness trial's rendering lacks the required "
        "stiffness_N_per_m (spec §2.5: plane point, normal and stiffness are required).",
        lambda f: edit(f, lambda m: trial_of(m, "stiffness-1")["rendering"].pop("stiffness_N_per_m")),
        extend=add_active_trial,
    ),
    Case(
        "surface-normal-not-unit",
        ["E307"],
        "An active stiffness trial's rendering surface_normal is [0, 0.1, 1] (norm 1.005).",
        extend=lambda w: add_active_trial(w, rendering={**RENDERING, "surface_normal": [0.0, 0.1, 1.0]}),
    ),
    Case(
        "sync-not-binary",
        ["E214"],
        "A sync stream holds the raw trigger voltage (0 V and 5 V), not 0 and 1.",
        extend=_sync_trial(lambda t: 5.0 * ((t >= 0.05) & (t < 0.1))),
    ),
    Case(
        "entities-on-plain-kind",
        ["E215"],
        "The handle_wrench stream declares entities ['h1'] (only markers and link_poses have them).",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(entities=["h1"])),
    ),
    Case(
        "joint-limits-empty",
        ["E115"],
        "The device's q2 range is [0, -0.5] rad: its upper limit lies below its lower one.",
        lambda f: edit(f, lambda m: _joint(m, "q2").update(upper={"constant": -0.5})),
    ),
    Case(
        "joint-limit-later-joint",
        ["E116"],
        "The device's q2 upper limit depends on q3, a later joint.",
        lambda f: edit(f, lambda m: _joint(m, "q2").update(upper={"constant": 1.7, "coefficients": {"q3": -0.5}})),
    ),
    Case(
        "date-not-calendar",
        ["E104"],
        "The session's date is 2026-02-30, which matches YYYY-MM-DD but does not exist.",
        lambda f: edit(f, lambda m: m.update(date="2026-02-30")),
    ),
    Case(
        "null-member",
        ["W407"],
        "The trial's notes and the rig's name are written as null instead of being omitted (warning only).",
        lambda f: edit(f, lambda m: (trial_of(m).update(notes=None), m["rig"].update(name=None))),
    ),
    Case(
        "several-problems",
        ["E110", "E203", "E204", "W404"],
        "Four independent problems in one trial, all reported: t decreases in handle_wrench, NaN in handle_accel, "
        "the handle_pose file is missing, and plate_wrench is absent.",
        _several,
    ),
]

VALID: list[Case] = [
    Case("parquet-basic", [], "The analytic free-space example session (Parquet)."),
    Case(
        "rendering-minimal",
        [],
        "An active stiffness trial whose rendering has only its required members (plane point, "
        "normal, stiffness): friction, software and loop rate are optional (spec §2.5).",
        extend=lambda w: add_active_trial(
            w, rendering={k: RENDERING[k] for k in ("surface_point_m", "surface_normal", "stiffness_N_per_m")}
        ),
    ),
    Case(
        "csv-multi-trial",
        [],
        "CSV session: a free-space trial, an active stiffness trial with rendering, and a workspace "
        "trial with markers and link poses.",
        fmt="csv",
        extend=_in_turn(
            lambda w: add_active_trial(w, fmt="csv"),
            lambda w: add_markers_trial(w, ["h1", "h2", "h3"], fmt="csv"),
            lambda w: w.add_stream(
                "workspace-1", "link_poses", _link_poses(["handle"]), rate_hz=100, fmt="csv", entities=["handle"]
            ),
        ),
    ),
]


# --- building ---------------------------------------------------------------------------------------


def build_case(case: Case, target: Path) -> None:
    """Write one fixture session to ``target`` (which must not exist)."""
    w = example_writer(session_id=f"fixture-{case.name}", duration_s=DURATION_S, fmt=case.fmt)
    if case.extend is not None:
        case.extend(w)
    w.write(target)
    if case.mutate is not None:
        case.mutate(target)


def sidecar(case: Case) -> dict:
    return {"codes": sorted(set(case.codes)), "exit_code": case.exit_code, "description": case.description}


def build_all(out: Path, only: set[str] | None = None) -> None:
    """(Re)build ``out/valid/<name>`` and ``out/invalid/<name>`` with sidecars, replacing the old ones.

    ``only`` restricts the build to the named fixtures (the others are left as they are).
    """
    out.mkdir(parents=True, exist_ok=True)
    for group, cases in (("valid", VALID), ("invalid", CASES)):
        folder = out / group
        folder.mkdir(exist_ok=True)
        for case in cases:
            if only is not None and case.name not in only:
                continue
            target = folder / case.name
            if target.is_symlink() or target.is_file():
                target.unlink()
            elif target.exists():
                shutil.rmtree(target)
            build_case(case, target)
            atomic_write_json(folder / f"{case.name}.expected.json", sidecar(case))


def stale_fixtures(fixtures: Path, scratch: Path) -> list[str]:
    """The fixtures under ``fixtures/{valid,invalid}`` whose logical content (or sidecar) differs from a fresh
    build into ``scratch``, plus fixture folders this script does not build; empty when all are current."""
    build_all(scratch)
    stale: list[str] = []
    for group, cases in (("valid", VALID), ("invalid", CASES)):
        built, committed = scratch / group, fixtures / group
        names = {c.name for c in cases}
        extra = (
            sorted(p.name for p in committed.iterdir() if p.name.removesuffix(".expected.json") not in names)
            if committed.is_dir()
            else []
        )
        stale += [f"{group}/{n} is not built by this script" for n in extra]
        for case in cases:
            if not (committed / case.name).exists() or not trees_agree(built / case.name, committed / case.name):
                stale.append(f"{group}/{case.name}")
            side = committed / f"{case.name}.expected.json"
            if not side.is_file() or json.loads(side.read_text(encoding="utf-8")) != sidecar(case):
                stale.append(f"{group}/{case.name}.expected.json")
    return stale


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "fixtures", help="fixtures folder (default: the repository's)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="rebuild only these fixtures")
    parser.add_argument("--check", action="store_true", help="only check that the committed fixtures are current")
    args = parser.parse_args(argv)
    known = {c.name for c in VALID + CASES}
    unknown = sorted(set(args.only or ()) - known)
    if unknown:
        parser.error(f"unknown fixture(s) {unknown}; known: {sorted(known)}")
    if args.check:
        with tempfile.TemporaryDirectory(prefix="haptify-fixtures-") as tmp:
            stale = stale_fixtures(args.out, Path(tmp))
        for line in stale:
            print(f"stale: {line}")
        print(f"bad-input and valid fixtures: {'stale' if stale else 'current'} ({len(VALID) + len(CASES)} fixtures)")
        return 1 if stale else 0
    build_all(args.out, set(args.only) if args.only else None)
    built = len(args.only) if args.only else len(VALID) + len(CASES)
    print(f"built {built} fixture(s) under {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
