"""Stream validation in chunks (spec §4.4): a stream read a few rows at a time gives exactly the findings
of its whole table — codes, messages, columns, time ranges — including findings that straddle a chunk
border, and the validator never holds more than one chunk of a stream it does not keep."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haptify.formats import storage
from haptify.formats.validation import SessionValidator, ValidationReport, streams, validate_session
from haptify_tools.example_session import example_writer
from haptify_tools.invalid_fixtures import defects, session_edits

REPO = Path(__file__).resolve().parents[1]
FIXTURES = sorted(p for group in ("invalid", "valid") for p in (REPO / "fixtures" / group).iterdir() if p.is_dir())
CHUNKS = [1, 2, 3, 6, 7, 8, 13, 10**6]


def _dump(report: ValidationReport) -> dict:
    return report.to_model().model_dump()


def _whole(folder: Path) -> dict:
    """The report with every stream read whole, as the gate reads the streams it computes from."""
    v = SessionValidator(folder)
    v.check_manifest()
    for entry in v.entries:
        v.check_stream(entry, keep=True)
    v.check_overlap()
    return _dump(v.finish())


# --- every fixture ----------------------------------------------------------------------------------


@pytest.mark.parametrize("folder", FIXTURES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_fixture_gives_the_whole_table_findings_in_chunks_of_1_and_7_rows(folder: Path):
    whole = _whole(folder)
    assert "E999" not in {f["code"] for f in whole["findings"]}
    for rows in (1, 7):
        assert _dump(validate_session(folder, chunk_rows=rows)) == whole, rows


# --- findings across a chunk border, by construction -------------------------------------------------
# handle_wrench: 200 samples at t = i / 1000 s; markers and handle_pose: 20 samples at t = i / 100 s.


def _set(column: str, rows, value: float) -> Callable[[pd.DataFrame], pd.DataFrame]:
    return session_edits.set_column("", column, rows, value)


def _swap_times(k: int) -> Callable[[pd.DataFrame], pd.DataFrame]:
    def fn(df: pd.DataFrame) -> pd.DataFrame:
        t = df["t"].to_numpy().copy()
        t[k], t[k + 1] = t[k + 1], t[k]
        df["t"] = t
        return df

    return fn


def _delay_from(k: int, seconds: float) -> Callable[[pd.DataFrame], pd.DataFrame]:
    def fn(df: pd.DataFrame) -> pd.DataFrame:
        t = df["t"].to_numpy().copy()
        t[k:] += seconds
        df["t"] = t
        return df

    return fn


def _scale_rows(rows: slice, factor: float) -> Callable[[pd.DataFrame], pd.DataFrame]:
    def fn(df: pd.DataFrame) -> pd.DataFrame:
        for c in ("qw", "qx", "qy", "qz"):
            v = df[c].to_numpy().copy()
            v[rows] *= factor
            df[c] = v
        return df

    return fn


# (stream kind, rewrite, formats, known findings: code, column, message, time range)
BORDER_CASES = {
    "nan-run": (
        "handle_wrench",
        _set("fz", slice(5, 13), float("nan")),
        ("parquet", "csv"),
        [("E204", "fz", "column 'fz' holds 8 NaN values; handle_wrench allows none", (0.005, 0.012))],
    ),
    "time-reversal": (
        "handle_wrench",
        _swap_times(6),
        ("parquet", "csv"),
        [("E203", "t", "time does not strictly increase at 1 intervals (first at row 7)", (0.006, 0.007))],
    ),
    "gap": (
        "handle_wrench",
        _delay_from(7, 0.001),
        ("parquet", "csv"),
        [
            (
                "W402",
                "t",
                "1 sample intervals lie outside [0.5, 1.5] × 0.001 s (largest 0.002 s, smallest 0.001 s)",
                (0.006, 0.008),
            )
        ],
    ),
    "nan-time": (
        "handle_wrench",
        _set("t", [7], float("nan")),
        ("parquet", "csv"),
        [("E203", "t", "time column holds 1 non-finite values", (0.006, 0.008))],
    ),
    "nan-time-run": (
        "handle_wrench",
        _set("t", slice(7, 10), float("nan")),
        ("parquet", "csv"),
        [("E203", "t", "time column holds 3 non-finite values", (0.006, 0.010))],
    ),
    "over-range": (
        "handle_wrench",
        _set("fz", slice(5, 13), -170.0),
        ("parquet", "csv"),
        [("W401", "fz", "column 'fz' exceeds the declared ±160 range at 8 samples (peak 170)", (0.005, 0.012))],
    ),
    "infinity": (
        "handle_wrench",
        _set("fx", slice(6, 8), float("inf")),
        ("parquet",),
        [("E210", "fx", "column 'fx' holds 2 infinite values", (0.006, 0.007))],
    ),
    "quaternions": (
        "handle_pose",
        _scale_rows(slice(5, 13), 1.5),
        ("parquet", "csv"),
        [("E207", "qw", "8 quaternions (qw, qx, qy, qz) are not unit; worst norm 1.5", (0.05, 0.12))],
    ),
}


def _border_session(root: Path, case: str, fmt: str) -> Path:
    kind, rewrite, _, _ = BORDER_CASES[case]
    folder = example_writer(duration_s=0.2, fmt=fmt).write(root / f"{case}-{fmt}")
    session_edits.rewrite_data(folder, kind, rewrite)
    return folder


@pytest.mark.parametrize("case, fmt", [(c, f) for c, v in BORDER_CASES.items() for f in v[2]])
def test_a_finding_across_chunk_borders_is_the_known_one_for_every_chunk_size(tmp_path: Path, case: str, fmt: str):
    folder = _border_session(tmp_path, case, fmt)
    whole = _whole(folder)
    for rows in CHUNKS:
        report = validate_session(folder, chunk_rows=rows)
        found = [(f.code, f.column, f.message, f.time_range) for f in report.findings]
        assert [(c, col, msg) for c, col, msg, _ in found] == [k[:3] for k in BORDER_CASES[case][3]], (rows, found)
        for (_, _, _, span), known in zip(found, BORDER_CASES[case][3]):
            assert span == pytest.approx(known[3], abs=1e-12), rows
        assert _dump(report) == whole, rows


def test_an_occlusion_across_chunk_borders_is_counted_once(tmp_path: Path):
    w = example_writer(duration_s=0.2)
    session_edits.add_markers_trial(w, ["h1", "h2"])
    folder = w.write(tmp_path / "s")
    defects._markers_nan(slice(5, 13), ["h1_x"])(folder)  # partial: 8 samples
    defects._markers_nan(slice(3, 9), ["h2_x", "h2_y", "h2_z"])(folder)  # whole entity: 6 of 20 samples
    whole = _whole(folder)
    for rows in CHUNKS:
        report = validate_session(folder, chunk_rows=rows)
        found = [(f.code, f.message, f.found) for f in report.findings]
        assert found == [
            ("E204", "h1: 8 samples have some but not all of ['h1_x', 'h1_y', 'h1_z'] NaN", "partial NaN"),
            ("W405", "h2 is occluded in 30% of the samples", 0.3),
        ], rows
        assert [f.time_range for f in report.findings] == [pytest.approx((0.05, 0.12)), pytest.approx((0.03, 0.08))]
        assert _dump(report) == whole, rows


# --- any damage, any chunking ------------------------------------------------------------------------


@st.composite
def damage(draw):
    """Random NaN, infinity, over-range, out-of-order and delayed samples in handle_wrench (200 rows)."""
    rows = st.lists(st.integers(0, 199), max_size=12, unique=True)
    return {
        "nan": draw(rows),
        "inf": draw(rows),
        "over": draw(rows),
        "swap": draw(st.lists(st.integers(0, 198), max_size=3)),
        "delay": draw(st.lists(st.integers(1, 199), max_size=3)),
        "chunk": draw(st.integers(1, 60)),
    }


_BASE: dict[str, Path] = {}


def _base(fmt: str) -> Path:
    if fmt not in _BASE:
        _BASE[fmt] = example_writer(duration_s=0.2, fmt=fmt).write(Path(tempfile.mkdtemp(prefix="haptify-chunks-")) / "s")
    return _BASE[fmt]


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(d=damage(), fmt=st.sampled_from(["parquet", "csv"]))
def test_any_damage_gives_the_whole_table_findings_in_any_chunking(tmp_path: Path, d: dict, fmt: str):
    folder = tmp_path / f"s-{fmt}"
    shutil.rmtree(folder, ignore_errors=True)
    shutil.copytree(_base(fmt), folder, symlinks=True)

    def hurt(df: pd.DataFrame) -> pd.DataFrame:
        t = df["t"].to_numpy().copy()
        for k in d["delay"]:
            t[k:] += 0.0007
        for k in d["swap"]:
            t[k], t[k + 1] = t[k + 1], t[k]
        df["t"] = t
        for column, key, value in (("fx", "nan", np.nan), ("fy", "over", 500.0), ("fz", "inf", np.inf)):
            if fmt == "csv" and key == "inf":
                continue  # the CSV grammar has no infinity (E112, spec §3.2)
            v = df[column].to_numpy().copy()
            v[d[key]] = value
            df[column] = v
        return df

    session_edits.rewrite_data(folder, "handle_wrench", hurt)
    assert _dump(validate_session(folder, chunk_rows=d["chunk"])) == _whole(folder)


# --- bounded memory ----------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_validation_holds_one_chunk_of_a_stream_at_a_time(tmp_path: Path, monkeypatch, fmt: str):
    folder = example_writer(duration_s=0.2, fmt=fmt).write(tmp_path / "s")
    seen: list[tuple[str, list[int]]] = []
    reader = storage.read_stream_chunks

    def spy(path, fmt_, columns, *, label, chunk_rows=None):
        digest, chunks = reader(path, fmt_, columns, label=label, chunk_rows=chunk_rows)
        sizes: list[int] = []
        seen.append((label, sizes))
        return digest, (sizes.append(len(c)) or c for c in chunks)

    monkeypatch.setattr(streams, "read_stream_chunks", spy)  # the global the stream checks read
    report = validate_session(folder, chunk_rows=16)
    assert report.findings == []
    rows = {s["file"]: s["rows"] for t in session_edits.manifest(folder)["trials"] for s in t["streams"]}
    assert {label for label, _ in seen} == set(rows)
    for label, sizes in seen:
        assert max(sizes) <= 16 and sum(sizes) == rows[label], (label, sizes)


def test_the_default_chunk_is_about_32_mib_of_float64_rows():
    v = SessionValidator(".")
    assert v.chunk_rows_for(7) == streams.STREAM_CHUNK_BYTES // 56
    assert v.chunk_rows_for(7) * 7 * 8 <= 32 * 2**20
    assert SessionValidator(".", chunk_rows=5).chunk_rows_for(7) == 5


def test_a_parquet_stream_whose_footer_rows_fit_one_chunk_is_read_whole_else_in_chunks(tmp_path: Path, monkeypatch):
    """spec §4.5: the footer's row count decides — a stream within one default chunk is read whole (one
    read, hashed as read), the same stream is chunked once the chunk is smaller than its rows."""
    folder = example_writer(duration_s=0.2).write(tmp_path / "s")
    declared = [s for t in session_edits.manifest(folder)["trials"] for s in t["streams"]]
    size = {s["file"]: 8 * s["rows"] * len(s["columns"]) for s in declared}  # decoded float64 bytes
    asked: dict[str, int | None] = {}
    reader = storage.read_stream_chunks

    def spy(path, fmt_, columns, *, label, chunk_rows=None):
        asked[label] = chunk_rows
        return reader(path, fmt_, columns, label=label, chunk_rows=chunk_rows)

    monkeypatch.setattr(streams, "read_stream_chunks", spy)
    assert validate_session(folder).findings == []
    assert asked == dict.fromkeys(size)  # every stream whole: each fits a 32 MiB chunk
    chunk = sorted(size.values())[len(size) // 2]  # the median stream fits, the larger ones do not
    monkeypatch.setattr(streams, "STREAM_CHUNK_BYTES", chunk)
    asked.clear()
    assert validate_session(folder).findings == []
    assert {f for f, rows in asked.items() if rows is None} == {f for f, b in size.items() if b <= chunk}
    assert len(set(asked.values())) > 1


def test_an_integer_column_with_a_null_is_e212_judged_on_the_schema(tmp_path: Path):
    """spec §3.2: a column that is not float is E212 — also when a null would make a reader widen it to float64."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    folder = example_writer(duration_s=0.2).write(tmp_path / "s")
    s = session_edits.stream_of(session_edits.manifest(folder), "handle_wrench")
    table = pq.read_table(folder / s["file"])
    fx_int = pa.array([None, *range(1, table.num_rows)], type=pa.int64())
    pq.write_table(table.set_column(table.column_names.index("fx"), "fx", fx_int), folder / s["file"])
    session_edits.edit(
        folder,
        lambda m: session_edits.stream_of(m, "handle_wrench").__setitem__("sha256", storage.sha256_file(folder / s["file"])),
    )
    for rows in (None, 7):
        report = validate_session(folder, chunk_rows=rows)
        assert [(f.code, f.column, f.found) for f in report.findings] == [("E212", "fx", "int64")], rows
