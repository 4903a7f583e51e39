"""Measurement uncertainty of the metrics: GUM budgets (spec chapter 19).

Which method applies to which metric, the Type B sources and the Monte Carlo parameters live in
``schemas/<v>/uncertainty.json``. Type A comes from the repetitions (s/√n, n − 1 degrees of freedom;
GUM 4.2). Type B is propagated by Monte Carlo (GUM Supplement 1) through the reference's own family
computations: each draw perturbs the cached calibrated hand force of every trial (a force offset and a
delay, common to the session) and recomputes the families that read it, sharing every other cached
intermediate (the pose, the plate, the calibration) with the plain computation. The two combine by
root sum of squares; the coverage factor is Student's t at the Welch–Satterthwaite effective degrees
of freedom (GUM G.4, G.6.4).
"""

from __future__ import annotations

import importlib
import math
import zlib
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any, Literal, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy import stats

from haptify import schemas
from haptify.metrics.metric_definitions import FamilyParameters, Parameter, validate_parameters
from haptify.pipeline.families import family_module
from haptify.pipeline.results import BudgetTerm, MetricResult, MetricUncertainty, ResultsFile, UncorrectedBias, Value
from haptify.processing import preprocessing
from haptify.processing.preprocessing import lowpass_resample

# --- the definition file (spec §19.1) ------------------------------------------------------------


class Source(BaseModel):
    """One source of uncertainty (spec §19.2–19.3): Type A (the repetitions) or a Type B input whose
    standard uncertainty comes from a rig figure of the same session."""

    model_config = ConfigDict(extra="forbid")
    type: Literal["A", "B"]
    distribution: Literal["t", "normal", "rectangular"]
    figure: str | None = Field(
        description="The rig metric whose value gives the input's standard uncertainty (normal) or half-width (rectangular)."
    )
    component: int | None = Field(description="Which component of a vector figure; null for a scalar.")
    unit: str
    perturbs: Literal["handle_force_offset", "handle_force_delay"] | None = Field(
        description="What one Monte Carlo draw changes in the cached calibrated hand force (§19.3)."
    )
    description: str


class Bias(BaseModel):
    """A systematic effect a metric's value keeps (spec §19.3): its estimate, from a rig figure of the same
    session or from the trial's own recording, is added to U (GUM F.2.4.5)."""

    model_config = ConfigDict(extra="forbid")
    figure: str | None = Field(
        description="The rig metric whose value is the effect's input (noise_maximum: the force noise's sd); null "
        "when the input is measured from the trial's own recording (mocap_noise: the track's noise, §19.3)."
    )
    component: int | None = Field(description="Which component of a vector figure; null for a scalar.")
    unit: str
    description: str


class MetricMethod(BaseModel):
    """How one metric's uncertainty is evaluated (spec §19.1): ``type_a``, ``type_a_mc`` (Type A and the
    Monte Carlo Type B of ``sources``) or ``none`` (with the reason); ``bias`` names a one-sided effect the
    value keeps (§19.3)."""

    model_config = ConfigDict(extra="forbid")
    method: Literal["type_a", "type_a_mc", "none"]
    sources: list[str] = Field(default_factory=list, description="Type B sources, for type_a_mc.")
    bias: Literal["noise_maximum", "mocap_noise"] | None = Field(
        None, description="A systematic effect left in the value, its estimate added to U (§19.3)."
    )
    reason: str | None = Field(None, description="Why Type B is not propagated (type_a) or nothing applies (none).")


class UncertaintyDefinitions(BaseModel):
    """``schemas/<v>/uncertainty.json`` (spec §19.1)."""

    model_config = ConfigDict(extra="forbid")
    version: str = Field(pattern=r"^\d+\.\d+\.\d+$")
    spec_section: str
    parameters: dict[str, Parameter]
    sources: dict[str, Source]
    biases: dict[str, Bias] = Field(default_factory=dict)
    metrics: dict[str, MetricMethod]


@lru_cache(maxsize=None)
def definitions() -> UncertaintyDefinitions:
    """The parsed ``uncertainty.json`` (spec §19.1)."""
    return UncertaintyDefinitions.model_validate(schemas.load("uncertainty.json"))


class UncertaintyParameters(FamilyParameters):
    """The parameters of ``uncertainty.json`` (spec §19.1), in the units its definition file states."""

    coverage_probability: float
    mc_draws: int
    mc_seed: int
    noise_bias_draws: int
    min_noise_differences: int


#: The uncertainty family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = validate_parameters(definitions().parameters, UncertaintyParameters, "uncertainty.json")


def method_of(metric_id: str) -> MetricMethod:
    """The method of ``metric_id`` (KeyError for an id without one; a test checks every metric has one)."""
    return definitions().metrics[metric_id]


# --- GUM arithmetic (spec §19.2, §19.4) ----------------------------------------------------------


def type_a(per_repetition: Sequence[Any]) -> tuple[np.ndarray, int]:
    """Standard uncertainty of the mean s/√n (ddof = 1) per component and its degrees of freedom n − 1
    (GUM 4.2.3; spec §19.2). ValueError below two repetitions."""
    x = np.asarray(per_repetition, dtype=float)
    if len(x) < 2:
        raise ValueError("Type A needs at least two repetitions")
    return x.std(axis=0, ddof=1) / math.sqrt(len(x)), len(x) - 1


def welch_satterthwaite(contributions: Sequence[Any] | np.ndarray, dofs: Sequence[float]) -> np.ndarray:
    """Effective degrees of freedom ν = u⁴ / Σ uᵢ⁴/νᵢ of the root-sum-square of ``contributions``
    (GUM G.4.1, eq. G.2b; spec §19.4); an infinite νᵢ adds nothing to the denominator."""
    c = np.asarray(contributions, dtype=float)
    nu = np.asarray(dofs, dtype=float).reshape((-1,) + (1,) * (c.ndim - 1))
    u4 = np.sum(c**2, axis=0) ** 2
    den = np.sum(np.where(np.isinf(nu), 0.0, c**4 / np.where(np.isinf(nu), 1.0, nu)), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, u4 / np.where(den > 0, den, 1.0), np.inf)


def coverage_factor(dof: float, p: float) -> float:
    """Student's t quantile t_{(1+p)/2}(ν) (GUM G.3.4, Table G.2; spec §19.4); the normal quantile for ν = ∞."""
    return float(stats.norm.ppf(0.5 + p / 2) if math.isinf(dof) else stats.t.ppf(0.5 + p / 2, dof))


def combine(terms: list[BudgetTerm], p: float) -> tuple[Any, Any, float, float | None]:
    """(u, U, k, ν_eff) from a budget (spec §19.4): root sum of squares of the contributions, ν_eff by
    :func:`welch_satterthwaite` over the least-degrees component, k = t_{(1+p)/2}(ν_eff). ν_eff is None
    when infinite (JSON has no infinity)."""
    c = np.array([t.contribution for t in terms], dtype=float)
    nus = [math.inf if t.dof is None else t.dof for t in terms]
    u = np.sqrt(np.sum(c**2, axis=0))
    nu = float(np.min(welch_satterthwaite(c, nus)))
    k = coverage_factor(nu, p)
    as_value = (lambda a: [float(x) for x in a]) if u.ndim else float
    return as_value(u), as_value(k * u), k, None if math.isinf(nu) else nu


# --- Type B inputs from the session's rig figures (spec §19.3) -------------------------------------


@dataclass
class Input:
    """One Type B input of this session: its source id, the figure's value and the standard uncertainty."""

    source: str
    figure_value: float
    u: float

    @property
    def spec(self) -> Source:
        return definitions().sources[self.source]

    @property
    def dimension(self) -> int:
        """Scalar inputs drawn per draw: three force components for an offset, one delay."""
        return 3 if self.spec.perturbs == "handle_force_offset" else 1


def rig_figure(ctx: Any, results: ResultsFile, metric_id: str) -> MetricResult | None:
    """The rig metric ``metric_id`` from ``results``, or computed on ``ctx`` when it was not asked for;
    None when the session cannot give it (spec §19.3)."""
    got = results.get(metric_id)
    if got is not None:
        return got
    from haptify.metrics.rig_checks import _safe_metric

    res = _safe_metric(ctx, metric_id)
    return res if isinstance(res, MetricResult) else None


def scalar(value: Value, component: int | None) -> float:
    """A figure's scalar: ``value`` itself, or its ``component`` of a vector (spec §19.3)."""
    if isinstance(value, list):
        if component is None:
            raise ValueError("a vector figure needs a component")
        return float(value[component])
    return float(value)


def session_inputs(ctx: Any, results: ResultsFile, source_ids: Sequence[str]) -> tuple[list[Input], list[str]]:
    """The Type B inputs of ``source_ids`` this session's rig figures give, and the ids it cannot give
    (spec §19.3). Normal: u = the figure; rectangular: half-width a = |figure|, u = a/√3 (GUM 4.3.7)."""
    found, missing = [], []
    for sid in source_ids:
        spec = definitions().sources[sid]
        fig = rig_figure(ctx, results, spec.figure) if spec.figure is not None else None
        if fig is None:
            missing.append(sid)
            continue
        value = abs(scalar(fig.value, spec.component))
        found.append(Input(sid, value, value if spec.distribution == "normal" else value / math.sqrt(3.0)))
    return found, missing


def draw_inputs(inputs: Sequence[Input], m: int, rng: np.random.Generator) -> np.ndarray:
    """The (m, Σ dimension) matrix of input draws (spec §19.3): normal N(0, u²) per component, or uniform
    in ±a (a = √3·u)."""
    cols = []
    for inp in inputs:
        shape = (m, inp.dimension)
        if inp.spec.distribution == "normal":
            cols.append(rng.normal(0.0, inp.u, shape))
        else:
            a = inp.u * math.sqrt(3.0)
            cols.append(rng.uniform(-a, a, shape))
    return np.concatenate(cols, axis=1) if cols else np.zeros((m, 0))


# --- perturbing the cached intermediates (spec §19.3) -----------------------------------------------

# Cache entries (by their key's first element) that do not depend on the calibrated hand force: a draw
# shares them with the plain computation. Everything else a family caches is recomputed per draw.
SHARED_KEYS = frozenset(
    {
        "handle_calibration",
        "handle_calibration_fit",
        "plate_bias",
        "plate_signals",
        "mocap_track",
        "handle_accel_native",
        "vibration",
        "free_space_plate",
        "workspace_model",
        "workspace_cloud",
        "workspace_solid",
        "workspace_track",
        "dynamics_model",
        "dynamics_given_model",
    }
)


def delayed(t: np.ndarray, x: np.ndarray, valid: np.ndarray, delay_s: float) -> np.ndarray:
    """``x`` delayed by ``delay_s`` on its grid ``t``: x(t − delay) at the valid rows, linear interpolation
    between valid rows, held at the ends (spec §19.3)."""
    out = x.copy()
    tv = t[valid]
    for c in range(x.shape[1]):
        out[valid, c] = np.interp(tv - delay_s, tv, x[valid, c])
    return out


def perturb_force(hs: Any, offset_n: np.ndarray, delay_s: float) -> Any:
    """A copy of :class:`haptify.processing.signals.HandleSignals` whose hand force is delayed by ``delay_s`` and
    offset by ``offset_n (3,)`` (spec §19.3); nothing else changes."""
    if hs.force is None:
        return hs
    force = delayed(hs.t, hs.force, hs.valid, delay_s) if delay_s else hs.force.copy()
    force[hs.valid] += offset_n
    return replace(hs, force=force)


class PerturbedContext:
    """A ComputeContext view for one Monte Carlo draw (spec §19.3): cached handle signals come from the
    base context with the draw's force offset and delay applied; :data:`SHARED_KEYS` come from the base;
    everything else is computed afresh on this view. Warnings raised in a draw are dropped."""

    def __init__(self, base: Any, wanted: set[str], offset_n: np.ndarray, delay_s: float):
        self.base, self.session, self.wanted, self.parameters = base, base.session, wanted, base.parameters
        self.offset_n, self.delay_s = offset_n, delay_s
        self.warnings: list[Any] = []
        self._cache: dict[Any, Any] = {}

    def cached(self, key: Any, build: Any) -> Any:
        if key[0] in SHARED_KEYS:
            return self.base.cached(key, build)
        if key[0] == "handle_signals":
            if key not in self._cache:
                self._cache[key] = perturb_force(self.base.cached(key, build), self.offset_n, self.delay_s)
            return self._cache[key]
        if key not in self._cache:
            self._cache[key] = build()
        return self._cache[key]

    def wants(self, metric_id: str) -> bool:
        return metric_id in self.wanted

    def warn(self, *args: Any, **kwargs: Any) -> None:
        return None


def draw_values(ctx: Any, metric_ids: Sequence[str], inputs: Sequence[Input], x: np.ndarray) -> dict[str, np.ndarray]:
    """The aggregated value of each metric under each draw (row of ``x``): NaN where a draw left the
    metric unavailable (spec §19.3). Families are run through their own ``compute``."""
    modules = sorted({family_module(m) for m in metric_ids})
    out = {m: np.full(len(x), np.nan) for m in metric_ids}
    for j, row in enumerate(x):
        offset, delay, col = np.zeros(3), 0.0, 0
        for inp in inputs:
            if inp.spec.perturbs == "handle_force_offset":
                offset = offset + row[col : col + 3]
            else:
                delay += float(row[col])
            col += inp.dimension
        view = PerturbedContext(ctx, set(metric_ids), offset, delay)
        for name in modules:
            for item in importlib.import_module(name).compute(view):
                if isinstance(item, MetricResult) and item.id in out:
                    out[item.id][j] = scalar(item.value, None)
    return out


def mc_terms(inputs: Sequence[Input], x: np.ndarray, y: np.ndarray) -> list[BudgetTerm]:
    """Type B budget terms from one metric's Monte Carlo sample (spec §19.3).

    The sample's standard deviation (M − 1 degrees of freedom, draws that left the metric unavailable
    dropped) is the Type B standard uncertainty; it is split among the sources by a least-squares linear
    fit of ``y`` on the draws: a source's sensitivity is the norm of its slopes (metric unit per input
    unit), its share |slope|·u, and the shares are scaled to add in quadrature to the sample's value
    (equal shares when the fit finds no linear part).
    """
    ok = np.isfinite(y)
    x, y = x[ok], y[ok]
    m = len(y)
    if m < 2:
        return []
    u_mc = float(y.std(ddof=1))
    fit = np.column_stack([np.ones(m), x - x.mean(axis=0)])
    slope = np.linalg.lstsq(fit, y, rcond=None)[0][1:] if m > x.shape[1] + 1 else np.zeros(x.shape[1])
    spread = x.std(axis=0, ddof=1)
    bounds = np.cumsum([0] + [inp.dimension for inp in inputs])
    shares = [float(np.sqrt(np.sum((slope[a:b] * spread[a:b]) ** 2))) for a, b in zip(bounds[:-1], bounds[1:])]
    if not any(shares):  # no linear part (e.g. a symmetric dependence): equal shares
        shares = [1.0] * len(shares)
    scale = u_mc / math.sqrt(sum(v**2 for v in shares))
    return [
        BudgetTerm(
            source=inp.source,
            type="B",
            distribution=inp.spec.distribution,
            u_input=inp.u,
            unit=inp.spec.unit,
            sensitivity=float(np.linalg.norm(slope[a:b])),
            contribution=share * scale,
            dof=m - 1,
        )
        for inp, share, a, b in zip(inputs, shares, bounds[:-1], bounds[1:])
    ]


# --- a one-sided effect: the noise's maximum (spec §19.3) -------------------------------------------


def force_noise(t: np.ndarray, native_rate_hz: float, draws: int, rng: np.random.Generator) -> np.ndarray:
    """``(len(t), draws)`` draws of the force noise on the grid times ``t`` (s), unit standard deviation:
    white Gaussian noise at the handle wrench stream's ``native_rate_hz`` low-passed and resampled exactly as
    the force (§7.2, :func:`lowpass_resample`), scaled by its sample standard deviation (spec §19.3)."""
    pad = 0.5  # s either side: the filter's start-up lies outside t
    t_src = np.arange(t[0] - pad, t[-1] + pad, 1.0 / native_rate_hz)
    e: np.ndarray = lowpass_resample(
        t_src, rng.standard_normal((len(t_src), draws)), t, preprocessing.PARAMETERS.wrench_cutoff_hz
    )
    return e / float(e.std())


def noise_maximum_excess(f: np.ndarray, noise: np.ndarray, sigma: float) -> float:
    """SIMEX estimate (Cook & Stefanski 1994) of how far ``max f`` reads above the maximum of the noise-free
    force, N (spec §19.3): with noise of sd ``sigma`` added once more (``noise``: unit-sd draws, one per
    column), the mean maximum rises by Δ; the maximum's excess grows as the noise's sd, so the excess at
    sd σ is Δ / (√2 − 1). Near zero where one sharp top decides the maximum, large on a noisy plateau."""
    added = float(np.mean(np.max(f[:, None] + sigma * noise, axis=0)))
    return (added - float(np.max(f))) / (math.sqrt(2.0) - 1.0)


def noise_maximum_bias(
    ctx: Any, results: ResultsFile, result: MetricResult, rng: np.random.Generator, draws: int
) -> UncorrectedBias | None:
    """The ``noise_maximum`` bias of ``result`` (spec §19.3): per trial the mean over its maxima of
    :func:`noise_maximum_excess` (the family's ``maximum_windows``), then the mean over the trials the value
    rests on, at least 0 (a maximum never reads low on average). None when the figure is missing."""
    spec = definitions().biases["noise_maximum"]
    assert spec.figure is not None  # noise_maximum rests on a rig figure (uncertainty.json)
    fig = rig_figure(ctx, results, spec.figure)
    if fig is None:
        return None
    sigma = abs(scalar(fig.value, spec.component))
    windows = importlib.import_module(family_module(result.id)).maximum_windows
    per_trial = []
    for trial_id in result.trials:
        rate = float(ctx.session.stream(trial_id, "handle_wrench").rate_hz)
        per_trial.append(
            np.mean([noise_maximum_excess(f, force_noise(t, rate, draws, rng), sigma) for t, f in windows(ctx, trial_id)])
        )
    return UncorrectedBias(source="noise_maximum", estimate=max(0.0, float(np.mean(per_trial))), u_input=sigma, unit=spec.unit)


# --- a systematic effect of the motion-capture noise on a cloud's metrics (spec §19.3) ---------------


def track_noise_sd(position: np.ndarray) -> np.ndarray:
    """Per-axis standard deviation (m) of the white noise on a motion-capture track ``(N, 3)`` in time order,
    NaN rows occluded (spec §19.3): the median absolute deviation (× 1.4826) of its third differences over
    √20 (white noise of sd σ gives third differences of variance 20σ²; a smooth path adds only its jerk
    times the sample interval cubed). NaN per axis with fewer than ``min_noise_differences`` differences."""
    d3 = np.diff(np.asarray(position, dtype=float), n=3, axis=0)
    d3 = d3[np.all(np.isfinite(d3), axis=1)]
    if len(d3) < PARAMETERS.min_noise_differences:
        return np.full(3, math.nan)
    mad = np.median(np.abs(d3 - np.median(d3, axis=0)), axis=0)
    sd: np.ndarray = 1.4826 * mad / math.sqrt(20.0)
    return sd


def mocap_noise_draws(ctx: Any, family: Any, trial_id: str, draws: int, seed: int) -> tuple[np.ndarray, list[dict[str, float]]]:
    """The trial's track noise sd (m, per axis; :func:`track_noise_sd`) and ``draws`` recomputations of the
    family's per-trial values with noise of that sd added once more to its cloud (spec §19.3), cached per
    trial so that every metric of the family shares them. The noise of a trial is drawn from numpy's
    ``default_rng([seed, 2, crc32(trial id)])``."""

    def build() -> tuple[np.ndarray, list[dict[str, float]]]:
        sigma = track_noise_sd(family.trial_track(ctx, trial_id)[1])
        if not np.all(np.isfinite(sigma)):
            return sigma, []
        rng = np.random.default_rng([seed, 2, zlib.crc32(trial_id.encode())])
        return sigma, [family.noisy_trial_values(ctx, trial_id, sigma, rng) for _ in range(draws)]

    cached: tuple[np.ndarray, list[dict[str, float]]] = ctx.cached(("mocap_noise_draws", trial_id, draws, seed), build)
    return cached


def mocap_noise_bias(ctx: Any, result: MetricResult, draws: int, seed: int) -> UncorrectedBias | None:
    """The ``mocap_noise`` bias of ``result`` (spec §19.3) by SIMEX: per trial, Δ = the mean of the value
    recomputed with the track's own noise added once more (:func:`mocap_noise_draws`) less the trial's value;
    the effect grows as the noise's variance, so Δ estimates it at the recorded noise. The mean Δ over the
    trials the value rests on, signed; None when a track's noise cannot be estimated."""
    family = importlib.import_module(family_module(result.id))
    shifts, sigmas = [], []
    for trial_id, value in zip(result.trials, result.per_repetition):
        sigma, values = mocap_noise_draws(ctx, family, trial_id, draws, seed)
        if not values:
            return None
        shifts.append(float(np.mean([v[result.id] for v in values])) - scalar(value, None))
        sigmas.append(float(np.sqrt(np.mean(sigma**2))))
    unit = definitions().biases["mocap_noise"].unit
    return UncorrectedBias(source="mocap_noise", estimate=float(np.mean(shifts)), u_input=float(np.mean(sigmas)), unit=unit)


def bias_estimate(
    ctx: Any, results: ResultsFile, result: MetricResult, rng: np.random.Generator, draws: int, seed: int
) -> UncorrectedBias | None:
    """The estimate of the bias ``result``'s method names (spec §19.3), or None when it names none or its
    input is missing: ``noise_maximum`` with the force-noise generator ``rng`` and ``draws`` draws,
    ``mocap_noise`` with ``noise_bias_draws`` recomputations per trial."""
    name = method_of(result.id).bias
    if name == "noise_maximum":
        return noise_maximum_bias(ctx, results, result, rng, draws)
    if name == "mocap_noise":
        return mocap_noise_bias(ctx, result, PARAMETERS.noise_bias_draws, seed)
    return None


def repeatability_term(result: MetricResult) -> BudgetTerm:
    """The Type A term of a metric record with an ``sd`` (spec §19.2): s/√n of its per-repetition values,
    or for a metric whose n counts other samples (rig.cop_error: placements), sd/√n with n − 1 degrees."""
    if result.n != len(result.per_repetition):
        u = np.asarray(result.sd, dtype=float) / math.sqrt(result.n)
        dof = result.n - 1
    else:
        u, dof = type_a(result.per_repetition)
    contrib = [float(v) for v in u] if np.ndim(u) else float(u)
    return BudgetTerm(
        source="repeatability",
        type="A",
        distribution="t",
        u_input=contrib,
        unit=result.unit,
        sensitivity=1.0,
        contribution=contrib,
        dof=float(dof),
    )


def attach(ctx: Any, results: ResultsFile, *, draws: int | None = None, seed: int | None = None) -> ResultsFile:
    """Give every metric of ``results`` its uncertainty record where its method applies (spec §19.4);
    U = k·u, plus the magnitude of the estimate of the bias the method names (§19.3).

    A metric with fewer than two repetitions gets none (Type A cannot be evaluated, §19.2). The Type B
    inputs are drawn once for the session; the metrics with the same sources share one Monte Carlo run
    (their families recomputed once per draw). A metric that a draw leaves unavailable uses the others.
    """
    p = PARAMETERS.coverage_probability
    m = int(PARAMETERS.mc_draws if draws is None else draws)
    seed = int(PARAMETERS.mc_seed if seed is None else seed)
    eligible = [r for r in results.metrics if method_of(r.id).method != "none" and r.sd is not None]
    mc = [r for r in eligible if method_of(r.id).method == "type_a_mc"]
    inputs, missing = session_inputs(ctx, results, sorted({s for r in mc for s in method_of(r.id).sources}))
    x = draw_inputs(inputs, m, np.random.default_rng(seed))
    columns, col = {}, 0
    for inp in inputs:
        columns[inp.source] = np.arange(col, col + inp.dimension)
        col += inp.dimension
    groups: dict[tuple[str, ...], list[MetricResult]] = {}
    for r in mc:
        groups.setdefault(tuple(s for s in method_of(r.id).sources if s in columns), []).append(r)
    samples: dict[str, tuple[list[Input], np.ndarray, np.ndarray]] = {}
    for group, members in groups.items():
        if not group:
            continue
        mine = [i for i in inputs if i.source in group]
        xg = x[:, np.concatenate([columns[s.source] for s in mine])]
        ys = draw_values(ctx, [r.id for r in members], mine, xg)
        samples.update({r.id: (mine, xg, ys[r.id]) for r in members})
    noise_rng = np.random.default_rng([seed, 1])
    for r in eligible:
        method = method_of(r.id)
        terms = [repeatability_term(r)]
        if r.id in samples:
            terms += mc_terms(*samples[r.id])
        u, big_u, k, nu = combine(terms, p)
        bias = bias_estimate(ctx, results, r, noise_rng, m, seed)
        r.uncertainty = MetricUncertainty(
            method=method.method,
            u=u,
            U=big_u + abs(bias.estimate) if bias is not None else big_u,
            bias=bias,
            k=k,
            coverage_probability=p,
            dof_eff=nu,
            budget=terms,
            mc_draws=m if r.id in samples else None,
            sources_missing=sorted(s for s in method.sources if s in missing),
        )
    return results
