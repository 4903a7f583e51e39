"""A Dask cluster started as separate commands, as one is on real machines: ``dask scheduler`` and ``dask worker
tcp://…`` subprocesses on loopback ports (spec §17.9). For the tests and benchmarks/bench_reverify.py."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from _registry_fixtures import free_port

ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@dataclass
class SeparateCluster:
    """The scheduler's address and the worker processes by worker address."""

    address: str
    scheduler: subprocess.Popen
    workers: dict[str, subprocess.Popen] = field(default_factory=dict)

    def kill_worker(self, address: str) -> None:
        """SIGKILL one worker process (no nanny restarts it): the scheduler sees its connection drop."""
        proc = self.workers.pop(address)
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)


def _dask(*args: str, log: Path) -> subprocess.Popen:
    env = {**os.environ, **ONE_THREAD}
    return subprocess.Popen(
        [sys.executable, "-m", "dask", *args], stdout=subprocess.DEVNULL, stderr=open(log, "wb"), env=env, start_new_session=True
    )


@contextlib.contextmanager
def separate_cluster(n_workers: int, logs: Path, timeout: float = 120.0):
    """``dask scheduler`` and ``n_workers`` × ``dask worker --nthreads 1 --no-nanny``, each its own process;
    yields a :class:`SeparateCluster` once every worker has joined; stops them all after."""
    from distributed import Client

    logs.mkdir(parents=True, exist_ok=True)
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = _dask("scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard", log=logs / "scheduler.log")
    cluster = SeparateCluster(address, scheduler)
    try:
        for i in range(n_workers):
            wport = free_port()
            cluster.workers[f"tcp://127.0.0.1:{wport}"] = _dask(
                "worker",
                address,
                "--host",
                "127.0.0.1",
                "--worker-port",
                str(wport),
                "--nthreads",
                "1",
                "--no-nanny",
                "--no-dashboard",
                "--name",
                f"w{i}",
                "--death-timeout",
                "60",
                log=logs / f"worker{i}.log",
            )
        deadline = time.monotonic() + timeout
        with Client(address, timeout=timeout) as client:
            client.wait_for_workers(n_workers, timeout=max(1.0, deadline - time.monotonic()))
        yield cluster
    finally:
        for proc in [*cluster.workers.values(), scheduler]:
            if proc.poll() is None:
                proc.terminate()
        for proc in [*cluster.workers.values(), scheduler]:
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
