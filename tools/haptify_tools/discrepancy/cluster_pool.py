"""The candidate search's simulations on a Dask cluster (spec §17.9): :class:`ClusterPool` stands where
:func:`.identify.process_pool` stands, with the same ``submit``; imported only when a client is given."""

from __future__ import annotations

import uuid

from distributed import WorkerPlugin

from haptify_tools.discrepancy.data import _WORKER_TRIALS, MeasuredTrial, share_trials


class SharedTrials(WorkerPlugin):
    """Runs :func:`.data.share_trials` on each worker when it joins: the cluster's counterpart of the process
    pool's initializer."""

    def __init__(self, trials: list[MeasuredTrial]) -> None:
        self.trials = trials

    def setup(self, worker) -> None:
        share_trials(self.trials)

    def teardown(self, worker) -> None:
        _WORKER_TRIALS.clear()


class ClusterPool:
    """The (twin, trial) simulations of :func:`.data.simulate_many` as tasks of a Dask cluster: the trials go to
    every worker once (:class:`SharedTrials`; a worker joining later gets them too), so a task names its trial by
    id, as with the process pool. One search at a time per cluster: the workers hold one set of trials."""

    def __init__(self, client, trials: list[MeasuredTrial]) -> None:
        self.client = client
        self.name = f"haptify-discrepancy-trials-{uuid.uuid4().hex}"
        client.register_plugin(SharedTrials(trials), name=self.name)

    def submit(self, fn, *args):
        return self.client.submit(fn, *args, pure=False)

    def __enter__(self) -> "ClusterPool":
        return self

    def __exit__(self, *exc) -> None:
        self.client.unregister_worker_plugin(self.name)
