"""The submission bundle (spec §17.2): what a lab sends to a results registry.

A bundle is a gzip-compressed POSIX tar archive holding only regular files:

``bundle.json``           the bundle manifest (:class:`Bundle`): who, which device and rig, which
                          implementation, and the size and sha256 of every other file;
``results.json``          the results (``haptify.pipeline.results.ResultsFile``);
``conformance.json``      optional: the ``haptify-conform --json-report`` of that implementation;
``session/session.json``  the session manifest the results were computed from (and ``session/<file>``
                          for a device file it references);
``session/…``             with ``--include-raw``: every other file of the session folder (the streams).

The bundle's identity is its **digest**: the sha256 of the canonical JSON of ``bundle.json`` (keys
sorted, no whitespace, UTF-8). Because ``bundle.json`` lists the sha256 of every file, the digest
commits to every byte of content, and it does not depend on how the archive was compressed. Packing is
deterministic as well (sorted members, zero times and owners, fixed modes, gzip without name or time),
so packing the same content twice gives byte-identical archives on the same zlib.

Unpacking never trusts the archive: sizes are counted on the bytes actually decompressed and on the
bytes actually written, every member must be a regular, non-sparse file (or a directory entry) at a
safe relative path, and each file is written with ``O_EXCL | O_NOFOLLOW``, mode 0600, into a fresh
folder (spec §17.4).
"""

from __future__ import annotations

import gzip
import hashlib
import io
import os
import tarfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from pydantic import ValidationError

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail
from haptify.formats.bundle_format import (
    BUNDLE_JSON,
    CONFORMANCE_JSON,
    RESULTS_JSON,
    SESSION_DIR,
    Bundle,
    BundleDevice,
    BundleFile,
    BundleLab,
    Role,
    bundle_digest,
    canonical_json,
)
from haptify.formats.session_format import is_safe_relative_path
from haptify.formats.storage import MANIFEST, parse_json_file, pydantic_findings, resolve_inside, sha256_file

CHUNK = 1 << 16
FILE_MODE = 0o600  # what the registry writes is readable by its service user only (spec §17.7)
DIR_MODE = 0o700


# --- packing -------------------------------------------------------------------------------------


def _session_files(session_dir: Path, manifest: dict, include_raw: bool) -> list[tuple[str, Path, Role]]:
    """``(archive path, source, role)`` of the session files a bundle carries (spec §17.2)."""
    out: list[tuple[str, Path, Role]] = [(f"{SESSION_DIR}/{MANIFEST}", session_dir / MANIFEST, "session-manifest")]
    device = manifest.get("device")
    referenced: set[str] = set()
    if isinstance(device, dict) and "file" in device:
        referenced.add(device["file"])
    streams = {s["file"] for t in manifest.get("trials", []) for s in t.get("streams", [])}
    if include_raw:
        for dirpath, dirnames, filenames in os.walk(session_dir):
            dirnames.sort()
            for name in sorted(filenames):
                rel = Path(dirpath, name).relative_to(session_dir).as_posix()
                if rel != MANIFEST:
                    referenced.add(rel)
    for rel in sorted(referenced):
        source = resolve_inside(session_dir, rel, label=rel)
        if not source.is_file():
            raise fail(
                Code.BUNDLE_FILE_MISMATCH,
                f"the session file {rel!r} does not exist",
                file=rel,
                expected="a regular file",
                found="missing",
            )
        out.append((f"{SESSION_DIR}/{rel}", source, "stream" if rel in streams else "session-file"))
    return out


def _file_entry(path: str, source: Path, role: Role) -> BundleFile:
    return BundleFile(path=path, role=role, size=source.stat().st_size, sha256=sha256_file(source))


def build_bundle(
    session_dir: str | os.PathLike,
    results_path: str | os.PathLike,
    conformance_path: str | os.PathLike | None = None,
    *,
    include_raw: bool = False,
    supersedes: str | None = None,
) -> tuple[Bundle, list[tuple[str, Path]]]:
    """The bundle manifest and the ``(archive path, source file)`` list for a session and its results.
    Spec §17.2.

    Reads the session manifest and the results only as far as needed to fill ``bundle.json``; the full
    checks are :func:`haptify_tools.registry.checks.check_bundle`'s (the registry runs the same).
    """
    from haptify.formats.storage import open_session, read_json_model
    from haptify.pipeline.results import ResultsFile

    session_dir = Path(session_dir)
    session = open_session(session_dir)
    results = read_json_model(results_path, ResultsFile, Code.BUNDLE_CONTENT_INVALID)
    device = session.device()
    sources: list[tuple[str, Path, Role]] = [(RESULTS_JSON, Path(results_path), "results")]
    if conformance_path is not None:
        if not Path(conformance_path).is_file():
            raise fail(
                Code.CONFORMANCE_NOT_PASSING,
                f"the conformance report {str(conformance_path)!r} does not exist",
                file=str(conformance_path),
            )
        sources.append((CONFORMANCE_JSON, Path(conformance_path), "conformance"))
    sources += _session_files(session_dir, session.raw, include_raw)
    bundle = Bundle(
        spec_version=results.spec_version,
        lab=BundleLab(id=session.manifest.lab.id),
        device=BundleDevice(manufacturer=device.manufacturer, model=device.model, serial=device.serial),
        rig=session.manifest.rig,
        implementation=results.implementation,
        session_id=session.session_id,
        includes_raw=include_raw,
        supersedes=supersedes,
        files=[_file_entry(p, s, r) for p, s, r in sorted(sources)],
    )
    return bundle, [(p, s) for p, s, _ in sorted(sources)]


def _tar_info(name: str, size: int) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.size, info.mtime, info.mode, info.type = size, 0, 0o644, tarfile.REGTYPE
    info.uid = info.gid = 0
    info.uname = info.gname = ""
    return info


def pack(bundle: Bundle, files: list[tuple[str, Path]], target: str | os.PathLike) -> str:
    """Write the bundle archive deterministically to ``target``; returns the bundle digest (spec §17.2).

    Members are ``bundle.json`` first, then the files in path order; every member has time 0, owner 0,
    mode 0644; the gzip header has no file name and time 0. Each file is checked against its declared
    sha256 while it is copied, so a file changed after :func:`build_bundle` is E965, never a bad bundle.
    """
    declared = {f.path: f for f in bundle.files}
    with (
        open(target, "wb") as raw,
        gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0, compresslevel=6) as gz,
        tarfile.open(fileobj=gz, mode="w", format=tarfile.PAX_FORMAT) as tar,
    ):
        manifest = canonical_json(bundle.model_dump(mode="json"))
        tar.addfile(_tar_info(BUNDLE_JSON, len(manifest)), io.BytesIO(manifest))
        for path, source in sorted(files):
            entry = declared[path]
            with open(source, "rb") as fh:
                data = fh.read()
            if len(data) != entry.size or hashlib.sha256(data).hexdigest() != entry.sha256:
                raise fail(
                    Code.BUNDLE_FILE_MISMATCH,
                    f"{path!r} changed while the bundle was packed",
                    file=path,
                    expected=entry.sha256,
                    found=hashlib.sha256(data).hexdigest(),
                )
            tar.addfile(_tar_info(path, len(data)), io.BytesIO(data))
        raw.flush()
        os.fsync(raw.fileno())
    return bundle_digest(bundle)


# --- unpacking -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Limits:
    """The registry's size limits (spec §17.4); every one is a setting of the service."""

    # Sized from the demo dossier (3 repetitions of every protocol, spec §17.4; its bundle sizes, float64 and compact
    # §3.2.1, in benchmarks/RESULTS.md): 1 GiB leaves four times its float64 bundle, and a bundle unpacks to about its size.
    max_archive_bytes: int = 1 << 30  # the upload as sent
    max_unpacked_bytes: int = 2 << 30  # sum of the bytes the archive decompresses to
    max_ratio: float = 100.0  # decompressed / compressed, judged once more than ratio_floor_bytes came out
    ratio_floor_bytes: int = 1 << 20
    max_members: int = 10_000
    max_json_bytes: int = 32 << 20  # each JSON document of the bundle
    worker_memory_bytes: int = 4 << 30  # address space of the process that unpacks and re-computes (RLIMIT_AS)
    worker_seconds: float = 900.0  # wall-clock time of that process, per step


class _CountingReader(io.RawIOBase):
    """The decompressed stream, counted: E960/E963 as soon as the limits are passed (never after)."""

    def __init__(self, gz: gzip.GzipFile, compressed_size: int, limits: Limits) -> None:
        self.gz, self.compressed, self.limits, self.count = gz, max(compressed_size, 1), limits, 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:  # type: ignore[override]
        try:
            data = self.gz.read(min(len(buffer), CHUNK))
        except (OSError, EOFError, zlib.error) as exc:
            raise fail(
                Code.BUNDLE_ARCHIVE_INVALID,
                f"the archive is not valid gzip: {exc}",
                file="<upload>",
                expected="gzip-compressed tar",
            ) from None
        n = len(data)
        buffer[:n] = data
        self.count += n
        if self.count > self.limits.max_unpacked_bytes:
            raise fail(
                Code.BUNDLE_TOO_LARGE,
                "the archive decompresses to more than the registry accepts",
                file="<upload>",
                expected=f"≤ {self.limits.max_unpacked_bytes} bytes",
                found=f"> {self.limits.max_unpacked_bytes} bytes",
            )
        if self.count > self.limits.ratio_floor_bytes and self.count > self.limits.max_ratio * self.compressed:
            raise fail(
                Code.BUNDLE_DECOMPRESSION_BOMB,
                "the archive expands more than any real bundle does (a decompression bomb)",
                file="<upload>",
                expected=f"expansion ≤ {self.limits.max_ratio:g}×",
                found=f"> {self.count / self.compressed:.0f}×",
            )
        return n


@dataclass
class Unpacked:
    """A bundle unpacked into ``root``: the member sizes and sha256 as actually read.
    Sizes in bytes; spec §17.4."""

    root: Path
    members: dict[str, tuple[int, str]] = field(default_factory=dict)
    archive_sha256: str = ""
    archive_size: int = 0


def _member_name_problem(name: str) -> str | None:
    if "\x00" in name:
        return "contains a NUL byte"
    if name.startswith("/") or (len(name) > 1 and name[1] == ":"):
        return "is an absolute path"
    stripped = name[:-1] if name.endswith("/") else name
    if ".." in stripped.split("/"):
        return "climbs out with '..'"
    if not is_safe_relative_path(stripped):
        return "is not a plain relative POSIX path"
    if len(name.encode("utf-8")) > 1024 or any(len(p.encode("utf-8")) > 255 for p in stripped.split("/")):
        return "is longer than a file system allows"
    return None


def _unsafe(name: str, why: str, found: str | None = None) -> HaptifyError:
    return fail(
        Code.BUNDLE_UNSAFE_MEMBER,
        f"archive member {name!r} {why}",
        file=name,
        expected="a regular file at a relative path inside the bundle",
        found=found or why,
    )


def unpack(archive: str | os.PathLike, root: str | os.PathLike, limits: Limits = Limits()) -> Unpacked:
    """Unpack a bundle archive into the new folder ``root`` under ``limits`` (spec §17.4).

    Refuses (E960–E963) oversize archives, decompression bombs, links, devices, sparse members, absolute
    or climbing paths and duplicate names; the bytes of each file are counted and hashed as they are
    written, and writing stops at ``max_unpacked_bytes``.
    """
    archive = Path(archive)
    size = archive.stat().st_size
    if size > limits.max_archive_bytes:
        raise fail(
            Code.BUNDLE_TOO_LARGE,
            "the bundle archive is larger than the registry accepts",
            file="<upload>",
            expected=f"≤ {limits.max_archive_bytes} bytes",
            found=f"{size} bytes",
        )
    root = Path(root)
    root.mkdir(mode=DIR_MODE, parents=True, exist_ok=False)
    out = Unpacked(root=root, archive_sha256=sha256_file(archive), archive_size=size)
    seen_folded: set[str] = set()
    with open(archive, "rb") as raw:
        with gzip.GzipFile(fileobj=raw, mode="rb") as gz:
            counter = _CountingReader(gz, size, limits)
            try:
                tar = tarfile.open(fileobj=io.BufferedReader(counter, CHUNK), mode="r|")
            except tarfile.TarError as exc:
                raise fail(
                    Code.BUNDLE_ARCHIVE_INVALID,
                    f"the upload is not a tar archive: {exc}",
                    file="<upload>",
                    expected="gzip-compressed tar",
                ) from None
            try:
                count = written = 0
                for member in tar:
                    count += 1
                    if count > limits.max_members:
                        raise fail(
                            Code.BUNDLE_TOO_LARGE,
                            "the archive has too many members",
                            file="<upload>",
                            expected=f"≤ {limits.max_members}",
                            found=f"> {limits.max_members}",
                        )
                    source = _member_source(tar, member, seen_folded, limits)
                    if source is None:
                        continue
                    size, digest, written = _write_member(root, member.name, source, written, limits)
                    out.members[member.name] = (size, digest)
            except tarfile.TarError as exc:
                raise fail(
                    Code.BUNDLE_ARCHIVE_INVALID,
                    f"the tar archive is damaged: {exc}",
                    file="<upload>",
                    expected="a complete tar archive",
                ) from None
            except (EOFError, zlib.error) as exc:
                raise fail(
                    Code.BUNDLE_ARCHIVE_INVALID,
                    f"the archive ends early or is corrupt: {exc}",
                    file="<upload>",
                    expected="gzip-compressed tar",
                ) from None
    return out


def _member_source(tar: tarfile.TarFile, member: tarfile.TarInfo, seen_folded: set[str], limits: Limits) -> IO[bytes] | None:
    """The bytes of a safe regular-file member, None for a folder; E962/E960 for a member the registry refuses
    (spec §17.4): an unsafe name, a link, a special or sparse member, a duplicate name (ignoring case), a
    member over ``max_unpacked_bytes``. ``seen_folded`` collects the case-folded names."""
    name = member.name
    problem = _member_name_problem(name)
    if problem:
        raise _unsafe(name, problem)
    if member.isdir():
        return None
    if member.issym() or member.islnk():
        raise _unsafe(name, f"is a {'symbolic' if member.issym() else 'hard'} link to {member.linkname!r}", "link")
    source = tar.extractfile(member) if member.isreg() else None
    if source is None:
        raise _unsafe(name, "is not a regular file (device, FIFO or other special member)", "special file")
    if member.issparse():  # its holes would be written as zeros the compressed stream never held
        raise _unsafe(name, "is a sparse member (its declared size is not in the archive)", "sparse file")
    folded = name.casefold()
    if folded in seen_folded:
        raise _unsafe(name, "appears twice (names must be unique, also ignoring case)", "duplicate")
    seen_folded.add(folded)
    if member.size > limits.max_unpacked_bytes:
        raise fail(
            Code.BUNDLE_TOO_LARGE,
            f"archive member {name!r} is larger than the registry accepts",
            file=name,
            expected=f"≤ {limits.max_unpacked_bytes} bytes",
            found=f"{member.size} bytes",
        )
    return source


def _write_member(root: Path, name: str, source: IO[bytes], written: int, limits: Limits) -> tuple[int, str, int]:
    """Write one member's bytes to a new file under ``root``, counting and hashing them (spec §17.4): its size
    (bytes), its SHA-256 and the archive's bytes written so far; E960 once they pass ``max_unpacked_bytes``."""
    target = root.joinpath(*name.split("/"))
    _make_parents(root, name)
    digest = hashlib.sha256()
    fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), FILE_MODE)
    size = 0
    with os.fdopen(fd, "wb") as fh:
        for chunk in iter(lambda: source.read(CHUNK), b""):
            size += len(chunk)
            written += len(chunk)
            if written > limits.max_unpacked_bytes:
                raise fail(
                    Code.BUNDLE_TOO_LARGE,
                    "the archive unpacks to more bytes than the registry accepts",
                    file=name,
                    expected=f"≤ {limits.max_unpacked_bytes} bytes written",
                    found=f"> {limits.max_unpacked_bytes} bytes written",
                )
            digest.update(chunk)
            fh.write(chunk)
    return size, digest.hexdigest(), written


def _make_parents(root: Path, name: str) -> None:
    """Create the folders of ``name`` inside ``root``; a member that is a file where a folder is needed is E962."""
    current = root
    for part in name.split("/")[:-1]:
        current = current / part
        if current.is_symlink() or (current.exists() and not current.is_dir()):
            raise _unsafe(name, f"needs {part!r} to be a folder, but it is a file")
        current.mkdir(mode=DIR_MODE, exist_ok=True)


def unpack_bundle(archive: str | os.PathLike, root: str | os.PathLike, limits: Limits = Limits()) -> tuple[Unpacked, Bundle]:
    """Steps 2 and 3 of spec §17.3: :func:`unpack` under ``limits``, then :func:`read_manifest`."""
    unpacked = unpack(archive, root, limits)
    return unpacked, read_manifest(unpacked, limits)


def read_manifest(unpacked: Unpacked, limits: Limits = Limits()) -> Bundle:
    """Parse and check ``bundle.json`` against the unpacked files (E964, E965; spec §17.2)."""
    if BUNDLE_JSON not in unpacked.members:
        raise fail(
            Code.BUNDLE_MANIFEST_INVALID,
            "the archive has no bundle.json",
            file=BUNDLE_JSON,
            expected="bundle.json at the top",
            found="missing",
        )
    if unpacked.members[BUNDLE_JSON][0] > limits.max_json_bytes:
        raise fail(
            Code.BUNDLE_TOO_LARGE,
            "bundle.json is too large",
            file=BUNDLE_JSON,
            expected=f"≤ {limits.max_json_bytes} bytes",
            found=f"{unpacked.members[BUNDLE_JSON][0]} bytes",
        )
    data = parse_json_file(unpacked.root / BUNDLE_JSON, Code.BUNDLE_MANIFEST_INVALID, BUNDLE_JSON)
    try:
        bundle = Bundle.model_validate(data)
    except ValidationError as exc:
        raise HaptifyError(*pydantic_findings(exc, Code.BUNDLE_MANIFEST_INVALID, BUNDLE_JSON)) from None
    declared, findings = _declared_files(bundle)
    findings += _file_findings(declared, unpacked)
    if any(f.role == "stream" for f in bundle.files) != bundle.includes_raw:
        findings.append(
            Finding(
                Code.BUNDLE_MANIFEST_INVALID,
                "includes_raw does not match the files",
                file=BUNDLE_JSON,
                pointer="/includes_raw",
                expected=any(f.role == "stream" for f in bundle.files),
                found=bundle.includes_raw,
            )
        )
    if findings:
        raise HaptifyError(*findings)
    return bundle


def _declared_files(bundle: Bundle) -> tuple[dict[str, BundleFile], list[Finding]]:
    """The files ``bundle.json`` declares by path, and E964 for what its list gets wrong (spec §17.2): a path
    declared twice, not exactly one results file and one session manifest, a misnamed conformance report."""
    findings: list[Finding] = []
    declared: dict[str, BundleFile] = {}
    for i, f in enumerate(bundle.files):
        if f.path in declared or f.path == BUNDLE_JSON:
            findings.append(
                Finding(
                    Code.BUNDLE_MANIFEST_INVALID,
                    f"{f.path!r} is declared twice",
                    file=BUNDLE_JSON,
                    pointer=f"/files/{i}/path",
                    expected="each path once",
                    found=f.path,
                )
            )
        declared[f.path] = f
    for role in ("results", "session-manifest"):
        paths = [f.path for f in bundle.files if f.role == role]
        want = RESULTS_JSON if role == "results" else f"{SESSION_DIR}/{MANIFEST}"
        if paths != [want]:
            findings.append(
                Finding(
                    Code.BUNDLE_MANIFEST_INVALID,
                    f"the bundle must declare exactly one {role} file, {want!r}",
                    file=BUNDLE_JSON,
                    pointer="/files",
                    expected=[want],
                    found=paths,
                )
            )
    conformance = [f.path for f in bundle.files if f.role == "conformance"]
    if conformance not in ([], [CONFORMANCE_JSON]):
        findings.append(
            Finding(
                Code.BUNDLE_MANIFEST_INVALID,
                f"the conformance report must be {CONFORMANCE_JSON!r}",
                file=BUNDLE_JSON,
                pointer="/files",
                expected=[CONFORMANCE_JSON],
                found=conformance,
            )
        )
    return declared, findings


def _file_findings(declared: dict[str, BundleFile], unpacked: Unpacked) -> list[Finding]:
    """The declared files against the unpacked ones (spec §17.2): E964 for a session file outside the session
    folder, E965 for a file missing, differing from its size or digest, or in the archive undeclared."""
    findings: list[Finding] = []
    for path, entry in declared.items():
        if entry.role in ("session-file", "stream") and not path.startswith(f"{SESSION_DIR}/"):
            findings.append(
                Finding(
                    Code.BUNDLE_MANIFEST_INVALID,
                    f"session file {path!r} lies outside {SESSION_DIR}/",
                    file=BUNDLE_JSON,
                    expected=f"{SESSION_DIR}/…",
                    found=path,
                )
            )
        if path not in unpacked.members:
            findings.append(
                Finding(
                    Code.BUNDLE_FILE_MISMATCH,
                    f"{path!r} is declared in bundle.json but not in the archive",
                    file=path,
                    expected="present",
                    found="missing",
                )
            )
            continue
        size, sha = unpacked.members[path]
        if size != entry.size or sha != entry.sha256:
            findings.append(
                Finding(
                    Code.BUNDLE_FILE_MISMATCH,
                    f"{path!r} differs from its declaration in bundle.json",
                    file=path,
                    expected={"size": entry.size, "sha256": entry.sha256},
                    found={"size": size, "sha256": sha},
                )
            )
    for path in sorted(set(unpacked.members) - set(declared) - {BUNDLE_JSON}):
        findings.append(
            Finding(
                Code.BUNDLE_FILE_MISMATCH,
                f"{path!r} is in the archive but not declared in bundle.json",
                file=path,
                expected="declared in bundle.json",
                found="undeclared",
            )
        )
    return findings
