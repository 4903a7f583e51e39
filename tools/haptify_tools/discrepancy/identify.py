"""Grouped forward selection of library effects (discrepancy README §2–3; shared notes, method steps 2–4).

Each round: simulate the current twin along the measured paths, form the residual, fit every
available library candidate to it (:mod:`.library`), score the fits (:mod:`.stats`), take the one with
the largest ΔBIC and accept it only when it clearly earns its parameter; an accepted effect is added to
the twin with its identified value and the next round starts from the re-simulated residual. The
first rejection (or ``max_effects``) ends the search; the residual left is then checked for structure.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from scipy.optimize import minimize_scalar

from haptify_tools.discrepancy import stats as st
from haptify_tools.discrepancy import workspace as ws
from haptify_tools.discrepancy.data import MeasuredTrial, Pool, share_trials, simulate_many
from haptify_tools.discrepancy.floor import Parameter, gauss_newton_step
from haptify_tools.discrepancy.library import LIBRARY, Candidate
from haptify_tools.discrepancy.shape import characterise
from haptify_tools.twin.model import TwinFile

EXTENSIONS = 2  # grid extensions when the best grid point is at an end
XATOL_LOG = 2e-4  # the continuous refinement stops within 0.02 % of the optimum (Brent, in log p)
JOINT_STEPS = 3  # Gauss–Newton steps of the joint refinement of the accepted values (each must lower the SSE)


@dataclass
class Dataset:
    """What a candidate is fitted to: the force trials (N) or the workspace sweeps (m), and how the twin
    predicts them (:func:`.data.simulate_all` or the examiner's radial stop, :mod:`.workspace`) (discrepancy README §1, §2).
    """

    kind: str  # "force" or "workspace"
    items: list
    commands: dict | None = None  # workspace: trial id → (face commands, ok)
    pool: Pool | None = None  # force: workers sharing the trials (:func:`.data.share_trials`)

    @property
    def measured(self) -> dict[str, np.ndarray]:
        return {it.trial_id: (it.force if self.kind == "force" else it.position) for it in self.items}

    def simulate(self, twin: TwinFile, only_active: bool = False, base: dict | None = None) -> dict[str, np.ndarray]:
        return self.simulate_many([twin], only_active, base)[0]

    def simulate_many(self, twins: list[TwinFile], only_active: bool = False, base: dict | None = None) -> list[dict]:
        """The predictions of several twins (force trials: every (twin, trial) pair in parallel when there is a pool)."""
        if self.kind == "force":
            return simulate_many(twins, self.items, only_active, base, self.pool)
        if self.commands is None:
            raise ValueError("a workspace dataset is made with its face commands (Dataset.sweeps)")
        commands = self.commands
        return [ws.sweep_predictions(tw, self.items, commands) for tw in twins]

    @staticmethod
    def sweeps(twin: TwinFile, sweeps: list) -> "Dataset":
        """The workspace dataset; points outside the twin's joint box are left out (``valid``)."""
        commands = {sw.trial_id: ws.face_commands(twin, sw.position) for sw in sweeps}
        for sw in sweeps:
            sw.valid = commands[sw.trial_id][1]
        return Dataset("workspace", sweeps, commands)


@dataclass
class Fit:
    """A candidate fitted to one residual: identified value and its standard error (the parameter's unit), predicted residual, scores (discrepancy README §2, §3)."""

    candidate: Candidate
    value: float
    stderr: float
    predicted: dict[str, np.ndarray]
    score: st.Score
    simulations: int
    interval: tuple[float, float] | None = None  # 95 % block-bootstrap interval (:func:`.stats.bootstrap_linear`)
    values: list[float] | None = None  # per drive (:func:`fit_per_drive`); ``value`` is then their mean
    stderrs: list[float] | None = None
    #: per drive against shared: the nested scores of the per-drive values on the shared fit's residual
    per_drive_score: st.Score | None = None

    @property
    def applied(self) -> float | list[float]:
        """What the twin's parameter is set to: the per-drive values, or the one shared value."""
        return self.values if self.values is not None else self.value


@dataclass
class Round:
    """One round of the selection: the residual it started from (N, or m for sweeps) and every candidate's fit (discrepancy README §3)."""

    residual: dict[str, np.ndarray]
    design: st.Design
    fits: list[Fit]
    chosen: Fit | None
    accepted: bool
    near_ties: list[str] = field(default_factory=list)
    workspace_residual: dict[str, np.ndarray] | None = None


@dataclass
class Selection:
    """Outcome of the search: the rounds, the accepted fits in order, the final twin and its simulated forces, N (discrepancy README §2, §3)."""

    rounds: list[Round]
    accepted: list[Fit]
    twin: TwinFile
    initial_sim: dict[str, np.ndarray]
    final_sim: dict[str, np.ndarray]
    structure: dict
    sweeps: Dataset | None = None
    initial_sweep: dict[str, np.ndarray] | None = None
    final_sweep: dict[str, np.ndarray] | None = None
    shape: dict | None = None  # the residual left, characterised (:func:`.shape.characterise`)


def _minus(a: dict, b: dict) -> dict:
    return {k: a[k] - b[k] for k in a}


def _sse(design: st.Design, residual: dict, predicted: dict) -> float:
    e = design.stack(residual, "train") - design.stack(predicted, "train")
    return float(np.dot(e, e))


def fit_candidate(
    cand: Candidate,
    twin: TwinFile,
    data: Dataset,
    design: st.Design,
    residual: dict,
    base: dict,
) -> Fit:
    """Fit one candidate to ``residual`` (measured − ``base``, the current twin's prediction of ``data``; N or m): affine by
    least squares or searched on a logarithmic grid (discrepancy README §2).
    """
    only_active = cand.scope == "active"
    zero = {k: np.zeros_like(v) for k, v in base.items()}
    trials = data.items

    probe = cand.probe(twin)
    ceiling = np.inf
    if cand.commanded_scale:
        ceiling = max((tr.commanded_max_N for tr in trials if tr.active), default=0.0)
        probe = ceiling if ceiling > 0 else probe

    def deltas(ps: list[float]) -> list[dict]:
        """δ(p) for several values, simulated together (values at or above the ceiling: zero)."""
        below = [p for p in ps if p < ceiling]
        sims = iter(data.simulate_many([cand.apply(twin, p) for p in below], only_active, base))
        return [_minus(next(sims), base) if p < ceiling else zero for p in ps]

    if only_active and not any(tr.active for tr in trials):
        return Fit(cand, probe, float("inf"), zero, st.score(design, residual, zero), 0)
    if cand.kind == "affine":
        return _fit_affine(cand, design, residual, probe, deltas)
    return _fit_searched(cand, design, residual, probe, ceiling, deltas)


def _fit_affine(
    cand: Candidate, design: st.Design, residual: dict, probe: float, deltas: Callable[[list[float]], list[dict]]
) -> Fit:
    """An affine candidate (discrepancy README §2): δ(p) = a + p·b from two simulations, least squares for p,
    re-linearised by secant steps where the fit earns something; ``deltas`` simulates δ for several values."""
    p1, p2 = probe, 2.0 * probe
    d1, d2 = deltas([p1, p2])
    b = {k: (d2[k] - d1[k]) / (p2 - p1) for k in d1}
    a = {k: d1[k] - p1 * b[k] for k in d1}
    p, se = st.affine_fit(design, residual, a, b)
    p = max(p, cand.lower + 1e-12 * probe)
    sims = 2
    pts = [(p1, d1), (p2, d2)]
    # re-linearising refines a fit that earns something; one that is worse than nothing stays rejected
    steps = cand.relinearise if st.score(design, residual, {k: a[k] + p * b[k] for k in a}).delta_bic > 0 else 0
    for _ in range(steps):
        # secant (Gauss–Newton) steps for an effect that is only nearly affine: re-linearise at p̂
        pts.append((p, deltas([p])[0]))
        sims += 1
        (pa, da), (pb, db) = sorted(pts, key=lambda x: abs(x[0] - p))[:2]
        if pa == pb:
            break
        b = {k: (db[k] - da[k]) / (pb - pa) for k in da}
        a = {k: da[k] - pa * b[k] for k in da}
        p, se = st.affine_fit(design, residual, a, b)
    pred = {k: a[k] + p * b[k] for k in a}
    interval: tuple[float, float] | None
    se, interval = st.bootstrap_linear(design, residual, pred, b, p)
    return Fit(cand, p, se, pred, st.score(design, residual, pred), sims, interval=interval)


def _fit_searched(
    cand: Candidate,
    design: st.Design,
    residual: dict,
    probe: float,
    ceiling: float,
    deltas: Callable[[list[float]], list[dict]],
) -> Fit:
    """A candidate searched on a logarithmic grid around ``probe``, extended while the best lies at an end (below
    ``ceiling``), then refined by a bounded Brent search in log p (discrepancy README §2)."""
    # 1-D search on a logarithmic grid, then a bounded Brent refinement in log p
    evals: dict[float, tuple[float, dict]] = {}

    def ev_many(ps: list[float]) -> None:
        new = [p for p in dict.fromkeys(ps) if p not in evals]
        for p, d in zip(new, deltas(new)):
            evals[p] = (_sse(design, residual, d), d)

    def ev(p: float) -> float:
        ev_many([p])
        return evals[p][0]

    ev_many([probe * f for f in cand.grid_factors])
    step = np.log(cand.grid_factors[-1] / cand.grid_factors[-2])
    for _ in range(EXTENSIONS):
        ps = sorted(evals)
        best = min(ps, key=lambda x: evals[x][0])
        if best == ps[0]:
            ev(ps[0] * np.exp(-step))
        elif best == ps[-1] and ps[-1] * np.exp(step) < ceiling:
            ev(ps[-1] * np.exp(step))
        else:
            break
    ps = sorted(evals)
    i = min(range(len(ps)), key=lambda j: evals[ps[j]][0])
    if 0 < i < len(ps) - 1:
        # continuous refinement to the optimum inside the bracket (not a grid point): bounded Brent in log p
        minimize_scalar(
            lambda x: ev(float(np.exp(x))),
            bounds=(np.log(ps[i - 1]), np.log(ps[i + 1])),
            method="bounded",
            options={"xatol": XATOL_LOG},
        )
    p = min(evals, key=lambda x: evals[x][0])
    pred = evals[p][1]
    se, interval = float("inf"), None
    if ps[0] < p < ps[-1]:  # bracketed: the uncertainty from the model linearised at p̂ (central difference)
        lo, hi = p * (1 - st.SLOPE_STEP), p * (1 + st.SLOPE_STEP)
        ev_many([lo, hi])
        slope = {k: (evals[hi][1][k] - evals[lo][1][k]) / (hi - lo) for k in pred}
        se, interval = st.bootstrap_linear(design, residual, pred, slope, p)
    return Fit(cand, p, se, pred, st.score(design, residual, pred), len(evals), interval=interval)


def fit_per_drive(shared: Fit, twin: TwinFile, data: Dataset, design: st.Design, residual: dict, base: dict) -> Fit:
    """The per-drive version of an affine fit (discrepancy README §2, per drive): ``δ(p₁…p_n) = a + Σ p_j·b_j``, ``b_j``
    from the twin with drive ``j`` alone at twice the probe (n + 1 simulations), least squares for the values. Kept —
    the returned fit has ``values`` — only when it earns its n − 1 extra parameters by the acceptance rule itself
    (ΔBIC, F test, validation) on the shared fit's residual; otherwise ``shared`` is returned with that score attached.
    """
    cand = shared.candidate
    n_d = len(getattr(twin.effect(cand.effect_id), cand.parameter))
    if not cand.per_drive or cand.kind != "affine" or n_d < 2:
        return shared
    p1 = cand.probe(twin)
    p2 = 2.0 * p1
    twins = [cand.apply(twin, [p1] * n_d)] + [cand.apply(twin, [p2 if j == i else p1 for j in range(n_d)]) for i in range(n_d)]
    sims = data.simulate_many(twins, cand.scope == "active", base)
    d1 = _minus(sims[0], base)
    bs = [{k: (sims[1 + i][k] - sims[0][k]) / (p2 - p1) for k in d1} for i in range(n_d)]
    a = {k: d1[k] - p1 * sum(b[k] for b in bs) for k in d1}
    p, se = st.affine_fit_many(design, residual, a, bs)
    p = np.maximum(p, cand.lower + 1e-12 * p1)
    pred = {k: a[k] + sum(pj * b[k] for pj, b in zip(p, bs)) for k in a}
    nested = st.score(design, _minus(residual, shared.predicted), _minus(pred, shared.predicted), k=n_d - 1)
    if not nested.accepted():
        return replace(shared, simulations=shared.simulations + len(twins), per_drive_score=nested)
    return Fit(
        cand,
        float(np.mean(p)),
        float(np.sqrt(np.sum(se**2)) / n_d),
        pred,
        st.score(design, residual, pred, k=n_d),
        shared.simulations + len(twins),
        values=[float(x) for x in p],
        stderrs=[float(x) for x in se],
        per_drive_score=nested,
    )


def accepted_parameters(accepted: list[Fit]) -> tuple[Parameter, ...]:
    """The accepted force effects' identified values, one per drive when identified per drive (the workspace effect is
    fitted to the sweep, not to the force) (discrepancy README §2, joint refinement; §3, uncertainty)."""
    out: list[Parameter] = []
    for f in accepted:
        if f.candidate.scope == "workspace":
            continue
        if f.values is not None:
            out += [Parameter(f.candidate, i, v) for i, v in enumerate(f.values)]
        else:
            out.append(Parameter(f.candidate, None, f.value))
    return tuple(out)


def _with_values(accepted: list[Fit], params: tuple[Parameter, ...], values: list[float]) -> list[Fit]:
    """``accepted`` with the force effects' values replaced, in the order of :func:`accepted_parameters`."""
    it = iter(values)
    out = []
    for f in accepted:
        if f.candidate.scope == "workspace":
            out.append(f)
        elif f.values is not None:
            vs = [next(it) for _ in f.values]
            out.append(replace(f, values=vs, value=float(np.mean(vs))))
        else:
            out.append(replace(f, value=next(it)))
    return out


def refine_jointly(twin: TwinFile, accepted: list[Fit], forces: Dataset, base: dict) -> tuple[TwinFile, list[Fit], dict]:
    """The accepted force effects' values refined together (discrepancy README §2, joint refinement): each round fits
    its effect with the earlier ones held at their values, and an effect accepted before another that was still missing
    keeps the bias that one caused (the demo's Coulomb friction, named first beside a missing series elasticity, came
    out 0.0387 N·m for 0.04, outside its interval). Gauss–Newton steps on all values at once
    (:func:`.floor.gauss_newton_step`, the replays' own re-estimation) while the training SSE falls, at most
    :data:`JOINT_STEPS`; values stay above their candidate's lower bound. Returns the twin, the fits and its prediction."""
    params = accepted_parameters(accepted)
    if len({q.candidate.effect_id for q in params}) < 2:
        return twin, accepted, base
    trials = forces.items
    residual = _minus(forces.measured, base)
    design = st.make_design(trials, residual)
    best = _sse(design, residual, {k: np.zeros_like(v) for k, v in residual.items()})
    for _ in range(JOINT_STEPS):
        values = gauss_newton_step(twin, params, trials, residual, forces.simulate_many)
        if not all(np.isfinite(values)):
            break
        values = [max(v, q.candidate.lower + 1e-6 * abs(q.value)) for q, v in zip(params, values)]
        trial_params = tuple(replace(q, value=v) for q, v in zip(params, values))
        candidate_twin = twin
        for q in trial_params:
            candidate_twin = q.set(candidate_twin, q.value)
        sim = forces.simulate(candidate_twin)
        new_residual = _minus(forces.measured, sim)
        sse = _sse(design, new_residual, {k: np.zeros_like(v) for k, v in new_residual.items()})
        if not sse < best:
            break
        best, twin, params, base, residual = sse, candidate_twin, trial_params, sim, new_residual
    return twin, _with_values(accepted, params, [q.value for q in params]), base


def select_effects(
    twin: TwinFile,
    trials: list[MeasuredTrial],
    max_effects: int = 5,
    library: tuple[Candidate, ...] = LIBRARY,
    log: Callable[[str], object] | None = None,
    workers: int = 1,
    sweeps: list | None = None,
    client=None,
) -> Selection:
    """Forward selection (see the module docstring; discrepancy README §2, §3); deterministic for a given twin and session.

    ``sweeps``: the measured workspace sweeps (:func:`.workspace.load_sweeps`) for the workspace
    candidate. ``workers`` > 1 runs the simulations — every (twin, trial) pair a job, the values a candidate
    needs at once simulated together — in that many processes (0: one per CPU, at most 4); with a Dask
    ``client`` (``--scheduler``) on its cluster instead (:class:`.cluster_pool.ClusterPool`). The result depends on neither.
    """
    if client is not None and trials:
        from haptify_tools.discrepancy.cluster_pool import ClusterPool

        with ClusterPool(client, trials) as pool:
            return _select(twin, Dataset("force", trials, pool=pool), sweeps or [], max_effects, library, log)
    n = pool_size(workers)
    if n <= 1 or not trials:
        return _select(twin, Dataset("force", trials), sweeps or [], max_effects, library, log)
    with process_pool(n, share_trials, (trials,)) as pool:
        return _select(twin, Dataset("force", trials, pool=pool), sweeps or [], max_effects, library, log)


def pool_size(workers: int) -> int:
    """Worker processes for a ``workers`` setting: itself, or for 0 one per CPU, at most 4."""
    return workers or min(4, os.cpu_count() or 1)


def process_pool(n: int, initializer=None, initargs: tuple = ()) -> ProcessPoolExecutor:
    """``n`` worker processes, forked where the platform can (the workers inherit what is loaded: the compiled
    drive loops, the trials, the twin's path memo)."""
    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
    return ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=initializer, initargs=initargs)


#: what a candidate is fitted to: the data, the design and the residual of the current twin, and its predictions
_Problem = tuple[Dataset, st.Design, dict[str, np.ndarray], dict[str, np.ndarray]]


def _fit(c: Candidate, twin: TwinFile, forces: _Problem, workspace: _Problem | None) -> Fit:
    """:func:`fit_candidate` on the force trials, or for a workspace candidate on the workspace sweeps."""
    if c.scope != "workspace":
        return fit_candidate(c, twin, *forces)
    if workspace is None:
        raise ValueError(f"{c.effect_id} is fitted to workspace sweeps, and there are none")
    return fit_candidate(c, twin, *workspace)


def _select(twin, forces: Dataset, sweeps, max_effects, library, log) -> Selection:
    trials = forces.items
    current = twin
    base = forces.simulate(current) if trials else {}
    sweep_data = Dataset.sweeps(current, sweeps) if sweeps else None
    base_w = sweep_data.simulate(current) if sweep_data else {}
    initial, initial_w = base, base_w
    rounds: list[Round] = []
    accepted: list[Fit] = []
    while True:
        residual = _minus(forces.measured, base)
        design = st.make_design(trials, residual)
        workspace: _Problem | None = None
        residual_w = None
        if sweep_data is not None:
            residual_w = _minus(sweep_data.measured, base_w)
            workspace = (sweep_data, st.make_design(sweeps, residual_w, st.SWEEP_REPEATS), residual_w, base_w)
        cands = [
            c for c in library if c.available(current) and (sweep_data is not None if c.scope == "workspace" else bool(trials))
        ]
        if len(accepted) >= max_effects or not cands:
            rounds.append(Round(residual, design, [], None, False, workspace_residual=residual_w))
            break
        fits = [_fit(c, current, (forces, design, residual, base), workspace) for c in cands]
        fits.sort(key=lambda f: -f.score.delta_bic)
        if fits[0].candidate.per_drive:  # the best effect, per drive when the data support it
            fits[0] = fit_per_drive(fits[0], current, forces, design, residual, base)
        best = fits[0]
        ok = best.score.accepted()
        ties = [f.candidate.effect_id for f in fits[1:] if f.score.accepted() and f.score.delta_bic >= 0.9 * best.score.delta_bic]
        rounds.append(Round(residual, design, fits, best, ok, ties, workspace_residual=residual_w))
        if log:
            shown = ("[" + ", ".join(f"{v:.4g}" for v in best.values) + "]") if best.values else f"{best.value:.4g}"
            log(
                f"round {len(rounds)}: best {best.candidate.effect_id} = {shown} {best.candidate.unit}, "
                f"ΔBIC {best.score.delta_bic:.1f}, p {best.score.p_value:.2g}, "
                f"validation residual {-100 * best.score.validation_improvement:+.0f} % → {'accepted' if ok else 'rejected'}"
            )
        if not ok:
            break
        accepted.append(best)
        current = best.candidate.apply(current, best.applied)
        if workspace is not None and best.candidate.scope == "workspace":  # (_fit fits none without sweeps)
            base_w = workspace[0].simulate(current)
        else:
            base = forces.simulate(current)
            before = [q.value for q in accepted_parameters(accepted)]
            current, accepted, base = refine_jointly(current, accepted, forces, base)
            after = [q.value for q in accepted_parameters(accepted)]
            if log and after != before:
                log(
                    "joint refinement: "
                    + ", ".join(
                        f"{q.candidate.effect_id}{'' if q.drive is None else f'[{q.drive}]'} {b:.4g} → {q.value:.4g}"
                        for q, b in zip(accepted_parameters(accepted), before)
                    )
                )
            if sweep_data and any(f.candidate.effect_id == "kinematics.link_length" for f in accepted):
                sweep_data = Dataset.sweeps(current, sweeps)
                base_w = sweep_data.simulate(current)
    structure = (
        st.structure_left(rounds[-1].design, rounds[-1].residual)
        if trials
        else {"heldout_share": 0.0, "f_p_value": 1.0, "ljung_box_p_value": 1.0, "structured": False}
    )
    shape = characterise(rounds[-1].design, rounds[-1].residual, current) if trials else None
    return Selection(rounds, accepted, current, initial, base, structure, sweep_data, initial_w, base_w, shape)
