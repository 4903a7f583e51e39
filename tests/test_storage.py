"""Storage (spec chapter 3): round trips, checksums, path safety, atomic writes."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from haptify.errors import HaptifyError
from haptify.formats.storage import atomic_write_text, open_session, resolve_inside, sha256_file
from haptify_tools.example_session import example_writer


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_written_session_reads_back_exactly(tmp_path, fmt):
    writer = example_writer(fmt=fmt)
    pending = {(p.trial_id, p.stream["kind"]): p.frame.copy() for p in writer._streams}
    path = writer.write(tmp_path / "s")
    session = open_session(path)
    for (trial, kind), frame in pending.items():
        back = session.read(trial, kind, verify=True)
        assert list(back.columns) == list(frame.columns)
        np.testing.assert_array_equal(back.to_numpy(), frame.to_numpy())
    stream = session.stream("free_space-1", "handle_wrench")
    assert stream.rows == 2000 and stream.sha256 == sha256_file(session.stream_path(stream))


def test_checksum_mismatch_is_coded(tmp_path):
    session = open_session(example_writer().write(tmp_path / "s"))
    stream = session.stream("free_space-1", "handle_pose")
    with open(session.stream_path(stream), "ab") as fh:
        fh.write(b"\0")
    with pytest.raises(HaptifyError) as err:
        session.read_stream(stream, verify=True)
    assert err.value.code == "E111"


def test_existing_output_is_refused_and_kept(tmp_path):
    target = tmp_path / "s"
    example_writer().write(target)
    before = (target / "session.json").read_text()
    with pytest.raises(HaptifyError) as err:
        example_writer(session_id="other").write(target)
    assert err.value.code == "E901"
    assert (target / "session.json").read_text() == before
    example_writer(session_id="other").write(target, overwrite=True)
    assert json.loads((target / "session.json").read_text())["session_id"] == "other"
    assert [p.name for p in tmp_path.iterdir()] == ["s"]  # no temporary folders left


def test_interrupted_write_leaves_nothing(tmp_path, monkeypatch):
    from haptify.formats.storage import writer

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(writer, "atomic_write_json", boom)
    with pytest.raises(OSError):
        example_writer().write(tmp_path / "s")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("bad", ["../x", "/etc/passwd", "a/../../b", "C:/x", "a\\b", "", "./a"])
def test_unsafe_paths_are_refused(tmp_path, bad):
    with pytest.raises(HaptifyError) as err:
        resolve_inside(tmp_path, bad)
    assert err.value.code == "E108"


def test_symlink_leaving_the_folder_is_refused(tmp_path):
    (tmp_path / "inside").mkdir()
    os.symlink("/etc", tmp_path / "inside" / "link")
    with pytest.raises(HaptifyError) as err:
        resolve_inside(tmp_path / "inside", "link/passwd")
    assert err.value.code == "E109"


def test_manifest_errors_are_coded(tmp_path):
    with pytest.raises(HaptifyError) as err:
        open_session(tmp_path / "nope")
    assert err.value.code == "E101"
    (tmp_path / "s").mkdir()
    with pytest.raises(HaptifyError) as err:
        open_session(tmp_path / "s")
    assert err.value.code == "E102"
    (tmp_path / "s" / "session.json").write_text('{"spec_version": "1.0",')
    with pytest.raises(HaptifyError) as err:
        open_session(tmp_path / "s")
    assert err.value.code == "E103" and "line 1" in str(err.value)
    (tmp_path / "s" / "session.json").write_text('{"spec_version": "9.9"}')
    with pytest.raises(HaptifyError) as err:
        open_session(tmp_path / "s")
    assert err.value.code == "E105"
    (tmp_path / "s" / "session.json").write_text('{"spec_version": "1.0", "session_id": 5}')
    with pytest.raises(HaptifyError) as err:
        open_session(tmp_path / "s")
    assert err.value.code == "E104"
    pointers = {f.pointer for f in err.value.findings}
    assert "/session_id" in pointers and "/trials" in pointers  # every problem, not only the first


def test_atomic_text_write_replaces_whole_file(tmp_path):
    target = tmp_path / "r.json"
    atomic_write_text(target, "a" * 1000)
    atomic_write_text(target, "b")
    assert target.read_text() == "b"
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_clock_offset_records_shift_time(tmp_path):
    writer = example_writer()
    writer.manifest["calibration"] = [
        {"kind": "clock_offset", "id": "off1", "stream_file": "trials/free_space-1/handle_accel.parquet", "offset_s": 0.25}
    ]
    session = open_session(writer.write(tmp_path / "s"))
    shifted = session.read("free_space-1", "handle_accel")
    raw = session.read("free_space-1", "handle_accel", session_clock=False)
    np.testing.assert_allclose(shifted["t"] - raw["t"], 0.25)
