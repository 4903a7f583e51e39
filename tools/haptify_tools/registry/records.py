"""The registry's settings, tokens and the records it answers with (spec §17.5–§17.7): :class:`Settings`
(where it keeps its records and what it accepts), token scopes and their stored hash, device slugs, the
per-token rate limiter, the authenticated :class:`Caller`, a submission's :class:`Outcome` and the
:class:`ReadContext` a submission's summary needs."""

from __future__ import annotations

import hashlib
import re
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from haptify_tools.registry import db
from haptify_tools.registry.bundle import Limits


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
