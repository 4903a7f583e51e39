"""Statistics of the discrepancy workflow (discrepancy README §3; method of shared notes "finding the missing effect").

- Contiguous blocks: each trial's rows are cut into ten consecutive blocks, roles
  train · validation · train · test · train, twice (60 / 20 / 20 %), so that every held-out role sees
  both halves of a trial (presses come and go); a workspace sweep, which visits the regions one after
  the other, into thirty. Neighbouring samples are correlated, so random splits would leak.
- Effective sample size: every usable row enters the fits, but the counts of the statistics (BIC, F
  test) are ``n_eff = n / D``, ``D`` the lag at which the round's residual autocorrelation (mean over
  trials and channels) first falls below 1/e — correlated samples are not counted as independent
  evidence (the "decimated sample count" of the method). Fitting on decimated rows instead would throw
  away short events (a press's rise lasts a fraction of a second).
- Scores (training rows): ``ΔBIC = n·ln(RSS₀/RSS₁) − k·ln n`` (k = 1 identified parameter), nested F
  test ``F = (RSS₀ − RSS₁)/k ÷ RSS₁/(n − k)``; validation improvement ``1 − RSS₁/RSS₀`` on the
  validation rows; share explained on the test rows.
- Structure left: a generic, non-physical regression of the residual on the state (position,
  velocity, a smooth sign of velocity, acceleration, penetration in contact, a constant) fitted on
  training rows; when it removes a clear share (:data:`STRUCTURE_SHARE`) of the held-out residual, out
  of sample, the residual is not noise. Its in-sample F test and a Ljung–Box whiteness test are reported
  beside it (a smooth structured residual has a long correlation lag, which leaves the decimated F test
  few rows, so the out-of-sample share is the criterion).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

from haptify_tools.discrepancy.data import MeasuredTrial

ROLES = ("train", "validation", "train", "test", "train")
FORCE_REPEATS = 2  # force trials: ten blocks
SWEEP_REPEATS = 6  # workspace sweeps visit regions one after the other: thirty blocks
BIC_MIN = 10.0  # "very strong" evidence on Kass & Raftery's scale
P_MAX = 1e-3  # nested F test
VALIDATION_MIN = 0.10  # the held-out validation residual energy must fall by at least 10 %
STRUCTURE_SHARE = 0.25  # generic regression removing ≥ 25 % of held-out energy → structure left
MAX_DECIMATION = 50
SLOPE_STEP = 0.02  # ±2 % around an identified value: the central difference that linearises δ(p) there
BOOTSTRAP_REPLICATES = 400  # block-bootstrap replicates of a parameter's uncertainty
BOOTSTRAP_SEED = 0  # deterministic, like the rest of the workflow
SUBBLOCK_MIN_ROWS = 50  # bootstrap units: runs of training rows of at least this many rows and 2 correlation lags


@dataclass
class Design:
    """Rows of the stacked residual: per trial the usable row indices and their contiguous-block roles; ``decimation``: the
    correlation lag D (rows) that turns row counts into effective sample counts (discrepancy README §3).
    """

    trials: list[MeasuredTrial]
    rows: dict[str, np.ndarray]
    roles: dict[str, np.ndarray]
    decimation: int

    def stack(self, per_trial: dict[str, np.ndarray], role: str | None = None) -> np.ndarray:
        """Flattened values ``(rows × 3)`` of ``per_trial`` arrays at the design rows (of one role)."""
        parts = []
        for tr in self.trials:
            idx = self.rows[tr.trial_id]
            if role is not None:
                idx = idx[self.roles[tr.trial_id] == role]
            parts.append(np.asarray(per_trial[tr.trial_id])[idx].ravel())
        return np.concatenate(parts) if parts else np.zeros(0)


def block_roles(n: int, repeats: int = FORCE_REPEATS) -> np.ndarray:
    """Role of each of ``n`` consecutive rows: ``5·repeats`` contiguous blocks, roles :data:`ROLES` repeated (discrepancy README §3)."""
    roles = ROLES * repeats
    b = np.minimum((np.arange(n) * len(roles)) // max(n, 1), len(roles) - 1)
    return np.asarray(roles)[b]


def heldout_rows(tr: MeasuredTrial) -> np.ndarray:
    """The usable rows of a trial that lie in its validation and test blocks (the held-out rows, bool)."""
    return tr.valid & (block_roles(len(tr.t)) != "train")


def correlation_lag(residual: dict[str, np.ndarray], trials: list[MeasuredTrial]) -> int:
    """Lag (rows, ≥ 1) at which the mean autocorrelation of the residual first falls below 1/e (discrepancy README §3)."""
    acfs = []
    for tr in trials:
        r = residual[tr.trial_id][tr.valid]
        for k in range(3):
            x = r[:, k] - r[:, k].mean()
            den = float(np.dot(x, x))
            if den <= 0 or len(x) < 4 * MAX_DECIMATION:
                continue
            acfs.append([float(np.dot(x[:-m], x[m:])) / den for m in range(1, MAX_DECIMATION + 1)])
    if not acfs:
        return 1
    mean = np.mean(acfs, axis=0)
    below = np.nonzero(mean < np.exp(-1.0))[0]
    return int(below[0] + 1) if len(below) else MAX_DECIMATION


def make_design(trials: list[MeasuredTrial], residual: dict[str, np.ndarray], repeats: int = FORCE_REPEATS) -> Design:
    """The design of a residual: every usable row, its contiguous block role, and the correlation lag ``D`` in rows (discrepancy README §3)."""
    d = correlation_lag(residual, trials)
    rows, roles = {}, {}
    for tr in trials:
        n = len(tr.t)
        role = block_roles(n, repeats)
        idx = np.flatnonzero(tr.valid)
        rows[tr.trial_id] = idx
        roles[tr.trial_id] = role[idx]
    return Design(trials, rows, roles, d)


@dataclass
class Score:
    """A fitted candidate's scores against the current residual: ΔBIC, F and p, validation and test shares (0–1), RSS in the residual's unit squared (discrepancy README §3)."""

    delta_bic: float
    f_stat: float
    p_value: float
    validation_improvement: float
    test_share: float
    rss_train: tuple[float, float]
    rss_validation: tuple[float, float]
    rss_test: tuple[float, float]
    n_train: int

    def accepted(self) -> bool:
        """True when the effect clearly earns its parameter: ΔBIC, F test and validation all agree."""
        return self.delta_bic > BIC_MIN and self.p_value < P_MAX and self.validation_improvement >= VALIDATION_MIN


def score(design: Design, residual: dict[str, np.ndarray], predicted: dict[str, np.ndarray], k: int = 1) -> Score:
    """Scores of the model ``residual ≈ predicted`` against ``residual ≈ 0`` (k new parameters), counting n_eff = n / D rows (discrepancy README §3)."""

    def rss(role):
        r = design.stack(residual, role)
        e = r - design.stack(predicted, role)
        return float(np.dot(r, r)), float(np.dot(e, e)), len(r)

    r0, r1, n_rows = rss("train")
    v0, v1, _ = rss("validation")
    t0, t1, _ = rss("test")
    n = max(n_rows // design.decimation, k + 2)  # effective (decorrelated) sample count
    tiny = 1e-300
    dbic = n * np.log(max(r0, tiny) / max(r1, tiny)) - k * np.log(max(n, 2))
    f = ((r0 - r1) / k) / max(r1 / max(n - k, 1), tiny)
    p = float(sps.f.sf(f, k, max(n - k, 1))) if f > 0 else 1.0
    return Score(
        float(dbic),
        float(f),
        p,
        1.0 - v1 / v0 if v0 > 0 else 0.0,
        1.0 - t1 / t0 if t0 > 0 else 0.0,
        (r0, r1),
        (v0, v1),
        (t0, t1),
        n,
    )


def affine_fit(design: Design, residual: dict, a: dict, b: dict) -> tuple[float, float]:
    """Least-squares ``p`` of ``residual ≈ a + p·b`` on the training rows, and its standard error
    (inflated by √D for the correlated rows); ``p`` is in the effect parameter's unit, ``b`` the residual per unit of it
    (discrepancy README §2, §3).
    """
    p, se = affine_fit_many(design, residual, a, [b])
    return float(p[0]), float(se[0])


def affine_fit_many(design: Design, residual: dict, a: dict, bs: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ``p`` (one value per regressor) of ``residual ≈ a + Σ p_j·b_j`` on the training rows, and the
    standard errors (``σ²·(BᵀB)⁻¹`` inflated by √D for the correlated rows; ∞ for a regressor the rows do not
    determine) — the per-drive values of an effect (discrepancy README §2, per drive)."""
    r = design.stack(residual, "train") - design.stack(a, "train")
    bb = np.column_stack([design.stack(b, "train") for b in bs])
    gram = bb.T @ bb
    k = len(bs)
    if len(r) <= k or np.linalg.matrix_rank(gram) < k:
        return np.zeros(k), np.full(k, np.inf)
    p = np.linalg.solve(gram, bb.T @ r)
    e = r - bb @ p
    sigma2 = float(np.dot(e, e)) / max(len(e) - k, 1)
    return p, np.sqrt(design.decimation * sigma2 * np.diag(np.linalg.inv(gram)))


def training_units(design: Design) -> list[tuple[str, np.ndarray]]:
    """The bootstrap's resampling units: every trial's training rows cut into runs of ``max(SUBBLOCK_MIN_ROWS, 2·D)``
    consecutive design rows (trial id, positions in the trial's design rows) (discrepancy README §3, uncertainty)."""
    size = max(SUBBLOCK_MIN_ROWS, 2 * design.decimation)
    units = []
    for tr in design.trials:
        pos = np.flatnonzero(design.roles[tr.trial_id] == "train")
        if len(pos) == 0:
            continue
        cuts = np.flatnonzero(np.diff(pos) > 1) + 1  # training blocks are separated by held-out ones
        for run in np.split(pos, cuts):
            n = max(len(run) // size, 1)
            units += [(tr.trial_id, part) for part in np.array_split(run, n)]
    return units


def bootstrap_linear(
    design: Design, residual: dict, at: dict, slope: dict, value: float, replicates: int = BOOTSTRAP_REPLICATES
) -> tuple[float, tuple[float, float]]:
    """Block-bootstrap uncertainty of a parameter identified at ``value`` (discrepancy README §3, uncertainty): the
    model linearised there, ``residual ≈ at + (p − value)·slope`` (``at`` = δ(value), ``slope`` = ∂δ/∂p), is refitted by
    least squares on resampled training units (:func:`training_units`, drawn with replacement); returns the replicates'
    standard deviation and the 95 % interval ``value ± t₀.₉₇₅,U−1 · sd · √(U/(U − 1))`` (U units: few units make the
    plain bootstrap too narrow). ∞ and (−∞, ∞) when the rows do not determine the parameter."""
    units = training_units(design)
    if len(units) < 2:
        return float("inf"), (-float("inf"), float("inf"))
    rg = np.array(
        [
            float(
                np.dot(np.ravel(slope[t][design.rows[t][u]]), np.ravel(residual[t][design.rows[t][u]] - at[t][design.rows[t][u]]))
            )
            for t, u in units
        ]
    )
    gg = np.array([float(np.sum(slope[t][design.rows[t][u]] ** 2)) for t, u in units])
    w = np.random.default_rng(BOOTSTRAP_SEED).multinomial(len(units), np.full(len(units), 1 / len(units)), size=replicates)
    den = w @ gg
    if np.any(den <= 0):
        return float("inf"), (-float("inf"), float("inf"))
    reps = value + (w @ rg) / den
    u = len(units)
    sd = float(np.std(reps, ddof=1))
    half = float(sps.t.ppf(0.975, u - 1)) * sd * np.sqrt(u / (u - 1))
    return sd, (value - half, value + half)


def state_features(tr: MeasuredTrial) -> np.ndarray:
    """Generic state regressors ``(N, m)`` of one trial for the structure check (no physics in them): position m, velocity m/s, acceleration m/s², penetration m (discrepancy README §3)."""
    v = np.gradient(tr.position, tr.t, axis=0)
    a = np.gradient(v, tr.t, axis=0)
    p = tr.position - tr.position.mean(axis=0)
    cols = [np.ones(len(tr.t)), *p.T, *v.T, *np.tanh(v / 0.005).T, *a.T]
    if tr.active:
        pen, _ = tr.penetration()
        cols.append(np.where(tr.contact, pen, 0.0))
        cols.append(tr.contact.astype(float))
    return np.column_stack(cols)


def structure_left(design: Design, residual: dict[str, np.ndarray]) -> dict:
    """Generic regression of the residual on the state (per trial and channel, every usable training row),
    judged on the held-out (validation + test) rows: share (0–1) of held-out energy it removes, an F test whose
    degrees of freedom count decimated rows, and a Ljung–Box whiteness p-value on the decimated held-out residual
    (discrepancy README §3).
    """
    d = design.decimation
    held0 = held1 = 0.0
    q_stats, dof = 0.0, 0
    n_tr, k_tot, r0_tr, r1_tr = 0, 0, 0.0, 0.0
    for tr in design.trials:
        v = tr.valid
        role = block_roles(len(tr.t))[v]
        x = state_features(tr)[v]
        r = residual[tr.trial_id][v]
        tr_rows, ho = role == "train", role != "train"
        if tr_rows.sum() <= 3 * x.shape[1] or ho.sum() < 2:
            continue
        for k in range(3):
            coef, *_ = np.linalg.lstsq(x[tr_rows], r[tr_rows, k], rcond=None)
            e = r[:, k] - x @ coef
            held0 += float(np.sum(r[ho, k] ** 2))
            held1 += float(np.sum(e[ho] ** 2))
            r0_tr += float(np.sum(r[tr_rows, k] ** 2))
            r1_tr += float(np.sum(e[tr_rows] ** 2))
            n_tr += int(tr_rows.sum()) // d
            k_tot += x.shape[1]
            y = r[ho, k][::d]
            y = y - y.mean()
            m = min(10, len(y) // 4)
            den = float(np.dot(y, y))
            if m >= 1 and den > 0:
                rho = np.array([np.dot(y[:-h], y[h:]) / den for h in range(1, m + 1)])
                q_stats += len(y) * (len(y) + 2) * float(np.sum(rho**2 / (len(y) - np.arange(1, m + 1))))
                dof += m
    share = 1.0 - held1 / held0 if held0 > 0 else 0.0
    f = ((r0_tr - r1_tr) / max(k_tot, 1)) / max(r1_tr / max(n_tr - k_tot, 1), 1e-300)
    p_f = float(sps.f.sf(f, max(k_tot, 1), max(n_tr - k_tot, 1))) if f > 0 and n_tr > k_tot else 1.0
    p_lb = float(sps.chi2.sf(q_stats, dof)) if dof else 1.0
    return {
        "heldout_share": float(share),
        "f_p_value": p_f,
        "ljung_box_p_value": p_lb,
        "structured": bool(share >= STRUCTURE_SHARE),
    }
