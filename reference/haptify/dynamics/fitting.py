"""Fitting a Hammerstein–Wiener model (spec §11.4): the fitting rules from the definition file, breakpoint
placement (§11.4.1), the ridge-regularised linear initialisation (§11.4.2) and Levenberg–Marquardt on the
normalised simulation error with the analytic Jacobian of :mod:`haptify.dynamics.jacobian` (§11.4.3).
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.signal import lfilter

from haptify.codes import Code
from haptify.dynamics import parameter_file
from haptify.dynamics.jacobian import (
    _add_normal_equations,
    _normal_equations,
    _Record,
    _Simulation,
    _simulation,
    _Structure,
    normal_equations_buffer,
)
from haptify.dynamics.parameter_file import (
    FAMILY,
    Channel,
    FitParameters,
    FitSummary,
    HWModelFile,
    PiecewiseLinearMap,
    QuaternionHemisphere,
    TransferFunction,
    UnitGainMap,
)
from haptify.dynamics.prediction import _delayed, hemisphere_align, rmse
from haptify.errors import fail
from haptify.formats.conventions import quat_mean
from haptify.metrics.metric_definitions import family


class FitOptions(FitParameters):
    """The fitting rules of spec §11.4 as one fit uses them (defaults: the definition file
    ``metrics/dynamics.json``)."""

    @classmethod
    def from_definition(cls, **overrides: Any) -> "FitOptions":
        """Options from the definition file, with keyword overrides (e.g. ``output_map="unit_gain"``)."""
        values: dict[str, Any] = parameter_file.PARAMETERS.model_dump(include=set(cls.model_fields))
        values.update(overrides)
        opts = cls.model_construct(**values)  # checked below, as the overrides need no type of their own
        for m in (opts.input_map, opts.output_map):
            if m not in parameter_file.MAP_TYPES:
                raise fail(Code.USAGE, f"unknown map type {m!r}", expected=list(parameter_file.MAP_TYPES), found=m)
        if opts.nb < 1 or opts.nf < 0 or opts.nk < 0 or opts.breakpoints < 2 or not abs(opts.initial_pole) < 1:
            raise fail(
                Code.USAGE,
                "invalid model orders or initialisation",
                expected="nb ≥ 1, nf ≥ 0, nk ≥ 0, breakpoints ≥ 2, |initial_pole| < 1",
                found={
                    "nb": opts.nb,
                    "nf": opts.nf,
                    "nk": opts.nk,
                    "breakpoints": opts.breakpoints,
                    "initial_pole": opts.initial_pole,
                },
            )
        return opts


def place_breakpoints(signal: np.ndarray, count: int, quantiles: tuple[float, float]) -> np.ndarray:
    """Breakpoints of a map fitted to ``signal`` (spec §11.4.1).

    Breakpoint k (1 … K) is the quantile p_lo + (p_hi − p_lo)(k − 1)/(K − 1) of the signal (numpy's
    default linear quantile). If two of them are closer than 1e-9 times their span, they are instead
    spread evenly between the end quantiles; if the span itself is below 1e-12·max(1, |centre|), the
    breakpoints are centre + (k − (K + 1)/2)·1e-6·max(1, |centre|).
    """
    x = np.asarray(signal, dtype=float)
    lo, hi = quantiles
    levels = lo + (hi - lo) * np.arange(count) / (count - 1)
    bp: np.ndarray = np.quantile(x, levels)
    span = bp[-1] - bp[0]
    centre = 0.5 * (bp[0] + bp[-1])
    scale = max(1.0, abs(centre))
    if span < 1e-12 * scale:
        out: np.ndarray = centre + (np.arange(count) - (count - 1) / 2.0) * 1e-6 * scale
        return out
    if np.min(np.diff(bp)) < 1e-9 * span:
        bp = np.linspace(bp[0], bp[-1], count)
    return bp


def _max_pole_modulus(st: _Structure, theta: np.ndarray) -> float:
    if st.nf == 0:
        return 0.0
    f = theta[st.f_idx].reshape(-1, st.nf)
    comp = np.zeros((len(f), st.nf, st.nf))
    comp[:, 0, :] = -f
    if st.nf > 1:
        comp[:, np.arange(1, st.nf), np.arange(st.nf - 1)] = 1.0
    return float(np.max(np.abs(np.linalg.eigvals(comp))))


@dataclass
class FitReport:
    """What :func:`fit` did: iterations, why it stopped, the cost history (spec §11.4.3)."""

    iterations: int
    stop_reason: str
    cost_history: list[float]


def _as_channels(names: Sequence[str] | None, units: Sequence[str] | None, n: int, prefix: str) -> list[Channel]:
    names = list(names) if names is not None else [f"{prefix}{k + 1}" for k in range(n)]
    units = list(units) if units is not None else ["1"] * n
    if len(names) != n or len(units) != n:
        raise fail(
            Code.HW_MODEL_DATA_MISMATCH,
            f"{n} {prefix} channels but {len(names)} names and {len(units)} units",
            expected=n,
            found=len(names),
        )
    return [Channel(name=a, unit=b) for a, b in zip(names, units)]


def _as_records(data: np.ndarray | Sequence[np.ndarray], what: str) -> list[np.ndarray]:
    records = [np.asarray(data, dtype=float)] if isinstance(data, np.ndarray) else [np.asarray(r, dtype=float) for r in data]
    if not records or any(r.ndim != 2 for r in records):
        raise fail(
            Code.HW_MODEL_DATA_MISMATCH,
            f"{what} must be a 2-D array (N, channels) or a list of them",
            expected="(N, channels)",
            found=[list(r.shape) for r in records],
        )
    return records


def fit(
    u: np.ndarray | Sequence[np.ndarray],
    y: np.ndarray | Sequence[np.ndarray],
    *,
    sample_rate_hz: float,
    options: FitOptions | None = None,
    input_names: Sequence[str] | None = None,
    input_units: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
    output_units: Sequence[str] | None = None,
    quaternion_columns: Sequence[int] | None = None,
    session_id: str | None = None,
    trial_id: str | None = None,
) -> tuple[HWModelFile, FitReport]:
    """Fit a Hammerstein–Wiener model to inputs ``u (N, nu)`` and outputs ``y (N, ny)`` (spec §11.4).

    ``u`` and ``y`` may also be lists of records (contiguous runs of one trial split by gaps); each
    record is simulated from zero initial conditions and the cost sums over all of them (as MATLAB
    does for merged multi-experiment data). Breakpoints at training quantiles, a ridge-regularised
    linear initialisation, then Levenberg–Marquardt on the normalised simulation error with an
    analytic Jacobian. Returns the parameter file model and a :class:`FitReport`.
    """
    with one_blas_thread():
        return _fit(
            u,
            y,
            sample_rate_hz=sample_rate_hz,
            options=options or FitOptions.from_definition(),
            input_names=input_names,
            input_units=input_units,
            output_names=output_names,
            output_units=output_units,
            quaternion_columns=quaternion_columns,
            session_id=session_id,
            trial_id=trial_id,
        )


def one_blas_thread() -> contextlib.AbstractContextManager[Any]:
    """BLAS limited to one thread while fitting (and in :func:`haptify.dynamics.distance.nearest_distances`),
    when ``threadpoolctl`` is installed.

    The fit's matrix products are tall and thin (≈ 200 × 14 000); a threaded BLAS gains little on them
    and collapses when the cores are shared (benchmarks/RESULTS.md, the local dynamic model). Results do not
    depend on it beyond floating-point rounding.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - the dependency is declared; this only guards odd installs
        return contextlib.nullcontext()
    limits: contextlib.AbstractContextManager[Any] = threadpool_limits(limits=1, user_api="blas")
    return limits


def _fit(
    u: np.ndarray | Sequence[np.ndarray],
    y: np.ndarray | Sequence[np.ndarray],
    *,
    sample_rate_hz: float,
    options: FitOptions,
    input_names: Sequence[str] | None,
    input_units: Sequence[str] | None,
    output_names: Sequence[str] | None,
    output_units: Sequence[str] | None,
    quaternion_columns: Sequence[int] | None,
    session_id: str | None,
    trial_id: str | None,
) -> tuple[HWModelFile, FitReport]:
    """:func:`fit` in one BLAS thread: the training records, the starting point (spec §11.4.1–2), the descent
    (§11.4.3), and the parameter file with its fit summary (§11.5.1)."""
    us, ys, hemi = _training_records(u, y, quaternion_columns)
    u_all, y_all = np.vstack(us), np.vstack(ys)
    n = len(u_all)
    start = _starting_point(us, u_all, y_all, options)
    rec = _Record.of(start.st, u_all, y_all, starts=np.cumsum([0] + [len(a) for a in us[:-1]]))
    wy = 1.0 / (start.sd_y * math.sqrt(n))  # residual weights (spec §11.4.2)
    descent = _levenberg_marquardt(_Cost(start.st, rec, start.theta0, options.ridge * start.scale**2, wy), options)
    model = _assemble(
        start.st,
        descent.theta,
        sample_rate_hz,
        hemi,
        _as_channels(input_names, input_units, start.st.nu, "u"),
        _as_channels(output_names, output_units, start.st.ny, "y"),
    )
    yhat = descent.sim.yhat  # the records simulated at the final θ (spec §11.3)
    err = np.linalg.norm(y_all - yhat, axis=0)
    denom = np.linalg.norm(y_all - start.mu_y, axis=0)
    fit_pct = np.where(denom > 0, 100.0 * (1.0 - err / np.where(denom > 0, denom, 1.0)), 0.0)
    model.fit = FitSummary(
        session_id=session_id,
        trial_id=trial_id,
        samples=n,
        iterations=descent.iterations,
        stop_reason=descent.stop_reason,
        cost=descent.cost,
        rmse=rmse(y_all, yhat).tolist(),
        fit_percent=fit_pct.tolist(),
        definition_version=family(FAMILY).version,
    )
    return model, FitReport(iterations=descent.iterations, stop_reason=descent.stop_reason, cost_history=descent.history)


def _training_records(
    u: np.ndarray | Sequence[np.ndarray], y: np.ndarray | Sequence[np.ndarray], quaternion_columns: Sequence[int] | None
) -> tuple[list[np.ndarray], list[np.ndarray], QuaternionHemisphere | None]:
    """The input and output records, checked to pair up and be finite (E703), the inputs' quaternions aligned
    to the hemisphere of their mean when ``quaternion_columns`` are given (spec §11.3 step 1, §11.5.1)."""
    us = _as_records(u, "inputs")
    ys = _as_records(y, "outputs")
    if (
        len(us) != len(ys)
        or any(len(a) != len(b) for a, b in zip(us, ys))
        or len({a.shape[1] for a in us}) != 1
        or len({b.shape[1] for b in ys}) != 1
    ):
        raise fail(
            Code.HW_MODEL_DATA_MISMATCH,
            "input and output records must pair up with equal lengths and channel counts",
            expected="matching records",
            found=[[list(a.shape), list(b.shape)] for a, b in zip(us, ys)],
        )
    if not all(np.all(np.isfinite(a)) for a in us + ys):
        raise fail(Code.HW_MODEL_DATA_MISMATCH, "training data hold non-finite values", expected="finite", found="NaN or inf")
    hemi = None
    if quaternion_columns is not None:
        cols = [int(c) for c in quaternion_columns]
        hemi = QuaternionHemisphere(columns=cols, reference=[float(v) for v in quat_mean(np.vstack(us)[:, cols])])
        us = [hemisphere_align(a, hemi) for a in us]
    return us, ys, hemi


@dataclass
class _Start:
    """Where the descent starts (spec §11.4.1–2): the structure with its breakpoints, θ₀, the scale D of the
    ridge term per parameter, and the outputs' means and standard deviations (1 where constant)."""

    st: _Structure
    theta0: np.ndarray
    scale: np.ndarray
    mu_y: np.ndarray
    sd_y: np.ndarray


def _starting_point(us: list[np.ndarray], u_all: np.ndarray, y_all: np.ndarray, opts: FitOptions) -> _Start:
    """Breakpoints, initial maps w_i = (u_i − mean)/std and y_j = mean + std · x_j, and the initial linear
    block of :func:`_initial_linear_block` (spec §11.4.1–2)."""
    nu, ny = u_all.shape[1], y_all.shape[1]
    # -- §11.4.1 input breakpoints and initial input maps: w_i = (u_i − mean)/std -------------------
    mu_u = u_all.mean(axis=0)
    sd_u = np.where(u_all.std(axis=0) > 0, u_all.std(axis=0), 1.0)
    pwl_in = opts.input_map == "piecewise_linear"
    in_bp = [place_breakpoints(u_all[:, i], opts.breakpoints, opts.breakpoint_quantiles) if pwl_in else None for i in range(nu)]
    mu_y = y_all.mean(axis=0)
    sd_y = np.where(y_all.std(axis=0) > 0, y_all.std(axis=0), 1.0)
    pwl_out = opts.output_map == "piecewise_linear"
    # -- §11.4.2 initial linear block, then the output breakpoints on its response ------------------
    inputs = [(a - mu_u) / sd_u if pwl_in else a for a in us]
    f0, b0, x0 = _initial_linear_block(inputs, (y_all - mu_y) / sd_y if pwl_out else y_all, opts)
    out_bp = [place_breakpoints(x0[:, j], opts.breakpoints, opts.breakpoint_quantiles) if pwl_out else None for j in range(ny)]
    st = _Structure(nu=nu, ny=ny, nb=opts.nb, nf=opts.nf, nk=opts.nk, in_bp=in_bp, out_bp=out_bp)
    theta0 = np.zeros(st.size)
    scale = np.ones(st.size)  # D of the ridge term
    for i, bp in enumerate(in_bp):
        if bp is not None:
            theta0[st.v_idx[i]] = (bp - mu_u[i]) / sd_u[i]
    for j, bp in enumerate(out_bp):
        for i in range(nu):
            theta0[st.b_idx[j, i]] = b0[i * opts.nb : (i + 1) * opts.nb, j]
            theta0[st.f_idx[j, i]] = f0
        if bp is not None:
            theta0[st.c_idx[j]] = mu_y[j] + sd_y[j] * bp
            scale[st.c_idx[j]] = 1.0 / sd_y[j]
    return _Start(st=st, theta0=theta0, scale=scale, mu_y=mu_y, sd_y=sd_y)


def _initial_linear_block(
    inputs: list[np.ndarray], target: np.ndarray, opts: FitOptions
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The initial linear block of spec §11.4.2 from the initially mapped input records: F = (1 − p q^-1)^nf
    and B by ridge least squares of ``target`` (N, ny) on the delayed, F-filtered inputs. Returns f₀, B₀
    (nu·nb, ny) and the block's response x₀ (N, ny)."""
    f0 = np.poly(np.full(opts.nf, opts.initial_pole))[1:] if opts.nf else np.zeros(0)
    regs = []
    for w0 in inputs:
        wf = lfilter([1.0], np.concatenate([[1.0], f0]), w0, axis=0)
        regs.append(np.column_stack([_delayed(wf[:, i], opts.nk + k) for i in range(w0.shape[1]) for k in range(opts.nb)]))
    reg = np.vstack(regs)
    n = len(reg)
    gram = reg.T @ reg / n + opts.ridge * np.eye(reg.shape[1])
    b0 = np.linalg.solve(gram, reg.T @ target / n)  # (nu·nb, ny)
    return f0, b0, reg @ b0


@dataclass
class _Cost:
    """The cost of spec §11.4.2 over the stacked records: the ridge term Σ d²(θ − θ₀)² plus the weighted
    squared simulation errors."""

    st: _Structure
    rec: _Record
    theta0: np.ndarray
    d2: np.ndarray  # ridge weight · D² per parameter
    wy: np.ndarray  # residual weight per output

    def __call__(self, theta: np.ndarray) -> tuple[float, _Simulation]:
        """The cost at θ and the simulation it ran (the next Jacobian's, if accepted)."""
        sim = _simulation(self.st, theta, self.rec)
        e = (self.rec.y - sim.yhat) * self.wy
        return float(np.sum(self.d2 * (theta - self.theta0) ** 2)) + float(np.sum(e * e)), sim


@dataclass
class _Descent:
    """Where Levenberg–Marquardt ended (spec §11.4.3): θ, its cost and simulation, the cost history, the
    accepted iterations and why it stopped."""

    theta: np.ndarray
    cost: float
    sim: _Simulation
    history: list[float]
    iterations: int
    stop_reason: str


def _levenberg_marquardt(cost: _Cost, opts: FitOptions) -> _Descent:
    """Levenberg–Marquardt from θ₀ on the normal equations of the analytic Jacobian (spec §11.4.3): stops at
    ``max_iterations``, when an accepted step lowers the cost by less than ``tolerance`` (relative), or when no
    damping up to its limit gives a stable step that lowers the cost."""
    st = cost.st
    mu, _, down, _ = opts.lm_damping
    theta = cost.theta0.copy()
    current, sim = cost(theta)
    history = [current]
    block = normal_equations_buffer(st, len(cost.rec.u))
    own = [st.own(j) for j in range(st.ny)]
    stop = "max_iterations"
    iterations = 0
    for iterations in range(1, opts.max_iterations + 1):
        hess = np.diag(cost.d2)
        grad = cost.d2 * (theta - cost.theta0)  # half the gradient of the cost
        for j, (gram, jac_e) in enumerate(_normal_equations(st, theta, cost.rec, cost.wy, sim, block)):
            _add_normal_equations(hess, grad, st.n_shared, own[j], gram, jac_e)
        step = _damped_step(cost, theta, current, hess, grad, mu, opts)
        if step is None:
            stop = "damping_limit"
            iterations -= 1
            break
        mu, theta, new, sim = step
        gain = (current - new) / current if current > 0 else 0.0
        current = new
        history.append(current)
        mu = max(mu * down, 1e-12)
        if gain < opts.tolerance:
            stop = "tolerance"
            break
    return _Descent(theta=theta, cost=current, sim=sim, history=history, iterations=iterations, stop_reason=stop)


def _damped_step(
    cost: _Cost, theta: np.ndarray, current: float, hess: np.ndarray, grad: np.ndarray, mu: float, opts: FitOptions
) -> tuple[float, np.ndarray, float, _Simulation] | None:
    """One Levenberg–Marquardt step (spec §11.4.3): the damping μ raised by ``up`` until (H + μ diag H) s = −g
    is solvable, θ + s keeps every pole inside ``stability_radius`` and lowers the cost; returns μ, θ + s, its
    cost and simulation, or None once μ passes its limit."""
    _, up, _, mu_max = opts.lm_damping
    while mu <= mu_max:
        try:
            step = -cho_solve(cho_factor(hess + mu * np.diag(np.diag(hess))), grad)
        except (np.linalg.LinAlgError, ValueError):  # not positive definite, or not finite
            mu *= up
            continue
        trial = theta + step
        if _max_pole_modulus(cost.st, trial) >= opts.stability_radius:
            mu *= up
            continue
        new, trial_sim = cost(trial)
        if np.isfinite(new) and new < current:
            return mu, trial, new, trial_sim
        mu *= up
    return None


def _assemble(
    st: _Structure,
    theta: np.ndarray,
    rate: float,
    hemi: QuaternionHemisphere | None,
    inputs: list[Channel],
    outputs: list[Channel],
) -> HWModelFile:
    def pwl(bp: np.ndarray | None, idx: np.ndarray | None) -> UnitGainMap | PiecewiseLinearMap:
        return UnitGainMap() if bp is None else PiecewiseLinearMap(breakpoints=bp.tolist(), values=theta[idx].tolist())

    return HWModelFile(
        sample_rate_hz=rate,
        inputs=inputs,
        outputs=outputs,
        input_maps=[pwl(st.in_bp[i], st.v_idx[i]) for i in range(st.nu)],
        output_maps=[pwl(st.out_bp[j], st.c_idx[j]) for j in range(st.ny)],
        linear=[
            [TransferFunction(b=theta[st.b_idx[j, i]].tolist(), f=theta[st.f_idx[j, i]].tolist(), nk=st.nk) for i in range(st.nu)]
            for j in range(st.ny)
        ],
        quaternion_hemisphere=hemi,
    )
