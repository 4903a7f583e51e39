"""The registry's records: SQLAlchemy 2 ORM models, engines and migrations (spec §17.5, §17.7).

Records are append-only: a submission row is never updated or deleted (database triggers refuse it, see
the first migration). A correction is a new submission whose ``supersedes_id`` names the old one; a
withdrawal is a row of ``withdrawals`` that keeps the submission and says why. The same code runs on
SQLite (the zero-set-up default, one file in the data folder) and on PostgreSQL (by URL).
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

from sqlalchemy import (
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    Text,
    UniqueConstraint,
    create_engine,
    event,
)
from sqlalchemy.engine import Engine
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

SQLITE_FILE = "registry.sqlite3"
SQLITE_BUSY_TIMEOUT_MS = 30_000  # a writer waits this long for another writer before E978


def utcnow() -> datetime:
    """The current time in UTC (stored with its zone)."""
    return datetime.now(timezone.utc)


class Base(DeclarativeBase):
    """The declarative base of the registry's tables (one schema for SQLite and PostgreSQL, spec §17.7)."""


class Lab(Base):
    """A laboratory that submits results; its id is the session's ``lab.id`` (spec §2.1)."""

    __tablename__ = "labs"
    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    name: Mapped[str | None] = mapped_column(String(200))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class Token(Base):
    """A per-lab API token; only its sha256 is stored (spec §17.6)."""

    __tablename__ = "tokens"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    lab_id: Mapped[str] = mapped_column(ForeignKey("labs.id"), index=True)
    scope: Mapped[str] = mapped_column(String(16))
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    rate_per_minute: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class Device(Base):
    """A device model (manufacturer + model); serial numbers stay with each submission.
    The aggregation key of spec §17.5."""

    __tablename__ = "devices"
    __table_args__ = (UniqueConstraint("manufacturer", "model", name="uq_devices_manufacturer_model"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    slug: Mapped[str] = mapped_column(String(200), unique=True)
    manufacturer: Mapped[str] = mapped_column(String(200))
    model: Mapped[str] = mapped_column(String(200))


class Submission(Base):
    """One accepted bundle: immutable (spec §17.5)."""

    __tablename__ = "submissions"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    digest: Mapped[str] = mapped_column(String(64), unique=True)
    archive_sha256: Mapped[str] = mapped_column(String(64))
    archive_size: Mapped[int] = mapped_column(Integer)
    archive_path: Mapped[str] = mapped_column(String(300), unique=True)
    lab_id: Mapped[str] = mapped_column(ForeignKey("labs.id"), index=True)
    device_id: Mapped[int] = mapped_column(ForeignKey("devices.id"), index=True)
    serial: Mapped[str | None] = mapped_column(String(200))
    spec_version: Mapped[str] = mapped_column(String(16))
    implementation_name: Mapped[str] = mapped_column(String(200))
    implementation_version: Mapped[str] = mapped_column(String(100))
    session_id: Mapped[str] = mapped_column(String(200))
    manifest_sha256: Mapped[str] = mapped_column(String(64))
    supersedes_id: Mapped[str | None] = mapped_column(ForeignKey("submissions.id"), unique=True)
    verification: Mapped[str] = mapped_column(String(16))  # verified | disagreeing | unverified
    verification_json: Mapped[str] = mapped_column(Text)
    bundle_json: Mapped[str] = mapped_column(Text)
    results_json: Mapped[str] = mapped_column(Text)
    has_raw: Mapped[bool] = mapped_column(Boolean)
    token_id: Mapped[int] = mapped_column(ForeignKey("tokens.id"))
    received_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow, index=True)

    lab: Mapped[Lab] = relationship()
    device: Mapped[Device] = relationship()
    metrics: Mapped[list["MetricValue"]] = relationship(back_populates="submission", order_by="MetricValue.metric_id")


class MetricValue(Base):
    """One metric of one submission, for aggregation queries (a copy of the results file's record).
    Spec §17.5."""

    __tablename__ = "metric_values"
    submission_id: Mapped[str] = mapped_column(ForeignKey("submissions.id"), primary_key=True)
    metric_id: Mapped[str] = mapped_column(String(100), primary_key=True, index=True)
    value: Mapped[float | None] = mapped_column(Float)  # scalar metrics; None for vector metrics
    value_json: Mapped[str] = mapped_column(Text)  # the value as JSON (number or list)
    per_repetition_json: Mapped[str] = mapped_column(Text)
    unit: Mapped[str] = mapped_column(String(50))
    n: Mapped[int] = mapped_column(Integer)
    sd_json: Mapped[str] = mapped_column(Text)
    definition_version: Mapped[str] = mapped_column(String(50))

    submission: Mapped[Submission] = relationship(back_populates="metrics")


class Withdrawal(Base):
    """A withdrawal: the submission stays, marked withdrawn with a reason (spec §17.5)."""

    __tablename__ = "withdrawals"
    submission_id: Mapped[str] = mapped_column(ForeignKey("submissions.id"), primary_key=True)
    reason: Mapped[str] = mapped_column(Text)
    token_id: Mapped[int] = mapped_column(ForeignKey("tokens.id"))
    at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ConformanceReport(Base):
    """A passing conformance report on file: later bundles of the same implementation may omit theirs (spec §17.3)."""

    __tablename__ = "conformance_reports"
    sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    implementation_name: Mapped[str] = mapped_column(String(200), index=True)
    implementation_version: Mapped[str] = mapped_column(String(100))
    spec_version: Mapped[str] = mapped_column(String(16))
    report_json: Mapped[str] = mapped_column(Text)
    submission_id: Mapped[str] = mapped_column(ForeignKey("submissions.id"))
    received_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class Challenge(Base):
    """A conformance challenge the registry issued (spec §17.8): its secret seed and cases with their
    expected values stay here; the implementation receives only the sessions and the case ids."""

    __tablename__ = "challenges"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    lab_id: Mapped[str] = mapped_column(ForeignKey("labs.id"), index=True)
    token_id: Mapped[int] = mapped_column(ForeignKey("tokens.id"))
    spec_version: Mapped[str] = mapped_column(String(16))
    seed: Mapped[str] = mapped_column(String(64))
    cases_json: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    expires_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))


class ChallengeResult(Base):
    """The judged answer to a challenge: at most one per challenge (the primary key refuses a replay)."""

    __tablename__ = "challenge_results"
    challenge_id: Mapped[str] = mapped_column(ForeignKey("challenges.id"), primary_key=True)
    implementation_name: Mapped[str] = mapped_column(String(200), index=True)
    implementation_version: Mapped[str] = mapped_column(String(100))
    passed: Mapped[bool] = mapped_column(Boolean)
    verdicts_json: Mapped[str] = mapped_column(Text)
    answered_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ReverifyRun(Base):
    """One registry-wide re-verification (spec §17.9): which reference re-computed, which submissions it
    planned (their ids, fixed when the run starts, so that a resumed run does the same work), on what."""

    __tablename__ = "reverify_runs"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    reference_version: Mapped[str] = mapped_column(String(50), index=True)
    spec_version: Mapped[str] = mapped_column(String(16))
    since_version: Mapped[str | None] = mapped_column(String(50))
    executor: Mapped[str] = mapped_column(String(300))  # "serial", "local N workers" or the scheduler's address
    planned_json: Mapped[str] = mapped_column(Text)  # the submission ids, sorted
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ReverifyRecord(Base):
    """The re-computation of one submission in one run, beside the submission's own record (never over it):
    at most one per (submission, reference version, run) — the primary key refuses a second (spec §17.9)."""

    __tablename__ = "reverify_records"
    submission_id: Mapped[str] = mapped_column(ForeignKey("submissions.id"), primary_key=True)
    reference_version: Mapped[str] = mapped_column(String(50), primary_key=True)
    run_id: Mapped[str] = mapped_column(ForeignKey("reverify_runs.id"), primary_key=True, index=True)
    status: Mapped[str] = mapped_column(String(16), index=True)  # changed | unchanged | failed
    verification: Mapped[str | None] = mapped_column(String(16))  # the state against the submitted values now
    previous_verification: Mapped[str] = mapped_column(String(16))
    checks_json: Mapped[str] = mapped_column(Text)  # per metric: previous, recomputed, tolerance, status
    findings_json: Mapped[str] = mapped_column(Text)  # why the re-computation was refused (status failed)
    worker: Mapped[str] = mapped_column(String(300))
    seconds: Mapped[float] = mapped_column(Float)
    recorded_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


def default_db_url(data_dir: Path) -> str:
    """The embedded default: SQLite in ``registry.sqlite3`` inside the data folder (spec §17.7)."""
    return f"sqlite:///{Path(data_dir).resolve() / SQLITE_FILE}"


def make_engine(url: str) -> Engine:
    """An engine for ``url``; SQLite gets WAL, full fsync, foreign keys and ``BEGIN IMMEDIATE`` for writers.
    Spec §17.7.

    Writers open their transaction with ``engine.execution_options(sqlite_immediate=True)`` so two
    writers never deadlock on a lock upgrade; readers use plain ``BEGIN`` and read the WAL snapshot.
    """
    for alias in ("postgresql://", "postgres://"):
        if url.startswith(alias):
            url = "postgresql+psycopg://" + url[len(alias) :]
    if not url.startswith("sqlite"):
        return create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20)
    engine = create_engine(
        url, connect_args={"check_same_thread": False, "timeout": SQLITE_BUSY_TIMEOUT_MS / 1000}, pool_size=20, max_overflow=20
    )

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_conn, _record) -> None:
        dbapi_conn.isolation_level = None  # let SQLAlchemy's begin event below emit BEGIN
        cur = dbapi_conn.cursor()
        cur.execute("PRAGMA journal_mode=WAL")
        cur.execute("PRAGMA synchronous=FULL")  # an acknowledged commit survives a power cut
        cur.execute("PRAGMA foreign_keys=ON")
        cur.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
        cur.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn) -> None:
        conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.get_execution_options().get("sqlite_immediate") else "BEGIN")

    return engine


def writer(engine: Engine) -> Engine:
    """The engine to open write transactions with (``BEGIN IMMEDIATE`` on SQLite; the same engine elsewhere)."""
    return engine.execution_options(sqlite_immediate=True) if engine.dialect.name == "sqlite" else engine


def migrate(engine: Engine, target: str = "head", *, down: bool = False) -> None:
    """Apply the Alembic migrations (``migrations/versions``) up to ``target`` (head: all; idempotent), or
    with ``down`` revert them down to ``target`` (``base``: none left); spec §17.7."""
    from alembic import command
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(Path(__file__).parent / "migrations"))
    with writer(engine).begin() as conn:
        cfg.attributes["connection"] = conn
        (command.downgrade if down else command.upgrade)(cfg, target)
