"""The executor for work that outgrows one process: Dask's distributed scheduler (spec §17.9).

Three ways to run the same tasks, chosen by the commands' ``--workers N`` / ``--scheduler ADDRESS``:

* ``--workers 0``: in this process, one after another (the serial reference the others must equal);
* ``--workers N`` (N ≥ 1): a ``LocalCluster`` of N worker processes, one thread each, started and stopped
  with the command;
* ``--scheduler tcp://host:8786``: an existing cluster (``dask scheduler`` on one machine, ``dask worker
  tcp://host:8786`` on each of the others), which the command only connects to.

Tasks are plain module-level functions of picklable arguments, submitted with an explicit key (the same
task twice is one task) and ``retries``: a task whose worker dies is re-run on another worker by the
scheduler, a task that raised is re-run ``retries`` times. :func:`each_completed` yields results in the
order they complete, so the caller — the one process that writes records — writes each as it arrives.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator

from haptify.codes import Code
from haptify.errors import fail

RETRIES = 3  # re-runs of a task that raised (a dead worker's tasks are re-run by the scheduler)
CONNECT_TIMEOUT_S = 20.0  # how long to wait for an existing scheduler


def add_executor_options(p, *, default_workers: int = 2) -> None:
    """``--workers N`` and ``--scheduler ADDRESS`` (mutually exclusive) on the parser ``p``."""
    group = p.add_mutually_exclusive_group()
    group.add_argument(
        "--workers",
        type=int,
        default=default_workers,
        metavar="N",
        help=f"worker processes of a local Dask cluster (default {default_workers}; 0: in this process, serially)",
    )
    group.add_argument(
        "--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, e.g. tcp://host:8786 (started with `dask scheduler`)"
    )


def describe(scheduler: str | None, workers: int) -> str:
    """How the tasks run, in words (recorded with a re-verification run)."""
    if scheduler:
        return f"dask scheduler {scheduler}"
    return "serial" if workers == 0 else f"dask LocalCluster, {workers} worker process{'es' if workers != 1 else ''}"


@contextmanager
def dask_client(scheduler: str | None = None, workers: int = 2) -> Iterator[Any]:
    """A ``distributed.Client``: of the cluster at ``scheduler``, else of a new ``LocalCluster`` with ``workers``
    processes (one thread each); ``None`` for ``workers == 0`` (serial). E980 when the scheduler does not answer."""
    if scheduler is None and workers == 0:
        yield None
        return
    if workers < 0:
        raise fail(Code.USAGE, "--workers must be 0 or more", expected=">= 0", found=workers)
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise fail(
                Code.CLUSTER_UNAVAILABLE,
                f"the Dask scheduler at {scheduler!r} does not answer: {exc}",
                expected="a running `dask scheduler`",
                found=scheduler,
            ) from None
        try:
            yield client
        finally:
            client.close()
        return
    with (
        LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            scheduler_port=0,
            silence_logs=logging.ERROR,
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


@dataclass
class Done:
    """One finished task: its key, and its value or the error it ended with after its retries."""

    key: str
    value: Any = None
    error: BaseException | None = None


def each_completed(client, fn: Callable, jobs: Iterable[tuple[str, tuple]], *, retries: int = RETRIES) -> Iterator[Done]:
    """``fn(*args)`` for every ``(key, args)`` of ``jobs``, yielded as each completes: serially in this process
    when ``client`` is None, else on the client's cluster (every job submitted at once, with ``retries``)."""
    if client is None:
        for key, args in jobs:
            try:
                yield Done(key, fn(*args))
            except Exception as exc:  # reported by the caller like a task that failed on a cluster
                yield Done(key, error=exc)
        return
    from distributed import as_completed

    futures = {client.submit(fn, *args, key=key, retries=retries, pure=False): key for key, args in jobs}
    for future in as_completed(futures):
        try:
            yield Done(futures[future], future.result())
        except Exception as exc:
            yield Done(futures[future], error=exc)
        finally:
            future.release()


def worker_name() -> str:
    """The address of the Dask worker running the caller, or ``"serial"`` outside a worker."""
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return "serial"
