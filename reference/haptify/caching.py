"""Per-run memoisation for functions that take a ComputeContext or a bare session (spec §15.4).

The preprocessing functions (calibration, handle signals, plate signals) accept either; with a
context they cache their result on it, so a trial is processed once per ``haptify compute`` run.
"""

from __future__ import annotations

from typing import Any, Callable


def session_of(ctx_or_session: Any) -> Any:
    """The session of a ComputeContext, or the argument itself when it is a session."""
    return getattr(ctx_or_session, "session", ctx_or_session)


def cached(ctx_or_session: Any, key: Any, build: Callable[[], Any]) -> Any:
    """``build()`` memoised under ``key`` on a context; computed afresh for a bare session."""
    if hasattr(ctx_or_session, "cached"):
        return ctx_or_session.cached(key, build)
    return build()
