"""Compact streams (spec §3.2.1): sensor columns stored as Parquet FLOAT with BYTE_STREAM_SPLIT read back as
the exact float32 values widened to float64, validate, and compute the same metrics within float32's
precision; ``t`` must stay DOUBLE (E212), and other column types are E212."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from haptify.errors import HaptifyError
from haptify.formats.storage import open_session, read_stream_file, write_table
from haptify.formats.validation import validate_session
from haptify.pipeline.compute import compute_session
from haptify_tools.example_session import example_writer

FAST = ["free_space.speed_mean", "vibration.rms", "vibration.spectral_centroid", "workspace.spec_box_volume"]


def _both(tmp_path: Path) -> tuple[Path, Path]:
    plain = example_writer(duration_s=2.0).write(tmp_path / "plain")
    w = example_writer(duration_s=2.0)
    w.compact = True
    return plain, w.write(tmp_path / "compact")


def test_compact_parquet_is_float32_byte_stream_split_except_t(tmp_path):
    plain, compact = _both(tmp_path)
    path = next((compact / "trials").rglob("plate_wrench.parquet"))
    meta = pq.ParquetFile(path).metadata
    names = [meta.schema.column(i).name for i in range(meta.num_columns)]
    types = {n: meta.schema.column(i).physical_type for i, n in enumerate(names)}
    assert types["t"] == "DOUBLE" and {types[n] for n in names if n != "t"} == {"FLOAT"}
    encodings = {names[i]: meta.row_group(0).column(i).encodings for i in range(meta.num_columns)}
    assert all("BYTE_STREAM_SPLIT" in encodings[n] for n in names if n != "t")
    small = sum(p.stat().st_size for p in (compact / "trials").rglob("*.parquet"))
    large = sum(p.stat().st_size for p in (plain / "trials").rglob("*.parquet"))
    assert small < 0.75 * large


def test_compact_session_validates_and_reads_the_float32_values_exactly(tmp_path):
    plain, compact = _both(tmp_path)
    assert validate_session(compact).valid, validate_session(compact).findings
    s_plain, s_compact = open_session(plain), open_session(compact)
    for trial in s_plain.manifest.trials:
        for stream in trial.streams:
            a = s_plain.read_stream(stream)
            b = s_compact.read_stream(
                next(x for x in next(t for t in s_compact.manifest.trials if t.id == trial.id).streams if x.kind == stream.kind)
            )
            assert list(b.dtypes.unique()) == [np.float64]
            assert np.array_equal(b["t"].to_numpy(), a["t"].to_numpy())  # t is kept as float64
            others = [c for c in a.columns if c != "t"]
            expect = a[others].to_numpy().astype(np.float32).astype(np.float64)
            assert np.array_equal(b[others].to_numpy(), expect, equal_nan=True)


def test_compact_metrics_agree_within_float32_precision(tmp_path):
    plain, compact = _both(tmp_path)
    a = {m.id: m.value for m in compute_session(open_session(plain), metrics=FAST).metrics}
    b = {m.id: m.value for m in compute_session(open_session(compact), metrics=FAST).metrics}
    assert set(a) == set(b) == set(FAST)
    for k in FAST:
        assert b[k] == pytest.approx(a[k], rel=1e-5, abs=1e-9), k


@pytest.mark.parametrize(
    "columns, bad",
    [
        ({"t": pa.float32(), "x": pa.float64()}, "t"),  # a float32 time column loses the sample period
        ({"t": pa.float64(), "x": pa.int64()}, "x"),  # not a float at all
    ],
)
def test_other_column_types_are_E212(tmp_path, columns, bad):
    path = tmp_path / "s.parquet"
    table = pa.table({n: pa.array(np.arange(5), type=t) for n, t in columns.items()})
    pq.write_table(table, path)
    with pytest.raises(HaptifyError) as err:
        read_stream_file(path, "parquet", list(columns), label="s.parquet")
    assert err.value.findings[0].code == "E212" and err.value.findings[0].column == bad


@settings(max_examples=30, deadline=None)
@given(arrays(np.float64, st.integers(1, 200), elements=st.one_of(st.floats(-1e6, 1e6), st.just(float("nan")))))
def test_any_float_column_round_trips_as_its_float32(tmp_path_factory, values):
    path = tmp_path_factory.mktemp("rt") / "s.parquet"
    frame = pd.DataFrame({"t": np.arange(len(values)) * 1e-3, "x": values})
    write_table(path, frame, "parquet", compact=True)
    back, _ = read_stream_file(path, "parquet", ["t", "x"], label="s.parquet")
    assert np.array_equal(back["x"].to_numpy(), values.astype(np.float32).astype(np.float64), equal_nan=True)
    assert np.array_equal(back["t"].to_numpy(), frame["t"].to_numpy())
