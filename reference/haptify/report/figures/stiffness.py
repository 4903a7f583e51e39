"""The stiffness family's report figures (spec §15.6), drawn from its computation in :mod:`haptify.metrics.stiffness`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from haptify.metrics.surface import contact_signals

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.report.document import ReportFigure
from haptify.metrics.stiffness import PROTOCOL, trial_fit

# --- report figures (spec §15.6; paper Fig. 11) ---------------------------------------------------


def report_figures(ctx: ComputeContext, results: Any) -> list[ReportFigure]:
    """Normal force against penetration for every stiffness trial, fit samples marked, fitted and commanded
    lines (paper Fig. 11)."""
    import matplotlib.pyplot as plt

    from haptify.errors import HaptifyError
    from haptify.report.document import ReportFigure

    trials = []
    for trial in ctx.session.trials_of(PROTOCOL):
        try:
            trials.append((trial.id, contact_signals(ctx, trial.id), trial_fit(ctx, trial.id)))
        except HaptifyError:
            continue
    if not trials:
        return []
    fig, ax = plt.subplots(figsize=(8, 6))
    top = 1.3 * max(max(p.peak_force for p in fit.presses) for _, _, fit in trials)
    for tid, cs, fit in trials:
        m = cs.valid & cs.contact
        ax.scatter(1000 * cs.penetration[m], cs.normal_force[m], s=2, alpha=0.4, label=f"{tid}")
        ax.scatter(1000 * fit.penetration, fit.normal_force, s=3, color="k")
        d = np.linspace(0.0, (top - fit.intercept) / fit.stiffness if fit.stiffness > 0 else 0.0, 20)
        ax.plot(1000 * d, fit.stiffness * d + fit.intercept, lw=1, label=f"{tid} fit: {fit.stiffness / 1000:.3g} N/mm")
    k_cmd = trials[0][1].stiffness_N_per_m
    d = np.linspace(0.0, top / k_cmd, 20)
    ax.plot(1000 * d, k_cmd * d, "r--", lw=1, label=f"commanded {k_cmd / 1000:.3g} N/mm")
    ax.set_ylim(top=top)
    ax.set_xlabel("penetration (mm)")
    ax.set_ylabel("normal force on the hand (N)")
    ax.legend(fontsize=8, loc="upper left")
    return [
        ReportFigure(
            "stiffness", "Normal force against penetration; black: the samples of the fit (paper Fig. 11; spec chapter 13).", fig
        )
    ]
