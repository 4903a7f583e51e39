"""The workspace family's report figures (spec §15.6), drawn from its computation in :mod:`haptify.metrics.workspace`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from haptify.errors import HaptifyError
from haptify.metrics.volume_operator import VoxelSolid as VoxelSolid
from haptify.metrics.volume_operator import overlap_volume as overlap_volume
from haptify.metrics.volume_operator import volume_solid as volume_solid

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.report.document import ReportFigure
from haptify.metrics.workspace import PROTOCOL, measured_points, modeled_solid

# --- report figures (spec §15.6; paper Fig. 5) ----------------------------------------------------


def report_figures(ctx: ComputeContext, results: Any) -> list[ReportFigure]:
    """Measured gimbal-centre clouds over the modeled workspace, side (x–z) and top (x–y) views (paper Fig. 5)."""
    import matplotlib.pyplot as plt

    from haptify.report.document import ReportFigure

    session = ctx.session
    device = session.device()
    clouds = {}
    for trial in session.trials_of(PROTOCOL):
        try:
            clouds[trial.id] = measured_points(session, trial.id)
        except HaptifyError:
            continue
    model = None
    kinematics = device.kinematics
    if kinematics is not None:
        placement = session.manifest.device_placement
        try:
            model = ctx.cached(("workspace_model",), lambda: modeled_solid(kinematics, placement.position, placement.quaternion))
        except HaptifyError:
            model = None
    if not clouds and model is None:
        return []
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    for ax, (i, j), title in zip(axes, ((0, 2), (0, 1)), ("side view (x–z)", "top view (x–y)")):
        if model is not None:
            c = model.centres()
            ax.scatter(c[:, i], c[:, j], s=1, c="0.85", label="modeled", rasterized=True)
        for tid, p in clouds.items():
            ax.scatter(p[:, i], p[:, j], s=1, label=f"measured {tid}", rasterized=True)
        ax.set_xlabel("xyz"[i] + " (m, W)")
        ax.set_ylabel("xyz"[j] + " (m, W)")
        ax.set_aspect("equal")
        ax.set_title(title)
    axes[0].legend(markerscale=8, fontsize=8, loc="upper right")
    return [
        ReportFigure(
            "workspace",
            "Measured gimbal-centre positions of the workspace trials over the modeled workspace (paper Fig. 5; spec chapter 8).",
            fig,
        )
    ]
