"""Reading stream files safely (spec §3.1, §3.2, §4.2): one pass that hashes as it reads, row groups,
duplicate JSON members, and memory bounded by a line whatever a CSV file holds."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haptify.errors import HaptifyError
from haptify.formats.storage import parse_json_file, read_stream_file
from haptify.formats.validation import validate_session
from haptify_tools.example_session import example_writer
from haptify_tools.invalid_fixtures import session_edits


def _session(tmp_path: Path, fmt: str = "parquet", name: str = "s") -> Path:
    return example_writer(duration_s=0.5, fmt=fmt).write(tmp_path / name)


# --- hash as you read ------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_one_read_gives_the_table_and_the_sha256_of_the_bytes(tmp_path: Path, fmt: str):
    folder = _session(tmp_path, fmt)
    stream = session_edits.stream_of(session_edits.manifest(folder), "handle_wrench")
    path = folder / stream["file"]
    table, digest = read_stream_file(path, fmt, [c["name"] for c in stream["columns"]], label=stream["file"])
    assert digest == hashlib.sha256(path.read_bytes()).hexdigest() == stream["sha256"]
    assert len(table) == stream["rows"] and np.allclose(np.diff(table["t"]), 1e-3)


# --- Parquet row groups (spec §3.2, §4.2) -------------------------------------------------------------


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(group_rows=st.integers(min_value=1, max_value=600))
def test_a_parquet_stream_in_any_number_of_row_groups_is_valid_and_reads_the_same(tmp_path_factory, group_rows: int):
    folder = _session(tmp_path_factory.mktemp("rg"))
    stream = session_edits.stream_of(session_edits.manifest(folder), "handle_wrench")
    path = folder / stream["file"]
    before = pq.read_table(path)
    pq.write_table(before, path, row_group_size=group_rows, compression="zstd")
    session_edits.rehash(folder, "handle_wrench")
    assert pq.ParquetFile(path).num_row_groups == -(-before.num_rows // group_rows)
    assert validate_session(folder).findings == []
    table, _ = read_stream_file(path, "parquet", before.column_names, label=stream["file"])
    assert np.array_equal(table.to_numpy(), before.to_pandas().to_numpy())


# --- duplicate JSON members (spec §3.1: E117) ------------------------------------------------------


@pytest.mark.parametrize(
    "old, new",
    [
        ('"date": "2026-11-22",', '"date": "2026-11-22", "date": "2026-11-23",'),  # top level
        ('"model": "Touch",', '"model": "Touch", "model": "Touch X",'),  # inside the device
        ('"rate_hz": 1000.0,', '"rate_hz": 1000.0, "rate_hz": 500.0,'),  # inside a stream
    ],
)
def test_a_member_named_twice_anywhere_in_session_json_is_e117(tmp_path: Path, old: str, new: str):
    folder = _session(tmp_path)
    text = (folder / "session.json").read_text(encoding="utf-8")
    compact = json.dumps(json.loads(text))
    assert old in compact, old
    (folder / "session.json").write_text(compact.replace(old, new, 1), encoding="utf-8")
    (f,) = validate_session(folder).findings
    assert (f.code, f.found) == ("E117", json.loads("{" + old.rstrip(",") + "}").popitem()[0])


def test_repeated_names_in_different_objects_are_fine(tmp_path: Path):
    path = tmp_path / "doc.json"
    path.write_text('{"a": {"x": 1}, "b": {"x": 2}, "c": [{"x": 3}, {"x": 4}]}', encoding="utf-8")
    assert parse_json_file(path, "E103", "doc.json") == {"a": {"x": 1}, "b": {"x": 2}, "c": [{"x": 3}, {"x": 4}]}
    path.write_text('{"c": [{"x": 3, "x": 4}]}', encoding="utf-8")
    with pytest.raises(HaptifyError) as err:
        parse_json_file(path, "E103", "doc.json")
    assert err.value.code == "E117"


# --- memory bounded by a line (spec §3.2) ------------------------------------------------------------

NUL_MIB = 256
MEMORY_BUDGET_MIB = 768  # above what the validator holds after its imports; far below 14 × 256 MiB

_CHILD = textwrap.dedent("""
    import resource, sys
    from haptify.formats.validation import validate_session
    def vm_bytes():
        with open("/proc/self/status") as fh:
            return next(int(l.split()[1]) * 1024 for l in fh if l.startswith("VmSize:"))
    limit = vm_bytes() + int(sys.argv[2]) * 2**20
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    report = validate_session(sys.argv[1])
    print(" ".join(f.code + ":" + f.message for f in report.findings))
""")


@pytest.mark.parametrize("header", [b"", b"t,px,py,pz,qw,qx,qy,qz\n"])
def test_a_csv_stream_of_nul_bytes_is_refused_within_a_memory_limit(tmp_path: Path, header: bytes):
    folder = _session(tmp_path, "csv")
    m = session_edits.manifest(folder)
    stream = session_edits.stream_of(m, "handle_pose")
    rows = NUL_MIB * 2**20 // (32 * len(stream["columns"]))  # the size limit of §4.2 admits the file
    path = folder / stream["file"]
    with open(path, "wb") as fh:
        fh.write(header)
        chunk = b"\0" * 2**20
        for _ in range(NUL_MIB):
            fh.write(chunk)
    stream.update(rows=rows)
    session_edits.save_manifest(folder, m)
    session_edits.rehash(folder, "handle_pose")
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(folder), str(MEMORY_BUDGET_MIB)], capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr
    codes = [item.split(":")[0] for item in out.stdout.split()]
    assert codes and codes[0] == ("E112" if header else "E211"), out.stdout
    assert "too large" not in out.stdout and "longer than" in out.stdout
