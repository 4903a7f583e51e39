"""The local dynamic model (spec chapter 11; paper §IV-D, §VI-D, eq. 9, Figs. 8–9).

A MIMO Hammerstein–Wiener model with exactly the structure of MATLAB's ``nlhw``:

    w_i(t) = f_i(u_i(t))                                        one static map per input  (§11.2)
    x_j(t) = Σ_i B_ji(q)/F_ji(q) · w_i(t − nk_ji)               ny × nu output-error block
    y_j(t) = h_j(x_j(t))                                        one static map per output

with piecewise-linear maps (linear extension beyond the end breakpoints) or unit-gain maps. This module
holds the parameter file model (:class:`HWModelFile`), deterministic prediction (:func:`predict`,
§11.3), fitting by Levenberg–Marquardt on the simulation error with an analytic Jacobian
(:func:`fit`, §11.4), the kinematic distance of paper eq. 9 (:func:`window_features`,
:func:`nearest_distances`, :func:`segment_table`, §11.6) and the family's ``compute(ctx)`` (§11.7).
Every parameter comes from ``schemas/<v>/metrics/dynamics.json``.
"""

from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Final, Literal, Sequence, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy.linalg import cho_factor, cho_solve
from scipy.signal import lfilter

from haptify.conventions import quat_mean
from haptify.errors import HaptifyError, fail
from haptify.filter_bank import FilterBank, lfilter_columns
from haptify.metric_definitions import family, param
from haptify.versions import SPEC_VERSION

if TYPE_CHECKING:
    from haptify.report import ReportFigure
    from haptify.results import MetricResult, Unavailable

FAMILY = "dynamics"
#: The segment index k and local coordinate s of every sample on a piecewise-linear map (:func:`_segments`).
Segments = tuple[np.ndarray, np.ndarray]
MODEL_FORMAT: Final = "haptify-hw-model"

#: The model's 13 inputs and 6 outputs (spec §11.1), in this order.
INPUT_NAMES = ("qw", "qx", "qy", "qz", "px", "py", "pz", "vx", "vy", "vz", "ax", "ay", "az")
INPUT_UNITS = ("1",) * 4 + ("m",) * 3 + ("m/s",) * 3 + ("m/s^2",) * 3
OUTPUT_NAMES = ("fx", "fy", "fz", "tx", "ty", "tz")
OUTPUT_UNITS = ("N",) * 3 + ("N*m",) * 3


# =============================================================================================
# The parameter file (spec §11.5)
# =============================================================================================


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _all_finite(values: Sequence[float], what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what} must be finite numbers")


class PiecewiseLinearMap(_Strict):
    """A static map through the points (breakpoints[k], values[k]), extended linearly beyond the ends; in the channel's units (spec §11.2, §11.5.1)."""

    type: Literal["piecewise_linear"] = "piecewise_linear"
    breakpoints: list[float] = Field(min_length=2, description="Strictly increasing abscissae (input units).")
    values: list[float] = Field(min_length=2, description="The map's value at each breakpoint.")

    @model_validator(mode="after")
    def _check(self) -> "PiecewiseLinearMap":
        if len(self.values) != len(self.breakpoints):
            raise ValueError(f"{len(self.breakpoints)} breakpoints but {len(self.values)} values")
        _all_finite(self.breakpoints, "breakpoints")
        _all_finite(self.values, "values")
        if any(b <= a for a, b in zip(self.breakpoints, self.breakpoints[1:])):
            raise ValueError("breakpoints must be strictly increasing")
        return self


class UnitGainMap(_Strict):
    """No map: the channel passes unchanged (MATLAB: an empty or unitgain nonlinearity) (spec §11.2, §11.5.1)."""

    type: Literal["unit_gain"] = "unit_gain"


StaticMap = Annotated[Union[PiecewiseLinearMap, UnitGainMap], Field(discriminator="type")]


class TransferFunction(_Strict):
    """One linear block B_ji(q)/F_ji(q) with delay nk (spec §11.2)."""

    b: list[float] = Field(min_length=1, description="b_1 … b_nb of B(q) = b_1 + b_2 q^-1 + … (delay not included).")
    f: list[float] = Field(default_factory=list, description="f_1 … f_nf of F(q) = 1 + f_1 q^-1 + … (leading 1 not stored).")
    nk: int = Field(ge=0, description="Input delay in samples.")

    @model_validator(mode="after")
    def _check(self) -> "TransferFunction":
        _all_finite(self.b, "b")
        _all_finite(self.f, "f")
        return self


class Channel(_Strict):
    """One model input or output channel: its name and SI unit, in channel order (spec §11.1, §11.5.1)."""

    name: str
    unit: str


class QuaternionHemisphere(_Strict):
    """Sign convention of the quaternion inputs: each sample q is replaced by sign(q·reference)·q (spec §11.5.1)."""

    columns: list[int] = Field(min_length=4, max_length=4, description="0-based input indices of w, x, y, z.")
    reference: list[float] = Field(min_length=4, max_length=4, description="Unit quaternion [w, x, y, z].")


class FitSummary(_Strict):
    """How the model was obtained (informative; prediction never reads it); errors in output units (spec §11.5.1)."""

    session_id: str | None = None
    trial_id: str | None = None
    samples: int = Field(ge=0)
    iterations: int = Field(ge=0)
    stop_reason: str
    cost: float = Field(description="Final value of the normalised cost of spec §11.4.")
    rmse: list[float] = Field(description="Training RMS error per output, output units.")
    fit_percent: list[float] = Field(description="MATLAB's fit: 100 (1 - |y - yhat| / |y - mean y|) per output.")
    definition_version: str | None = Field(None, description="Version of metrics/dynamics.json used.")


class HWModelFile(_Strict):
    """A Hammerstein–Wiener model parameter file (spec §11.5; schema ``hw-model``)."""

    format: Literal["haptify-hw-model"] = MODEL_FORMAT
    spec_version: str = SPEC_VERSION
    sample_rate_hz: float = Field(gt=0, description="Rate the model runs at; inputs must be sampled at it.")
    inputs: list[Channel] = Field(min_length=1)
    outputs: list[Channel] = Field(min_length=1)
    input_maps: list[StaticMap] = Field(description="One map per input channel, in input order.")
    output_maps: list[StaticMap] = Field(description="One map per output channel, in output order.")
    linear: list[list[TransferFunction]] = Field(description="linear[j][i] = B_ji/F_ji from input i to output j (ny × nu).")
    quaternion_hemisphere: QuaternionHemisphere | None = None
    fit: FitSummary | None = None

    @model_validator(mode="after")
    def _shapes(self) -> "HWModelFile":
        nu, ny = len(self.inputs), len(self.outputs)
        if len(self.input_maps) != nu:
            raise ValueError(f"input_maps has {len(self.input_maps)} entries, inputs has {nu}")
        if len(self.output_maps) != ny:
            raise ValueError(f"output_maps has {len(self.output_maps)} entries, outputs has {ny}")
        if len(self.linear) != ny or any(len(row) != nu for row in self.linear):
            raise ValueError(f"linear must be {ny} rows of {nu} transfer functions")
        if self.quaternion_hemisphere is not None and any(not 0 <= c < nu for c in self.quaternion_hemisphere.columns):
            raise ValueError("quaternion_hemisphere.columns must be input indices")
        return self

    @property
    def nu(self) -> int:
        return len(self.inputs)

    @property
    def ny(self) -> int:
        return len(self.outputs)


def load_model(path: str | os.PathLike[str]) -> HWModelFile:
    """Read and validate a parameter file (spec §11.5); E702 names the field when it is invalid."""
    from haptify.storage import read_json_model

    return read_json_model(path, HWModelFile, "E702")


def save_model(model: HWModelFile, path: str | os.PathLike[str]) -> Path:
    """Write the parameter file atomically (spec §3.6, §11.5)."""
    from haptify.storage import atomic_write_text

    p = Path(path)
    atomic_write_text(p, model.model_dump_json(indent=2) + "\n")
    return p


def _cell(items: list[Any]) -> np.ndarray:
    out = np.empty((len(items),), dtype=object)
    for k, item in enumerate(items):
        out[k] = item
    return out


def _mat_map(m: PiecewiseLinearMap | UnitGainMap) -> dict[str, Any]:
    if isinstance(m, UnitGainMap):
        return {"Type": "unit_gain", "BreakPoints": np.zeros((2, 0))}
    return {"Type": "piecewise_linear", "BreakPoints": np.array([m.breakpoints, m.values], dtype=float)}


def model_to_mat_dict(model: HWModelFile) -> dict[str, Any]:
    """The MATLAB struct written by :func:`export_mat` (field names in spec §11.5.2)."""
    ny, nu = model.ny, model.nu
    B = np.empty((ny, nu), dtype=object)
    F = np.empty((ny, nu), dtype=object)
    nb = np.zeros((ny, nu))
    nf = np.zeros((ny, nu))
    nk = np.zeros((ny, nu))
    for j in range(ny):
        for i in range(nu):
            tf = model.linear[j][i]
            B[j, i] = np.concatenate([np.zeros(tf.nk), tf.b])[None, :]
            F[j, i] = np.concatenate([[1.0], tf.f])[None, :]
            nb[j, i], nf[j, i], nk[j, i] = len(tf.b), len(tf.f), tf.nk
    hemi = model.quaternion_hemisphere
    return {
        "Format": model.format,
        "SpecVersion": model.spec_version,
        "Ts": 1.0 / model.sample_rate_hz,
        "InputName": _cell([c.name for c in model.inputs]),
        "InputUnit": _cell([c.unit for c in model.inputs]),
        "OutputName": _cell([c.name for c in model.outputs]),
        "OutputUnit": _cell([c.unit for c in model.outputs]),
        "InputNonlinearity": _cell([_mat_map(m) for m in model.input_maps]),
        "OutputNonlinearity": _cell([_mat_map(m) for m in model.output_maps]),
        "B": B,
        "F": F,
        "nb": nb,
        "nf": nf,
        "nk": nk,
        "QuaternionColumns": (np.array(hemi.columns, dtype=float) + 1.0) if hemi else np.zeros(0),
        "QuaternionReference": np.array(hemi.reference, dtype=float) if hemi else np.zeros(0),
    }


def export_mat(model: HWModelFile, path: str | os.PathLike[str]) -> Path:
    """Write the model as a MATLAB-loadable ``.mat`` holding the struct ``model`` (spec §11.5.2)."""
    from scipy.io import savemat

    p = Path(path)
    payload = {"model": model_to_mat_dict(model)}
    from haptify.storage import write_atomically

    write_atomically(p, lambda tmp: savemat(tmp, payload, do_compression=True, oned_as="row"))
    return p


# =============================================================================================
# Static maps and prediction (spec §11.3)
# =============================================================================================


def _segments(breakpoints: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment index k (0 … K−2) and local coordinate s of every u (spec §11.3 step 2).

    k is the last breakpoint ≤ u, clipped to the first and last segment, so values beyond the ends
    extend the end segments linearly (s < 0 or s > 1).
    """
    k = np.clip(np.searchsorted(breakpoints, u, side="right") - 1, 0, len(breakpoints) - 2)
    s = (u - breakpoints[k]) / (breakpoints[k + 1] - breakpoints[k])
    return k, s


def pwl_eval(breakpoints: np.ndarray, values: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Evaluate a piecewise-linear map with linear extension at ``u`` (spec §11.3)."""
    bp = np.asarray(breakpoints, dtype=float)
    v = np.asarray(values, dtype=float)
    k, s = _segments(bp, np.asarray(u, dtype=float))
    out: np.ndarray = v[k] + s * (v[k + 1] - v[k])
    return out


def pwl_basis(breakpoints: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The ``(N, K)`` matrix Φ with ``pwl_eval(bp, v, u) == Φ @ v`` (hat functions, extended at the ends).
    Φ of spec §11.4.3."""
    bp = np.asarray(breakpoints, dtype=float)
    k, s = _segments(bp, np.asarray(u, dtype=float))
    return _hat_columns(np.empty((len(k), len(bp))), k, s)


def _hat_columns(out: np.ndarray, k: np.ndarray, s: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """``scale`` times the hat functions of the segments (k, s) of :func:`_segments` written into ``out``
    (N, K), which may be a view (e.g. some columns of a Jacobian): row t is zero but for
    scale·(1 − s_t) in column k_t and scale·s_t in column k_t + 1."""
    out[:] = 0.0
    rows = np.arange(len(k))
    out[rows, k] = scale * (1.0 - s)
    out[rows, k + 1] = scale * s
    return out


def pwl_slope(breakpoints: np.ndarray, values: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Slope of the map at ``u`` (output units per input unit): that of the segment step 2 of spec §11.3 picks."""
    bp = np.asarray(breakpoints, dtype=float)
    v = np.asarray(values, dtype=float)
    k, _ = _segments(bp, np.asarray(u, dtype=float))
    out: np.ndarray = (v[k + 1] - v[k]) / (bp[k + 1] - bp[k])
    return out


def apply_map(m: PiecewiseLinearMap | UnitGainMap, u: np.ndarray) -> np.ndarray:
    """A channel's static map applied to a signal (spec §11.3)."""
    if isinstance(m, UnitGainMap):
        return np.asarray(u, dtype=float)
    return pwl_eval(np.asarray(m.breakpoints), np.asarray(m.values), u)


def _delayed(signal: np.ndarray, d: int) -> np.ndarray:
    """``signal`` delayed by ``d`` samples along axis 0, zeros before t = 0."""
    if d == 0:
        return signal
    out = np.zeros_like(signal)
    if d < len(signal):
        out[d:] = signal[: len(signal) - d]
    return out


def hemisphere_align(u: np.ndarray, hemi: QuaternionHemisphere | None) -> np.ndarray:
    """Flip each quaternion input sample to the hemisphere of the model's reference (spec §11.3 step 1)."""
    if hemi is None:
        return u
    u = np.array(u, dtype=float, copy=True)
    cols = list(hemi.columns)
    sign = np.where(u[:, cols] @ np.asarray(hemi.reference, dtype=float) < 0.0, -1.0, 1.0)
    u[:, cols] *= sign[:, None]
    return u


def _check_inputs(model: HWModelFile, u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    if u.ndim != 2 or u.shape[1] != model.nu:
        raise fail(
            "E703",
            f"the model has {model.nu} inputs but the data have shape {u.shape}",
            expected=f"(N, {model.nu})",
            found=list(u.shape),
        )
    if not np.all(np.isfinite(u)):
        bad = int(np.argmax(~np.all(np.isfinite(u), axis=1)))
        raise fail(
            "E703", f"model inputs hold a non-finite value (first at sample {bad})", expected="finite inputs", found="NaN or inf"
        )
    return u


def predict(model: HWModelFile, u: np.ndarray) -> np.ndarray:
    """Simulate the model on inputs ``u (N, nu)`` from zero initial conditions; returns ``y (N, ny)``.

    Spec §11.3: hemisphere alignment, input maps, the linear output-error block by the difference
    equation z(t) = Σ_k b_k w(t − nk − k + 1) − Σ_l f_l z(t − l) with w, z = 0 before t = 0, summation
    over inputs, output maps. Deterministic (double precision, no randomness).
    """
    u = hemisphere_align(_check_inputs(model, u), model.quaternion_hemisphere)
    w = np.column_stack([apply_map(model.input_maps[i], u[:, i]) for i in range(model.nu)])
    y = np.empty((len(u), model.ny))
    for j in range(model.ny):
        x = np.zeros(len(u))
        for i, tf in enumerate(model.linear[j]):
            num = np.concatenate([np.zeros(tf.nk), tf.b])
            x += lfilter(num, np.concatenate([[1.0], tf.f]), w[:, i])
        y[:, j] = apply_map(model.output_maps[j], x)
    return y


# =============================================================================================
# Fitting (spec §11.4)
# =============================================================================================


@dataclass(frozen=True)
class FitOptions:
    """The fitting rules of spec §11.4 (defaults: the definition file ``metrics/dynamics.json``)."""

    nb: int
    nf: int
    nk: int
    input_map: str
    output_map: str
    breakpoints: int
    breakpoint_quantiles: tuple[float, float]
    initial_pole: float
    ridge: float
    max_iterations: int
    tolerance: float
    lm_damping: tuple[float, float, float, float]
    stability_radius: float

    @classmethod
    def from_definition(cls, **overrides: Any) -> "FitOptions":
        """Options from the definition file, with keyword overrides (e.g. ``output_map="unit_gain"``)."""
        values: dict[str, Any] = {}
        for name in cls.__dataclass_fields__:
            v = param(FAMILY, name)
            values[name] = tuple(v) if isinstance(v, list) else v
        values.update(overrides)
        opts = cls(**values)
        for m in (opts.input_map, opts.output_map):
            if m not in ("piecewise_linear", "unit_gain"):
                raise fail("E903", f"unknown map type {m!r}", expected=["piecewise_linear", "unit_gain"], found=m)
        if opts.nb < 1 or opts.nf < 0 or opts.nk < 0 or opts.breakpoints < 2 or not abs(opts.initial_pole) < 1:
            raise fail(
                "E903",
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


@dataclass
class _Structure:
    """Fixed parts of a model being fitted, and the index layout of its parameter vector θ: the shared
    input-map values, then output by output its own parameters in the order of its Jacobian's columns
    (:func:`_output_jacobian`): b_1 of every input, …, b_nb of every input, f_1 of every input, …, f_nf of
    every input, then the output map's values."""

    nu: int
    ny: int
    nb: int
    nf: int
    nk: int
    in_bp: list[np.ndarray | None]  # input breakpoints (None: unit gain)
    out_bp: list[np.ndarray | None]  # output breakpoints (None: unit gain)
    v_idx: list[np.ndarray | None] = field(default_factory=list)  # θ indices of input map values
    b_idx: np.ndarray = field(init=False)  # (ny, nu, nb)
    f_idx: np.ndarray = field(init=False)  # (ny, nu, nf)
    c_idx: list[np.ndarray | None] = field(default_factory=list)  # θ indices of output map values
    size: int = 0

    def __post_init__(self) -> None:
        n = 0
        self.v_idx = []
        for bp in self.in_bp:
            self.v_idx.append(None if bp is None else np.arange(n, n + len(bp)))
            n += 0 if bp is None else len(bp)
        self.n_shared = n
        self.shared_input = np.array([i for i, bp in enumerate(self.in_bp) if bp is not None for _ in bp], dtype=int)
        self.b_idx = np.zeros((self.ny, self.nu, self.nb), dtype=int)
        self.f_idx = np.zeros((self.ny, self.nu, self.nf), dtype=int)
        self.c_idx = []
        for j in range(self.ny):
            self.b_idx[j] = n + np.arange(self.nb * self.nu).reshape(self.nb, self.nu).T
            n += self.nb * self.nu
            self.f_idx[j] = n + np.arange(self.nf * self.nu).reshape(self.nf, self.nu).T
            n += self.nf * self.nu
            bp = self.out_bp[j]
            self.c_idx.append(None if bp is None else np.arange(n, n + len(bp)))
            n += 0 if bp is None else len(bp)
        self.size = n

    def own(self, j: int) -> slice:
        """θ indices that only output j depends on (its B, F and output map), in Jacobian order: one
        contiguous range of θ."""
        start = int(self.b_idx[j, 0, 0])
        values = self.c_idx[j]
        stop = start + self.nu * (self.nb + self.nf) + (0 if values is None else len(values))
        return slice(start, stop)


@dataclass
class _Record:
    """The training records stacked (spec §11.4: each is simulated from rest; ``starts`` holds their first
    rows) and what the fit precomputes for them: the input basis Φ (N, shared parameters) and each mapped
    input's segments."""

    u: np.ndarray
    y: np.ndarray
    basis: np.ndarray
    segments: list[Segments | None]  # per input: its map's segments at u (None: unit gain)
    starts: np.ndarray
    _scratch: dict[str, Any] = field(default_factory=dict)

    def scratch(self, name: str, rows: int, width: int) -> np.ndarray:
        """A (rows, width) buffer reused from call to call under ``name`` (a fresh array of megabytes per call
        costs its page faults every time)."""
        buffer = self._scratch.get(name)
        if buffer is None or buffer.shape[0] < rows or buffer.shape[1] != width:
            buffer = self._scratch[name] = np.empty((rows, width))
        return buffer[:rows]

    @classmethod
    def of(cls, st: _Structure, u: np.ndarray, y: np.ndarray, starts: Sequence[int] | np.ndarray = (0,)) -> "_Record":
        basis = np.empty((len(u), st.n_shared))
        segments: list[Segments | None] = []
        for i, bp in enumerate(st.in_bp):
            segments.append(None if bp is None else _segments(bp, u[:, i]))
            if bp is not None:
                basis[:, st.v_idx[i]] = pwl_basis(bp, u[:, i])
        return cls(u=u, y=y, basis=basis, segments=segments, starts=np.asarray(starts, dtype=np.int64))


def _inputs_mapped(st: _Structure, theta: np.ndarray, rec: _Record) -> np.ndarray:
    """w (N, nu): each input through its map (as :func:`pwl_eval`, on the record's precomputed segments)."""
    w = np.array(rec.u, dtype=float, copy=True)
    for i, seg in enumerate(rec.segments):
        if seg is not None:
            k, s = seg
            v = theta[st.v_idx[i]]
            w[:, i] = v[k] + s * (v[k + 1] - v[k])
    return w


def _polynomials(st: _Structure, theta: np.ndarray, j: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Numerators q^-nk B (rows of nk + nb coefficients) and denominators F (rows of 1 + nf) of the
    transfer functions of output ``j`` (nu rows) or of all outputs (ny · nu rows, output-major)."""
    b_idx = st.b_idx if j is None else st.b_idx[j : j + 1]
    f_idx = st.f_idx if j is None else st.f_idx[j : j + 1]
    rows = b_idx.shape[0] * st.nu
    num = np.zeros((rows, st.nk + st.nb))
    num[:, st.nk :] = theta[b_idx].reshape(rows, st.nb)
    den = np.ones((rows, 1 + st.nf))
    den[:, 1:] = theta[f_idx].reshape(rows, st.nf)
    return num, den


@dataclass
class _Simulation:
    """The model under fit simulated on the stacked records (same algorithm as :func:`predict`, spec §11.3):
    the mapped inputs w (N, nu), the responses z (N, ny · nu, output-major) = q^-nk B_ji/F_ji w_i, their
    sums x (N, ny), the outputs ŷ (N, ny), and per output map its slope at x_j and segments (k, s), None for
    a unit gain (what the Jacobian of spec §11.4.3 reuses)."""

    w: np.ndarray
    z: np.ndarray
    x: np.ndarray
    yhat: np.ndarray
    slopes: list[np.ndarray | None]
    segments: list[Segments | None]


def _simulation(st: _Structure, theta: np.ndarray, rec: _Record) -> _Simulation:
    """Simulate the model under fit: the ny · nu transfer functions in one filter-bank call over w repeated
    for every output."""
    w = _inputs_mapped(st, theta, rec)
    num, den = _polynomials(st, theta)
    tiled = rec.scratch("inputs", len(w), st.ny * st.nu)  # w once per output
    tiled.reshape(len(w), st.ny, st.nu)[:] = w[:, None, :]
    z = lfilter_columns(num, den, tiled, starts=rec.starts)
    x = z @ np.kron(np.eye(st.ny), np.ones((st.nu, 1)))  # Σ_i z_ji for every output j
    yhat = x.copy()
    slopes: list[np.ndarray | None] = [None] * st.ny
    segments: list[Segments | None] = [None] * st.ny
    for j, bp in enumerate(st.out_bp):
        if bp is not None:
            value, slopes[j], k, s = _pwl_parts(bp, theta[st.c_idx[j]], x[:, j])
            yhat[:, j], segments[j] = value, (k, s)
    return _Simulation(w=w, z=z, x=x, yhat=yhat, slopes=slopes, segments=segments)


def _simulate(st: _Structure, theta: np.ndarray, rec: _Record) -> np.ndarray:
    """ŷ (N, ny) of the model under fit (:func:`_simulation`)."""
    return _simulation(st, theta, rec).yhat


def _pwl_parts(
    breakpoints: np.ndarray, values: np.ndarray, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`pwl_eval` and :func:`pwl_slope` of one map at ``x``, and the segments (k, s) that
    :func:`_hat_columns` turns into :func:`pwl_basis`, from one segment search."""
    k, s = _segments(breakpoints, x)
    lo, hi = values[k], values[k + 1]
    return lo + s * (hi - lo), (hi - lo) / (breakpoints[k + 1] - breakpoints[k]), k, s


def _delay_filters(den: np.ndarray, taps: Sequence[tuple[int, float]]) -> tuple[np.ndarray, np.ndarray]:
    """Numerators ``sign · q^-delay`` and denominators F for every (delay, sign) of ``taps`` in turn, each over
    every row of ``den``: the filters ``sign · q^-delay / F`` of the B and F columns of a Jacobian (spec §11.4.3)."""
    num = np.zeros((len(taps), len(den), max(d for d, _ in taps) + 1))
    for m, (delay, sign) in enumerate(taps):
        num[m, :, delay] = sign
    return num.reshape(-1, num.shape[2]), np.tile(den, (len(taps), 1))


@dataclass
class _JacobianPass:
    """Output j's Jacobian (spec §11.4.3) being formed block of rows by block of rows: what every block needs
    (ŷ_j, the output map's slope times the weight, its segments) and the filter banks of its columns, whose
    delays carry from one block to the next (:class:`haptify.filter_bank.FilterBank`)."""

    yhat: np.ndarray
    gain: np.ndarray  # weight · h_j'(x_j) per sample
    weight: float
    segments: Segments | None  # (k, s) of the output map at x_j; None: unit gain
    hats: int  # the output map's breakpoints (0: unit gain)
    shared: FilterBank  # the columns of the input-map values (over Φ)
    linear: FilterBank  # the B and F columns (over ``signals``)
    signals: list[np.ndarray]  # w (N, nu) nb times, then z_j (N, nu) nf times

    @property
    def columns(self) -> int:
        """The Jacobian's width: shared input-map values, output j's B and F, its output-map values."""
        return self.shared.columns + self.linear.columns + self.hats

    @classmethod
    def of(cls, st: _Structure, theta: np.ndarray, rec: _Record, j: int, weight: float, sim: _Simulation) -> "_JacobianPass":
        nu, nb, nf = st.nu, st.nb, st.nf
        segments, slope, out_bp = sim.segments[j], sim.slopes[j], st.out_bp[j]
        gain: np.ndarray
        if segments is None:
            gain, hats = np.full(len(rec.u), weight), 0
        else:  # _simulation gives a mapped output its slope and segments together, from its breakpoints
            assert slope is not None and out_bp is not None
            gain, hats = weight * slope, len(out_bp)
        num, den = _polynomials(st, theta, j)
        taps = [(st.nk + k, 1.0) for k in range(nb)] + [(lag, -1.0) for lag in range(1, nf + 1)]
        return cls(
            yhat=sim.yhat[:, j],
            gain=gain,
            weight=weight,
            segments=segments,
            hats=hats,
            shared=FilterBank(num[st.shared_input], den[st.shared_input]),
            linear=FilterBank(*_delay_filters(den, taps)),
            signals=[sim.w] * nb + [sim.z[:, j * nu : (j + 1) * nu]] * nf,
        )

    def rows(self, rec: _Record, rows: slice, out: np.ndarray) -> None:
        """Write the Jacobian's rows ``rows`` (the block after the previous call's) into ``out``:
        ∂z_ji/∂v_ik = q^-nk B_ji/F_ji φ_ik over Φ, ∂z_ji/∂b_k = q^-(nk+k-1)/F_ji w_i and ∂z_ji/∂f_l =
        −q^-l/F_ji z_ji over ``signals``, each times the gain; the output map's hat functions times the weight."""
        ns, n_lin = self.shared.columns, self.linear.columns
        starts = rec.starts[(rec.starts >= rows.start) & (rec.starts < rows.stop)] - rows.start
        gain = self.gain[rows]
        if ns:
            self.shared(rec.basis[rows], out=out[:, :ns], gain=gain, starts=starts)
        signals = rec.scratch("signals", len(gain), n_lin)
        width = n_lin // len(self.signals)
        for m, signal in enumerate(self.signals):
            signals[:, m * width : (m + 1) * width] = signal[rows]
        self.linear(signals, out=out[:, ns : ns + n_lin], gain=gain, starts=starts)
        if self.segments is not None:
            _hat_columns(out[:, ns + n_lin :], self.segments[0][rows], self.segments[1][rows], self.weight)


def _output_jacobian(
    st: _Structure, theta: np.ndarray, rec: _Record, j: int, weight: float = 1.0, sim: _Simulation | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """ŷ_j and ``weight`` times its analytic Jacobian (spec §11.4.3) at once (:class:`_JacobianPass` over all
    rows): one row per sample, one column per parameter in θ's order (:class:`_Structure`): ``[shared
    input-map values, output j's own b_1 … b_nb, f_1 … f_nf (each for every input), output-map values]``.
    ``sim`` is :func:`_simulation` at θ (computed when not given)."""
    jacobian = _JacobianPass.of(st, theta, rec, j, weight, _simulation(st, theta, rec) if sim is None else sim)
    jac = np.empty((len(rec.u), jacobian.columns))
    jacobian.rows(rec, slice(0, len(rec.u)), jac)
    return jacobian.yhat, jac


#: Rows of the Jacobians formed at a time by :func:`_normal_equations`: a block of 2048 × ~200 columns (3 MiB)
#: stays in the processor's cache between being filtered and entering the Gram matrix.
BLOCK_ROWS = 2048


def _normal_equations(
    st: _Structure, theta: np.ndarray, rec: _Record, weights: np.ndarray, sim: _Simulation, buffer: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray]]:
    """JᵀJ and Jᵀe of every output j (spec §11.4.3; J of :func:`_output_jacobian` with weight ``weights[j]``,
    e the weighted residuals), accumulated over blocks of :data:`BLOCK_ROWS` rows formed in ``buffer``
    (≥ BLOCK_ROWS × columns + 1): one symmetric product per block of ``[J | e]``, the outputs' blocks of the
    same rows one after the other (so a block of the input basis Φ is read once for all outputs)."""
    passes = [_JacobianPass.of(st, theta, rec, j, weights[j], sim) for j in range(st.ny)]
    residuals = [(rec.y[:, j] - p.yhat) * weights[j] for j, p in enumerate(passes)]
    grams = [np.zeros((p.columns + 1, p.columns + 1)) for p in passes]
    n = len(rec.u)
    for start in range(0, n, BLOCK_ROWS):
        rows = slice(start, min(start + BLOCK_ROWS, n))
        for jacobian, e, gram in zip(passes, residuals, grams):
            block = buffer[: rows.stop - rows.start, : jacobian.columns + 1]
            jacobian.rows(rec, rows, block[:, :-1])
            block[:, -1] = e[rows]
            gram += block.T @ block
    return [(gram[:-1, :-1], gram[:-1, -1]) for gram in grams]


def _add_normal_equations(hess: np.ndarray, grad: np.ndarray, ns: int, own: slice, gram: np.ndarray, jac_e: np.ndarray) -> None:
    """Add one output's JᵀJ and −Jᵀe (rows ``[shared, own]`` of :func:`_output_jacobian`) to the normal
    equations of spec §11.4.3: the shared parameters are θ[:ns], the output's own a contiguous range."""
    hess[:ns, :ns] += gram[:ns, :ns]
    hess[:ns, own] += gram[:ns, ns:]
    hess[own, :ns] += gram[ns:, :ns]
    hess[own, own] += gram[ns:, ns:]
    grad[:ns] -= jac_e[:ns]
    grad[own] -= jac_e[ns:]


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
        raise fail("E703", f"{n} {prefix} channels but {len(names)} names and {len(units)} units", expected=n, found=len(names))
    return [Channel(name=a, unit=b) for a, b in zip(names, units)]


def _as_records(data: np.ndarray | Sequence[np.ndarray], what: str) -> list[np.ndarray]:
    records = [np.asarray(data, dtype=float)] if isinstance(data, np.ndarray) else [np.asarray(r, dtype=float) for r in data]
    if not records or any(r.ndim != 2 for r in records):
        raise fail(
            "E703",
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
    with _one_blas_thread():
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


def _one_blas_thread() -> contextlib.AbstractContextManager[Any]:
    """BLAS limited to one thread while fitting, when ``threadpoolctl`` is installed.

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


def _fit(  # noqa: C901 (over ruff's limit of 15: to be split)
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
    opts = options
    us = _as_records(u, "inputs")
    ys = _as_records(y, "outputs")
    if (
        len(us) != len(ys)
        or any(len(a) != len(b) for a, b in zip(us, ys))
        or len({a.shape[1] for a in us}) != 1
        or len({b.shape[1] for b in ys}) != 1
    ):
        raise fail(
            "E703",
            "input and output records must pair up with equal lengths and channel counts",
            expected="matching records",
            found=[[list(a.shape), list(b.shape)] for a, b in zip(us, ys)],
        )
    if not all(np.all(np.isfinite(a)) for a in us + ys):
        raise fail("E703", "training data hold non-finite values", expected="finite", found="NaN or inf")
    nu, ny = us[0].shape[1], ys[0].shape[1]
    hemi = None
    if quaternion_columns is not None:
        cols = [int(c) for c in quaternion_columns]
        hemi = QuaternionHemisphere(columns=cols, reference=[float(v) for v in quat_mean(np.vstack(us)[:, cols])])
        us = [hemisphere_align(a, hemi) for a in us]
    u_all, y_all = np.vstack(us), np.vstack(ys)
    n = len(u_all)

    # -- §11.4.1 input breakpoints and initial input maps: w_i = (u_i − mean)/std -------------------
    mu_u = u_all.mean(axis=0)
    sd_u = np.where(u_all.std(axis=0) > 0, u_all.std(axis=0), 1.0)
    pwl_in = opts.input_map == "piecewise_linear"
    in_bp = [place_breakpoints(u_all[:, i], opts.breakpoints, opts.breakpoint_quantiles) if pwl_in else None for i in range(nu)]
    mu_y = y_all.mean(axis=0)
    sd_y = np.where(y_all.std(axis=0) > 0, y_all.std(axis=0), 1.0)
    pwl_out = opts.output_map == "piecewise_linear"

    # -- §11.4.2 initial linear block: F = (1 − p q^-1)^nf, B by ridge least squares -------------
    f0 = np.poly(np.full(opts.nf, opts.initial_pole))[1:] if opts.nf else np.zeros(0)
    regs = []
    for a in us:
        w0 = (a - mu_u) / sd_u if pwl_in else a
        wf = lfilter([1.0], np.concatenate([[1.0], f0]), w0, axis=0)
        regs.append(np.column_stack([_delayed(wf[:, i], opts.nk + k) for i in range(nu) for k in range(opts.nb)]))
    reg = np.vstack(regs)
    target = (y_all - mu_y) / sd_y if pwl_out else y_all
    gram = reg.T @ reg / n + opts.ridge * np.eye(reg.shape[1])
    b0 = np.linalg.solve(gram, reg.T @ target / n)  # (nu·nb, ny)
    x0 = reg @ b0
    out_bp = [place_breakpoints(x0[:, j], opts.breakpoints, opts.breakpoint_quantiles) if pwl_out else None for j in range(ny)]

    st = _Structure(nu=nu, ny=ny, nb=opts.nb, nf=opts.nf, nk=opts.nk, in_bp=in_bp, out_bp=out_bp)
    theta0 = np.zeros(st.size)
    scale = np.ones(st.size)  # D of the ridge term
    for i in range(nu):
        if in_bp[i] is not None:
            theta0[st.v_idx[i]] = (in_bp[i] - mu_u[i]) / sd_u[i]
    for j in range(ny):
        for i in range(nu):
            theta0[st.b_idx[j, i]] = b0[i * opts.nb : (i + 1) * opts.nb, j]
            theta0[st.f_idx[j, i]] = f0
        if out_bp[j] is not None:
            theta0[st.c_idx[j]] = mu_y[j] + sd_y[j] * out_bp[j]
            scale[st.c_idx[j]] = 1.0 / sd_y[j]

    rec = _Record.of(st, u_all, y_all, starts=np.cumsum([0] + [len(a) for a in us[:-1]]))
    block = np.empty((min(n, BLOCK_ROWS), st.n_shared + max(st.own(j).stop - st.own(j).start for j in range(ny)) + 1))
    wy = 1.0 / (sd_y * math.sqrt(n))  # residual weights (spec §11.4.2)
    d2 = opts.ridge * scale**2

    def cost(theta: np.ndarray) -> tuple[float, _Simulation]:
        """The cost of spec §11.4.2 and the simulation it ran (the next Jacobian's, if accepted)."""
        sim = _simulation(st, theta, rec)
        e = (rec.y - sim.yhat) * wy
        return float(np.sum(d2 * (theta - theta0) ** 2)) + float(np.sum(e * e)), sim

    # -- §11.4.3 Levenberg–Marquardt ------------------------------------------------------------------
    mu, up, down, mu_max = opts.lm_damping
    theta = theta0.copy()
    current, sim = cost(theta)
    history = [current]
    ns = st.n_shared
    own = [st.own(j) for j in range(ny)]
    stop = "max_iterations"
    iterations = 0
    for iterations in range(1, opts.max_iterations + 1):
        hess = np.diag(d2)
        grad = d2 * (theta - theta0)  # half the gradient of the cost
        for j, (gram, jac_e) in enumerate(_normal_equations(st, theta, rec, wy, sim, block)):
            _add_normal_equations(hess, grad, ns, own[j], gram, jac_e)
        accepted = False
        while mu <= mu_max:
            try:
                step = -cho_solve(cho_factor(hess + mu * np.diag(np.diag(hess))), grad)
            except (np.linalg.LinAlgError, ValueError):  # not positive definite, or not finite
                mu *= up
                continue
            trial = theta + step
            if _max_pole_modulus(st, trial) >= opts.stability_radius:
                mu *= up
                continue
            new, trial_sim = cost(trial)
            if np.isfinite(new) and new < current:
                accepted = True
                break
            mu *= up
        if not accepted:
            stop = "damping_limit"
            iterations -= 1
            break
        gain = (current - new) / current if current > 0 else 0.0
        theta, current, sim = trial, new, trial_sim
        history.append(current)
        mu = max(mu * down, 1e-12)
        if gain < opts.tolerance:
            stop = "tolerance"
            break

    model = _assemble(
        st,
        theta,
        sample_rate_hz,
        hemi,
        _as_channels(input_names, input_units, nu, "u"),
        _as_channels(output_names, output_units, ny, "y"),
    )
    yhat = sim.yhat  # the records simulated at the final θ (spec §11.3)
    err = np.linalg.norm(y_all - yhat, axis=0)
    denom = np.linalg.norm(y_all - mu_y, axis=0)
    fit_pct = np.where(denom > 0, 100.0 * (1.0 - err / np.where(denom > 0, denom, 1.0)), 0.0)
    model.fit = FitSummary(
        session_id=session_id,
        trial_id=trial_id,
        samples=n,
        iterations=iterations,
        stop_reason=stop,
        cost=current,
        rmse=rmse(y_all, yhat).tolist(),
        fit_percent=fit_pct.tolist(),
        definition_version=family(FAMILY).version,
    )
    return model, FitReport(iterations=iterations, stop_reason=stop, cost_history=history)


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


def rmse(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """Per-column RMS error of ``yhat`` against ``y`` (same units; spec §11.7)."""
    d = np.asarray(y, dtype=float) - np.asarray(yhat, dtype=float)
    out: np.ndarray = np.sqrt(np.mean(d * d, axis=0))
    return out


# =============================================================================================
# Kinematic distance (paper eq. 9; spec §11.6)
# =============================================================================================


@dataclass(frozen=True)
class DistanceScales:
    """R_p (m), R_v (m/s), R_a (m/s²), R_θ (rad) of paper eq. 9."""

    p: float
    v: float
    a: float
    theta: float

    @classmethod
    def from_definition(cls) -> "DistanceScales":
        """R_p, R_v, R_a, R_θ from the definition file (R_θ converted from degrees; spec §11.6.2)."""
        return cls(
            p=param(FAMILY, "R_p"), v=param(FAMILY, "R_v"), a=param(FAMILY, "R_a"), theta=math.radians(param(FAMILY, "R_theta"))
        )


@dataclass(frozen=True)
class WindowFeatures:
    """Per-window means (spec §11.6.1): position, velocity, acceleration (W, 3), orientation (W, 4)."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    orientation: np.ndarray

    def __len__(self) -> int:
        return len(self.position)


def window_features(
    position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, quaternion: np.ndarray, window_samples: int
) -> WindowFeatures:
    """Split signals (N, 3)/(N, 4) into consecutive windows of ``window_samples`` samples, dropping the
    incomplete tail, and average each (spec §11.6.1): arithmetic means of position, velocity and
    acceleration; the Markley mean of the quaternions (:func:`haptify.conventions.quat_mean`)."""
    n_win = len(position) // window_samples
    m = n_win * window_samples

    def means(x: np.ndarray, width: int) -> np.ndarray:
        out: np.ndarray = np.asarray(x, dtype=float)[:m].reshape(n_win, window_samples, width).mean(axis=1)
        return out

    q = np.asarray(quaternion, dtype=float)[:m].reshape(n_win, window_samples, 4)
    orient = np.array([quat_mean(block) for block in q]) if n_win else np.zeros((0, 4))
    return WindowFeatures(means(position, 3), means(velocity, 3), means(acceleration, 3), orient)


def pair_distance(a: WindowFeatures, b: WindowFeatures, scales: DistanceScales) -> np.ndarray:
    """Δ (dimensionless) of paper eq. 9 between every window of ``a`` and every window of ``b``:
    an array (len(a), len(b)) (spec §11.6.2)."""
    from scipy.spatial.distance import cdist

    dot = np.abs(a.orientation @ b.orientation.T)
    out = (2.0 / scales.theta) * np.arccos(np.clip(dot, 0.0, 1.0))
    out += cdist(a.position, b.position) / scales.p
    out += cdist(a.velocity, b.velocity) / scales.v
    out += cdist(a.acceleration, b.acceleration) / scales.a
    result: np.ndarray = out
    return result


def nearest_distances(test: WindowFeatures, train: WindowFeatures, scales: DistanceScales, chunk: int = 512) -> np.ndarray:
    """For each test window, the minimum over training windows of Δ (paper eq. 9; spec §11.6.2).

    Exact brute force, vectorised in chunks of ``chunk`` test windows (memory ≈ chunk × training
    windows × 8 bytes × a few arrays).
    """
    if len(train) == 0:
        raise fail("E701", "the training set has no complete distance window", expected="≥ 1 window", found=0)
    out = np.empty(len(test))
    with _one_blas_thread():
        for start in range(0, len(test), chunk):
            stop = min(start + chunk, len(test))
            part = WindowFeatures(
                test.position[start:stop], test.velocity[start:stop], test.acceleration[start:stop], test.orientation[start:stop]
            )
            out[start:stop] = pair_distance(part, train, scales).min(axis=1)
    return out


def segment_distances(window_distances: np.ndarray, windows_per_segment: int) -> np.ndarray:
    """Mean of the window minima over each complete segment (spec §11.6.3); incomplete tail dropped."""
    n_seg = len(window_distances) // windows_per_segment
    out: np.ndarray = window_distances[: n_seg * windows_per_segment].reshape(n_seg, windows_per_segment).mean(axis=1)
    return out


def segment_force_errors(force: np.ndarray, predicted: np.ndarray, segment_samples: int) -> np.ndarray:
    """Each complete segment's force error (spec §11.6.4): the mean over x, y, z of the per-axis RMS error."""
    n_seg = len(force) // segment_samples
    m = n_seg * segment_samples
    d = (np.asarray(force, dtype=float)[:m] - np.asarray(predicted, dtype=float)[:m]).reshape(n_seg, segment_samples, -1)
    out: np.ndarray = np.sqrt(np.mean(d * d, axis=1)).mean(axis=1)
    return out


def line_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Ordinary least-squares line ``y = slope·x + intercept`` (spec §11.6.5).

    E701 unless the distances span more than 1e-6 (distances are dimensionless, O(1)).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if len(x) < 2 or np.ptp(x) <= 1e-6:
        raise fail(
            "E701",
            "a line needs at least two segments at different distances",
            expected="≥ 2 distinct distances",
            found=len(np.unique(x)),
        )
    xm, ym = x.mean(), y.mean()
    slope = float(np.sum((x - xm) * (y - ym)) / np.sum((x - xm) ** 2))
    return slope, float(ym - slope * xm)


# =============================================================================================
# Session level: training and test trials, the family's metrics (spec §11.1, §11.7)
# =============================================================================================

#: Protocols whose passive trials serve as test sets (spec §11.7).
TEST_PROTOCOLS = ("local_dynamic", "free_space", "other")
REQUIRED_STREAMS = ("handle_pose", "handle_wrench", "handle_accel")


@dataclass
class TrialData:
    """A trial's model inputs u (N, 13) and measured outputs y (N, 6) on the model's grid (spec §11.1).

    Rows where ``valid`` is False (motion capture unusable) hold NaN and are never used.
    """

    trial_id: str
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    valid: np.ndarray

    def runs(self) -> list[slice]:
        """Contiguous valid runs of at least 2 rows, each simulated from zero initial conditions (spec §11.1, §11.3)."""
        return valid_runs(self.valid)


def valid_runs(valid: np.ndarray, min_samples: int = 2) -> list[slice]:
    """Slices of the contiguous True runs of ``valid`` with at least ``min_samples`` samples.
    The runs of spec §11.1."""
    v = np.concatenate([[False], np.asarray(valid, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(v.astype(np.int8)))
    return [slice(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_samples]


def trial_data(ctx_or_session: Any, trial_id: str, rate_hz: float | None = None) -> TrialData:
    """The 13 inputs and 6 outputs of a trial from :func:`haptify.signals.handle_signals` (spec §7.5, §11.1)."""
    from haptify.signals import handle_signals

    rate = float(param(FAMILY, "sample_rate_hz")) if rate_hz is None else float(rate_hz)
    sig = handle_signals(ctx_or_session, trial_id, rate_hz=rate)
    missing = [name for name, arr in (("handle_accel", sig.acceleration), ("handle_wrench", sig.force)) if arr is None]
    if missing:
        raise fail(
            "E302",
            f"trial {trial_id!r} has no {' or '.join(missing)} stream; the dynamic model needs it",
            file="session.json",
            expected=list(REQUIRED_STREAMS),
            found=missing,
        )
    assert sig.acceleration is not None and sig.force is not None and sig.torque is not None  # the wrench has both
    u = np.column_stack([sig.quaternion, sig.position, sig.velocity, sig.acceleration])
    y = np.column_stack([sig.force, sig.torque])
    valid = np.asarray(sig.valid, dtype=bool) & np.all(np.isfinite(u), axis=1) & np.all(np.isfinite(y), axis=1)
    return TrialData(trial_id=trial_id, t=np.asarray(sig.t, dtype=float), u=u, y=y, valid=valid)


def predict_trial(model: HWModelFile, data: TrialData) -> np.ndarray:
    """The model's outputs over a trial, run by run from rest; NaN on invalid rows (spec §11.3, §11.7)."""
    out = np.full((len(data.t), model.ny), np.nan)
    for run in data.runs():
        out[run] = predict(model, data.u[run])
    return out


def training_trial(session: Any) -> Any:
    """The training trial: the local_dynamic trial with the lowest repetition (normally 1; spec §11.7)."""
    trials = session.trials_of("local_dynamic")
    if not trials:
        raise fail(
            "E302",
            "the session has no local_dynamic trial to fit the dynamic model to",
            file="session.json",
            expected="a local_dynamic trial",
            found=[t.protocol for t in session.trials],
        )
    return trials[0]


def held_out_trials(session: Any, train_id: str) -> list[Any]:
    """Test trials (spec §11.7): every other unpowered local_dynamic, free_space or other trial with all three handle streams."""
    return [
        t
        for t in session.trials
        if t.id != train_id
        and t.protocol in TEST_PROTOCOLS
        and not t.powered
        and all(session.stream(t.id, k) is not None for k in REQUIRED_STREAMS)
    ]


def fit_trial(ctx_or_session: Any, trial_id: str, options: FitOptions | None = None) -> tuple[HWModelFile, TrialData]:
    """Fit the model to one trial (spec §11.4, §11.7); E701 when its valid data are shorter than ``min_training_s``."""
    data = trial_data(ctx_or_session, trial_id)
    rate = float(param(FAMILY, "sample_rate_hz"))
    runs = data.runs()
    seconds = sum(r.stop - r.start for r in runs) / rate
    if seconds < param(FAMILY, "min_training_s"):
        raise fail(
            "E701",
            f"trial {trial_id!r} has {seconds:.1f} s of valid data; the dynamic model needs at least "
            f"{param(FAMILY, 'min_training_s')} s",
            expected=f">= {param(FAMILY, 'min_training_s')} s",
            found=round(seconds, 2),
        )
    session = getattr(ctx_or_session, "session", ctx_or_session)
    model, _ = fit(
        [data.u[r] for r in runs],
        [data.y[r] for r in runs],
        sample_rate_hz=rate,
        options=options,
        input_names=INPUT_NAMES,
        input_units=INPUT_UNITS,
        output_names=OUTPUT_NAMES,
        output_units=OUTPUT_UNITS,
        quaternion_columns=[0, 1, 2, 3],
        session_id=session.session_id,
        trial_id=trial_id,
    )
    return model, data


def given_model_trial(ctx_or_session: Any, trial_id: str, relative: str) -> tuple[HWModelFile, TrialData]:
    """A parameter file inside the session folder used instead of fitting (spec §16.2 ``parameters.model``):
    the metrics then measure the given model's prediction (§11.3) on the trial. E702 when the path is unsafe."""
    from haptify.session_format import is_safe_relative_path

    session = getattr(ctx_or_session, "session", ctx_or_session)
    if not isinstance(relative, str) or not is_safe_relative_path(relative):
        raise fail("E702", f"model file {relative!r} is not a relative path inside the session folder", file=str(relative))
    model = load_model(session.root / relative)
    return model, trial_data(ctx_or_session, trial_id, model.sample_rate_hz)


def _window_valid(valid: np.ndarray, window: int) -> np.ndarray:
    n = len(valid) // window
    return np.asarray(valid[: n * window].reshape(n, window).all(axis=1))


def trial_features(data: TrialData, window: int) -> tuple[WindowFeatures, np.ndarray]:
    """Window features of a trial and which windows are wholly valid (spec §11.6.1)."""
    filled = np.where(data.valid[:, None], data.u, np.r_[1.0, np.zeros(12)])  # rows outside valid stretches are masked out
    feats = window_features(filled[:, 4:7], filled[:, 7:10], filled[:, 10:13], filled[:, 0:4], window)
    return feats, _window_valid(data.valid, window)


def _subset(f: WindowFeatures, mask: np.ndarray) -> WindowFeatures:
    return WindowFeatures(f.position[mask], f.velocity[mask], f.acceleration[mask], f.orientation[mask])


def segment_table(model: HWModelFile, train: TrialData, tests: list[TrialData], labels: dict[str, str]) -> list[dict[str, Any]]:
    """Every complete, wholly valid 5 s segment of the training and test trials with its kinematic distance to
    the training set and its force error (spec §11.6)."""
    rate = model.sample_rate_hz
    window = int(round(param(FAMILY, "window_s") * rate))
    if window < 1:  # a parameter file at a few Hz: windows of round(window_s · rate) = 0 samples
        raise fail(
            "E701",
            f"at the model's {rate:g} Hz a {param(FAMILY, 'window_s')} s distance window holds no sample",
            expected="round(window_s · sample_rate_hz) >= 1",
            found=rate,
        )
    per_segment = int(round(param(FAMILY, "segment_s") / param(FAMILY, "window_s")))
    scales = DistanceScales.from_definition()
    train_feats, train_ok = trial_features(train, window)
    reference = _subset(train_feats, train_ok)
    rows = []
    for data in [train] + tests:
        feats, ok = trial_features(data, window)
        minima = np.full(len(ok), np.nan)
        if ok.any():
            minima[ok] = nearest_distances(_subset(feats, ok), reference, scales)
        n_seg = len(ok) // per_segment
        seg_ok = ok[: n_seg * per_segment].reshape(n_seg, per_segment).all(axis=1)
        distances = segment_distances(minima, per_segment)
        predicted = predict_trial(model, data)
        errors = segment_force_errors(data.y[:, :3], predicted[:, :3], window * per_segment)
        for k in np.flatnonzero(seg_ok):
            rows.append(
                {
                    "trial": data.trial_id,
                    "set": labels[data.trial_id],
                    "start_s": float(data.t[k * per_segment * window]),
                    "distance": float(distances[k]),
                    "force_error": float(errors[k]),
                }
            )
    return rows


def _unavailable_all(code: str, reason: str, ids: list[str]) -> list[MetricResult | Unavailable]:
    from haptify.results import Unavailable

    return [Unavailable(id=i, code=code, reason=reason) for i in ids]


def compute(ctx: Any) -> list[MetricResult | Unavailable]:
    """The dynamics family's metrics for a session (spec §11.7): training-fit RMS errors and error vs distance."""
    from haptify.results import MetricResult

    fam = family(FAMILY)
    ids = [m.id for m in fam.metrics]
    session = ctx.session
    try:
        train = training_trial(session)
        missing = [k for k in REQUIRED_STREAMS if session.stream(train.id, k) is None]
        if missing:
            raise fail("E302", f"training trial {train.id!r} lacks {missing}", expected=list(REQUIRED_STREAMS), found=missing)
        given = (getattr(ctx, "parameters", None) or {}).get("model")
        if given:
            model, data = ctx.cached(("dynamics_given_model", train.id, given), lambda: given_model_trial(ctx, train.id, given))
        else:
            model, data = ctx.cached(("dynamics_model", train.id), lambda: fit_trial(ctx, train.id))
    except HaptifyError as err:
        return _unavailable_all(err.code, err.findings[0].message, ids)

    unit = {m.id: m.unit for m in fam.metrics}
    out: list[MetricResult | Unavailable] = []
    predicted = predict_trial(model, data)
    ok = data.valid & np.all(np.isfinite(predicted), axis=1)  # runs of one row have no prediction
    n = int(ok.sum())
    if n == 0:  # e.g. a given parameter file whose rate leaves single-row runs: no RMS, not NaN (spec §15.2)
        return _unavailable_all(
            "E701",
            f"training trial {train.id!r} has no valid run of at least 2 samples at {model.sample_rate_hz:g} Hz to predict",
            ids,
        )
    err_rmse = rmse(data.y[ok], predicted[ok])
    summary = (
        {
            "iterations": model.fit.iterations,
            "stop_reason": model.fit.stop_reason,
            "fit_percent": model.fit.fit_percent,
            "samples": n,
        }
        if model.fit
        else {"model": given, "samples": n}
    )
    for name, cols in (("force", slice(0, 3)), ("torque", slice(3, 6))):
        vec = [float(v) for v in err_rmse[cols]]
        mid = f"dynamics.{name}_rmse"
        out.append(
            MetricResult(
                id=mid,
                value=vec,
                unit=unit[mid],
                per_repetition=[vec],
                trials=[train.id],
                n=n,
                diagnostics=summary,
                definition_version=fam.version,
            )
        )
        out.append(
            MetricResult(
                id=mid + "_mean",
                value=float(np.mean(vec)),
                unit=unit[mid + "_mean"],
                per_repetition=[float(np.mean(vec))],
                trials=[train.id],
                n=n,
                definition_version=fam.version,
            )
        )

    eid = "dynamics.error_vs_distance"
    if not ctx.wants(eid):
        return out
    tests = held_out_trials(session, train.id)
    if not tests:
        return out + _unavailable_all(
            "E701",
            "no test trial (another local_dynamic repetition, free_space or an unpowered "
            "'other' trial) with handle pose, wrench and acceleration",
            [eid],
        )
    try:
        labels = {train.id: "training"}
        datasets = []
        for t in tests:
            labels[t.id] = f"{t.protocol}:{t.label}" if t.label else t.protocol
            datasets.append(trial_data(ctx, t.id, model.sample_rate_hz))
        rows = segment_table(model, data, datasets, labels)
        slope, intercept = line_fit(np.array([r["distance"] for r in rows]), np.array([r["force_error"] for r in rows]))
    except HaptifyError as err:
        return out + _unavailable_all(err.code, err.findings[0].message, [eid])
    used = [train.id] + [t.id for t in tests if any(r["trial"] == t.id for r in rows)]
    out.append(
        MetricResult(
            id=eid,
            value=[slope, intercept],
            unit=unit[eid],
            trials=used,
            n=len(rows),
            diagnostics={"order": ["slope", "intercept"], "segments": rows},
            definition_version=fam.version,
        )
    )
    return out


def report_figures(ctx: Any, results: Any) -> list[ReportFigure]:
    """RMS force error of every 5 s segment against its kinematic distance to the training set, with
    the fitted line (paper Fig. 9; spec §11.7). Drawn from ``dynamics.error_vs_distance``'s diagnostics."""
    import matplotlib.pyplot as plt

    from haptify.report import ReportFigure

    metric = results.get("dynamics.error_vs_distance") if results is not None else None
    if metric is None:
        return []
    rows = metric.diagnostics.get("segments", [])
    slope, intercept = metric.value
    fig, ax = plt.subplots(figsize=(8, 5))
    for name in sorted({r["set"] for r in rows}, key=lambda s: (s != "training", s)):
        pts = [(r["distance"], r["force_error"]) for r in rows if r["set"] == name]
        distances, errors = zip(*pts)
        ax.scatter(distances, errors, s=14, label=name)
    d = np.array([0.0, max((r["distance"] for r in rows), default=1.0)])
    ax.plot(d, intercept + slope * d, "k-", lw=1, label=f"fit: {slope:.3g} N per unit distance + {intercept:.3g} N")
    ax.set_xlabel("kinematic distance to the training set (paper eq. 9, dimensionless)")
    ax.set_ylabel("RMS force error of the segment (N)")
    ax.legend(fontsize=8)
    return [
        ReportFigure(
            "dynamics_error_vs_distance",
            "Force prediction error of the local dynamic model against the "
            "kinematic distance of each 5 s segment (paper Fig. 9; spec chapter 11).",
            fig,
        )
    ]
