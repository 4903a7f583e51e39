"""Corrupt inputs get specific codes from every command that reads a session (spec §4.1, §4.8): bytes
flipped, files truncated and JSON values swapped for another type, in every file of a valid session, with
and without the manifest's checksum updated to the damaged file. Never E999, never a traceback.

The number of examples is ``HAPTIFY_CORRUPTION_EXAMPLES`` (default 40 in ``make test``; the figure for
2 000 is in benchmarks/RESULTS.md).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haptify.cli.main import main
from haptify.formats.storage import sha256_file
from haptify_tools.example_session import example_writer
from haptify_tools.invalid_fixtures import defects, session_edits

EXAMPLES = int(os.environ.get("HAPTIFY_CORRUPTION_EXAMPLES", "40"))
MODEL = Path(__file__).resolve().parents[1] / "fixtures" / "conformance" / "dyn-predict" / "model-a.json"


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> dict[str, Path]:
    """Two valid sessions (Parquet and CSV streams, the device in its own file) and the side inputs."""
    root = tmp_path_factory.mktemp("pristine")
    sessions = {}
    for fmt in ("parquet", "csv"):
        folder = example_writer(session_id=f"corrupt-{fmt}", duration_s=0.3, fmt=fmt).write(root / fmt)
        defects._device_file({})(folder)
        sessions[fmt] = folder
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["twin", "export", "--preset", "touch", "-o", str(root / "twin.json")]) == 0
        assert main(["compute", str(sessions["parquet"]), "-o", str(root / "results.json")]) == 0
    return {**sessions, "twin": root / "twin.json", "results": root / "results.json"}


def _files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


OTHER_TYPES = [None, True, 0, -1.5, 1e308, "", "x", [], [1, "a"], {}, {"a": None}]


def _json_nodes(node, pointer=()):
    yield pointer
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        yield from _json_nodes(v, pointer + (k,))


def _swap_type(data: bytes, draw) -> bytes:
    """Replace one value of a JSON document by a value of another type."""
    doc = json.loads(data)
    pointers = [p for p in _json_nodes(doc) if p]
    if not pointers:
        return data
    pointer = draw(st.sampled_from(pointers))
    parent = doc
    for k in pointer[:-1]:
        parent = parent[k]
    old = parent[pointer[-1]]
    parent[pointer[-1]] = draw(st.sampled_from([v for v in OTHER_TYPES if type(v) is not type(old)]))
    return json.dumps(doc).encode("utf-8")


def _corrupt(folder: Path, draw) -> str:
    rel = draw(st.sampled_from(_files(folder)))
    path = folder / rel
    data = path.read_bytes()
    kind = draw(st.sampled_from(["flip", "truncate", "swap"] if rel.endswith(".json") else ["flip", "truncate"]))
    if kind == "truncate":
        data = data[: draw(st.integers(0, max(0, len(data) - 1)))]
    elif kind == "flip" and data:
        buf = bytearray(data)
        for _ in range(draw(st.integers(1, 8))):
            buf[draw(st.integers(0, len(buf) - 1))] = draw(st.integers(0, 255))
        data = bytes(buf)
    elif kind == "swap":
        data = _swap_type(data, draw)
    path.write_bytes(data)
    if not rel.endswith(".json") and draw(st.booleans()):  # the damage behind an updated checksum
        with contextlib.suppress(Exception):
            m = session_edits.manifest(folder)
            for trial in m["trials"]:
                for s in trial["streams"]:
                    if s["file"] == rel:
                        s["sha256"] = sha256_file(path)
            session_edits.save_manifest(folder, m)
    return f"{kind} {rel}"


def _commands(s: str, out: Path, inputs: dict[str, Path]) -> list[list[str]]:
    return [
        ["validate", s],
        ["compute", s, "-o", str(out / "results.json")],
        ["report", s, "-o", str(out / "report")],
        ["view", s, "--save", str(out / "s.rrd")],
        ["dynamics", "fit", s, "-o", str(out / "m.json")],
        ["dynamics", "predict", str(MODEL), s, "-o", str(out / "p.parquet")],
        ["rig-check", s],
        ["discrepancy", "--session", s, "--twin", str(inputs["twin"]), "-o", str(out / "d"), "--overwrite"],
        ["submit", s, "--results", str(inputs["results"]), "--dry-run"],
    ]


@pytest.mark.slow
@settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(fmt=st.sampled_from(["parquet", "csv"]), data=st.data())
def test_no_corrupt_input_ends_in_an_internal_error(pristine, tmp_path_factory, fmt, data):
    work = tmp_path_factory.mktemp("corrupt")
    folder = work / "session"
    shutil.copytree(pristine[fmt], folder)
    what = _corrupt(folder, data.draw)
    out = work / "out"
    for argv in _commands(str(folder), out, pristine):
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir()
        stdout, stderr = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            status = main(["--json", *argv])
        text = stdout.getvalue() + stderr.getvalue()
        assert "E999" not in text and "Traceback" not in text, (what, argv, text[-2000:])
        assert status in (0, 1, 2), (what, argv, status)
