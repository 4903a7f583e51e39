"""Computing every metric a session allows (spec §15.4).

Each family's module (:mod:`haptify.pipeline.families`) receives a :class:`~haptify.pipeline.context.ComputeContext`. Work shared between
families (calibrated handle signals, plate wrenches) is cached on the context, so it is done once per trial.
"""

from __future__ import annotations

import importlib
from typing import Callable, Iterable

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError
from haptify.formats.storage import MANIFEST, SessionFolder, sha256_file
from haptify.metrics.metric_definitions import all_families
from haptify.pipeline.context import ComputeContext as ComputeContext
from haptify.pipeline.families import family_modules
from haptify.pipeline.gate import CheckedSession
from haptify.pipeline.results import DeviceSummary, Implementation, MetricResult, ResultsFile
from haptify.versions import PACKAGE_VERSION


def compute_session(
    session: SessionFolder,
    metrics: Iterable[str] | None = None,
    progress: Callable[[int], None] | None = None,
    ctx: ComputeContext | None = None,
    uncertainty: bool = False,
) -> ResultsFile:
    """Compute every metric (or those in ``metrics``) that the session's trials allow (spec §15.4).

    A session opened through the gate (spec §4.8) that one of a family's reads refused raises
    :class:`~haptify.pipeline.gate.SessionRefused` once that family ends: the families catch a trial's coded
    error to mark its metrics unavailable, and no later family is computed for a refused session.

    Pass ``ctx`` to share its cache with later work on the same session (the report's figures; a context
    made with ``keep=False``, as one made here, drops a trial's entries once no family still to run reads
    its protocol). With
    ``uncertainty`` (or the case parameter ``{"uncertainty": true}``, §16.2), every metric whose method
    applies gets its uncertainty record (spec chapter 19), propagated through the context's cached intermediates.
    """
    wanted = set(metrics) if metrics else None
    definitions = {f.family: f for f in all_families()}
    known = {m.id for f in definitions.values() for m in f.metrics}
    if wanted and not wanted <= known:
        unknown = sorted(wanted - known)
        raise HaptifyError(Finding(Code.USAGE, f"unknown metric id(s) {unknown}", expected=sorted(known), found=unknown))
    ctx = ctx or ComputeContext(session=session, keep=False)
    ctx.wanted = wanted
    device = session.device()
    out = ResultsFile(
        implementation=Implementation(name="haptify-reference", version=PACKAGE_VERSION),
        session_id=session.session_id,
        device=DeviceSummary(manufacturer=device.manufacturer, model=device.model, serial=device.serial),
        manifest_sha256=sha256_file(session.root / MANIFEST),
    )
    runs = [
        (family, module_name)
        for family, module_name in family_modules()
        if wanted is None or {m.id for m in definitions[family].metrics} & wanted
    ]
    reads = {family: {p for m in definitions[family].metrics for p in m.protocols} for family, _ in runs}
    with_uncertainty = uncertainty or ctx.parameters.get("uncertainty") is True
    release = not ctx.keep and not with_uncertainty  # the uncertainty pass re-reads the whole cache
    for k, (family, module_name) in enumerate(runs):
        module = importlib.import_module(module_name)
        for item in module.compute(ctx):
            if not ctx.wants(item.id):
                continue
            (out.metrics if isinstance(item, MetricResult) else out.unavailable).append(item)
        if isinstance(session, CheckedSession):  # a stream the family read refused the session: compute no more
            session.refuse_on_errors()
        if release:
            _forget_finished_trials(ctx, set().union(*(reads[later] for later, _ in runs[k + 1 :])))
        if progress:
            progress(1)
    out.warnings = ctx.warnings
    if with_uncertainty:
        from haptify.metrics.uncertainty import attach

        attach(ctx, out)
        ctx.wanted = wanted
    return out


def _forget_finished_trials(ctx: ComputeContext, protocols_still_read: set[str]) -> None:
    """Drop what the run memoised for the trials of protocols no family still to run reads (spec §15.4):
    their processed signals would otherwise stay in memory until the end. Session-wide entries (the
    calibration, the plate bias) stay."""
    for trial in ctx.session.manifest.trials:
        if trial.protocol not in protocols_still_read:
            ctx.forget_trial(trial.id)
