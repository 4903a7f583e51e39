"""The registry's behaviour, independent of HTTP (spec §17.4–§17.7): settings, tokens, the write path,
withdrawals, and the read queries the JSON API and the web pages share.

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
import re
import secrets
import shutil
import statistics
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, AsyncIterator

from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError, OperationalError
from sqlalchemy.orm import Session as DBSession
from sqlalchemy.orm import selectinload
from starlette.concurrency import run_in_threadpool

from haptify.errors import Finding, HaptifyError, fail
from haptify.results import DeviceSummary, Implementation, MetricResult, ResultsFile
from haptify.versions import PACKAGE_VERSION
from haptify_conform.report import ConformReport
from haptify_tools.registry import db, interlab
from haptify_tools.registry.bundle import (
    DIR_MODE,
    FILE_MODE,
    SESSION_DIR,
    Limits,
    bundle_digest,
    submission_id,
    unpack,
    unpack_bundle,
)
from haptify_tools.registry.checks import Checked, check_bundle, check_conformance, verify_bundle
from haptify_tools.registry.worker import run_contained

log = logging.getLogger("haptify.registry")

SCOPES = ("submit", "admin")
TOKEN_PREFIX = "hpt_"
DEFAULT_RATE_PER_MINUTE = 120
STATES = ("current", "superseded", "withdrawn")
VERIFICATIONS = ("verified", "disagreeing", "unverified")  # spec §17.3.1
RANKED = ("verified", "all")  # which results aggregates and rankings count: verified only (default) or all


@dataclass
class Settings:
    """Where the registry keeps its records and what it accepts (spec §17.7)."""

    data_dir: Path = Path("haptify-registry")
    db_url: str | None = None  # None: SQLite in data_dir (zero set-up); or a postgresql:// URL
    limits: Limits = field(default_factory=Limits)
    verify_raw: bool = True  # re-compute metrics when raw streams are included
    default_rate_per_minute: int = DEFAULT_RATE_PER_MINUTE
    challenge_ttl_s: float = 3600.0  # a challenge must be answered within this time (spec §17.8)
    upload_ttl_s: float = 24 * 3600.0  # a resumable upload without a chunk for this long expires (spec §17.5.2)

    @property
    def url(self) -> str:
        return self.db_url or db.default_db_url(self.data_dir)


def hash_token(token: str) -> str:
    """The stored form of a token: its sha256 (hex). Tokens carry 256 random bits, so no slow hash is needed.
    Spec §17.6."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def slugify(manufacturer: str, model: str) -> str:
    """A device's URL id, e.g. ``3d-systems-touch-x``."""
    return re.sub(r"[^a-z0-9]+", "-", f"{manufacturer} {model}".lower()).strip("-") or "device"


class RateLimiter:
    """A token bucket per API token: ``rate`` requests per minute, bursts up to ``rate`` (spec §17.6)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._buckets: dict[int, tuple[float, float]] = {}

    def take(self, token_id: int, rate_per_minute: int) -> float:
        """0 when allowed; otherwise the seconds to wait."""
        now = time.monotonic()
        with self._lock:
            level, last = self._buckets.get(token_id, (float(rate_per_minute), now))
            level = min(float(rate_per_minute), level + (now - last) * rate_per_minute / 60.0)
            if level < 1.0:
                self._buckets[token_id] = (level, now)
                return (1.0 - level) * 60.0 / rate_per_minute
            self._buckets[token_id] = (level - 1.0, now)
            return 0.0


@dataclass
class Caller:
    """The authenticated caller of a request (token scope and lab, spec §17.6)."""

    token_id: int
    lab_id: str
    scope: str


@dataclass
class Outcome:
    """What the registry says to a submission.
    ``accepted``, ``duplicate`` or a dry run's ``would-accept``; spec §17.5."""

    id: str
    digest: str
    status: str  # accepted | duplicate | would-accept
    verification: dict
    supersedes: str | None = None

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "digest": self.digest,
            "status": self.status,
            "supersedes": self.supersedes,
            "verification": self.verification,
            "url": f"/api/v1/submissions/{self.id}",
        }


@dataclass
class ReadContext:
    """What a submission's summary needs beyond its row: withdrawals, supersessions and, per implementation
    name and version, its latest passed conformance challenge and the metric families that challenge
    covered (spec §17.5, §17.8)."""

    withdrawn: dict[str, db.Withdrawal]
    superseded_by: dict[str, str]
    proven: dict[tuple[str, str], tuple[str, list[str]]]


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class Registry:
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
                    "E978",
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
            raise fail("E975", f"unknown scope {scope!r}", expected=list(SCOPES), found=scope)
        from haptify_tools.registry.bundle import BundleLab

        try:
            BundleLab(id=lab)
        except Exception:
            raise fail(
                "E975", f"lab id {lab!r} is not an identifier", expected="letters, digits, '.', '_', '-' (≤ 64)", found=lab
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
            raise fail("E970", "no API token", file="Authorization", expected="Bearer <token>", found="missing")
        token = authorization[len("Bearer ") :].strip()
        with DBSession(self.engine) as s:
            row = s.scalar(select(db.Token).where(db.Token.token_sha256 == hash_token(token)))
            if row is None:
                raise fail(
                    "E970",
                    "the API token is not known to this registry",
                    file="Authorization",
                    expected="a token from `haptify registry token create`",
                    found=token[: len(TOKEN_PREFIX) + 4] + "…",
                )
            caller = Caller(row.id, row.lab_id, row.scope)
            rate = row.rate_per_minute
        if need == "admin" and caller.scope != "admin":
            raise fail("E971", "this request needs an admin token", file="Authorization", expected="admin", found=caller.scope)
        if rate_limit:
            wait = self.limiter.take(caller.token_id, rate)
            if wait > 0:
                err = fail(
                    "E972",
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
                            "E960",
                            "the bundle archive is larger than the registry accepts",
                            file="<upload>",
                            expected=f"≤ {limit} bytes",
                            found=f"> {limit} bytes",
                        )
                    fh.write(chunk)
                if total == 0:
                    raise fail("E961", "the request has no body", file="<upload>", expected="a .tar.gz bundle", found="0 bytes")
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
                    "E977",
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
                    "E967",
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
                    "E973",
                    f"the submission {old_id!r} to supersede does not exist",
                    file="bundle.json",
                    pointer="/supersedes",
                    expected="an existing submission id",
                    found=old_id,
                )
            state = self._state(s, old)
            if old.lab_id != caller.lab_id:
                raise fail(
                    "E974",
                    "a lab can supersede only its own submissions",
                    file="bundle.json",
                    pointer="/supersedes",
                    expected=caller.lab_id,
                    found=old.lab_id,
                )
            if state != "current":
                raise fail(
                    "E974",
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
                    "E974",
                    f"submission {checked.bundle.supersedes} was superseded meanwhile",
                    file="bundle.json",
                    pointer="/supersedes",
                    expected="current",
                    found="superseded",
                ) from None
            raise fail("E978", f"the record could not be stored: {exc.orig}") from None
        except OperationalError as exc:
            self._drop_unreferenced(rel)
            raise fail("E978", f"the database is unavailable: {exc.orig}") from None
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
                "E975", "a withdrawal needs a reason", file="body", pointer="/reason", expected="a non-empty reason", found=reason
            )
        try:
            with DBSession(self.writer) as s, s.begin():
                row = s.get(db.Submission, sid)
                if row is None:
                    raise fail("E973", f"no submission {sid!r}", expected="an existing submission id", found=sid)
                if caller.scope != "admin" and row.lab_id != caller.lab_id:
                    raise fail(
                        "E971",
                        "a submit token can withdraw only its own lab's submissions",
                        file="Authorization",
                        expected=row.lab_id,
                        found=caller.lab_id,
                    )
                state = self._state(s, row)
                if state == "withdrawn":
                    raise fail("E974", f"submission {sid} is already withdrawn", expected="current or superseded", found=state)
                s.add(db.Withdrawal(submission_id=sid, reason=reason.strip(), token_id=caller.token_id))
        except IntegrityError:
            raise fail("E974", f"submission {sid} is already withdrawn", expected="not withdrawn", found="withdrawn") from None
        return self.submission(sid)

    # --- reading -------------------------------------------------------------------------------
    @staticmethod
    def _state(s: DBSession, row: db.Submission) -> str:
        if s.get(db.Withdrawal, row.id) is not None:
            return "withdrawn"
        if s.scalar(select(db.Submission.id).where(db.Submission.supersedes_id == row.id)) is not None:
            return "superseded"
        return "current"

    def _summary(self, row: db.Submission, ctx: ReadContext) -> dict:
        w = ctx.withdrawn.get(row.id)
        state = "withdrawn" if w else "superseded" if row.id in ctx.superseded_by else "current"
        challenge, families = ctx.proven.get((row.implementation_name, row.implementation_version), (None, []))
        return {
            "id": row.id,
            "digest": row.digest,
            "state": state,
            "lab": row.lab_id,
            "device": {"slug": row.device.slug, "manufacturer": row.device.manufacturer, "model": row.device.model},
            "serial": row.serial,
            "spec_version": row.spec_version,
            "implementation": {"name": row.implementation_name, "version": row.implementation_version},
            "conformance": {"status": "proven" if challenge else "self-asserted", "challenge": challenge, "families": families},
            "session_id": row.session_id,
            "verification": row.verification,
            "has_raw": row.has_raw,
            "received_at": row.received_at.isoformat(),
            "supersedes": row.supersedes_id,
            "superseded_by": ctx.superseded_by.get(row.id),
            "withdrawal": {"reason": w.reason, "at": w.at.isoformat()} if w else None,
        }

    def _context(self, s: DBSession) -> ReadContext:
        withdrawn = {w.submission_id: w for w in s.scalars(select(db.Withdrawal))}
        superseded_by = {
            old: new
            for new, old in s.execute(
                select(db.Submission.id, db.Submission.supersedes_id).where(db.Submission.supersedes_id.is_not(None))
            )
            if old is not None  # (the query's own condition, for the type checker)
        }
        from haptify_tools.registry.challenge import cases_from_json, families_of

        proven: dict[tuple[str, str], tuple[str, list[str]]] = {}
        for name, version, cid, cases in s.execute(
            select(
                db.ChallengeResult.implementation_name,
                db.ChallengeResult.implementation_version,
                db.ChallengeResult.challenge_id,
                db.Challenge.cases_json,
            )
            .join(db.Challenge, db.Challenge.id == db.ChallengeResult.challenge_id)
            .where(db.ChallengeResult.passed.is_(True))
            .order_by(db.ChallengeResult.answered_at)
        ):
            proven[(name, version)] = (cid, families_of(cases_from_json(cases)))  # the latest passed challenge
        return ReadContext(withdrawn, superseded_by, proven)

    def submissions(
        self,
        *,
        lab: str | None = None,
        device: str | None = None,
        state: str | None = None,
        verification: str | None = None,
        limit: int = 100,
        offset: int = 0,
    ) -> list[dict]:
        """Submission summaries, newest first, filtered by lab, device slug, state and verification state."""
        with DBSession(self.engine) as s:
            q = (
                select(db.Submission)
                .options(selectinload(db.Submission.device))
                .order_by(db.Submission.received_at.desc(), db.Submission.id)
            )
            if lab:
                q = q.where(db.Submission.lab_id == lab)
            if device:
                q = q.join(db.Device).where(db.Device.slug == device)
            if verification not in (None, "all"):
                q = q.where(db.Submission.verification == verification)
            ctx = self._context(s)
            rows = [self._summary(r, ctx) for r in s.scalars(q)]
        rows = [r for r in rows if state in (None, "all") or r["state"] == state]
        return rows[offset : offset + limit]

    def submission(self, sid: str) -> dict:
        """One submission with its results, verification and bundle manifest (E973 when unknown)."""
        with DBSession(self.engine) as s:
            row = s.get(db.Submission, sid)
            if row is None:
                raise fail("E973", f"no submission {sid!r}", expected="an existing submission id", found=sid)
            ctx = self._context(s)
            out = self._summary(row, ctx)
            out.update(
                archive_sha256=row.archive_sha256,
                archive_size=row.archive_size,
                verification_details=json.loads(row.verification_json),
                results=json.loads(row.results_json),
                bundle=json.loads(row.bundle_json),
            )
            return out

    def archive(self, sid: str) -> Path:
        """The stored archive of a submission."""
        with DBSession(self.engine) as s:
            row = s.get(db.Submission, sid)
            if row is None:
                raise fail("E973", f"no submission {sid!r}", expected="an existing submission id", found=sid)
            return self.data / row.archive_path

    def session_folder(self, sid: str) -> Path:
        """The submission's ``session/`` folder (manifest, and streams when included), unpacked once under the
        limits into ``DATA/cache/<digest>/`` — for report figures and the viewer. Derived data: safe to delete."""
        archive = self.archive(sid)
        target = self.data / "cache" / archive.name[: -len(".tar.gz")]
        if not target.is_dir():
            work = self.tmp / f"cache-{uuid.uuid4().hex}"
            run_contained(unpack, archive, work, self.settings.limits, limits=self.settings.limits)
            target.parent.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
            try:
                os.replace(work, target)
            except OSError:  # another request unpacked it first
                shutil.rmtree(work, ignore_errors=True)
        return target / SESSION_DIR

    def labs(self) -> list[dict]:
        with DBSession(self.engine) as s:
            counts = dict(s.execute(select(db.Submission.lab_id, func.count()).group_by(db.Submission.lab_id)).all())
            return [
                {"id": lab.id, "name": lab.name, "submissions": counts.get(lab.id, 0)}
                for lab in s.scalars(select(db.Lab).order_by(db.Lab.id))
            ]

    def lab(self, lab_id: str) -> dict:
        for lab in self.labs():
            if lab["id"] == lab_id:
                return {**lab, "recent": self.submissions(lab=lab_id, state="all", limit=50)}
        raise fail("E973", f"no lab {lab_id!r}", expected="an existing lab id", found=lab_id)

    def devices(self) -> list[dict]:
        with DBSession(self.engine) as s:
            counts = dict(s.execute(select(db.Submission.device_id, func.count()).group_by(db.Submission.device_id)).all())
            return [
                {"slug": d.slug, "manufacturer": d.manufacturer, "model": d.model, "submissions": counts.get(d.id, 0)}
                for d in s.scalars(select(db.Device).order_by(db.Device.manufacturer, db.Device.model))
            ]

    def _device_row(self, s: DBSession, slug: str) -> db.Device:
        d = s.scalar(select(db.Device).where(db.Device.slug == slug))
        if d is None:
            raise fail("E973", f"no device {slug!r}", expected="a device slug from /api/v1/devices", found=slug)
        return d

    def current_metric_rows(
        self, slug: str, *, verification: str = "verified"
    ) -> tuple[dict, list[tuple[dict, db.MetricValue]], list[tuple[dict, db.Submission]]]:
        """The device, ``(submission summary, metric row)`` of its current submissions that count under
        ``verification`` (``verified``: only verified ones; ``all``: every one), and ``(summary, row)`` of
        its current submissions that do not count (spec §17.3.1). A counted summary carries ``uncertainties``: its
        results file's uncertainty record by metric id (None when absent, spec §19.4)."""
        if verification not in RANKED:
            raise fail(
                "E975",
                f"unknown verification filter {verification!r}",
                pointer="/verification",
                expected=list(RANKED),
                found=verification,
            )
        with DBSession(self.engine) as s:
            d = self._device_row(s, slug)
            device = {"slug": d.slug, "manufacturer": d.manufacturer, "model": d.model}
            ctx = self._context(s)
            subs = s.scalars(
                select(db.Submission)
                .options(selectinload(db.Submission.metrics), selectinload(db.Submission.device))
                .where(db.Submission.device_id == d.id)
                .order_by(db.Submission.received_at)
            ).all()
            counted, apart = [], []
            for sub in subs:
                summary = self._summary(sub, ctx)
                if summary["state"] != "current":
                    continue
                if verification == "verified" and sub.verification != "verified":
                    apart.append((summary, sub))
                    continue
                records = {m["id"]: m.get("uncertainty") for m in json.loads(sub.results_json)["metrics"]}
                summary = {**summary, "uncertainties": records}
                counted += [(summary, m) for m in sub.metrics]
            return device, counted, apart

    def device_results(self, slug: str, *, verification: str = "verified") -> dict:
        """Per metric of a device: mean and spread over labs and repetitions of its current submissions that
        count under ``verification`` (spec §17.5); the current submissions that do not count are listed
        apart in ``not_counted``, one entry per metric, with their state (and for a disagreeing one both
        the submitted and the recomputed value, spec §17.3.1)."""
        device, rows, apart = self.current_metric_rows(slug, verification=verification)
        by_metric: dict[str, list[tuple[dict, db.MetricValue]]] = {}
        for summary, m in rows:
            by_metric.setdefault(m.metric_id, []).append((summary, m))
        metrics = [aggregate(metric, items) for metric, items in sorted(by_metric.items())]
        n_subs = len({summary["id"] for summary, _ in rows})
        return {
            "device": device,
            "submissions": n_subs,
            "verification": verification,
            "metrics": metrics,
            "not_counted": [entry for summary, sub in apart for entry in not_counted(summary, sub)],
        }

    def comparison(self, slugs: list[str], *, verification: str = "verified") -> list[ResultsFile]:
        """One synthetic results file per device, holding its aggregated means (for ``haptify.compare``)."""
        out = []
        for slug in slugs:
            agg = self.device_results(slug, verification=verification)
            metrics = []
            for m in agg["metrics"]:
                metrics.append(
                    MetricResult(
                        id=m["metric"],
                        value=m["mean"],
                        unit=m["unit"],
                        n=m["repetitions"],
                        sd=defined_sd(m["sd"]),
                        definition_version=m["definition_version"],
                        uncertainty=None,
                    )
                )
            dev = agg["device"]
            out.append(
                ResultsFile(
                    implementation=Implementation(name="haptify-registry", version=PACKAGE_VERSION),
                    session_id=slug,
                    device=DeviceSummary(manufacturer=dev["manufacturer"], model=dev["model"]),
                    manifest_sha256="0" * 64,
                    metrics=metrics,
                )
            )
        return out

    def export_rows(self, *, device: str | None = None, state: str = "current", verification: str = "all") -> list[dict]:
        """One row per submission × metric (the CSV export), filtered by state and verification state."""
        with DBSession(self.engine) as s:
            q = (
                select(db.Submission)
                .options(selectinload(db.Submission.metrics), selectinload(db.Submission.device))
                .order_by(db.Submission.received_at, db.Submission.id)
            )
            if device:
                q = q.join(db.Device).where(db.Device.slug == device)
            ctx = self._context(s)
            out = []
            for sub in s.scalars(q):
                summary = self._summary(sub, ctx)
                if state != "all" and summary["state"] != state or verification not in ("all", sub.verification):
                    continue
                for m in sub.metrics:
                    out.append(
                        {
                            "submission": sub.id,
                            "state": summary["state"],
                            "verification": sub.verification,
                            "lab": sub.lab_id,
                            "device": sub.device.slug,
                            "manufacturer": sub.device.manufacturer,
                            "model": sub.device.model,
                            "serial": sub.serial or "",
                            "implementation": f"{sub.implementation_name} {sub.implementation_version}",
                            "metric": m.metric_id,
                            "value": m.value_json,
                            "unit": m.unit,
                            "n": m.n,
                            "sd": m.sd_json,
                            "received_at": sub.received_at.isoformat(),
                        }
                    )
            return out


def not_counted(summary: dict, sub: db.Submission) -> list[dict]:
    """The metrics of a submission that does not count (not verified), one entry each: submission, lab,
    state, metric, submitted value and unit, and — from its verification record — the recomputed value,
    the tolerance and why it does not agree (spec §17.3.1)."""
    checks = {c["metric"]: c for c in json.loads(sub.verification_json).get("checks", [])}
    out = []
    for m in sub.metrics:
        check = checks.get(m.metric_id, {})
        out.append(
            {
                "submission": sub.id,
                "lab": sub.lab_id,
                "verification": sub.verification,
                "metric": m.metric_id,
                "submitted": json.loads(m.value_json),
                "unit": m.unit,
                "recomputed": check.get("recomputed"),
                "check": check.get("status"),
                "tolerance": check.get("tolerance"),
                "why": check.get("message") or json.loads(sub.verification_json).get("note", ""),
                "implementation": summary["implementation"],
            }
        )
    return out


def defined_sd(sd: float | list[float | None] | None) -> float | list[float] | None:
    """An aggregate's sd as a results file carries it (spec §15.2): a vector metric's sd is given for
    every component or not at all (with one repetition no component has one)."""
    if not isinstance(sd, list):
        return sd
    components = [v for v in sd if v is not None]
    return components if len(components) == len(sd) else None


def _components(value: Any) -> list[float]:
    return [float(v) for v in value] if isinstance(value, list) else [float(value)]


def aggregate(metric: str, items: list[tuple[dict, db.MetricValue]]) -> dict:
    """Mean and spread of one metric over labs and repetitions (spec §17.5).

    Repetitions: every per-repetition value of every current submission (the submitted value when a
    submission lists none); ``mean``, ``sd`` (ddof = 1), ``min``, ``max`` over them. Labs: each lab's
    mean of its repetitions; ``between_lab_sd`` is the sd of those means (ddof = 1, with ≥ 2 labs).
    Vector metrics are aggregated per component. A scalar metric also has ``uncertainty``, the pooled
    uncertainty of the mean from the submissions' records (None when one lacks it), and ``interlab``, the
    ISO 5725-2 table of its labs (None with fewer than two labs of ≥ 2 repetitions; spec §17.5.3).
    """
    reps: list[list[float]] = []
    per_lab: dict[str, list[list[float]]] = {}
    for summary, m in items:
        values = json.loads(m.per_repetition_json) or [json.loads(m.value_json)]
        for v in values:
            comp = _components(v)
            reps.append(comp)
            per_lab.setdefault(summary["lab"], []).append(comp)
    width = len(reps[0])
    reps = [r for r in reps if len(r) == width]

    def stat(fn, rows: list[list[float]]) -> list[float | None]:
        return [fn([r[i] for r in rows]) if rows else None for i in range(width)]

    def sd(xs: list[float]) -> float | None:
        return statistics.stdev(xs) if len(xs) >= 2 else None

    lab_means = [[statistics.fmean([r[i] for r in rows]) for i in range(width)] for rows in per_lab.values()]
    unwrap = (lambda v: v[0]) if width == 1 else (lambda v: v)
    first = items[0][1]
    return {
        "metric": metric,
        "unit": first.unit,
        "definition_version": first.definition_version,
        "mean": unwrap(stat(statistics.fmean, reps)),
        "sd": unwrap(stat(sd, reps)),
        "min": unwrap(stat(min, reps)),
        "max": unwrap(stat(max, reps)),
        "repetitions": len(reps),
        "submissions": len(items),
        "labs": len(per_lab),
        "lab_means": {lab: unwrap(mean) for lab, mean in zip(per_lab, lab_means)},
        "between_lab_sd": unwrap(stat(sd, lab_means)),
        **scalar_precision(metric, items, per_lab, width),
    }


def scalar_precision(
    metric: str, items: list[tuple[dict, db.MetricValue]], per_lab: dict[str, list[list[float]]], width: int
) -> dict:
    """``uncertainty`` and ``interlab`` of a scalar metric's aggregate (spec §17.5.3); both None for a vector."""
    if width != 1:
        return {"uncertainty": None, "interlab": None}
    records = [(m.n, summary.get("uncertainties", {}).get(metric)) for summary, m in items]
    return {
        "uncertainty": interlab.pooled_uncertainty(records),
        "interlab": interlab.table({lab: [r[0] for r in rows] for lab, rows in per_lab.items()}),
    }


def findings_of(err: HaptifyError) -> list[dict]:
    """The findings of a refusal as JSON objects: code, message, location, expected, found (spec §17.5.1)."""
    return [f.to_dict() for f in err.findings]


__all__ = ["Settings", "Registry", "Caller", "Outcome", "hash_token", "slugify", "aggregate", "Finding"]
