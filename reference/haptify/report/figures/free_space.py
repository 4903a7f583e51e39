"""The free space family's report figures (spec §15.6), drawn from its computation in :mod:`haptify.metrics.free_space`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from haptify.errors import HaptifyError
from haptify.metrics import free_space
from haptify.processing.preprocessing import mocap_track
from haptify.processing.signals import handle_signals

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.report.document import ReportFigure
from haptify.metrics.free_space import PROTOCOL, plate_force_about_weight, plate_force_samples

# --- report figures (spec §15.6; paper Fig. 6) ----------------------------------------------------


def report_figures(ctx: ComputeContext, results: Any) -> list[ReportFigure]:
    """Speeds and forces over time for the first usable free-space trial, and the force field (top view).
    Spec §9.2–9.5, §15.6."""
    import matplotlib.pyplot as plt

    from haptify.report.document import ReportFigure

    figures = []
    for trial in ctx.session.trials_of(PROTOCOL):
        try:
            hs = handle_signals(ctx, trial.id)
            track = mocap_track(ctx, trial.id)
        except HaptifyError:
            continue
        fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
        axes[0].plot(track.t, np.linalg.norm(track.velocity, axis=1))
        axes[0].axhline(free_space.PARAMETERS.speed_limit_m_per_s, color="r", ls="--", lw=0.8)
        axes[0].set_ylabel("speed (m/s)")
        axes[1].plot(track.t, np.degrees(np.linalg.norm(track.angular_velocity, axis=1)))
        axes[1].axhline(np.degrees(free_space.PARAMETERS.angular_speed_limit_rad_per_s), color="r", ls="--", lw=0.8)
        axes[1].set_ylabel("angular speed (°/s)")
        if hs.force is not None:
            axes[2].plot(hs.t, np.linalg.norm(hs.force, axis=1), label="hand |F|")
        try:
            t_plate, p = plate_force_samples(ctx, trial.id)
            axes[2].plot(t_plate, np.linalg.norm(plate_force_about_weight(p), axis=1), label="plate |P − mean P_z|", alpha=0.7)
        except HaptifyError:
            pass
        axes[2].set_ylabel("force (N)")
        axes[2].set_xlabel("t (s)")
        axes[2].legend(fontsize=8, loc="upper right")
        figures.append(
            ReportFigure(
                f"free_space_{trial.id}", f"Speeds and forces in free-space trial {trial.id} (paper Fig. 6; spec §9.2–9.4).", fig
            )
        )
        break
    record = results.get("free_space.force_mean") if results is not None else None
    bins = record.diagnostics.get("force_field", {}).get("bins", []) if record is not None else []
    if bins:
        c = np.array([b["centre_m"] for b in bins])
        f = np.array([b["mean_force_N"] for b in bins])
        fig, ax = plt.subplots(figsize=(7, 6))
        q = ax.quiver(c[:, 0], c[:, 1], f[:, 0], f[:, 1], np.linalg.norm(f, axis=1), cmap="viridis")
        fig.colorbar(q, ax=ax, label="|mean F| (N)")
        ax.set_xlabel("x (m, W)")
        ax.set_ylabel("y (m, W)")
        ax.set_aspect("equal")
        figures.append(
            ReportFigure(
                "free_space_force_field",
                "Free-space force field: mean force on the hand per "
                f"{free_space.PARAMETERS.force_field_bin_m * 100:g} cm bin, top view (spec §9.5).",
                fig,
            )
        )
    return figures
