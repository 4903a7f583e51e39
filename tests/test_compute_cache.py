"""What a compute run memoises (spec §15.4): a context that keeps (the report's) holds every trial's processed
signals to the end; one that does not (``haptify compute``'s) drops a trial's entries as soon as no family
still to run reads its protocol — with the same results."""

from __future__ import annotations

from pathlib import Path

from haptify.formats.storage import open_session
from haptify.metrics.metric_definitions import all_families
from haptify.pipeline.compute import compute_session
from haptify.pipeline.context import ComputeContext
from haptify.pipeline.families import family_modules
from haptify_tools.example_session import example_writer


def _trial_keys(ctx: ComputeContext, trial_id: str) -> list[tuple]:
    return [k for k in ctx._cache if isinstance(k, tuple) and trial_id in k[1:]]


def test_a_trial_is_forgotten_after_the_last_family_that_reads_its_protocol_and_results_are_the_same(tmp_path: Path):
    session = open_session(example_writer(duration_s=3.0).write(tmp_path / "s"))
    (trial,) = session.manifest.trials
    order = [family for family, _ in family_modules()]
    protocols = {f.family: {p for m in f.metrics for p in m.protocols} for f in all_families()}
    last_reader = max(k for k, family in enumerate(order) if trial.protocol in protocols[family])
    assert sum(trial.protocol in protocols[f] for f in order) >= 2  # free space: its own family and vibration

    kept = ComputeContext(session=session)
    with_cache = compute_session(session, ctx=kept)
    assert _trial_keys(kept, trial.id)  # the report's figures read these after the run

    released = ComputeContext(session=session, keep=False)
    families_done = [0]
    forgotten_after: list[int] = []
    forget = released.forget_trial

    def spy(trial_id: str) -> None:
        if _trial_keys(released, trial_id):
            forgotten_after.append(families_done[0])
        forget(trial_id)

    released.forget_trial = spy  # type: ignore[method-assign]
    without = compute_session(session, ctx=released, progress=lambda n: families_done.__setitem__(0, families_done[0] + n))
    assert forgotten_after == [last_reader]  # dropped once, before the progress tick of the last family reading it
    assert not _trial_keys(released, trial.id)
    assert set(released._cache) <= set(kept._cache)  # session-wide entries (calibration, plate bias) stay
    assert without.model_dump() == with_cache.model_dump()


def test_the_uncertainty_pass_keeps_the_cache_it_propagates_through(tmp_path: Path):
    session = open_session(example_writer(duration_s=3.0).write(tmp_path / "s"))
    (trial,) = session.manifest.trials
    ctx = ComputeContext(session=session, keep=False)
    compute_session(session, ["free_space.force_mean"], ctx=ctx, uncertainty=True)
    assert _trial_keys(ctx, trial.id)
