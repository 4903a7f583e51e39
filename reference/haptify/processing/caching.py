"""Per-run memoisation for functions that take a ComputeContext or a bare session (spec §15.4).

The preprocessing functions (calibration, handle signals, plate signals) accept either; with a
context they cache their result on it, so a trial is processed once per ``haptify compute`` run.
"""

from __future__ import annotations

from typing import Any, Callable, Hashable, TypeVar

T = TypeVar("T")


def session_of(ctx_or_session: Any) -> Any:
    """The session of a ComputeContext, or the argument itself when it is a session."""
    return getattr(ctx_or_session, "session", ctx_or_session)


def cached(ctx_or_session: Any, key: Hashable, build: Callable[[], T]) -> T:
    """``build()`` memoised under ``key`` on a context; computed afresh for a bare session."""
    if hasattr(ctx_or_session, "cached"):
        memo: T = ctx_or_session.cached(key, build)
        return memo
    return build()
