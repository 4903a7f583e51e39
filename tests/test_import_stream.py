"""Large C3D files stream (spec §5.5.1): the chunked reader of the data block reads what
ezc3d reads, on every variant the importer meets (REAL and INTEGER words, scaled and offset analog
channels, truncated files, header/data disagreements, analog-only files, a long file past 65535
frames, the real recordings when present), and an import in small chunks writes exactly the streams
of the whole-file import."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from haptify.formats.importers import import_c3d, read_c3d, recording_chunks
from haptify.formats.storage import open_session
from haptify_tools.c3d_variants import (
    PLATFORM_UNITS,
    C3DSpec,
    Platform,
    float32,
    grow_c3d,
    known_load_channels,
    patch_header,
    patch_parameter,
    rectangle_corners,
    to_integer,
    write_c3d,
)
from haptify_tools.example_session import TOUCH_DEVICE

REPO = Path(__file__).resolve().parents[1]
REAL = [d / "shared" / "data" / "c3d" for d in (REPO.parent, REPO.parent.parent)]


def recording(n: int = 23, per_frame: int = 3, seed: int = 1) -> C3DSpec:
    """Three markers (quarter-millimetre steps, one occluded sample), two plain analog channels and a
    type-2 platform carrying a known load, 300 Hz analog; every value an int16 after to_integer."""
    rng = np.random.default_rng(seed)
    pts = rng.integers(-3000, 3000, size=(n, 3, 3)) * 0.25
    res = np.ones((n, 3))
    res[3, 1] = -1.0
    k = n * per_frame
    force = np.column_stack([rng.integers(-50, 50, k), rng.integers(-50, 50, k), rng.integers(100, 300, k)]).astype(float)
    load = known_load_channels(
        2, force, rng.integers(-50, 50, (k, 2)).astype(float), rng.integers(-900, 900, k), (0.0, 0.0, -40.0)
    )
    analogs = np.vstack([rng.integers(-2000, 2000, size=(2, k)).astype(float), load])
    return C3DSpec(
        labels=["a", "b", "c"],
        points=pts,
        residuals=res,
        analog_rate=100.0 * per_frame,
        analog_labels=["x", "y", *[f"F{i}" for i in range(6)]],
        analog_units=["V", "V", *PLATFORM_UNITS[2]],
        analogs=analogs,
        platforms=[
            Platform(2, rectangle_corners([100.0, 50.0, 0.0], 600.0, 400.0), np.array([0.0, 0.0, -40.0]), list(range(3, 9)))
        ],
    )


def scaled(path: Path) -> Path:
    """The analog scaling other writers set: per-channel SCALE and OFFSET (one negative, which ezc3d
    subtracts by magnitude) and a GEN_SCALE."""
    patch_parameter(path, "ANALOG", "SCALE", [0.003, -0.25, 1, 1, 1, 1, 1, 1])
    patch_parameter(path, "ANALOG", "OFFSET", [12, -7, 0, 0, 0, 0, 0, 0])
    return patch_parameter(path, "ANALOG", "GEN_SCALE", [1.5])


def variants(tmp: Path) -> dict[str, Path]:
    out = {"real": write_c3d(tmp / "real.c3d", recording())}
    out["scaled"] = scaled(write_c3d(tmp / "scaled.c3d", recording()))
    out["integer"] = to_integer(out["scaled"], tmp / "integer.c3d", 0.25)
    out["short"] = patch_header(write_c3d(tmp / "short.c3d", recording()), last_frame=30)  # declares 30, holds 23
    out["cut"] = patch_header(write_c3d(tmp / "cut.c3d", recording()), last_frame=12)  # declares 12 of 23
    ao = recording()
    ao.labels, ao.points, ao.residuals, ao.point_rate, ao.frames = [], None, None, 0.0, 23
    out["analog-only"] = write_c3d(tmp / "ao.c3d", ao)
    n = 70_000  # past 65535 frames: the header and POINT:FRAMES hold the long-file mark
    out["long"] = write_c3d(
        tmp / "long.c3d",
        C3DSpec(
            labels=["m"],
            points=float32(np.arange(3.0 * n).reshape(n, 1, 3) % 977),
            analog_rate=200.0,
            analog_labels=["v"],
            analog_units=["V"],
            analogs=float32(np.arange(2.0 * n).reshape(1, -1) % 101),
        ),
    )
    out["grown"] = grow_c3d(
        tmp / "grown.c3d",
        recording(n=5),
        301,
        lambda at, n: (
            np.arange(at, at + n)[:, None, None] * np.array([[[1.0, 2.0, 3.0]]]) + np.zeros((1, 3, 1)),
            float32(np.sin(np.arange(8 * 3 * n).reshape(8, 3 * n) + at)),
        ),
    )
    out.update({f"lab-{p.stem}": p for d in REAL if d.is_dir() for p in sorted(d.glob("*.c3d"))})
    return out


def test_the_chunked_reader_reads_what_ezc3d_reads(tmp_path):
    for name, path in variants(tmp_path).items():
        whole = read_c3d(path, stream=False)
        streamed = read_c3d(path, stream=True)
        assert streamed.layout is not None, name
        assert streamed.summary() == whole.summary(), name  # labels, rates, frames, platforms, W501 warnings
        for chunk in (1, 7, 10**6) if whole.frames < 1000 else (9999, 10**6):
            parts = [part for _, part in recording_chunks(streamed, chunk)]
            np.testing.assert_array_equal(np.concatenate([p.points for p in parts]), whole.points, err_msg=name)
            np.testing.assert_array_equal(np.concatenate([p.analogs for p in parts], axis=1), whole.analogs, err_msg=name)
            assert [p.point_first_frame for p in parts] == [whole.point_first_frame + k for k in range(0, whole.frames, chunk)]


FACTS = {
    "session": {
        "date": "2026-11-25",
        "lab": {"id": "lab-s"},
        "examiner": {"id": "ex-s"},
        "device": TOUCH_DEVICE,
        "device_placement": {"position": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]},
    },
    "trial": {"powered": False},
}


@pytest.mark.parametrize("variant", ["scaled", "integer"])
@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_an_import_in_small_chunks_writes_what_the_whole_file_import_writes(tmp_path, variant, fmt):
    path = scaled(write_c3d(tmp_path / "scaled.c3d", recording()))
    if variant == "integer":
        path = to_integer(path, tmp_path / "integer.c3d", 0.25)
    m = {
        "source": "c3d",
        **json.loads(json.dumps(FACTS)),
        "platform_wrench": {"format": fmt},
        "markers": {"format": fmt},
        "streams": {"sync": {"columns": {"trigger": {"source": "x", "threshold": 0.0}}}},
    }
    seen = []
    whole = import_c3d(path, tmp_path / "whole", None, overrides=m, stream=False)
    parts = import_c3d(
        path,
        tmp_path / "parts",
        None,
        overrides=m,
        stream=True,
        chunk_frames=4,
        progress=lambda done, total: seen.append((done, total)),
    )
    assert seen == [(min(k, 23), 23) for k in range(4, 27, 4)]
    assert whole.streams == parts.streams and whole.warnings == parts.warnings
    a, b = open_session(tmp_path / "whole"), open_session(tmp_path / "parts")
    assert [s.kind for s in a.trials[0].streams] == ["markers", "sync", "plate_wrench"]
    strip = [{k: v for k, v in s.model_dump().items() if k != "sha256"} for s in a.trials[0].streams]
    assert strip == [{k: v for k, v in s.model_dump().items() if k != "sha256"} for s in b.trials[0].streams]
    for s in a.trials[0].streams:
        left, right = a.read(a.trials[0].id, s.kind), b.read(b.trials[0].id, s.kind)
        assert left.equals(right), s.kind


@pytest.mark.parametrize("fmt", ["tsv", "tsv-3d", "motive"])
def test_a_text_export_in_small_chunks_imports_as_the_whole_file(tmp_path, fmt):
    """Qualisys TSV (6DOF and 3-D with QTM's zero gaps) and Motive CSV stream too (§5.5.1): the same
    streams, row for row, as the whole-file import."""
    from test_import_exports import workspace_map, write_motive, write_qtm_6d

    from haptify.formats.importers.exports import import_export, read_export

    path = tmp_path / ("t.csv" if fmt == "motive" else "t.tsv")
    kind = fmt.split("-")[0]
    if fmt == "tsv-3d":
        lines = [
            "NO_OF_FRAMES\t7",
            "NO_OF_CAMERAS\t4",
            "NO_OF_MARKERS\t2",
            "FREQUENCY\t100",
            "NO_OF_ANALOG\t0",
            "DATA_INCLUDED\t3D",
            "MARKER_NAMES\tp\tq",
            "Frame\tTime\tp X\tp Y\tp Z\tq X\tq Y\tq Z",
        ]
        lines += [f"{k + 3}\t{k / 100:.2f}\t{k}.5\t0\t1\t" + ("0\t0\t0" if k == 4 else f"{-k}\t2\t3") for k in range(7)]
        path.write_text("\n".join(lines) + "\n")
        m = {
            "source": "tsv",
            **json.loads(json.dumps(FACTS)),
            "lab_to_world": {"position": [0, 0, 0], "quaternion": [1, 0, 0, 0]},
        }
    else:
        (write_motive if kind == "motive" else write_qtm_6d)(path, frames=203)
        m = workspace_map(kind)
    whole = read_export(kind, path, stream=False)
    streamed = read_export(kind, path, stream=True)
    assert streamed.summary() == whole.summary()
    seen = []
    a = import_export(kind, path, tmp_path / "whole", None, overrides=m, stream=False)
    b = import_export(
        kind,
        path,
        tmp_path / "parts",
        None,
        overrides=m,
        stream=True,
        chunk_frames=3,
        progress=lambda done, total: seen.append(done),
    )
    assert a.streams == b.streams and a.warnings == b.warnings and seen[-1] == whole.frames
    sa, sb = open_session(tmp_path / "whole"), open_session(tmp_path / "parts")
    for s in sa.trials[0].streams:
        assert sa.read(sa.trials[0].id, s.kind).equals(sb.read(sb.trials[0].id, s.kind)), s.kind
