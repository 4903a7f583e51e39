"""The registry's behaviour, independent of HTTP (spec §17.4–§17.7): settings, tokens, the write path,
withdrawals, and the read queries the JSON API and the web pages share. The settings, token and record
types are in :mod:`haptify_tools.registry.records`, the read queries in
:mod:`haptify_tools.registry.queries` (a base of :class:`Registry`), the aggregates over labs and
repetitions in :mod:`haptify_tools.registry.aggregates`; this module keeps the write path.

Write path of a submission (nothing accepted is ever lost, nothing half-stored is ever kept):

1. the upload is streamed to ``DATA/tmp/upload-*.tar.gz`` (size-limited) and fsynced;
2. it is unpacked into ``DATA/tmp/unpack-*/`` under the limits and checked (spec §17.3);
3. the archive is renamed to its content address ``DATA/bundles/<d[:2]>/<digest>.tar.gz`` and the folder
   is fsynced;
4. one database transaction inserts the submission and its metric rows; only its commit acknowledges.

A crash before 3 leaves files in ``tmp/`` only; a crash between 3 and 4 leaves an archive no row refers
to. Start-up (:meth:`Registry.sweep`) deletes both, before the service answers. The archive is renamed
before the commit, never after, so a committed row always has its archive. One process owns a data
folder (an exclusive lock on ``DATA/registry.lock``); two would sweep each other's uploads.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import logging
import os
import secrets
import shutil
import threading
import uuid
from pathlib import Path
from typing import AsyncIterator

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError, OperationalError
from sqlalchemy.orm import Session as DBSession
from starlette.concurrency import run_in_threadpool

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail
from haptify.formats.bundle_format import bundle_digest, submission_id
from haptify_conform.report import ConformReport
from haptify_tools.registry import db
from haptify_tools.registry.aggregates import aggregate
from haptify_tools.registry.bundle import DIR_MODE, FILE_MODE, unpack_bundle
from haptify_tools.registry.checks import Checked, check_bundle, check_conformance, verify_bundle
from haptify_tools.registry.queries import RegistryQueries
from haptify_tools.registry.records import (
    SCOPES,
    TOKEN_PREFIX,
    Caller,
    Outcome,
    RateLimiter,
    Settings,
    hash_token,
    slugify,
)
from haptify_tools.registry.worker import run_contained

log = logging.getLogger("haptify.registry")


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class Registry(RegistryQueries):
    """One registry: its database, its data folder and its in-process state (rate buckets, digest locks).
    Spec §17.3, §17.5, §17.7."""

    def __init__(self, settings: Settings, *, lock: bool = True) -> None:
        self.settings = settings
        self.data = Path(settings.data_dir)
        self.data.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
        os.chmod(self.data, DIR_MODE)  # records and archives are the service user's only (spec §17.7)
        self.tmp = self.data / "tmp"
        self.bundles = self.data / "bundles"
        self._lock_fh = None
        if lock:
            self._lock_fh = os.fdopen(os.open(self.data / "registry.lock", os.O_RDWR | os.O_CREAT, FILE_MODE), "a+")
            try:
                fcntl.flock(self._lock_fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                self._lock_fh.close()
                raise fail(
                    Code.REGISTRY_UNAVAILABLE,
                    f"another registry process serves the data folder {str(self.data)!r}",
                    file=str(self.data),
                    expected="one process per data folder",
                    found="locked",
                ) from None
        if settings.db_url is None:  # SQLite creates its -wal and -shm files with the database file's mode
            os.close(os.open(self.data / db.SQLITE_FILE, os.O_RDWR | os.O_CREAT, FILE_MODE))
            os.chmod(self.data / db.SQLITE_FILE, FILE_MODE)
        self.engine = db.make_engine(settings.url)
        self.writer = db.writer(self.engine)
        db.migrate(self.engine)
        self.limiter = RateLimiter()
        self._digest_locks: dict[str, threading.Lock] = {}
        self._locks_guard = threading.Lock()

    def close(self) -> None:
        self.engine.dispose()
        if self._lock_fh is not None:
            self._lock_fh.close()
            self._lock_fh = None

    # --- start-up ------------------------------------------------------------------------------
    def sweep(self) -> dict[str, int]:
        """Delete what an interrupted submission left (spec §17.7): all of ``tmp/`` and every archive no
        row refers to. Returns the counts, and the number of rows whose archive is missing (should be 0)."""
        removed_tmp = 0
        if self.tmp.exists():
            for entry in self.tmp.iterdir():
                shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
                removed_tmp += 1
        self.tmp.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
        self.bundles.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
        with DBSession(self.engine) as s:
            referenced = set(s.scalars(select(db.Submission.archive_path)))
        removed_orphans = 0
        for path in self.bundles.rglob("*"):
            if path.is_file() or path.is_symlink():
                rel = path.relative_to(self.data).as_posix()
                if rel not in referenced:
                    path.unlink()
                    removed_orphans += 1
        missing = sum(1 for rel in referenced if not (self.data / rel).is_file())
        if missing:
            log.error("%d accepted submissions have no archive in %s", missing, self.bundles)
        return {"tmp": removed_tmp, "orphans": removed_orphans, "missing": missing}

    # --- tokens --------------------------------------------------------------------------------
    def create_token(
        self, lab: str, scope: str = "submit", rate_per_minute: int | None = None, lab_name: str | None = None
    ) -> str:
        """Create a token for ``lab`` (created if new); returns the token, which is stored only hashed."""
        if scope not in SCOPES:
            raise fail(Code.REQUEST_INVALID, f"unknown scope {scope!r}", expected=list(SCOPES), found=scope)
        from haptify.formats.bundle_format import BundleLab

        try:
            BundleLab(id=lab)
        except Exception:
            raise fail(
                Code.REQUEST_INVALID,
                f"lab id {lab!r} is not an identifier",
                expected="letters, digits, '.', '_', '-' (≤ 64)",
                found=lab,
            ) from None
        token = TOKEN_PREFIX + secrets.token_urlsafe(32)
        with DBSession(self.writer) as s, s.begin():
            if s.get(db.Lab, lab) is None:
                s.add(db.Lab(id=lab, name=lab_name))
            s.add(
                db.Token(
                    lab_id=lab,
                    scope=scope,
                    token_sha256=hash_token(token),
                    rate_per_minute=rate_per_minute or self.settings.default_rate_per_minute,
                )
            )
        return token

    def authenticate(self, authorization: str | None, need: str = "submit", *, rate_limit: bool = True) -> Caller:
        """The caller of ``Authorization: Bearer <token>``: E970 unknown, E971 scope, E972 rate (spec §17.6)."""
        if not authorization or not authorization.startswith("Bearer "):
            raise fail(Code.TOKEN_INVALID, "no API token", file="Authorization", expected="Bearer <token>", found="missing")
        token = authorization[len("Bearer ") :].strip()
        with DBSession(self.engine) as s:
            row = s.scalar(select(db.Token).where(db.Token.token_sha256 == hash_token(token)))
            if row is None:
                raise fail(
                    Code.TOKEN_INVALID,
                    "the API token is not known to this registry",
                    file="Authorization",
                    expected="a token from `haptify registry token create`",
                    found=token[: len(TOKEN_PREFIX) + 4] + "…",
                )
            caller = Caller(row.id, row.lab_id, row.scope)
            rate = row.rate_per_minute
        if need == "admin" and caller.scope != "admin":
            raise fail(
                Code.TOKEN_SCOPE, "this request needs an admin token", file="Authorization", expected="admin", found=caller.scope
            )
        if rate_limit:
            wait = self.limiter.take(caller.token_id, rate)
            if wait > 0:
                err = fail(
                    Code.RATE_LIMITED,
                    f"more than {rate} requests per minute with this token",
                    file="Authorization",
                    expected=f"≤ {rate}/min",
                    found=f"retry after {wait:.1f} s",
                )
                err.retry_after = wait  # type: ignore[attr-defined]
                raise err
        return caller

    # --- submissions -------------------------------------------------------------------------
    async def receive(self, chunks: AsyncIterator[bytes]) -> Path:
        """Stream an upload to ``tmp/`` (E960 as soon as it passes the archive limit) and fsync it.

        Memory stays bounded by one chunk; the file is removed when anything goes wrong."""
        self.tmp.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
        path = self.tmp / f"upload-{uuid.uuid4().hex}.tar.gz"
        limit, total = self.settings.limits.max_archive_bytes, 0
        try:
            with os.fdopen(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, FILE_MODE), "wb") as fh:
                async for chunk in chunks:
                    total += len(chunk)
                    if total > limit:
                        raise fail(
                            Code.BUNDLE_TOO_LARGE,
                            "the bundle archive is larger than the registry accepts",
                            file="<upload>",
                            expected=f"≤ {limit} bytes",
                            found=f"> {limit} bytes",
                        )
                    fh.write(chunk)
                if total == 0:
                    raise fail(
                        Code.BUNDLE_ARCHIVE_INVALID,
                        "the request has no body",
                        file="<upload>",
                        expected="a .tar.gz bundle",
                        found="0 bytes",
                    )
                fh.flush()
                await run_in_threadpool(os.fsync, fh.fileno())
        except BaseException:
            path.unlink(missing_ok=True)
            raise
        return path

    def _digest_lock(self, digest: str) -> threading.Lock:
        with self._locks_guard:
            return self._digest_locks.setdefault(digest, threading.Lock())

    def submit(self, upload: Path, caller: Caller, *, dry_run: bool = False) -> Outcome:
        """Check and store one uploaded bundle (spec §17.3–§17.5); the upload file is consumed.

        Unpacking, the document checks and the re-computation each run in a worker process under the
        worker limits (:func:`~haptify_tools.registry.worker.run_contained`, spec §17.4.1); this process
        only reads and writes the records."""
        work = self.tmp / f"unpack-{uuid.uuid4().hex}"
        limits = self.settings.limits
        try:
            unpacked, bundle = run_contained(unpack_bundle, upload, work, limits, limits=limits)
            if bundle.lab.id != caller.lab_id:
                raise fail(
                    Code.LAB_MISMATCH,
                    "the bundle is from another lab than the token",
                    file="bundle.json",
                    pointer="/lab/id",
                    expected=caller.lab_id,
                    found=bundle.lab.id,
                )
            digest = bundle_digest(bundle)
            existing = self._existing(digest)
            if existing is not None:
                return existing
            checked = run_contained(check_bundle, unpacked, limits, limits=limits)
            report = checked.conformance or self._report_on_file(checked)
            if report is None:
                impl = checked.results.implementation
                raise fail(
                    Code.CONFORMANCE_NOT_PASSING,
                    f"no passing conformance report of {impl.name} {impl.version} for spec "
                    f"{checked.bundle.spec_version} is included or on file",
                    file="conformance.json",
                    expected="a haptify-conform --json-report of the implementation",
                    found="missing",
                )
            if checked.conformance is None:
                check_conformance(report, checked.results, checked.bundle.spec_version, file="(report on file)")
            self._check_supersede(checked, caller)
            if checked.bundle.includes_raw and self.settings.verify_raw:  # re-computation reads the streams
                checked.verification = run_contained(verify_bundle, checked, unpacked, True, limits=limits)
            else:  # nothing of the bundle is read: no worker needed
                checked.verification = verify_bundle(checked, unpacked, self.settings.verify_raw)
            sid = submission_id(digest)
            if dry_run:
                return Outcome(sid, digest, "would-accept", checked.verification.to_dict(), bundle.supersedes)
            with self._digest_lock(digest):
                existing = self._existing(digest)
                if existing is not None:
                    return existing
                return self._store(upload, unpacked.archive_sha256, unpacked.archive_size, checked, caller)
        finally:
            shutil.rmtree(work, ignore_errors=True)
            upload.unlink(missing_ok=True)

    def _existing(self, digest: str) -> Outcome | None:
        with DBSession(self.engine) as s:
            row = s.scalar(select(db.Submission).where(db.Submission.digest == digest))
            if row is None:
                return None
            return Outcome(row.id, row.digest, "duplicate", json.loads(row.verification_json), row.supersedes_id)

    def _report_on_file(self, checked: Checked) -> ConformReport | None:
        impl = checked.results.implementation
        with DBSession(self.engine) as s:
            row = s.scalar(
                select(db.ConformanceReport)
                .where(
                    db.ConformanceReport.implementation_name == impl.name,
                    db.ConformanceReport.implementation_version == impl.version,
                    db.ConformanceReport.spec_version == checked.bundle.spec_version,
                )
                .order_by(db.ConformanceReport.received_at)
            )
            return ConformReport.model_validate_json(row.report_json) if row else None

    def _check_supersede(self, checked: Checked, caller: Caller) -> None:
        old_id = checked.bundle.supersedes
        if old_id is None:
            return
        with DBSession(self.engine) as s:
            old = s.get(db.Submission, old_id)
            if old is None:
                raise fail(
                    Code.NOT_FOUND,
                    f"the submission {old_id!r} to supersede does not exist",
                    file="bundle.json",
                    pointer="/supersedes",
                    expected="an existing submission id",
                    found=old_id,
                )
            state = self._state(s, old)
            if old.lab_id != caller.lab_id:
                raise fail(
                    Code.SUPERSEDE_CONFLICT,
                    "a lab can supersede only its own submissions",
                    file="bundle.json",
                    pointer="/supersedes",
                    expected=caller.lab_id,
                    found=old.lab_id,
                )
            if state != "current":
                raise fail(
                    Code.SUPERSEDE_CONFLICT,
                    f"submission {old_id} is {state}",
                    file="bundle.json",
                    pointer="/supersedes",
                    expected="current",
                    found=state,
                )

    def _device(self, s: DBSession, manufacturer: str, model: str) -> db.Device:
        row = s.scalar(select(db.Device).where(db.Device.manufacturer == manufacturer, db.Device.model == model))
        if row is not None:
            return row
        base = slug = slugify(manufacturer, model)
        n = 1
        while s.scalar(select(db.Device.id).where(db.Device.slug == slug)) is not None:
            n += 1
            slug = f"{base}-{n}"
        try:
            with s.begin_nested():
                row = db.Device(slug=slug, manufacturer=manufacturer, model=model)
                s.add(row)
        except IntegrityError:  # created meanwhile by another transaction (PostgreSQL)
            row = s.scalar(select(db.Device).where(db.Device.manufacturer == manufacturer, db.Device.model == model))
            if row is None:  # the conflict was not this device's: the database's error stands
                raise
        return row

    def _store(self, upload: Path, archive_sha: str, archive_size: int, checked: Checked, caller: Caller) -> Outcome:
        digest = checked.digest
        sid = submission_id(digest)
        rel = f"bundles/{digest[:2]}/{digest}.tar.gz"
        final = self.data / rel
        final.parent.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
        os.replace(upload, final)
        _fsync_dir(final.parent)
        results = checked.results
        try:
            with DBSession(self.writer) as s, s.begin():
                device = self._device(s, checked.bundle.device.manufacturer, checked.bundle.device.model)
                s.add(
                    db.Submission(
                        id=sid,
                        digest=digest,
                        archive_sha256=archive_sha,
                        archive_size=archive_size,
                        archive_path=rel,
                        lab_id=caller.lab_id,
                        device_id=device.id,
                        serial=checked.bundle.device.serial,
                        spec_version=checked.bundle.spec_version,
                        implementation_name=results.implementation.name,
                        implementation_version=results.implementation.version,
                        session_id=results.session_id,
                        manifest_sha256=results.manifest_sha256,
                        supersedes_id=checked.bundle.supersedes,
                        verification=checked.verification.status,
                        verification_json=json.dumps(checked.verification.to_dict(), default=str),
                        bundle_json=checked.bundle.model_dump_json(),
                        results_json=results.model_dump_json(),
                        has_raw=checked.bundle.includes_raw,
                        token_id=caller.token_id,
                    )
                )
                s.flush()
                for m in results.metrics:
                    s.add(
                        db.MetricValue(
                            submission_id=sid,
                            metric_id=m.id,
                            value=m.value if not isinstance(m.value, list) else None,
                            value_json=json.dumps(m.value),
                            per_repetition_json=json.dumps(m.per_repetition),
                            unit=m.unit,
                            n=m.n,
                            sd_json=json.dumps(m.sd),
                            definition_version=m.definition_version,
                        )
                    )
                if checked.conformance is not None:
                    report_sha = hashlib.sha256(checked.conformance.model_dump_json().encode()).hexdigest()
                    if s.get(db.ConformanceReport, report_sha) is None:
                        s.add(
                            db.ConformanceReport(
                                sha256=report_sha,
                                implementation_name=results.implementation.name,
                                implementation_version=results.implementation.version,
                                spec_version=checked.bundle.spec_version,
                                report_json=checked.conformance.model_dump_json(),
                                submission_id=sid,
                            )
                        )
        except IntegrityError as exc:
            existing = self._existing(digest)
            if existing is not None:
                return existing
            self._drop_unreferenced(rel)
            if checked.bundle.supersedes:
                raise fail(
                    Code.SUPERSEDE_CONFLICT,
                    f"submission {checked.bundle.supersedes} was superseded meanwhile",
                    file="bundle.json",
                    pointer="/supersedes",
                    expected="current",
                    found="superseded",
                ) from None
            raise fail(Code.REGISTRY_UNAVAILABLE, f"the record could not be stored: {exc.orig}") from None
        except OperationalError as exc:
            self._drop_unreferenced(rel)
            raise fail(Code.REGISTRY_UNAVAILABLE, f"the database is unavailable: {exc.orig}") from None
        except BaseException:
            self._drop_unreferenced(rel)
            raise
        return Outcome(sid, digest, "accepted", checked.verification.to_dict(), checked.bundle.supersedes)

    def _drop_unreferenced(self, rel: str) -> None:
        with DBSession(self.engine) as s:
            if s.scalar(select(db.Submission.id).where(db.Submission.archive_path == rel)) is None:
                (self.data / rel).unlink(missing_ok=True)

    def withdraw(self, sid: str, reason: str, caller: Caller) -> dict:
        """Mark a submission withdrawn with ``reason``; the record stays (spec §17.5)."""
        if not reason.strip():
            raise fail(
                Code.REQUEST_INVALID,
                "a withdrawal needs a reason",
                file="body",
                pointer="/reason",
                expected="a non-empty reason",
                found=reason,
            )
        try:
            with DBSession(self.writer) as s, s.begin():
                row = s.get(db.Submission, sid)
                if row is None:
                    raise fail(Code.NOT_FOUND, f"no submission {sid!r}", expected="an existing submission id", found=sid)
                if caller.scope != "admin" and row.lab_id != caller.lab_id:
                    raise fail(
                        Code.TOKEN_SCOPE,
                        "a submit token can withdraw only its own lab's submissions",
                        file="Authorization",
                        expected=row.lab_id,
                        found=caller.lab_id,
                    )
                state = self._state(s, row)
                if state == "withdrawn":
                    raise fail(
                        Code.SUPERSEDE_CONFLICT,
                        f"submission {sid} is already withdrawn",
                        expected="current or superseded",
                        found=state,
                    )
                s.add(db.Withdrawal(submission_id=sid, reason=reason.strip(), token_id=caller.token_id))
        except IntegrityError:
            raise fail(
                Code.SUPERSEDE_CONFLICT, f"submission {sid} is already withdrawn", expected="not withdrawn", found="withdrawn"
            ) from None
        return self.submission(sid)

    # --- reading -------------------------------------------------------------------------------


def findings_of(err: HaptifyError) -> list[dict]:
    """The findings of a refusal as JSON objects: code, message, location, expected, found (spec §17.5.1)."""
    return [f.to_dict() for f in err.findings]


__all__ = ["Settings", "Registry", "Caller", "Outcome", "hash_token", "slugify", "aggregate", "Finding"]
