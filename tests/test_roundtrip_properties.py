"""Properties of storage and validation (spec chapters 3 and 4), checked with hypothesis.

1. Random valid sessions round-trip through Parquet and through CSV exactly: every float comes back
   bit-identical (signed zeros, subnormals, extremes) and NaN (motion-capture occlusion) stays exactly
   where it was; the written session validates without errors.
2. Random mutations of valid sessions — of session.json and of the stream files — are either still
   valid or produce coded findings; validation never raises and never reports an internal error.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haptify.errors import catalogue
from haptify.formats.session_format import ALLOWED_VALUES, expected_columns, kind_table, quaternion_groups
from haptify.formats.storage import MANIFEST, SessionWriter, open_session, read_table, sha256_file, write_table
from haptify.formats.validation import MOCAP_KINDS, validate_session
from haptify_tools.example_session import example_writer

REPO = Path(__file__).resolve().parents[1]
VALID = [REPO / "fixtures" / "valid" / "parquet-basic", REPO / "fixtures" / "valid" / "csv-multi-trial"]
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

ENTITY_KINDS = {"markers": ["h1", "h2", "h3"], "link_poses": ["handle"]}
KINDS = [
    "handle_wrench",
    "handle_accel",
    "plate_wrench",
    "handle_pose",
    "markers",
    "link_poses",
    "commanded_wrench",
    "device_joint_angles",
    "sync",
]

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def stream_data(draw, kind: str, t0: float) -> tuple[dict, float, list[str] | None]:
    """Columns of one valid stream of ``kind``: exact time grid, arbitrary finite floats, unit quaternions,
    whole-entity NaN occlusion in motion-capture kinds."""
    entities = None
    if kind in ENTITY_KINDS:
        pool = ENTITY_KINDS[kind]
        entities = draw(st.lists(st.sampled_from(pool), min_size=1, max_size=len(pool), unique=True))
    present = ["q4", "q5", "q6"] if kind == "device_joint_angles" and draw(st.booleans()) else []
    cols = [c for c, _ in expected_columns(kind, entities, present)]
    rate = float(kind_table(kind)["recommended_rate_hz"]) * draw(st.sampled_from([1, 2, 4]))
    n = draw(st.integers(2, 25))
    data = {"t": t0 + np.arange(n) / rate}
    for c in cols[1:]:
        allowed = ALLOWED_VALUES.get((kind, c))  # a closed value set (the sync trigger: 0 or 1, E214)
        values = st.sampled_from(allowed) if allowed is not None else finite
        data[c] = np.array(draw(st.lists(values, min_size=n, max_size=n)), dtype=np.float64)
    for group in quaternion_groups(kind, entities):
        raw = np.array(draw(st.lists(st.lists(st.floats(-1, 1), min_size=4, max_size=4), min_size=n, max_size=n)))
        raw[np.linalg.norm(raw, axis=1) < 1e-3] = [1.0, 0.0, 0.0, 0.0]
        unit = raw / np.linalg.norm(raw, axis=1, keepdims=True)
        for k, c in enumerate(group):
            data[c] = unit[:, k]
    if kind in MOCAP_KINDS:
        width = len(kind_table(kind).get("entity_columns", kind_table(kind).get("columns")))
        groups = [cols[1 + k * width : 1 + (k + 1) * width] for k in range(len(entities or [None]))]
        for g in groups:
            mask = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
            for c in g:
                data[c] = np.where(mask, np.nan, data[c])
    return data, rate, entities


@st.composite
def sessions(draw) -> tuple[str, list[tuple[str, dict, float, list[str] | None]]]:
    fmt = draw(st.sampled_from(["parquet", "csv"]))
    kinds = draw(st.lists(st.sampled_from(KINDS), min_size=1, max_size=4, unique=True))
    t0 = draw(st.floats(0, 1000, allow_subnormal=False))
    return fmt, [(k, *draw(stream_data(k, t0))) for k in kinds]


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    return bool(np.array_equal(nan_a, nan_b) and np.array_equal(a[~nan_a].view(np.uint64), b[~nan_b].view(np.uint64)))


@settings(max_examples=25, **SETTINGS)
@given(sessions())
def test_random_sessions_round_trip_bit_for_bit_and_validate(case):
    fmt, streams = case
    with tempfile.TemporaryDirectory() as tmp:
        w = SessionWriter(manifest={**example_writer().manifest, "session_id": "prop"})
        w.add_trial("prop-1", "other", powered=False, label="property")
        for kind, data, rate, entities in streams:
            w.add_stream("prop-1", kind, data, rate_hz=rate, fmt=fmt, entities=entities)
        folder = w.write(Path(tmp) / "s")
        session = open_session(folder)
        trial = session.trial("prop-1")
        for (kind, data, _, _), stream in zip(streams, trial.streams):
            table = session.read_stream(stream, verify=True)
            assert list(table.columns) == list(data)
            for c, values in data.items():
                got = table[c].to_numpy()
                assert got.dtype == np.float64
                assert _same_bits(np.asarray(values, dtype=np.float64), got), (fmt, kind, c)
        report = validate_session(folder)
        assert report.errors == [], [str(f) for f in report.errors]  # warnings (e.g. W401 ranges) may occur


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_extreme_floats_round_trip_exactly(fmt: str, tmp_path: Path):
    tricky = np.array(
        [
            -0.0,
            0.0,
            5e-324,
            -2.2250738585072014e-308,
            1.7976931348623157e308,
            -1.7976931348623157e308,
            0.1,
            1 / 3,
            2.0**-1074 * 3,
            123456789.12345679,
            -1e-300,
            9.999999999999999e22,
        ]
    )
    n = len(tricky)
    data = {"t": np.arange(n) / 1000.0, **{c: np.roll(tricky, k) for k, c in enumerate(["fx", "fy", "fz", "tx", "ty", "tz"])}}
    w = SessionWriter(manifest={**example_writer().manifest, "session_id": "extremes"})
    w.add_trial("x-1", "other", powered=False, label="extremes")
    w.add_stream("x-1", "commanded_wrench", data, rate_hz=1000, fmt=fmt)
    session = open_session(w.write(tmp_path / "s"))
    table = session.read("x-1", "commanded_wrench", verify=True)
    for c, values in data.items():
        assert _same_bits(values, table[c].to_numpy()), c


# --- mutations -------------------------------------------------------------------------------------

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**15), 10**15) | finite | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=6,
)


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


@st.composite
def json_mutation(draw, manifest: dict):
    paths = [p for p in _paths(manifest) if p]
    path = draw(st.sampled_from(paths))
    op = draw(st.sampled_from(["replace", "delete", "duplicate", "retype"]))
    value = draw(json_values)
    return path, op, value


def _apply_json(manifest: dict, mutation) -> dict:
    path, op, value = mutation
    parent = manifest
    for key in path[:-1]:
        parent = parent[key]
    key = path[-1]
    if op == "replace":
        parent[key] = value
    elif op == "delete":
        del parent[key]
    elif op == "duplicate" and isinstance(parent, list):
        parent.append(json.loads(json.dumps(parent[key])))
    elif op == "retype":
        old = parent[key]
        parent[key] = str(old) if not isinstance(old, str) else (float(len(old)) if old else None)
    return manifest


def _copy(base: Path, tmp: str) -> Path:
    target = Path(tmp) / "s"
    shutil.copytree(base, target, symlinks=True)
    return target


def _check(report) -> None:
    codes = catalogue()
    assert "E999" not in report.codes, [str(f) for f in report.findings]
    assert all(f.code in codes and f.file for f in report.findings)
    assert report.exit_code == (1 if report.errors else 0)


@pytest.mark.parametrize("base", VALID, ids=lambda p: p.name)
@settings(max_examples=30, **SETTINGS)
@given(data=st.data())
def test_random_manifest_mutations_give_coded_findings_never_exceptions(base: Path, data):
    manifest = json.loads((base / MANIFEST).read_text(encoding="utf-8"))
    mutation = data.draw(json_mutation(manifest))
    with tempfile.TemporaryDirectory() as tmp:
        folder = _copy(base, tmp)
        mutated = _apply_json(json.loads(json.dumps(manifest)), mutation)
        (folder / MANIFEST).write_text(json.dumps(mutated), encoding="utf-8")
        _check(validate_session(folder))


@st.composite
def data_mutation(draw, files: list[str]):
    rel = draw(st.sampled_from(files))
    op = draw(st.sampled_from(["truncate", "flip", "append", "cell", "cell-rehash", "delete", "symlink", "reorder"]))
    return rel, op, draw(st.integers(0, 2**31)), draw(st.floats(allow_nan=True, allow_infinity=True))


def _apply_data(folder: Path, manifest: dict, mutation) -> None:
    rel, op, seed, value = mutation
    path = folder / rel
    stream = next(s for t in manifest["trials"] for s in t["streams"] if s["file"] == rel)
    raw = path.read_bytes()
    rng = np.random.default_rng(seed)
    if op == "truncate":
        path.write_bytes(raw[: int(rng.integers(0, len(raw)))])
    elif op == "flip":
        k = int(rng.integers(0, len(raw)))
        path.write_bytes(raw[:k] + bytes([raw[k] ^ (1 << int(rng.integers(0, 8)))]) + raw[k + 1 :])
    elif op == "append":
        path.write_bytes(raw + rng.bytes(int(rng.integers(1, 64))))
    elif op == "delete":
        path.unlink()
    elif op == "symlink":
        path.unlink()
        os.symlink(["../" * int(rng.integers(1, 6)) + "x.parquet", "/etc/hostname", "."][int(rng.integers(0, 3))], path)
    else:
        table = read_table(path, stream["format"], [c["name"] for c in stream["columns"]], label=rel)
        if op == "reorder":
            table = table.iloc[rng.permutation(len(table))].reset_index(drop=True)
        else:
            col = table.columns[int(rng.integers(0, len(table.columns)))]
            values = table[col].to_numpy().copy()
            values[int(rng.integers(0, len(values)))] = value
            table[col] = values
        write_table(path, table, stream["format"])
        if op == "cell-rehash":
            stream["sha256"] = sha256_file(path)
            (folder / MANIFEST).write_text(json.dumps(manifest), encoding="utf-8")


@pytest.mark.parametrize("base", VALID, ids=lambda p: p.name)
@settings(max_examples=30, **SETTINGS)
@given(data=st.data())
def test_random_data_mutations_give_coded_findings_never_exceptions(base: Path, data):
    manifest = json.loads((base / MANIFEST).read_text(encoding="utf-8"))
    files = [s["file"] for t in manifest["trials"] for s in t["streams"]]
    mutation = data.draw(data_mutation(files))
    with tempfile.TemporaryDirectory() as tmp:
        folder = _copy(base, tmp)
        _apply_data(folder, json.loads(json.dumps(manifest)), mutation)
        report = validate_session(folder)
        _check(report)
        rel, op = mutation[:2]
        if op in ("truncate", "flip", "append", "delete", "symlink"):
            # the bytes changed (or the file went): the checksum or the reading must object
            assert report.errors, mutation
