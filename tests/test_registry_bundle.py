"""The submission bundle (spec §17.2, §17.4): deterministic packing, and unpacking that refuses every
hostile archive with its code."""

from __future__ import annotations

import gzip
import json
import tarfile
from pathlib import Path

import pytest
from _registry_fixtures import base, bundle_for, member, tar_gz  # noqa: F401  (base: fixture)
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.errors import HaptifyError
from haptify.formats.bundle_format import Bundle, bundle_digest, canonical_json
from haptify_tools.registry.bundle import Limits, _member_name_problem, read_manifest, unpack
from haptify_tools.registry.checks import agrees, check_bundle, tolerances


@pytest.fixture
def material(base):
    root, session, results, report, impl = base
    return root, session, results, report


def codes(exc: pytest.ExceptionInfo) -> list[str]:
    return [f.code for f in exc.value.findings]


def test_packing_is_deterministic_and_the_digest_is_content(material, tmp_path):
    root, session, results, report = material
    a, da = bundle_for(session, results, report, tmp_path / "a.tar.gz", include_raw=True)
    b, db_ = bundle_for(session, results, report, tmp_path / "b.tar.gz", include_raw=True)
    assert a.read_bytes() == b.read_bytes() and da == db_
    # the digest is the sha256 of canonical bundle.json, whatever the compression
    unpacked = unpack(a, tmp_path / "u")
    bundle = read_manifest(unpacked)
    import hashlib

    assert hashlib.sha256(canonical_json(bundle.model_dump(mode="json"))).hexdigest() == da
    assert (tmp_path / "u" / "bundle.json").read_bytes() == canonical_json(bundle.model_dump(mode="json"))
    recompressed = tmp_path / "c.tar.gz"
    with tarfile.open(a, "r:gz") as src, tarfile.open(recompressed, "w:gz", compresslevel=1) as dst:
        for m in src.getmembers():
            dst.addfile(m, src.extractfile(m))
    assert recompressed.read_bytes() != a.read_bytes()
    assert bundle_digest(read_manifest(unpack(recompressed, tmp_path / "u2"))) == da
    # every file is declared with its sha256; streams only with --include-raw
    roles = {f.role for f in bundle.files}
    assert {"results", "conformance", "session-manifest", "stream"} <= roles
    _, d_noraw = bundle_for(session, results, report, tmp_path / "n.tar.gz")
    assert d_noraw != da


def test_bundle_schema_is_generated_from_the_model():
    schema = Bundle.model_json_schema()
    assert {"lab", "device", "rig", "spec_version", "implementation", "files", "includes_raw"} <= set(schema["properties"])


def _limits(**kw) -> Limits:
    return Limits(**kw)


def test_size_limits(material, tmp_path):
    root, session, results, report = material
    archive, _ = bundle_for(session, results, report, tmp_path / "a.tar.gz", include_raw=True)
    size = archive.stat().st_size
    with pytest.raises(HaptifyError) as e:
        unpack(archive, tmp_path / "u1", _limits(max_archive_bytes=size - 1))
    assert codes(e) == ["E960"]
    with pytest.raises(HaptifyError) as e:
        unpack(archive, tmp_path / "u2", _limits(max_unpacked_bytes=20_000))
    assert codes(e) == ["E960"]
    with pytest.raises(HaptifyError) as e:
        unpack(archive, tmp_path / "u3", _limits(max_members=3))
    assert codes(e) == ["E960"]
    unpacked = unpack(archive, tmp_path / "u4")
    with pytest.raises(HaptifyError) as e:
        check_bundle(unpacked, _limits(max_json_bytes=1000))
    assert codes(e) == ["E960"]


@pytest.mark.parametrize(
    "name, why",
    [
        ("../evil.txt", "climbs"),
        ("session/../../evil.txt", "climbs"),
        ("/etc/passwd", "absolute"),
        ("C:/x.txt", "absolute"),
        ("a\\b.txt", "plain relative"),
        ("./bundle.json", "plain relative"),
    ],
)
def test_unsafe_paths_are_refused(tmp_path, name, why):
    data = tar_gz([(member(name), b"x")])
    (tmp_path / "a.tar.gz").write_bytes(data)
    with pytest.raises(HaptifyError) as e:
        unpack(tmp_path / "a.tar.gz", tmp_path / "u")
    assert codes(e) == ["E962"] and why in e.value.findings[0].message
    assert not (tmp_path / "evil.txt").exists() and not (tmp_path.parent / "evil.txt").exists()


@pytest.mark.parametrize(
    "kind, linkname, word",
    [
        (tarfile.SYMTYPE, "/etc/passwd", "symbolic link"),
        (tarfile.SYMTYPE, "results.json", "symbolic link"),
        (tarfile.LNKTYPE, "results.json", "hard link"),
        (tarfile.CHRTYPE, "", "not a regular file"),
        (tarfile.FIFOTYPE, "", "not a regular file"),
    ],
)
def test_links_and_special_files_are_refused(tmp_path, kind, linkname, word):
    data = tar_gz([(member("results.json"), b"{}"), (member("session/x", kind, linkname), None)])
    (tmp_path / "a.tar.gz").write_bytes(data)
    with pytest.raises(HaptifyError) as e:
        unpack(tmp_path / "a.tar.gz", tmp_path / "u")
    assert codes(e) == ["E962"] and word in e.value.findings[0].message


def test_duplicate_and_case_folded_names_are_refused(tmp_path):
    for i, second in enumerate(["results.json", "RESULTS.json"]):
        (tmp_path / f"a{i}.tar.gz").write_bytes(tar_gz([(member("results.json"), b"{}"), (member(second), b"[]")]))
        with pytest.raises(HaptifyError) as e:
            unpack(tmp_path / f"a{i}.tar.gz", tmp_path / f"u{i}")
        assert codes(e) == ["E962"]


def test_a_file_where_a_folder_is_needed_is_refused(tmp_path):
    (tmp_path / "a.tar.gz").write_bytes(tar_gz([(member("session"), b"x"), (member("session/session.json"), b"{}")]))
    with pytest.raises(HaptifyError) as e:
        unpack(tmp_path / "a.tar.gz", tmp_path / "u")
    assert codes(e) == ["E962"]


def test_decompression_bomb_is_stopped_early(tmp_path):
    # 4 MiB of zeros compress to ~4 KiB: expansion ~1000x, refused after about ratio x compressed bytes
    zeros = b"\0" * (4 << 20)
    data = tar_gz([(member("session/big.bin"), zeros)])
    assert len(data) < 200_000
    (tmp_path / "bomb.tar.gz").write_bytes(data)
    with pytest.raises(HaptifyError) as e:
        unpack(tmp_path / "bomb.tar.gz", tmp_path / "u")
    assert codes(e) == ["E963"]
    written = sum(p.stat().st_size for p in (tmp_path / "u").rglob("*") if p.is_file())
    assert written <= Limits().max_ratio * len(data) + (1 << 20)
    # zeros alone are an empty tar archive: reading stops at its end marker, nothing else is decompressed
    gz = gzip.compress(b"\0" * (200 << 20), mtime=0)
    (tmp_path / "pad.tar.gz").write_bytes(gz)
    unpacked = unpack(tmp_path / "pad.tar.gz", tmp_path / "u2")
    assert unpacked.members == {}
    with pytest.raises(HaptifyError) as e:
        read_manifest(unpacked)
    assert codes(e) == ["E964"]


@pytest.mark.parametrize("payload", [b"not gzip at all", gzip.compress(b"not a tar archive" * 10, mtime=0), b""])
def test_not_an_archive_is_E961(tmp_path, payload):
    (tmp_path / "a.tar.gz").write_bytes(payload)
    with pytest.raises(HaptifyError) as e:
        unpack(tmp_path / "a.tar.gz", tmp_path / "u")
    assert codes(e) == ["E961"]


def test_truncated_archive_is_E961(material, tmp_path):
    root, session, results, report = material
    archive, _ = bundle_for(session, results, report, tmp_path / "a.tar.gz", include_raw=True)
    data = archive.read_bytes()
    (tmp_path / "t.tar.gz").write_bytes(data[: len(data) // 2])
    with pytest.raises(HaptifyError) as e:
        unpack(tmp_path / "t.tar.gz", tmp_path / "u")
    assert codes(e) == ["E961"]


def _rewrite(archive: Path, target: Path, change) -> Path:
    """Copy an archive, letting ``change(name, bytes)`` return new bytes (or None to drop the member)."""
    out = []
    with tarfile.open(archive, "r:gz") as tar:
        for m in tar.getmembers():
            data = change(m.name, tar.extractfile(m).read())
            if data is not None:
                out.append((member(m.name), data))
    target.write_bytes(tar_gz(out))
    return target


@pytest.mark.parametrize(
    "case, code",
    [
        ("malformed-bundle-json", "E964"),
        ("schema-invalid-bundle-json", "E964"),
        ("missing-bundle-json", "E964"),
        ("file-changed", "E965"),
        ("file-missing", "E965"),
        ("file-undeclared", "E965"),
        ("malformed-results", "E966"),
        ("schema-invalid-results", "E966"),
        ("non-finite-results", "E966"),
        ("malformed-conformance", "E966"),
    ],
)
def test_malformed_and_invalid_documents(material, tmp_path, case, code):
    root, session, results, report = material
    archive, _ = bundle_for(session, results, report, tmp_path / "a.tar.gz")

    def change(name: str, data: bytes):
        doc = json.loads(data) if name.endswith(".json") else None
        if case == "malformed-bundle-json" and name == "bundle.json":
            return data[:-5]
        if case == "schema-invalid-bundle-json" and name == "bundle.json":
            doc["lab"] = {"id": "../x"}
            return canonical_json(doc)
        if case == "missing-bundle-json" and name == "bundle.json":
            return None
        if name == "results.json":
            if case == "file-changed":
                return data + b" "
            if case == "file-missing":
                return None
        if name == "bundle.json" and case.endswith("-results") or (case == "malformed-conformance" and name == "bundle.json"):
            target = "results.json" if case.endswith("-results") else "conformance.json"
            new = {
                "malformed-results": b'{"metrics": [',
                "schema-invalid-results": json.dumps({**json.loads(results.read_text()), "session_id": 5}).encode(),
                "non-finite-results": results.read_text()
                .replace('"value": 0.0', '"value": NaN', 1)
                .replace('"n": 1', '"n": Infinity', 1)
                .encode(),
                "malformed-conformance": b"{]",
            }[case]
            change.new = (target, new)
            import hashlib

            for f in doc["files"]:
                if f["path"] == target:
                    f["size"], f["sha256"] = len(new), hashlib.sha256(new).hexdigest()
            return canonical_json(doc)
        if hasattr(change, "new") and name == change.new[0]:
            return change.new[1]
        return data

    entries = []
    with tarfile.open(archive, "r:gz") as tar:  # bundle.json comes first, so change.new is set before its target
        for m in tar.getmembers():
            data = change(m.name, tar.extractfile(m).read())
            if data is not None:
                entries.append((member(m.name), data))
    if case == "file-undeclared":
        entries.append((member("session/extra.txt"), b"x"))
    (tmp_path / "b.tar.gz").write_bytes(tar_gz(entries))
    with pytest.raises(HaptifyError) as e:
        check_bundle(unpack(tmp_path / "b.tar.gz", tmp_path / "u"))
    assert code in codes(e)
    f = next(f for f in e.value.findings if f.code == code)
    assert f.file  # every refusal names the file


def test_tolerance_is_the_loosest_case_tolerance_per_metric():
    from haptify_conform.cases import load_cases

    tol = tolerances("1.0")
    # the envelope takes, per metric, the largest absolute and the largest relative part over its cases
    for metric in ("workspace.coverage", "vibration.rms", "free_space.force_sd"):
        cases = [c for c in load_cases() if c.metric == metric]
        assert tol[metric] == {"abs": max(c.tolerance.abs for c in cases), "rel": max(c.tolerance.rel for c in cases)}
    assert "validate" not in tol
    assert agrees(1.0019, 1.0, {"abs": 0.0, "rel": 0.002}) and not agrees(1.0021, 1.0, {"abs": 0.0, "rel": 0.002})
    assert agrees([1.0, 2.0, 3.0], [1.0, 2.0, 3.001], {"abs": 0.002, "rel": 0.0})
    assert not agrees([1.0, 2.0], [1.0, 2.0, 3.0], {"abs": 1.0, "rel": 1.0})


def test_metric_records_must_match_their_definitions(material):
    from haptify.pipeline.results import ResultsFile
    from haptify_tools.registry.checks import metric_findings

    root, session, results, report = material
    data = json.loads(results.read_text())
    assert metric_findings(ResultsFile.model_validate(data)) == []
    data["metrics"][0]["unit"] = "km/h"
    data["metrics"][1]["id"] = "vibration.loudness"
    data["metrics"][2]["value"] = [1.0, 2.0]
    data["metrics"][3]["definition_version"] = "0.9.0"
    data["metrics"].append(dict(data["metrics"][4]))
    found = {(f.pointer, str(f.found)) for f in metric_findings(ResultsFile.model_validate(data))}
    assert found == {
        ("/metrics/0/unit", "km/h"),
        ("/metrics/1/id", "vibration.loudness"),
        ("/metrics/2/value", "list of 2"),
        ("/metrics/3/definition_version", "0.9.0"),
        ("/metrics/5", data["metrics"][4]["id"]),
    }


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from(["a", "b", ".", "..", "", "/", "\\", "C:", "x.json", "\x00"]), min_size=1, max_size=8))
def test_an_accepted_member_name_never_leaves_the_bundle_folder(parts):
    """Property: whatever a member is called, a name that passes the check resolves inside the folder."""
    import os.path

    name = "".join(p if p in ("/", "\\") else p + "/" for p in parts).rstrip("/") or "/"
    if _member_name_problem(name) is None:
        root = "/bundle-root"
        resolved = os.path.normpath(os.path.join(root, *name.split("/")))
        assert resolved.startswith(root + "/") and "\\" not in name and "\x00" not in name


@pytest.mark.parametrize(
    "edit, code, pointer",
    [
        (lambda d: d.update(spec_version="2.0"), "E968", "/spec_version"),
        (lambda d: d.update(manifest_sha256="0" * 64), "E966", "/manifest_sha256"),
        (lambda d: d["device"].update(model="Falcon"), "E966", "/device"),
        (lambda d: d.update(metrics=[]), "E966", "/metrics"),
    ],
)
def test_documents_must_agree(material, tmp_path, edit, code, pointer):
    root, session, results, report = material
    data = json.loads(results.read_text())
    edit(data)
    (tmp_path / "results.json").write_text(json.dumps(data))
    archive, _ = bundle_for(session, tmp_path / "results.json", report, tmp_path / "a.tar.gz")
    with pytest.raises(HaptifyError) as e:
        check_bundle(unpack(archive, tmp_path / "u"))
    f = next(f for f in e.value.findings if f.code == code)
    assert f.pointer == pointer and f.expected != f.found
