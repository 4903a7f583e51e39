"""The surface family's report figures (spec §15.6), drawn from its computation in :mod:`haptify.metrics.surface`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.report.document import ReportFigure
from haptify.metrics.surface import PROTOCOL, contact_signals, planar_force

# --- report figures (spec §15.6; paper Fig. 10) ---------------------------------------------------


def report_figures(ctx: ComputeContext, results: Any) -> list[ReportFigure]:
    """Planar force magnitude over the contact positions of each surface trial, top view (paper Fig. 10)."""
    import matplotlib.pyplot as plt

    from haptify.errors import HaptifyError
    from haptify.report.document import ReportFigure

    figures = []
    for trial in ctx.session.trials_of(PROTOCOL):
        try:
            cs = contact_signals(ctx, trial.id)
        except HaptifyError:
            continue
        if not cs.used.any():
            continue
        p = cs.position[cs.used]
        mag = np.linalg.norm(planar_force(cs.force[cs.used], cs.normal), axis=1)
        fig, ax = plt.subplots(figsize=(7, 6))
        sc = ax.scatter(p[:, 0], p[:, 1], c=mag, s=4, cmap="viridis")
        fig.colorbar(sc, ax=ax, label="|planar force| (N)")
        ax.set_xlabel("x (m, W)")
        ax.set_ylabel("y (m, W)")
        ax.set_aspect("equal")
        ax.set_title(f"{trial.id}: mean {mag.mean():.3g} N")
        figures.append(
            ReportFigure(
                f"surface_{trial.id}",
                f"Planar force on the hand while in contact, trial {trial.id} (paper Fig. 10; spec chapter 12).",
                fig,
            )
        )
    return figures
