"""Stiffness rendering (spec chapter 13).

Repeated presses into the rendered stiff plane (paper §IV-F, §V-E): presses are the contact runs of
chapter 12's rule; each press contributes its rising-phase samples between two shares of its peak force
to one least-squares line of measured normal force against measured penetration per trial; the slope
is the measured stiffness, and each press's largest normal force its peak.
Parameters: ``schemas/<v>/metrics/stiffness.json`` (contact rule: ``surface.json``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from haptify.caching import cached
from haptify.errors import fail
from haptify.metric_definitions import param
from haptify.repetitions import TrialValue, aggregate, protocol_trials
from haptify.surface import contact_signals

FAMILY = "stiffness"
PROTOCOL = "stiffness"
IDS = ("stiffness.measured", "stiffness.accuracy", "stiffness.peak_force")


def stp(key: str) -> Any:
    """A parameter of the stiffness family (spec §13.1)."""
    return param(FAMILY, key)


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs ``[start, stop)`` of True in ``mask`` (sample indices; the runs of spec §13.2)."""
    edges = np.flatnonzero(np.diff(np.r_[0, np.asarray(mask, dtype=np.int8), 0]))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


@dataclass
class Press:
    """One qualifying press (spec §13.2): its sample range, peak normal force (N) and fit samples (indices)."""

    start: int
    stop: int
    peak_force: float
    max_penetration: float
    fit: np.ndarray


@dataclass
class StiffnessFit:
    """One trial's fit (spec §13.3): slope (N/m), intercept (N), the presses and the pooled fit samples."""

    stiffness: float
    intercept: float
    r2: float
    presses: list[Press]
    penetration: np.ndarray = field(repr=False)
    normal_force: np.ndarray = field(repr=False)

    @property
    def peak_force(self) -> float:
        """Mean of the presses' peak normal forces (spec §13.4), N."""
        return float(np.mean([p.peak_force for p in self.presses]))


def find_presses(t: np.ndarray, penetration: np.ndarray, normal_force: np.ndarray, contact: np.ndarray,
                 valid: np.ndarray | None = None) -> list[Press]:
    """Qualifying presses of a trial (spec §13.2).

    A press is a maximal run of ``contact`` samples lasting at least ``min_press_s`` and reaching a
    penetration of at least ``min_press_depth_m``. Its peak is the largest normal force in the run, at
    sample k*. Its fit samples are those from the run's start to k* (the rising phase) whose normal
    force lies within [fit_low_fraction, fit_high_fraction] × peak; a press with fewer than
    ``min_fit_samples`` of them does not qualify, nor does a run that starts right after samples that
    are not ``valid`` (the remainder of a press an occlusion interrupted: its plateau or release).
    """
    out = []
    for a, b in runs(contact):
        if valid is not None and a > 0 and not valid[a - 1]:
            continue
        if t[b - 1] - t[a] < float(stp("min_press_s")) - 1e-12:
            continue
        depth = float(np.max(penetration[a:b]))
        if depth < float(stp("min_press_depth_m")):
            continue
        k = a + int(np.argmax(normal_force[a:b]))
        peak = float(normal_force[k])
        if not peak > 0:
            continue
        rising = np.arange(a, k + 1)
        f = normal_force[rising]
        fit = rising[(f >= float(stp("fit_low_fraction")) * peak) & (f <= float(stp("fit_high_fraction")) * peak)]
        if len(fit) >= int(stp("min_fit_samples")):
            out.append(Press(a, b, peak, depth, fit))
    return out


def fit_stiffness(t: np.ndarray, penetration: np.ndarray, normal_force: np.ndarray, contact: np.ndarray, trial_id: str = "",
                  valid: np.ndarray | None = None) -> StiffnessFit:
    """Least-squares line normal_force = k · penetration + c through the fit samples of every press (spec §13.3).

    Inputs on one time grid: ``t`` (s), ``penetration`` (m), ``normal_force`` (N), ``contact`` (bool) and,
    when known, ``valid`` (bool: motion capture and force usable; §12.2).
    E315 when no press qualifies or the fit samples span no penetration.
    """
    presses = find_presses(t, penetration, normal_force, contact, valid)
    if not presses:
        raise fail("E315", f"trial {trial_id!r}: no press qualifies (>= {stp('min_press_s')} s of contact, "
                   f">= {stp('min_press_depth_m')} m deep, >= {stp('min_fit_samples')} rising samples)", expected="at least one press", found=0)
    idx = np.concatenate([p.fit for p in presses])
    x, y = penetration[idx], normal_force[idx]
    if float(np.ptp(x)) <= 0:
        raise fail("E315", f"trial {trial_id!r}: the fit samples do not span any penetration", expected="varying penetration", found=float(x[0]))
    a = np.column_stack([x, np.ones_like(x)])
    (k, c), *_ = np.linalg.lstsq(a, y, rcond=None)
    resid = y - (k * x + c)
    ss = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - float(np.sum(resid ** 2)) / ss if ss > 0 else 1.0
    return StiffnessFit(float(k), float(c), r2, presses, x, y)


def trial_fit(ctx: Any, trial_id: str) -> StiffnessFit:
    """:func:`fit_stiffness` on a stiffness trial's contact signals (spec §13.5); cached on a ComputeContext."""
    def build() -> StiffnessFit:
        cs = contact_signals(ctx, trial_id)  # contact is False wherever the sample is not valid
        return fit_stiffness(cs.t, cs.penetration, cs.normal_force, cs.contact, trial_id, cs.valid)

    return cached(ctx, ("stiffness_fit", trial_id), build)


def compute(ctx: Any) -> list:
    """stiffness.measured, stiffness.accuracy and stiffness.peak_force (spec §13.5)."""
    if not any(ctx.wants(m) for m in IDS):
        return []
    done, missing = protocol_trials(ctx, PROTOCOL, IDS, lambda tid: trial_fit(ctx, tid), "stiffness.measured")
    if missing:
        return missing
    codes: dict[str, list[str]] = {}
    for tid, f in done.items():
        codes[tid] = []
        if len(f.presses) < int(stp("recommended_presses")):
            codes[tid].append("W414")
            ctx.warn("W414", f"trial {tid!r}: {len(f.presses)} press(es) qualified, {stp('recommended_presses')} recommended",
                     metric="stiffness.measured", trial=tid)
    commanded = {tid: contact_signals(ctx, tid).stiffness_N_per_m for tid in done}
    diag = {"intercept_N": [f.intercept for f in done.values()], "r2": [f.r2 for f in done.values()],
            "presses": [len(f.presses) for f in done.values()], "commanded_N_per_m": list(commanded.values()),
            "press_peaks_N": [[p.peak_force for p in f.presses] for f in done.values()]}
    return [
        aggregate(FAMILY, "stiffness.measured", [TrialValue(t, f.stiffness, codes[t]) for t, f in done.items()], diagnostics=diag),
        aggregate(FAMILY, "stiffness.accuracy", [TrialValue(t, 100.0 * f.stiffness / commanded[t], codes[t]) for t, f in done.items()]),
        aggregate(FAMILY, "stiffness.peak_force", [TrialValue(t, f.peak_force, codes[t]) for t, f in done.items()]),
    ]


# --- report figures (spec §15.6; paper Fig. 11) ---------------------------------------------------

def report_figures(ctx: Any, results: Any) -> list:
    """Normal force against penetration for every stiffness trial, fit samples marked, fitted and commanded
    lines (paper Fig. 11)."""
    import matplotlib.pyplot as plt

    from haptify.errors import HaptifyError
    from haptify.report import ReportFigure

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
    return [ReportFigure("stiffness", "Normal force against penetration; black: the samples of the fit "
                                      "(paper Fig. 11; spec chapter 13).", fig)]
