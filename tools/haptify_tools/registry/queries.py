"""The registry's read queries, shared by the JSON API and the web pages (spec §17.4–§17.5): submission
summaries and their states, one submission with its results and archive, labs and devices, a device's
current submissions that count, its per-metric aggregates, the synthetic results files a comparison reads
and the rows of the CSV export. :class:`RegistryQueries` is a base of
:class:`haptify_tools.registry.service.Registry`, whose database engine and data folder it reads.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from pathlib import Path

from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session as DBSession
from sqlalchemy.orm import selectinload

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.bundle_format import SESSION_DIR
from haptify.pipeline.results import DeviceSummary, Implementation, MetricResult, ResultsFile
from haptify.versions import PACKAGE_VERSION
from haptify_tools.registry import db
from haptify_tools.registry.aggregates import aggregate, defined_sd, not_counted
from haptify_tools.registry.bundle import DIR_MODE, unpack
from haptify_tools.registry.records import RANKED, ReadContext, Settings
from haptify_tools.registry.worker import run_contained


class RegistryQueries:
    """The read side of :class:`haptify_tools.registry.service.Registry` (spec §17.4–§17.5)."""

    # set by Registry.__init__
    settings: Settings
    data: Path
    tmp: Path
    engine: Engine

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
                raise fail(Code.NOT_FOUND, f"no submission {sid!r}", expected="an existing submission id", found=sid)
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
                raise fail(Code.NOT_FOUND, f"no submission {sid!r}", expected="an existing submission id", found=sid)
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
        raise fail(Code.NOT_FOUND, f"no lab {lab_id!r}", expected="an existing lab id", found=lab_id)

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
            raise fail(Code.NOT_FOUND, f"no device {slug!r}", expected="a device slug from /api/v1/devices", found=slug)
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
                Code.REQUEST_INVALID,
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
        """One synthetic results file per device, holding its aggregated means (for ``haptify.pipeline.compare``)."""
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
