"""Stiffness rendering (spec chapter 13).

Repeated presses into the rendered stiff plane (paper §IV-F, §V-E): presses are the contact runs of
chapter 12's rule. Each press is read on its loading stroke only (onset to deepest penetration): its
first samples (the contact transient) are set aside, its rise ends where the force stops rising, and the
samples of the rise up to a share of it enter one least-squares line of measured normal
force against measured penetration per trial. The slope is the measured stiffness, each press's largest
settled loading force its peak. Parameters: ``schemas/<v>/metrics/stiffness.json`` (contact rule:
``surface.json``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from haptify.codes import Code
from haptify.errors import fail
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters
from haptify.metrics.surface import contact_signals
from haptify.pipeline.repetitions import TrialValue, aggregate, protocol_trials
from haptify.processing.caching import cached

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.pipeline.results import MetricResult, Unavailable

FAMILY = "stiffness"
PROTOCOL = "stiffness"
IDS = ("stiffness.measured", "stiffness.accuracy", "stiffness.peak_force")


class StiffnessParameters(FamilyParameters):
    """The parameters of ``metrics/stiffness.json`` (spec chapter 13), in the units its definition file states."""

    min_press_s: float
    min_press_depth_m: float
    contact_settle_s: float
    rise_hold_s: float
    fit_high_fraction: float
    min_fit_samples: int
    recommended_presses: int


#: The stiffness family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = load_parameters(FAMILY, StiffnessParameters)


@dataclass(frozen=True)
class FitRule:
    """The press and fit parameters of spec §13.1 on a grid of ``rate_hz``: durations as whole grid samples.

    ``settle`` and ``hold`` are ``round(contact_settle_s · rate_hz)`` and ``round(rise_hold_s · rate_hz)``
    samples (round half to even, spec §13.2); ``high`` the share of the rise the fit stops at;
    ``min_samples`` the fewest fit samples of a qualifying press.
    """

    min_press_s: float
    min_press_depth_m: float
    settle: int
    hold: int
    high: float
    min_samples: int

    @classmethod
    def at_rate(cls, rate_hz: float) -> "FitRule":
        """The rule of the definition file on a grid of ``rate_hz`` (Hz)."""
        return cls(
            min_press_s=PARAMETERS.min_press_s,
            min_press_depth_m=PARAMETERS.min_press_depth_m,
            settle=round(PARAMETERS.contact_settle_s * rate_hz),
            hold=round(PARAMETERS.rise_hold_s * rate_hz),
            high=PARAMETERS.fit_high_fraction,
            min_samples=PARAMETERS.min_fit_samples,
        )


def grid_rate(t: np.ndarray) -> float:
    """The grid's rate (Hz): one over the median sample interval of ``t`` (s); spec §7.3."""
    dt = np.diff(np.asarray(t, dtype=float))
    return 1.0 / float(np.median(dt)) if len(dt) and np.median(dt) > 0 else 1.0


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs ``[start, stop)`` of True in ``mask`` (sample indices; the runs of spec §13.2)."""
    edges = np.flatnonzero(np.diff(np.r_[0, np.asarray(mask, dtype=np.int8), 0]))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def end_of_rise(force: np.ndarray, hold: int) -> int:
    """Index into ``force`` (a settled loading phase, N) of the first sample that none of the next ``hold``
    samples exceeds — where the force stops rising (spec §13.2). The last sample always qualifies."""
    f = np.asarray(force, dtype=float)
    if hold < 1:
        return 0
    ahead = sliding_window_view(np.r_[f[1:], np.full(hold, -np.inf)], hold)[: len(f)]
    return int(np.argmax(f >= ahead.max(axis=1)))


@dataclass
class Press:
    """One press (spec §13.2): grid samples ``[start, stop)``, its deepest sample, its first settled sample
    and the end of its rise (indices), the normal force at the first settled sample, its peak and the force
    at the deepest sample (N), its largest penetration (m), its fit samples (indices) and its contact
    overshoot (N, §13.4; set once the trial's line is known)."""

    start: int
    stop: int
    deepest: int
    settled: int
    rise_end: int
    settled_force: float
    peak_force: float
    deepest_force: float
    max_penetration: float
    fit: np.ndarray
    overshoot: float = 0.0

    def qualifies(self, rule: FitRule) -> bool:
        """At least ``min_fit_samples`` fit samples (spec §13.2)."""
        return len(self.fit) >= rule.min_samples


def press_of(t: np.ndarray, penetration: np.ndarray, normal_force: np.ndarray, a: int, b: int, rule: FitRule) -> Press | None:
    """The press of contact run ``[a, b)`` (spec §13.2), or None when the run is too short or too shallow.

    Loading phase ``a … m`` (m: first sample of the largest penetration); contact transient ``a … s − 1``
    with ``s = a + settle``; peak f* = the largest force of ``s … m``; end of the rise r (:func:`end_of_rise`
    on ``s … m``); fit samples: those of ``s … r`` with ``f_s ≤ f ≤ f_s + high·(f_r − f_s)``. A press whose
    loading phase ends inside its contact transient, or whose force does not rise, has no fit samples.
    """
    if t[b - 1] - t[a] < rule.min_press_s - 1e-12:
        return None
    d, f = penetration, normal_force
    depth = float(np.max(d[a:b]))
    if depth < rule.min_press_depth_m:
        return None
    m = a + int(np.argmax(d[a:b]))
    s = a + rule.settle
    if s > m:
        return Press(a, b, m, s, m, float("nan"), float("nan"), float(f[m]), depth, np.empty(0, dtype=int))
    r = s + end_of_rise(f[s : m + 1], rule.hold)
    f_s = float(f[s])
    rise = float(f[r]) - f_s
    rising = np.arange(s, r + 1)
    fit = rising[(f[rising] >= f_s) & (f[rising] <= f_s + rule.high * rise)] if rise > 0 else rising[:0]
    return Press(a, b, m, s, r, f_s, float(np.max(f[s : m + 1])), float(f[m]), depth, fit)


def find_presses(
    t: np.ndarray,
    penetration: np.ndarray,
    normal_force: np.ndarray,
    contact: np.ndarray,
    valid: np.ndarray | None = None,
    rule: FitRule | None = None,
) -> list[Press]:
    """Every press of a trial, qualifying or not (spec §13.2).

    A press is a maximal run of ``contact`` samples lasting at least ``min_press_s`` and reaching a
    penetration of at least ``min_press_depth_m`` (:func:`press_of`); a run that starts right after
    samples that are not ``valid`` is the remainder of a press an occlusion interrupted and is no press.
    """
    rule = rule or FitRule.at_rate(grid_rate(t))
    out = []
    for a, b in runs(contact):
        if valid is not None and a > 0 and not valid[a - 1]:
            continue
        p = press_of(t, penetration, normal_force, a, b, rule)
        if p is not None:
            out.append(p)
    return out


def contact_overshoot(press: Press, penetration: np.ndarray, normal_force: np.ndarray, k: float, c: float) -> float:
    """How far (N) the normal force rises above the trial's line ``k·d + c`` during the press's contact
    transient (its first ``settle`` samples, up to its deepest sample); 0 when it stays below (spec §13.4)."""
    i = np.arange(press.start, min(press.settled, press.deepest + 1))
    if len(i) == 0:
        return 0.0
    return max(0.0, float(np.max(normal_force[i] - (k * penetration[i] + c))))


@dataclass
class StiffnessFit:
    """One trial's fit (spec §13.3): slope (N/m), intercept (N), r², the qualifying presses, the presses with
    too few fit samples (W415) and the pooled fit samples."""

    stiffness: float
    intercept: float
    r2: float
    presses: list[Press]
    thin: list[Press]
    penetration: np.ndarray = field(repr=False)
    normal_force: np.ndarray = field(repr=False)

    @property
    def peak_force(self) -> float:
        """Mean of the qualifying presses' peaks (spec §13.4), N."""
        return float(np.mean([p.peak_force for p in self.presses]))


def least_squares_line(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Ordinary least-squares line ``y = k·x + c``: (k, c, r²) (spec §13.3)."""
    a = np.column_stack([x, np.ones_like(x)])
    (k, c), *_ = np.linalg.lstsq(a, y, rcond=None)
    ss = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - float(np.sum((y - (k * x + c)) ** 2)) / ss if ss > 0 else 1.0
    return float(k), float(c), r2


def fit_stiffness(
    t: np.ndarray,
    penetration: np.ndarray,
    normal_force: np.ndarray,
    contact: np.ndarray,
    trial_id: str = "",
    valid: np.ndarray | None = None,
    rule: FitRule | None = None,
) -> StiffnessFit:
    """Least-squares line normal_force = k · penetration + c through the fit samples of every qualifying
    press (spec §13.3), and each press's contact overshoot above that line (§13.4).

    Inputs on one time grid: ``t`` (s), ``penetration`` (m), ``normal_force`` (N), ``contact`` (bool) and,
    when known, ``valid`` (bool: motion capture and force usable; §12.2). ``rule`` defaults to the
    definition file's parameters at the grid's rate. E315 when no press qualifies or the fit samples span
    no penetration.
    """
    rule = rule or FitRule.at_rate(grid_rate(t))
    found = find_presses(t, penetration, normal_force, contact, valid, rule)
    presses = [p for p in found if p.qualifies(rule)]
    thin = [p for p in found if not p.qualifies(rule)]
    if not presses:
        raise fail(
            Code.NO_PRESSES,
            f"trial {trial_id!r}: no press qualifies (>= {rule.min_press_s} s of contact, >= {rule.min_press_depth_m} m "
            f"deep, >= {rule.min_samples} fit samples on the rise); {len(thin)} press(es) had too few fit samples",
            expected="at least one press",
            found=0,
        )
    idx = np.concatenate([p.fit for p in presses])
    x, y = penetration[idx], normal_force[idx]
    if float(np.ptp(x)) <= 0:
        raise fail(
            Code.NO_PRESSES,
            f"trial {trial_id!r}: the fit samples do not span any penetration",
            expected="varying penetration",
            found=float(x[0]),
        )
    k, c, r2 = least_squares_line(x, y)
    presses = [replace(p, overshoot=contact_overshoot(p, penetration, normal_force, k, c)) for p in presses]
    return StiffnessFit(k, c, r2, presses, thin, x, y)


def trial_fit(ctx: ComputeContext, trial_id: str) -> StiffnessFit:
    """:func:`fit_stiffness` on a stiffness trial's contact signals (spec §13.5); cached on a ComputeContext."""

    def build() -> StiffnessFit:
        cs = contact_signals(ctx, trial_id)  # contact is False wherever the sample is not valid
        return fit_stiffness(cs.t, cs.penetration, cs.normal_force, cs.contact, trial_id, cs.valid)

    return cached(ctx, ("stiffness_fit", trial_id), build)


def maximum_windows(ctx: ComputeContext, trial_id: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """The grid times (s) and normal forces (N) of the samples ``s … m`` each qualifying press of a trial takes
    its peak from (spec §13.2 step 3): where the noise's maximum biases ``stiffness.peak_force`` (§19.3)."""
    cs = contact_signals(ctx, trial_id)
    return [
        (cs.t[p.settled : p.deepest + 1], cs.normal_force[p.settled : p.deepest + 1]) for p in trial_fit(ctx, trial_id).presses
    ]


def trial_codes(ctx: ComputeContext, trial_id: str, fit: StiffnessFit) -> list[str]:
    """W414 (too few qualifying presses) and W415 (presses with too few fit samples) for one trial, each
    also recorded on ``ctx`` (spec §13.2–13.3)."""
    codes: list[str] = []
    if len(fit.presses) < PARAMETERS.recommended_presses:
        codes.append(Code.FEW_PRESSES)
        ctx.warn(
            Code.FEW_PRESSES,
            f"trial {trial_id!r}: {len(fit.presses)} press(es) qualified, {PARAMETERS.recommended_presses} recommended",
            metric="stiffness.measured",
            trial=trial_id,
        )
    if fit.thin:
        codes.append(Code.PRESS_TOO_FAST)
        where = ", ".join(f"sample {p.start} ({len(p.fit)} fit samples)" for p in fit.thin)
        ctx.warn(
            Code.PRESS_TOO_FAST,
            f"trial {trial_id!r}: {len(fit.thin)} press(es) left out with fewer than {PARAMETERS.min_fit_samples} "
            f"fit samples: {where}",
            metric="stiffness.measured",
            trial=trial_id,
        )
    return codes


def compute(ctx: ComputeContext) -> list[MetricResult | Unavailable]:
    """stiffness.measured, stiffness.accuracy and stiffness.peak_force (spec §13.5)."""
    if not any(ctx.wants(m) for m in IDS):
        return []
    done, missing = protocol_trials(ctx, PROTOCOL, IDS, lambda tid: trial_fit(ctx, tid), "stiffness.measured")
    if missing:
        return list(missing)
    codes = {tid: trial_codes(ctx, tid, f) for tid, f in done.items()}
    commanded = {tid: contact_signals(ctx, tid).stiffness_N_per_m for tid in done}
    fits = list(done.values())
    diag = {
        "intercept_N": [f.intercept for f in fits],
        "r2": [f.r2 for f in fits],
        "presses": [len(f.presses) for f in fits],
        "commanded_N_per_m": list(commanded.values()),
        "press_fit_samples": [[len(p.fit) for p in f.presses] for f in fits],
        "presses_left_out": [len(f.thin) for f in fits],
    }
    peak_diag = {
        "press_peaks_N": [[p.peak_force for p in f.presses] for f in fits],
        "press_overshoot_N": [[p.overshoot for p in f.presses] for f in fits],
    }
    return [
        aggregate(
            FAMILY, "stiffness.measured", [TrialValue(t, f.stiffness, codes[t]) for t, f in done.items()], diagnostics=diag
        ),
        aggregate(
            FAMILY, "stiffness.accuracy", [TrialValue(t, 100.0 * f.stiffness / commanded[t], codes[t]) for t, f in done.items()]
        ),
        aggregate(
            FAMILY,
            "stiffness.peak_force",
            [TrialValue(t, f.peak_force, codes[t]) for t, f in done.items()],
            diagnostics=peak_diag,
        ),
    ]
