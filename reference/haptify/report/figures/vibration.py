"""The vibration family's report figures (spec §15.6), drawn from its computation in :mod:`haptify.metrics.vibration`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from haptify.errors import HaptifyError

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.report.document import ReportAudio, ReportFigure
from haptify.metrics.vibration import GROUPS, CombinedVibration, power_spectrum, trial_vibration


def report_trials(ctx: ComputeContext) -> list[CombinedVibration]:
    """Every vibration trial of the session combined (spec §10.3), skipping those that cannot be read."""
    out = []
    for protocol in GROUPS:
        for trial in ctx.session.trials_of(protocol):
            try:
                out.append(trial_vibration(ctx, trial.id))
            except HaptifyError:
                continue
    return out


def report_figures(ctx: ComputeContext, results: Any) -> list[ReportFigure]:
    """The combined vibration signal with ±RMS, and its power spectrum with the centroid (paper Fig. 7)."""
    import matplotlib.pyplot as plt

    from haptify.report.document import ReportFigure

    figures = []
    for v in report_trials(ctx):
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 6))
        ax1.plot(v.t, v.signal, lw=0.4)
        for sign in (1, -1):
            ax1.axhline(sign * v.rms, color="r", lw=0.8)
        ax1.set_xlabel("t (s)")
        ax1.set_ylabel("DFT321 acceleration (m/s²)")
        ax1.set_title(f"{v.trial_id}: RMS {v.rms:.4g} m/s², centroid {v.centroid:.4g} Hz")
        f, p = power_spectrum(v.signal, v.rate_hz)
        ax2.semilogy(f[1:], p[1:] + 1e-30, lw=0.4)
        ax2.axvline(v.centroid, color="r", lw=0.8)
        ax2.set_xlabel("frequency (Hz)")
        ax2.set_ylabel("power (periodogram, arbitrary units)")
        figures.append(
            ReportFigure(
                f"vibration_{v.trial_id}",
                f"Combined (DFT321) vibration of {v.trial_id} with its RMS "
                "and spectral centroid (paper Fig. 7; spec chapter 10).",
                fig,
            )
        )
    return figures


def report_audio(ctx: ComputeContext) -> list[ReportAudio]:
    """Each trial's combined vibration signal, for the report's WAV files (paper §VI-C)."""
    from haptify.report.document import ReportAudio

    return [
        ReportAudio(f"vibration_{v.trial_id}", f"Combined vibration of {v.trial_id}", v.signal, v.rate_hz)
        for v in report_trials(ctx)
    ]
