"""Conformance by challenge (spec §17.8): known-answer sessions the registry generates itself, from a
secret seed, with the conformance suite's fixture generators; the answers never leave the registry.

A challenge is a handful of vibration sessions (spec chapter 10) written by
:func:`haptify_tools.build_conformance_fixtures.write_vibration_session`, each with tones whose
frequencies, amplitudes and axes, accelerometer rate, duration, stream format and rig are drawn from the
seed. Their answers are analytic — :func:`~haptify_tools.build_conformance_fixtures.tones_rms` and
:func:`~haptify_tools.build_conformance_fixtures.tones_centroid` of the tones — so no implementation, the
reference included, is trusted to produce them. An implementation that only replays the published
suite's answers, or a result file of an earlier challenge, cannot pass: every challenge has new values
and new case ids.

A case passes under the judge's rule of spec §16.3 with the loosest tolerance the suite allows for its
metric (the rule of §17.3.1); the challenge passes when every case passes.
"""

from __future__ import annotations

import gzip
import io
import json
import math
import os
import secrets
import shutil
import tarfile
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession

from haptify.errors import fail
from haptify.results import Implementation
from haptify.versions import SPEC_VERSION
from haptify_tools.build_conformance_fixtures import tones_centroid, tones_rms, write_vibration_session
from haptify_tools.registry.checks import tolerances

SESSIONS = 2  # sessions per challenge; each gives the four vibration cases below
METRICS = ("vibration.rms", "vibration.spectral_centroid", "vibration.baseline_rms", "vibration.baseline_centroid")
UNITS = {"vibration.rms": "m/s^2", "vibration.spectral_centroid": "Hz", "vibration.baseline_rms": "m/s^2",
         "vibration.baseline_centroid": "Hz"}
RATES_HZ = (1000.0, 1500.0, 2000.0)
SECONDS = (4.0, 6.0)
LOWEST_HZ = 20  # well above the 10 Hz high-pass cut-off (§10.2): the filter's gain is then analytic to < 1e-4


@dataclass(frozen=True)
class ChallengeCase:
    """One case of a challenge: public id, metric, session folder (relative to the archive) and the
    secret expected value with its tolerance (spec §17.8)."""

    id: str
    metric: str
    session: str
    expected: float
    unit: str
    tolerance: dict[str, float]

    def public(self) -> dict:
        """What the implementation is told: id, metric, session folder, unit; never the expected value."""
        return {"id": self.id, "metric": self.metric, "session": self.session, "parameters": {}, "unit": self.unit}


def _tones(rng: np.random.Generator, rate: float) -> dict[int, list[tuple[float, float]]]:
    """One to three tones on one to three axes: integer frequencies in [LOWEST_HZ, 0.45·rate], amplitudes
    0.01–0.2 m/s² (rounded, so the session files carry them exactly)."""
    out: dict[int, list[tuple[float, float]]] = {}
    for _ in range(int(rng.integers(1, 4))):
        axis = int(rng.integers(0, 3))
        f = float(rng.integers(LOWEST_HZ, int(0.45 * rate)))
        amp = round(float(rng.uniform(0.01, 0.2)), 4)
        if all(f != g for tones in out.values() for g, _ in tones):  # one frequency once: the power adds per tone
            out.setdefault(axis, []).append((f, amp))
    return out


def generate(seed: int, root: Path, tag: str) -> list[ChallengeCase]:
    """Write the challenge's sessions under ``root`` and return its cases (spec §17.8).

    Deterministic in ``seed``; ``tag`` (the challenge id) makes the case ids and session ids unique to
    this challenge.
    """
    rng = np.random.default_rng(seed)
    tol = tolerances(SPEC_VERSION)
    cases: list[ChallengeCase] = []
    for i in range(1, SESSIONS + 1):
        rate = float(rng.choice(RATES_HZ))
        secs = float(rng.choice(SECONDS))
        fmt = "csv" if rng.random() < 0.5 else "parquet"
        rig = "rotated" if rng.random() < 0.5 else "example"
        fs_tones, base_tones = _tones(rng, rate), _tones(rng, rate)
        name = f"s{i}"
        write_vibration_session(root / name, f"challenge-{tag}-{name}", fmt, rate, secs, fs_tones, base_tones, rig)
        fs_all = [t for ts in fs_tones.values() for t in ts]
        base_all = [t for ts in base_tones.values() for t in ts]
        truth = {"vibration.rms": tones_rms(fs_all), "vibration.spectral_centroid": tones_centroid(fs_all),
                 "vibration.baseline_rms": tones_rms(base_all), "vibration.baseline_centroid": tones_centroid(base_all)}
        for metric in METRICS:
            cases.append(ChallengeCase(f"challenge-{tag}.{name}.{metric.removeprefix('vibration.')}", metric, name,
                                       truth[metric], UNITS[metric], dict(tol[metric])))
    return cases


def pack_sessions(root: Path, target: Path) -> None:
    """The challenge's session folders as one ``.tar.gz`` (regular files only, sorted, mode 0600)."""
    with open(os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600), "wb") as raw, \
            gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as gz, \
            tarfile.open(fileobj=gz, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for path in sorted(p for p in root.rglob("*") if p.is_file()):
            data = path.read_bytes()
            info = tarfile.TarInfo(path.relative_to(root).as_posix())
            info.size, info.mode, info.mtime = len(data), 0o644, 0
            tar.addfile(info, io.BytesIO(data))
        raw.flush()
        os.fsync(raw.fileno())


def judge_answer(case: ChallengeCase, answer: Any) -> dict:
    """The verdict of one answer (a results document, or ``{"error": "…"}``) under spec §16.3: passed when
    the case's metric is there, in its unit, finite and within ``abs + rel·|expected|`` of the truth."""
    out = {"case": case.id, "metric": case.metric, "expected": case.expected, "tolerance": case.tolerance,
           "actual": None, "status": "failed", "message": ""}
    if not isinstance(answer, dict) or "metrics" not in answer:
        out["message"] = str(answer.get("error", "no results")) if isinstance(answer, dict) else "no results"
        return out
    record = next((m for m in answer["metrics"] if isinstance(m, dict) and m.get("id") == case.metric), None)
    if record is None:
        out["message"] = f"metric {case.metric} missing from the results"
        return out
    value = record.get("value")
    out["actual"] = value
    if record.get("unit") != case.unit:
        out["message"] = f"unit {record.get('unit')!r}, expected {case.unit!r}"
    elif not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        out["message"] = f"value {value!r} is not a finite number"
    elif abs(value - case.expected) <= case.tolerance["abs"] + case.tolerance["rel"] * abs(case.expected):
        out["status"] = "passed"
    else:
        out["message"] = (f"found {value!r}; allowed |difference| ≤ {case.tolerance['abs']:g} + "
                          f"{case.tolerance['rel']:g}·|expected|")
    return out


def cases_to_json(cases: list[ChallengeCase]) -> str:
    return json.dumps([c.__dict__ for c in cases])


def cases_from_json(text: str) -> list[ChallengeCase]:
    return [ChallengeCase(**c) for c in json.loads(text)]


# --- the registry's side: issue, serve, judge, record (spec §17.8) ---------------------------------

def _aware(t: datetime) -> datetime:
    """A stored time with its zone (SQLite returns naive UTC)."""
    return t if t.tzinfo else t.replace(tzinfo=timezone.utc)


def issue(reg, caller) -> dict:
    """Create a challenge for the caller's lab: a fresh secret seed, its sessions packed into
    ``DATA/challenges/<id>.tar.gz`` (mode 0600), its cases with their answers in the database."""
    from haptify_tools.registry import db
    from haptify_tools.registry.bundle import DIR_MODE

    cid = secrets.token_hex(10)
    seed = secrets.randbits(128)
    work = reg.tmp / f"challenge-{cid}"
    folder = reg.data / "challenges"
    folder.mkdir(mode=DIR_MODE, exist_ok=True)
    partial = reg.tmp / f"challenge-{cid}.tar.gz"
    try:
        cases = generate(seed, work, cid)
        pack_sessions(work, partial)
        os.replace(partial, folder / f"{cid}.tar.gz")
    finally:
        shutil.rmtree(work, ignore_errors=True)
        partial.unlink(missing_ok=True)
    now = datetime.now(timezone.utc)
    with DBSession(reg.writer) as s, s.begin():
        s.add(db.Challenge(id=cid, lab_id=caller.lab_id, token_id=caller.token_id, spec_version=SPEC_VERSION,
                           seed=f"{seed:032x}", cases_json=cases_to_json(cases), created_at=now,
                           expires_at=now + timedelta(seconds=reg.settings.challenge_ttl_s)))
    return record(reg, cid)


def _row(s, cid: str):
    from haptify_tools.registry import db

    row = s.get(db.Challenge, cid)
    if row is None:
        raise fail("E973", f"no challenge {cid!r}", expected="an id from POST /api/v1/challenges", found=cid)
    return row


def record(reg, cid: str) -> dict:
    """A challenge as anyone may read it: its cases without answers while it is open; once answered, the
    implementation, the verdict and every case's expected and found value (spec §17.8)."""
    from haptify_tools.registry import db

    with DBSession(reg.engine) as s:
        row = _row(s, cid)
        result = s.get(db.ChallengeResult, cid)
        cases = cases_from_json(row.cases_json)
        out = {"id": row.id, "lab": row.lab_id, "spec_version": row.spec_version,
               "created_at": _aware(row.created_at).isoformat(), "expires_at": _aware(row.expires_at).isoformat(),
               "sessions": f"/api/v1/challenges/{row.id}/sessions.tar.gz", "cases": [c.public() for c in cases]}
        if result is None:
            out["state"] = "expired" if datetime.now(timezone.utc) > _aware(row.expires_at) else "open"
            out["result"] = None
        else:
            out["state"] = "passed" if result.passed else "failed"
            out["result"] = {"implementation": {"name": result.implementation_name, "version": result.implementation_version},
                             "passed": result.passed, "answered_at": _aware(result.answered_at).isoformat(),
                             "cases": json.loads(result.verdicts_json)}
        return out


def sessions_archive(reg, cid: str) -> Path:
    """The packed sessions of an open challenge (E973 unknown, E979 expired or answered)."""
    from haptify_tools.registry import db

    with DBSession(reg.engine) as s:
        row = _row(s, cid)
        _require_open(row, s.get(db.ChallengeResult, cid))
    return reg.data / "challenges" / f"{cid}.tar.gz"


def _require_open(row, result) -> None:
    if result is not None:
        raise fail("E979", f"challenge {row.id} has been answered already; an answer is judged once (no replay)",
                   pointer="/challenge", expected="an open challenge", found="answered")
    if datetime.now(timezone.utc) > _aware(row.expires_at):
        raise fail("E979", f"challenge {row.id} expired at {_aware(row.expires_at).isoformat()}",
                   pointer="/challenge", expected="an open challenge", found="expired")


class Answers(BaseModel):
    """The body of ``POST /api/v1/challenges/{id}/answers``: the implementation, and per case id its
    output — a results document (spec §15.1), a findings document, or ``{"error": "…"}`` (spec §17.8)."""

    model_config = ConfigDict(extra="forbid")
    implementation: Implementation
    answers: dict[str, dict]


def answer(reg, cid: str, caller, body: Answers) -> dict:
    """Judge the answers to challenge ``cid`` against its secret cases and record the result, once.

    E971 another lab's challenge; E979 expired or already answered (a replay); E975 answers that are not
    exactly this challenge's cases (a result file of another challenge names other ids) or results naming
    another implementation than the one the answer is for."""
    from haptify_tools.registry import db

    with DBSession(reg.engine) as s:
        row = _row(s, cid)
        if row.lab_id != caller.lab_id:
            raise fail("E971", "a challenge is answered by the lab it was issued to", file="Authorization",
                       expected=row.lab_id, found=caller.lab_id)
        _require_open(row, s.get(db.ChallengeResult, cid))
        cases = cases_from_json(row.cases_json)
    ids = [c.id for c in cases]
    if sorted(body.answers) != sorted(ids):
        raise fail("E975", "the answers are not those of this challenge's cases", file="body", pointer="/answers",
                   expected=ids, found=sorted(body.answers)[:20])
    impl = body.implementation.model_dump()
    for case_id, doc in body.answers.items():
        named = doc.get("implementation") if isinstance(doc, dict) else None
        if isinstance(named, dict) and {k: named.get(k) for k in ("name", "version")} != impl:
            raise fail("E975", f"the results for {case_id} name another implementation", file="body",
                       pointer=f"/answers/{case_id}/implementation", expected=impl, found=named)
    verdicts = [judge_answer(c, body.answers[c.id]) for c in cases]
    passed = all(v["status"] == "passed" for v in verdicts)
    try:
        with DBSession(reg.writer) as s, s.begin():
            s.add(db.ChallengeResult(challenge_id=cid, implementation_name=impl["name"], implementation_version=impl["version"],
                                     passed=passed, verdicts_json=json.dumps(verdicts)))
    except IntegrityError:
        raise fail("E979", f"challenge {cid} has been answered already; an answer is judged once (no replay)",
                   pointer="/challenge", expected="an open challenge", found="answered") from None
    return record(reg, cid)


def implementations(reg) -> list[dict]:
    """Every implementation and version that answered a challenge: how many it passed and failed, and its
    latest passed challenge (what makes its submissions' conformance 'proven', spec §17.8)."""
    from haptify_tools.registry import db

    out: dict[tuple[str, str], dict] = {}
    with DBSession(reg.engine) as s:
        for r in s.scalars(select(db.ChallengeResult).order_by(db.ChallengeResult.answered_at)):
            e = out.setdefault((r.implementation_name, r.implementation_version),
                               {"name": r.implementation_name, "version": r.implementation_version, "passed": 0,
                                "failed": 0, "latest_passed": None})
            e["passed" if r.passed else "failed"] += 1
            if r.passed:
                e["latest_passed"] = r.challenge_id
    return sorted(out.values(), key=lambda e: (e["name"], e["version"]))


__all__ = ["ChallengeCase", "generate", "pack_sessions", "judge_answer", "issue", "record", "answer", "implementations"]
