"""What an unexplained residual looks like (discrepancy README §3 "characterising the residual").

When no library effect explains the residual the workflow describes it instead of naming an effect: where it lives
(protocols × force axes) and which state it follows best, with the shape. A small set of nonparametric regressions,
each fitted on the training blocks and judged on the held-out blocks (energy removed, out of sample):

- a constant per trial and axis (the baseline every shape is measured against: an offset follows no state);
- binned means — :data:`BINS` quantile bins of one state, per trial and axis (a smooth dependence of any form);
- for the coordinates of position and configuration, a least-squares periodogram (Lomb–Scargle with the phase
  free): ``a·sin(2πs/λ) + b·cos(2πs/λ)`` per axis, shared by the trials, over a logarithmic grid of periods λ, then
  refined. A force periodic in ``s`` reaches the residual through the workflow's low-pass at
  :data:`.data.RESIDUAL_CUTOFF_HZ` (``s`` changes fast when the hand moves), so the regressors are made the same way
  (on a :data:`WAVE_RATE_HZ` grid, low-passed) and the fitted amplitude is the force's own, not the filtered one.

The states: hand position (world x, y, z, m), velocity (m/s) per axis and speed, acceleration (m/s²) per axis, the
configuration (the twin's arm angles q1…q3, rad) and time in the trial (s). ``held-out R²`` of a shape is
``1 − SSE_shape / SSE_constant`` on the held-out rows, all axes pooled; the state followed best is the one with the
largest, and the residual is structured when it reaches :data:`STRUCTURE_R2` (or the constant alone removes
:data:`.stats.STRUCTURE_SHARE` of the held-out energy: an offset).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from haptify.processing.preprocessing import lowpass
from haptify_tools.discrepancy import stats as st
from haptify_tools.discrepancy.data import RESIDUAL_CUTOFF_HZ, MeasuredTrial
from haptify_tools.twin.kinematics import hand_to_joints
from haptify_tools.twin.model import TwinFile

BINS = 12  # quantile bins of a state for the binned means
STRUCTURE_R2 = 0.25  # a shape removing this share of the held-out residual beyond a constant is structure
#: periodogram grids (log-spaced): position in m, configuration in rad
#: (the shortest periods are 2 mm and 0.02 rad, ≈ 2.6 mm at the hand: shorter ones fit the path's own noise)
PERIODS = {"position": (0.002, 0.05), "configuration": (0.02, 0.5)}
PERIOD_STEPS = 100
REFINE_STEPS = 15
#: the periodogram's regressors are made on this grid (a 2 mm period at 0.5 m/s is 250 Hz: what aliases back below the
#: 5 Hz cut-off comes only from faster strokes than the protocols make), low-passed, and put on the trial's grid
WAVE_RATE_HZ = 250.0
CHANNELS = ("fx", "fy", "fz")
WHERE_SHARE = 0.8  # "where": the protocol × axis cells holding this share of the held-out energy


@dataclass
class StateFit:
    """One shape of the residual against one state: held-out R² beyond a constant, and its description."""

    state: str
    kind: str  # "binned" or "periodic"
    heldout_r2: float
    description: str
    period: float | None = None
    amplitude_N: float | None = None
    amplitude_per_axis_N: list[float] = field(default_factory=list)


def states(tr: MeasuredTrial, twin: TwinFile) -> dict[str, tuple[str, np.ndarray]]:
    """State name → (group, values on the trial's grid): position, velocity, speed, acceleration, configuration, time."""
    v = np.gradient(tr.position, tr.t, axis=0)
    a = np.gradient(v, tr.t, axis=0)
    out: dict[str, tuple[str, np.ndarray]] = {}
    for k, ax in enumerate("xyz"):
        out[ax] = ("position", tr.position[:, k])
    for k, ax in enumerate("xyz"):
        out[f"v{ax}"] = ("velocity", v[:, k])
    out["speed"] = ("velocity", np.linalg.norm(v, axis=1))
    for k, ax in enumerate("xyz"):
        out[f"a{ax}"] = ("acceleration", a[:, k])
    q, _, ok = hand_to_joints(twin, tr.position)
    if ok.all():
        for k in range(q.shape[1]):
            out[f"q{k + 1}"] = ("configuration", q[:, k])
    out["time"] = ("time", tr.t - tr.t[0])
    return out


@dataclass
class _Rows:
    """Per trial: usable rows, which are training rows, the residual there ``(n, 3)`` minus the per-trial training mean."""

    trial: MeasuredTrial
    idx: np.ndarray
    train: np.ndarray
    r: np.ndarray


def _rows(design: st.Design, residual: dict[str, np.ndarray]) -> list[_Rows]:
    out = []
    for tr in design.trials:
        idx = design.rows[tr.trial_id]
        train = design.roles[tr.trial_id] == "train"
        if train.sum() < 2 * BINS or (~train).sum() < 2:
            continue
        r = residual[tr.trial_id][idx]
        out.append(_Rows(tr, idx, train, r - r[train].mean(axis=0)))
    return out


def _held_energy(rows: list[_Rows], fitted: list[np.ndarray] | None = None) -> float:
    e = 0.0
    for i, rw in enumerate(rows):
        x = rw.r[~rw.train] - (0.0 if fitted is None else fitted[i][~rw.train])
        e += float(np.sum(x**2))
    return e


def binned_fit(rows: list[_Rows], values: list[np.ndarray]) -> tuple[list[np.ndarray], list[tuple[np.ndarray, np.ndarray]]]:
    """Binned means of the residual on one state (per trial: :data:`BINS` quantile bins of its training rows); the
    fitted values on every row and, per trial, the bins' centres and means ``(BINS, 3)``."""
    fitted, curves = [], []
    for rw, s in zip(rows, values):
        edges = np.unique(np.quantile(s[rw.train], np.linspace(0, 1, BINS + 1)))
        b = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, max(len(edges) - 2, 0))
        means = np.zeros((max(len(edges) - 1, 1), 3))
        centres = np.zeros(len(means))
        for j in range(len(means)):
            m = rw.train & (b == j)
            if m.any():
                means[j] = rw.r[m].mean(axis=0)
                centres[j] = float(np.mean(s[m]))
        fitted.append(means[b])
        curves.append((centres, means))
    return fitted, curves


def _filtered_waves(tr: MeasuredTrial, idx: np.ndarray, s_fine: np.ndarray, periods: np.ndarray) -> np.ndarray:
    """``sin``/``cos(2πs/λ)`` for every period on the :data:`WAVE_RATE_HZ` grid, low-passed like the force, at the rows ``idx``: ``(n, 2, P)``."""
    fine_t = _fine_grid(tr)
    phase = 2 * np.pi * s_fine[:, None] / periods[None, :]
    waves = lowpass(np.concatenate([np.sin(phase), np.cos(phase)], axis=1), WAVE_RATE_HZ, RESIDUAL_CUTOFF_HZ)
    pos = np.interp(tr.t[idx], fine_t, np.arange(len(fine_t)))
    lo = np.floor(pos).astype(int).clip(0, len(fine_t) - 2)
    w = (pos - lo)[:, None]
    at = waves[lo] * (1 - w) + waves[lo + 1] * w
    return at.reshape(len(idx), 2, len(periods))


def _fine_grid(tr: MeasuredTrial) -> np.ndarray:
    dt = 1.0 / WAVE_RATE_HZ
    fine = np.arange(tr.t[0], tr.t[-1] + 0.5 * dt, dt)
    return fine[fine <= tr.t[-1]]


def _periodic_sse(rows: list[_Rows], waves: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per period: training SSE reduction, held-out SSE after, and the coefficients ``(P, 2, 3)`` of the
    shared sine/cosine fit per axis (least squares on the training rows of every trial)."""
    p = waves[0].shape[2]
    ata = np.zeros((p, 2, 2))
    atb = np.zeros((p, 2, 3))
    for rw, w in zip(rows, waves):
        wt = w[rw.train]  # (n, 2, P)
        ata += np.einsum("nip,njp->pij", wt, wt)
        atb += np.einsum("nip,nk->pik", wt, rw.r[rw.train])
    coef = np.linalg.solve(ata + 1e-12 * np.eye(2)[None], atb)  # (P, 2, 3)
    gain = np.einsum("pik,pik->p", coef, atb)
    held = np.zeros(p)
    for rw, w in zip(rows, waves):
        wh = w[~rw.train]
        pred = np.einsum("nip,pik->pnk", wh, coef)
        held += np.sum((rw.r[~rw.train][None] - pred) ** 2, axis=(1, 2))
    return gain, held, coef


def periodic_fit(
    rows: list[_Rows], fine_values: list[np.ndarray], lo: float, hi: float, unit: str, state: str, base: float
) -> StateFit:
    """The least-squares periodogram of the residual against one state (module docstring): the period with the largest
    training gain on a log grid from ``lo`` to ``hi``, refined on a finer grid around it (±one step)."""
    grid = np.geomspace(lo, hi, PERIOD_STEPS)
    waves = [_filtered_waves(rw.trial, rw.idx, s, grid) for rw, s in zip(rows, fine_values)]
    gain, _, _ = _periodic_sse(rows, waves)
    i = int(np.argmax(gain))
    step = grid[1] / grid[0]
    fine = np.geomspace(grid[i] / step, grid[i] * step, REFINE_STEPS)
    waves = [_filtered_waves(rw.trial, rw.idx, s, fine) for rw, s in zip(rows, fine_values)]
    gain, held, coef = _periodic_sse(rows, waves)
    j = int(np.argmax(gain))
    amp = np.hypot(coef[j, 0], coef[j, 1])  # per axis, N
    total = float(np.linalg.norm(amp))
    r2 = 1.0 - held[j] / base if base > 0 else 0.0
    scale, u = (1e3, "mm") if unit == "m" else (1.0, unit)
    per_axis = ", ".join(f"{c} {a:.2g}" for c, a in zip(CHANNELS, amp))
    return StateFit(
        state,
        "periodic",
        float(r2),
        f"periodic in {state}, period ≈ {fine[j] * scale:.3g} {u}, amplitude ≈ {total:.2g} N ({per_axis} N)",
        float(fine[j]),
        total,
        [float(a) for a in amp],
    )


def _binned_description(state: str, unit: str, curves: list[tuple[np.ndarray, np.ndarray]], r2: float) -> str:
    centres = np.concatenate([c for c, _ in curves])
    means = np.concatenate([m for _, m in curves])
    k = int(np.argmax(np.ptp(means, axis=0)))
    order = np.argsort(centres)
    lo_i, hi_i = order[0], order[-1]
    return (
        f"follows {state} (binned means, held-out R² {r2:.2f}): {CHANNELS[k]} residual "
        f"{means[lo_i, k]:+.2g} N at {state} = {centres[lo_i]:.3g} {unit} → {means[hi_i, k]:+.2g} N at "
        f"{centres[hi_i]:.3g} {unit} (range {np.ptp(means[:, k]):.2g} N)"
    )


UNITS = {"position": "m", "velocity": "m/s", "acceleration": "m/s²", "configuration": "rad", "time": "s"}


def where_it_lives(rows: list[_Rows]) -> list[tuple[str, str, float, float]]:
    """(protocol, axis, held-out RMS N, share of held-out energy) for the cells holding :data:`WHERE_SHARE` of it, largest first."""
    cells: dict[tuple[str, str], list[float]] = {}
    for rw in rows:
        x = rw.r[~rw.train] + 0.0
        for k, c in enumerate(CHANNELS):
            cell = cells.setdefault((rw.trial.protocol, c), [0.0, 0.0])
            cell[0] += float(np.sum(x[:, k] ** 2))
            cell[1] += len(x)
    total = sum(e for e, _ in cells.values()) or 1.0
    out: list[tuple[str, str, float, float]] = []
    acc = 0.0
    for (proto, c), (e, n) in sorted(cells.items(), key=lambda kv: -kv[1][0]):
        out.append((proto, c, float(np.sqrt(e / max(n, 1))), e / total))
        acc += e / total
        if acc >= WHERE_SHARE:
            break
    return out


def characterise(design: st.Design, residual: dict[str, np.ndarray], twin: TwinFile) -> dict:
    """The residual's description (module docstring): where it lives, the constant's share of held-out energy, every
    state's best shape (held-out R² beyond the constant), the state followed best and whether it is structured."""
    rows = _rows(design, residual)
    if not rows:
        return {"where": [], "offset_share": 0.0, "fits": [], "best": None, "structured": False}
    raw = sum(float(np.sum((residual[rw.trial.trial_id][rw.idx][~rw.train]) ** 2)) for rw in rows)
    base = _held_energy(rows)
    offset_share = 1.0 - base / raw if raw > 0 else 0.0
    per_trial = [states(rw.trial, twin) for rw in rows]
    names = [n for n in per_trial[0] if all(n in s for s in per_trial)]
    fits: list[StateFit] = []
    for name in names:
        group = per_trial[0][name][0]
        values = [s[name][1][rw.idx] for s, rw in zip(per_trial, rows)]
        fitted, curves = binned_fit(rows, values)
        r2 = 1.0 - _held_energy(rows, fitted) / base if base > 0 else 0.0
        best = StateFit(name, "binned", float(r2), _binned_description(name, UNITS[group], curves, r2))
        if group in PERIODS:
            fine = [CubicSpline(rw.trial.t, s[name][1])(_fine_grid(rw.trial)) for s, rw in zip(per_trial, rows)]
            per = periodic_fit(rows, fine, *PERIODS[group], UNITS[group], name, base)
            if per.heldout_r2 > best.heldout_r2:
                best = per
        fits.append(best)
    fits.sort(key=lambda f: -f.heldout_r2)
    top = fits[0] if fits else None
    structured = bool((top is not None and top.heldout_r2 >= STRUCTURE_R2) or offset_share >= st.STRUCTURE_SHARE)
    return {
        "where": where_it_lives(rows),
        "offset_share": float(offset_share),
        "fits": fits,
        "best": top,
        "structured": structured,
    }
