"""Jobs for the registry's worker process in tests (spec §17.4.1): module-level, with few imports, so a
worker (a child of the forkserver) imports them quickly."""

from __future__ import annotations

import os
import signal
import time

import numpy as np


def allocate(n_bytes: int) -> float:
    """Sum an array of ``n_bytes`` bytes of ones (the number of float64 elements)."""
    return float(np.ones(n_bytes // 8).sum())


def sleep(seconds: float) -> None:
    time.sleep(seconds)


def kill_self() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def refuse() -> None:
    from haptify.errors import fail

    raise fail("E962", "a coded refusal from the worker", file="x", expected="y", found="z")
