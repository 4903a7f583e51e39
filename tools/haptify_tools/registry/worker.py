"""Containment of hostile bundles (spec §17.4.1): unpacking, checking and re-computing run in a worker
process with a memory and a time limit, so a bundle that exhausts either fails alone, with a code, while
the registry keeps serving.

:func:`run_contained` runs a module-level function in a child of a *forkserver* (started once, with the
registry's modules preloaded, so a child costs a fork and not an interpreter start, and never inherits
the server's threads or database connections). The child lowers its address space (``RLIMIT_AS``) to
``Limits.worker_memory_bytes`` and its CPU time (``RLIMIT_CPU``) to ``Limits.worker_seconds`` before it
touches the bundle; the parent waits at most ``worker_seconds`` of wall-clock time and kills it after.

The child answers through a pipe with the function's value or its coded findings. A child that runs out
of memory (``MemoryError``), is killed (a signal: the kernel's ``SIGKILL``, ``SIGXCPU``, ``SIGSEGV``) or
overruns its time is E976 with what happened; the parent's memory never holds the bundle's data.
"""

from __future__ import annotations

import multiprocessing
import resource
import signal
import threading
import traceback
from typing import Any, Callable

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail
from haptify_tools.registry.bundle import Limits

PRELOAD = ["haptify_tools.registry.checks", "haptify.pipeline.compute", "haptify.formats.validation"]
_context_lock = threading.Lock()
_context: Any = None


def _forkserver():
    """The forkserver context (started on first use, modules of :data:`PRELOAD` imported once there)."""
    global _context
    with _context_lock:
        if _context is None:
            ctx = multiprocessing.get_context("forkserver")
            ctx.set_forkserver_preload(PRELOAD)
            _context = ctx
        return _context


def _child(conn, fn: Callable, args: tuple, memory_bytes: int, seconds: float) -> None:
    """The worker: limits first, then ``fn(*args)``; sends ``("ok", value)`` or ``("refused", findings)``."""
    try:
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
        cpu = max(1, int(seconds + 0.999))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
        try:
            answer = ("ok", fn(*args))
        except HaptifyError as err:
            answer = ("refused", list(err.findings))
        except MemoryError:
            answer = ("refused", [_limit_finding(f"ran out of its {memory_bytes} bytes of memory", "MemoryError")])
        except Exception as exc:  # a defect of the registry, reported as such and not as the bundle's fault
            answer = ("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=8)}")
        conn.send(answer)
    finally:
        conn.close()


def _limit_finding(what: str, found: str) -> Finding:
    return Finding(
        Code.BUNDLE_WORKER_LIMIT,
        f"checking the bundle {what}; it is refused and the registry goes on serving",
        file="<upload>",
        expected="a bundle the registry can check within its worker limits",
        found=found,
    )


def run_contained(fn: Callable, *args: Any, limits: Limits = Limits()) -> Any:
    """``fn(*args)`` in a worker process under ``limits.worker_memory_bytes`` and ``limits.worker_seconds``.

    Returns the value; raises the worker's coded findings, E976 when the worker ran out of memory or
    time or was killed, E999 when it failed on a defect. ``fn`` and its arguments and value must pickle.
    """
    ctx = _forkserver()
    receiver, sender = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(sender, fn, args, limits.worker_memory_bytes, limits.worker_seconds), daemon=True)
    proc.start()
    sender.close()
    try:
        if not receiver.poll(limits.worker_seconds):
            proc.kill()
            raise HaptifyError(_limit_finding(f"took longer than {limits.worker_seconds:g} s", "time limit"))
        try:
            kind, payload = receiver.recv()
        except (EOFError, OSError):
            proc.join(5)
            raise _died(proc.exitcode, limits) from None
    finally:
        receiver.close()
        proc.join(5)
        if proc.is_alive():
            proc.kill()
            proc.join()
    if kind == "ok":
        return payload
    if kind == "refused":
        raise HaptifyError(*payload)
    raise fail(Code.INTERNAL_ERROR, f"the bundle worker failed: {payload}")


def _died(exitcode: int | None, limits: Limits) -> HaptifyError:
    """E976 for a worker that ended without answering: by which signal, or with which exit status."""
    if exitcode is not None and exitcode < 0:
        sig = signal.Signals(-exitcode).name
        what = {
            "SIGXCPU": f"used more than {limits.worker_seconds:g} s of CPU time",
            "SIGKILL": "was killed (SIGKILL: the out-of-memory killer or the operator)",
        }.get(sig, f"was killed by {sig}")
        return HaptifyError(_limit_finding(what, sig))
    return HaptifyError(_limit_finding(f"ended without an answer (exit status {exitcode})", f"exit {exitcode}"))


__all__ = ["run_contained", "PRELOAD"]
