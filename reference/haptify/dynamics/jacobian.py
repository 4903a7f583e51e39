"""The model under fit (spec §11.4.3): the layout of the parameter vector θ, the training records with their
precomputed input basis, the simulation on the stacked records (same algorithm as prediction, §11.3) and the
analytic Jacobian of the simulation error, accumulated into normal equations block of rows by block of rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from haptify.dynamics.prediction import Segments, _hat_columns, _segments, pwl_basis
from haptify.processing.filter_bank import FilterBank, lfilter_columns


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
    delays carry from one block to the next (:class:`haptify.processing.filter_bank.FilterBank`)."""

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

    def rows(
        self, rec: _Record, rows: slice, out: np.ndarray, residual: np.ndarray | None = None, sums: np.ndarray | None = None
    ) -> None:
        """Write the Jacobian's rows ``rows`` (the block after the previous call's) into ``out``:
        ∂z_ji/∂v_ik = q^-nk B_ji/F_ji φ_ik over Φ, ∂z_ji/∂b_k = q^-(nk+k-1)/F_ji w_i and ∂z_ji/∂f_l =
        −q^-l/F_ji z_ji over ``signals``, each times the gain; the output map's hat functions times the weight.
        ``out`` is float64, or float32 for a Gram matrix: the rows are then rounded to single precision as
        they are written, values below :data:`SINGLE_PRECISION_FLOOR` zeroed (:func:`_single_precision`).
        With the block's weighted residuals ``residual`` and ``sums`` (columns,), ``sums += residualᵀ J``
        in double precision, from the rows before rounding."""
        ns, n_lin = self.shared.columns, self.linear.columns
        starts = rec.starts[(rec.starts >= rows.start) & (rec.starts < rows.stop)] - rows.start
        gain = self.gain[rows]
        single = out.dtype == np.float32
        floor = SINGLE_PRECISION_FLOOR if single else 0.0

        def summing(columns: slice) -> dict[str, Any]:
            return {} if residual is None or sums is None else {"weights": residual, "sums": sums[columns]}

        if ns:
            self.shared(rec.basis[rows], out=out[:, :ns], gain=gain, starts=starts, floor=floor, **summing(slice(0, ns)))
        signals = rec.scratch("signals", len(gain), n_lin)
        width = n_lin // len(self.signals)
        for m, signal in enumerate(self.signals):
            signals[:, m * width : (m + 1) * width] = signal[rows]
        lin = slice(ns, ns + n_lin)
        self.linear(signals, out=out[:, lin], gain=gain, starts=starts, floor=floor, **summing(lin))
        if self.segments is not None:
            hats = rec.scratch("hats", len(gain), self.hats) if single else out[:, ns + n_lin :]
            _hat_columns(hats, self.segments[0][rows], self.segments[1][rows], self.weight)
            if residual is not None and sums is not None:
                sums[ns + n_lin :] += residual @ hats
            if single:
                _single_precision(hats, out[:, ns + n_lin :])


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


#: Rows of the Jacobians formed at a time by :func:`_normal_equations`: a block of 2048 × ~200 columns
#: (1.6 MiB in single precision) stays in the processor's cache between being filtered and entering the Gram matrix.
BLOCK_ROWS = 2048


def normal_equations_buffer(st: _Structure, rows: int) -> np.ndarray:
    """The single-precision buffer :func:`_normal_equations` forms its blocks of J in, for ``rows`` stacked
    samples: up to :data:`BLOCK_ROWS` rows, as wide as the widest output's Jacobian."""
    width = st.n_shared + max(st.own(j).stop - st.own(j).start for j in range(st.ny))
    return np.empty((min(rows, BLOCK_ROWS), width), dtype=np.float32)


#: Values of J below this magnitude (2^-63 ≈ 1.1e-19) enter JᵀJ as zeros: the product of two larger ones is
#: at least 2^-126, single precision's smallest normal number.
SINGLE_PRECISION_FLOOR = 2.0**-63


def _single_precision(block: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``block`` (float64) rounded to single precision into ``out`` (float32, same shape), every value below
    :data:`SINGLE_PRECISION_FLOOR` in magnitude set to zero (spec §11.4.3), so that no product of two
    values of the rounded block is subnormal. Decaying filter responses put values down to 1e-300 in J; the
    ones zeroed change JᵀJ by less than 1e-15 against a ridge term of 1e-5, but a processor multiplies
    subnormals an order of magnitude slower (on an AVX-512 machine a 2048 × 192 block's Gram matrix took
    8 ms instead of 0.8 ms). The filter bank applies the same rule to the columns it writes
    (:meth:`_JacobianPass.rows`); this function to the output map's few columns."""
    with np.errstate(over="ignore"):  # beyond single precision's range: ±inf
        out[...] = block
    out[np.abs(out) < SINGLE_PRECISION_FLOOR] = 0.0
    return out


def _normal_equations(
    st: _Structure, theta: np.ndarray, rec: _Record, weights: np.ndarray, sim: _Simulation, buffer: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray]]:
    """JᵀJ and Jᵀe of every output j (spec §11.4.3; J of :func:`_output_jacobian` with weight ``weights[j]``,
    e the weighted residuals), accumulated over blocks of :data:`BLOCK_ROWS` rows formed in ``buffer``
    (float32, ≥ BLOCK_ROWS × columns), the outputs' blocks of the same rows one after the other (so a block
    of the input basis Φ is read once for all outputs). Jᵀe is summed in double precision as the rows are
    formed; JᵀJ from the block rounded to single precision, its tiniest values zeroed
    (:func:`_single_precision`; spec §11.4.3: it only shapes the step, the gradient fixes where the descent
    stops), summed in double."""
    passes = [_JacobianPass.of(st, theta, rec, j, weights[j], sim) for j in range(st.ny)]
    residuals = [(rec.y[:, j] - p.yhat) * weights[j] for j, p in enumerate(passes)]
    grams = [np.zeros((p.columns, p.columns)) for p in passes]
    gradients = [np.zeros(p.columns) for p in passes]
    n = len(rec.u)
    for start in range(0, n, BLOCK_ROWS):
        rows = slice(start, min(start + BLOCK_ROWS, n))
        for jacobian, e, gram, jac_e in zip(passes, residuals, grams, gradients):
            block = buffer[: rows.stop - rows.start, : jacobian.columns]
            jacobian.rows(rec, rows, block, e[rows], jac_e)
            gram += block.T @ block
    return list(zip(grams, gradients))


def _add_normal_equations(hess: np.ndarray, grad: np.ndarray, ns: int, own: slice, gram: np.ndarray, jac_e: np.ndarray) -> None:
    """Add one output's JᵀJ and −Jᵀe (rows ``[shared, own]`` of :func:`_output_jacobian`) to the normal
    equations of spec §11.4.3: the shared parameters are θ[:ns], the output's own a contiguous range."""
    hess[:ns, :ns] += gram[:ns, :ns]
    hess[:ns, own] += gram[:ns, ns:]
    hess[own, :ns] += gram[ns:, :ns]
    hess[own, own] += gram[ns:, ns:]
    grad[:ns] -= jac_e[:ns]
    grad[own] -= jac_e[ns:]
