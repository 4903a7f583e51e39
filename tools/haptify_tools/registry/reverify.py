"""Registry-wide re-verification (spec §17.9): re-compute every stored submission that has raw
streams with the installed reference, on a Dask cluster, and record the new values beside the old ones.

The work is split so that nothing but the driver touches the database:

* the **driver** (this process) plans the run — the submissions with raw streams, fixed by id in the run's
  record — and submits one task per submission not yet recorded for the run;
* a **task** (:func:`recompute`, on any worker) fetches the archive from the bundle store
  (:mod:`.storage`), unpacks it under the registry's limits and runs the registry's own verification
  (:func:`.checks.verify`: validation of the session, re-computation, comparison with the submitted values);
  it returns values, it writes nothing;
* the driver judges each returned value against the submission's previous re-computation with the metric's
  conformance tolerance (:func:`judge`) and inserts one ``reverify_records`` row. The row's key is
  (submission, reference version, run): a task the scheduler ran twice (a worker died after finishing it)
  cannot be recorded twice, and a resumed run skips what is recorded.
"""

from __future__ import annotations

import json
import re
import tempfile
import time
import uuid
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.bundle_format import SESSION_DIR
from haptify.pipeline.results import ResultsFile
from haptify.versions import PACKAGE_VERSION, SPEC_VERSION
from haptify_tools.cluster import RETRIES, each_completed, worker_name
from haptify_tools.registry import db
from haptify_tools.registry.bundle import Limits, unpack_bundle
from haptify_tools.registry.checks import agrees, tolerances, verify
from haptify_tools.registry.storage import BundleStore

EXACT = {"abs": 0.0, "rel": 0.0}  # a metric without conformance cases moves when its value moves at all
METRIC_STATES = ("changed", "unchanged", "first", "failed")
RECORD_STATES = ("changed", "unchanged", "failed")


class StoreUnavailable(RuntimeError):
    """The bundle store could not give a task its archive: not the submission's fault, so nothing is
    recorded; the task is retried, and a resumed run tries it again."""


@dataclass(frozen=True)
class Job:
    """What a worker needs to re-verify one submission: the archive's key in the store and the accepted
    results (as stored with the submission); small and picklable."""

    submission_id: str
    archive: str
    results_json: str
    spec_version: str


def recompute(store: BundleStore, job: Job, limits: Limits) -> dict:
    """Task: unpack the archive into a scratch folder and run :func:`.checks.verify` on it (spec §17.3.1).

    Returns ``{"verification": …, "findings": [], "worker", "seconds"}``, or with the refusal's findings
    and no verification when the reference refuses the session now. Raises :class:`StoreUnavailable`."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="haptify-reverify-") as tmp:
        try:
            archive = store.materialize(job.archive, Path(tmp))
        except HaptifyError as err:
            raise StoreUnavailable("; ".join(f.message for f in err.findings)) from None
        out: dict[str, Any]
        try:
            unpacked, _ = unpack_bundle(archive, Path(tmp) / "bundle", limits)
            results = ResultsFile.model_validate_json(job.results_json)
            out = {"verification": verify(unpacked.root / SESSION_DIR, results, job.spec_version).to_dict(), "findings": []}
        except HaptifyError as err:
            out = {"verification": None, "findings": [f.to_dict() for f in err.findings]}
    return {**out, "worker": worker_name(), "seconds": time.perf_counter() - t0}


@dataclass
class Baseline:
    """What a submission's values are compared with: its latest earlier re-computation, else the one made
    when it was accepted (metric → recomputed value; ``None`` where there was none) and the state then."""

    values: dict[str, Any]
    verification: str


def judge(out: dict, baseline: Baseline, spec_version: str) -> tuple[str, list[dict]]:
    """The record's status and per-metric checks for a task's ``out`` (spec §17.9).

    A metric is ``changed`` when ``|previous − recomputed| > abs + rel·|recomputed|`` for a component, with
    the loosest tolerance of its conformance cases (the rule of §17.3.1; exact for a metric without cases),
    ``unchanged`` when within, ``first`` without a previous value, ``failed`` when the reference no longer
    computes it. The submission is ``failed`` when the reference refuses it, ``changed`` when a metric
    changed or failed after having a value, else ``unchanged``."""
    if out["verification"] is None:
        return "failed", []
    tols = tolerances(spec_version)
    checks = []
    for check in out["verification"]["checks"]:
        metric, now = check["metric"], check["recomputed"]
        prev = baseline.values.get(metric)
        tol = check["tolerance"] or tols.get(metric) or EXACT
        if now is None:
            state = "failed"
        elif prev is None:
            state = "first"
        else:
            state = "unchanged" if agrees(prev, now, tol) else "changed"
        checks.append(
            {
                "metric": metric,
                "status": state,
                "previous": prev,
                "recomputed": now,
                "tolerance": tol,
                "submitted": check["submitted"],
                "code": Code.REVERIFIED_VALUE_MOVED if state == "changed" else None,
            }
        )
    moved = any(c["status"] == "changed" or c["status"] == "failed" and c["previous"] is not None for c in checks)
    return ("changed" if moved else "unchanged"), checks


def _recomputed(checks: list[dict]) -> dict[str, Any]:
    return {c["metric"]: c.get("recomputed") for c in checks}


def baselines(s: DBSession, ids: list[str], run_id: str) -> dict[str, Baseline]:
    """Per submission, its :class:`Baseline`: the latest record of another run that re-computed it, else
    its own verification record."""
    out: dict[str, Baseline] = {}
    for sub in s.scalars(select(db.Submission).where(db.Submission.id.in_(ids))):
        out[sub.id] = Baseline(_recomputed(json.loads(sub.verification_json).get("checks", [])), sub.verification)
    records = s.scalars(
        select(db.ReverifyRecord)
        .where(
            db.ReverifyRecord.submission_id.in_(ids),
            db.ReverifyRecord.run_id != run_id,
            db.ReverifyRecord.verification.is_not(None),
        )
        .order_by(db.ReverifyRecord.recorded_at)
    )
    for rec in records:  # oldest first: the latest wins
        if rec.verification is None:  # (left out by the query; for the type checker)
            continue
        out[rec.submission_id] = Baseline(_recomputed(json.loads(rec.checks_json)), rec.verification)
    return out


def version_key(version: str) -> tuple[int, ...]:
    """``"1.2.10"`` → ``(1, 2, 10)`` for ordering reference versions (E903 for anything else)."""
    if not re.fullmatch(r"\d+(\.\d+)*", version):
        raise fail(
            Code.USAGE, f"{version!r} is not a version number", expected="digits separated by dots, e.g. 0.2.0", found=version
        )
    return tuple(int(p) for p in version.split("."))


def plan(s: DBSession, since_version: str | None = None) -> list[str]:
    """The ids of the submissions a new run re-verifies: every one with raw streams; with ``since_version``
    only those no reference of that version or later has re-verified yet (spec §17.9)."""
    ids = sorted(s.scalars(select(db.Submission.id).where(db.Submission.has_raw.is_(True))))
    if since_version is None:
        return ids
    floor = version_key(since_version)
    done = {
        sid
        for sid, version in s.execute(select(db.ReverifyRecord.submission_id, db.ReverifyRecord.reference_version))
        if re.fullmatch(r"\d+(\.\d+)*", version) and version_key(version) >= floor
    }
    return [sid for sid in ids if sid not in done]


@dataclass
class Summary:
    """What a run found (spec §17.9): submissions by status, metrics by status, verification states that
    changed, the submissions whose values moved, and what this invocation did."""

    run_id: str
    reference_version: str
    executor: str
    planned: int
    recorded: int
    submissions: dict[str, int]
    metrics: dict[str, dict[str, int]]
    transitions: dict[str, int]
    changed: dict[str, list[str]]
    failed: dict[str, list[str]]
    computed_now: int = 0
    skipped: int = 0
    duplicates_refused: int = 0
    errors: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def complete(self) -> bool:
        return self.recorded == self.planned

    def to_dict(self) -> dict:
        return {**asdict(self), "complete": self.complete}


def summarize(s: DBSession, run: db.ReverifyRun) -> Summary:
    """The summary of every record of ``run`` (whichever invocation wrote them)."""
    records = list(
        s.scalars(select(db.ReverifyRecord).where(db.ReverifyRecord.run_id == run.id).order_by(db.ReverifyRecord.submission_id))
    )
    metrics: dict[str, Counter] = {}
    changed: dict[str, list[str]] = {}
    failed: dict[str, list[str]] = {}
    transitions: Counter[str] = Counter()
    for rec in records:
        checks = json.loads(rec.checks_json)
        for c in checks:
            metrics.setdefault(c["metric"], Counter())[c["status"]] += 1
        if rec.status == "changed":
            changed[rec.submission_id] = [c["metric"] for c in checks if c["status"] in ("changed", "failed")]
        if rec.status == "failed":
            failed[rec.submission_id] = sorted({f["code"] for f in json.loads(rec.findings_json)})
        if rec.verification is not None and rec.verification != rec.previous_verification:
            transitions[f"{rec.previous_verification} → {rec.verification}"] += 1
    by_status = Counter(rec.status for rec in records)
    return Summary(
        run.id,
        run.reference_version,
        run.executor,
        len(json.loads(run.planned_json)),
        len(records),
        {k: by_status.get(k, 0) for k in RECORD_STATES},
        {m: {k: c.get(k, 0) for k in METRIC_STATES} for m, c in sorted(metrics.items())},
        dict(sorted(transitions.items())),
        changed,
        failed,
    )


def start_run(engine, executor: str, since_version: str | None = None) -> str:
    """Record a new run with its plan (the submissions to re-verify, by id); returns its id."""
    run_id = uuid.uuid4().hex[:20]
    with DBSession(db.writer(engine)) as s, s.begin():
        ids = plan(s, since_version)
        s.add(
            db.ReverifyRun(
                id=run_id,
                reference_version=PACKAGE_VERSION,
                spec_version=SPEC_VERSION,
                since_version=since_version,
                executor=executor,
                planned_json=json.dumps(ids),
            )
        )
    return run_id


def load_run(engine, run_id: str) -> db.ReverifyRun:
    """The run ``run_id`` to resume: E973 when unknown, E981 when another reference version started it."""
    with DBSession(engine) as s:
        run = s.get(db.ReverifyRun, run_id)
        if run is None:
            raise fail(
                Code.NOT_FOUND,
                f"no re-verification run {run_id!r}",
                expected="a run id printed by `haptify registry reverify`",
                found=run_id,
            )
        if run.reference_version != PACKAGE_VERSION:
            raise fail(
                Code.REVERIFY_RUN_OF_ANOTHER_REFERENCE,
                f"run {run_id} was started by reference {run.reference_version}; this is {PACKAGE_VERSION}",
                expected=run.reference_version,
                found=PACKAGE_VERSION,
            )
        s.expunge(run)
        return run


def run_reverify(
    engine,
    store: BundleStore,
    run_id: str,
    client=None,
    *,
    limits: Limits = Limits(),
    retries: int = RETRIES,
    on_record: Callable[[str, str], object] | None = None,
    progress: Callable[[int], object] | None = None,
) -> Summary:
    """Re-verify the submissions of run ``run_id`` not yet recorded for it, on ``client``'s cluster (serially
    in this process when None), writing each record as its task completes; returns the run's summary.

    ``on_record(submission id, status)`` is called after each record is committed and ``progress(1)`` after
    each task; a task that still fails after ``retries`` (or whose archive the store cannot give) is not
    recorded and is listed in ``errors`` — resuming the run retries it."""
    t0 = time.perf_counter()
    run = load_run(engine, run_id)
    planned = json.loads(run.planned_json)
    with DBSession(engine) as s:
        recorded = set(s.scalars(select(db.ReverifyRecord.submission_id).where(db.ReverifyRecord.run_id == run_id)))
        remaining = [sid for sid in planned if sid not in recorded]
        rows = {r.id: r for r in s.scalars(select(db.Submission).where(db.Submission.id.in_(remaining)))}
        jobs = [
            (
                f"reverify-{run_id}-{sid}",
                (store, Job(sid, rows[sid].archive_path, rows[sid].results_json, rows[sid].spec_version), limits),
            )
            for sid in remaining
        ]
        base = baselines(s, remaining, run_id)
    computed = refused = 0
    errors: dict[str, str] = {}
    if progress and recorded:
        progress(len(recorded))
    for done in each_completed(client, recompute, jobs, retries=retries):
        sid = done.key.rsplit("-", 1)[1]
        if progress:
            progress(1)
        if done.error is not None:
            errors[sid] = f"{type(done.error).__name__}: {done.error}"
            continue
        computed += 1
        status, checks = judge(done.value, base[sid], rows[sid].spec_version)
        verification = done.value["verification"]
        try:
            with DBSession(db.writer(engine)) as s, s.begin():
                s.add(
                    db.ReverifyRecord(
                        submission_id=sid,
                        reference_version=run.reference_version,
                        run_id=run_id,
                        status=status,
                        verification=verification["status"] if verification else None,
                        previous_verification=base[sid].verification,
                        checks_json=json.dumps(checks),
                        findings_json=json.dumps(done.value["findings"]),
                        worker=done.value["worker"],
                        seconds=done.value["seconds"],
                    )
                )
        except IntegrityError:  # recorded already (a second driver on the same run): the first record stands
            refused += 1
            continue
        if on_record:
            on_record(sid, status)
    with DBSession(engine) as s:
        summary = summarize(s, run)
    summary.computed_now, summary.skipped, summary.duplicates_refused = computed, len(recorded), refused
    summary.errors, summary.seconds = errors, time.perf_counter() - t0
    return summary


def record_values(engine, run_id: str) -> dict[str, dict]:
    """Per submission of a run: status, verification and metric → recomputed value (for comparing runs)."""
    with DBSession(engine) as s:
        return {
            r.submission_id: {
                "status": r.status,
                "verification": r.verification,
                "values": _recomputed(json.loads(r.checks_json)),
                "findings": sorted(f["code"] for f in json.loads(r.findings_json)),
            }
            for r in s.scalars(select(db.ReverifyRecord).where(db.ReverifyRecord.run_id == run_id))
        }


__all__ = ["Job", "recompute", "judge", "plan", "start_run", "run_reverify", "summarize", "Summary", "record_values"]
