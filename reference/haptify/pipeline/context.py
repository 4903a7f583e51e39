"""The context a metric family's ``compute`` receives (spec §15.4): the session, the metrics asked for, the case
parameters (§16.8.2), a per-run cache and a warning sink."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Hashable, TypeVar

from haptify.codes import Code
from haptify.errors import Finding
from haptify.formats.storage import SessionFolder
from haptify.pipeline.results import ResultWarning

T = TypeVar("T")


@dataclass
class ComputeContext:
    """What a family's ``compute`` receives: the session, a per-run cache and a warning sink.
    Spec §15.4; ``parameters`` as §16.8.2."""

    session: SessionFolder
    wanted: set[str] | None = None  # metric ids asked for (None: all)
    parameters: dict[str, Any] = field(default_factory=dict)  # case parameters (spec §16.2), e.g. {"model": file}
    warnings: list[ResultWarning] = field(default_factory=list)
    # keep every memoised entry for later work on this context (the report's figures); False: a trial's
    # entries are dropped once no family still to run reads its protocol (spec §15.4)
    keep: bool = True
    _cache: dict[Hashable, Any] = field(default_factory=dict)

    def cached(self, key: Hashable, build: Callable[[], T]) -> T:
        """Memoise ``build()`` under ``key`` for this run (e.g. ``("handle_signals", trial_id)``)."""
        if key not in self._cache:
            self._cache[key] = build()
        memo: T = self._cache[key]
        return memo

    def forget_trial(self, trial_id: str) -> None:
        """Drop what was memoised for one trial (the keys that name it, e.g. ``("handle_signals", id, rate)``),
        keeping session-wide entries such as the calibration; for work that visits each trial once."""
        for key in [k for k in self._cache if isinstance(k, tuple) and trial_id in k[1:]]:
            del self._cache[key]

    def wants(self, metric_id: str) -> bool:
        return self.wanted is None or metric_id in self.wanted

    def warn(self, code: Code, message: str, metric: str | None = None, trial: str | None = None) -> None:
        Finding(code, message)  # checks the code is catalogued
        self.warnings.append(ResultWarning(code=code, message=message, metric=metric, trial=trial))
