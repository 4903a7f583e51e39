"""The dynamics family's report figure (spec §11.7; paper Fig. 9): force error against kinematic distance."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.report.document import ReportFigure


def report_figures(ctx: ComputeContext, results: Any) -> list[ReportFigure]:
    """RMS force error of every 5 s segment against its kinematic distance to the training set, with
    the fitted line (paper Fig. 9; spec §11.7). Drawn from ``dynamics.error_vs_distance``'s diagnostics."""
    import matplotlib.pyplot as plt

    from haptify.report.document import ReportFigure

    metric = results.get("dynamics.error_vs_distance") if results is not None else None
    if metric is None:
        return []
    rows = metric.diagnostics.get("segments", [])
    slope, intercept = metric.value
    fig, ax = plt.subplots(figsize=(8, 5))
    for name in sorted({r["set"] for r in rows}, key=lambda s: (s != "training", s)):
        pts = [(r["distance"], r["force_error"]) for r in rows if r["set"] == name]
        distances, errors = zip(*pts)
        ax.scatter(distances, errors, s=14, label=name)
    d = np.array([0.0, max((r["distance"] for r in rows), default=1.0)])
    ax.plot(d, intercept + slope * d, "k-", lw=1, label=f"fit: {slope:.3g} N per unit distance + {intercept:.3g} N")
    ax.set_xlabel("kinematic distance to the training set (paper eq. 9, dimensionless)")
    ax.set_ylabel("RMS force error of the segment (N)")
    ax.legend(fontsize=8)
    return [
        ReportFigure(
            "dynamics_error_vs_distance",
            "Force prediction error of the local dynamic model against the "
            "kinematic distance of each 5 s segment (paper Fig. 9; spec chapter 11).",
            fig,
        )
    ]
