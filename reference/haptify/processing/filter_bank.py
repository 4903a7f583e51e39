"""A bank of linear filters: each column of a signal through its own B(q)/F(q) (spec §11.3, §11.4.3).

The Hammerstein–Wiener fit of spec §11.4 filters ny · nu · (breakpoints + 2) signals per Jacobian, each
by a different transfer function B_ji(q)/F_ji(q). ``scipy.signal.lfilter`` takes one denominator per
call, so a Python loop over transfer functions made the calls' overhead and its generic inner loop the
fit's main cost. :class:`FilterBank` runs them all in one compiled loop (numba, compiled on
first use and cached on disk) over time-major data, one SIMD lane per column, with exactly ``lfilter``'s
arithmetic: the transposed direct form II in the same order of operations and without fused
multiply-adds, so column m equals ``lfilter(b[m], a[m], x[:, m])`` to the last bit whenever F has an order
≥ 1 (scipy computes a pure FIR filter by convolution, which sums in another order). A bank keeps its
filters' delays between calls, so a long signal can be filtered a block of rows at a time (the fit forms
its Jacobian in blocks that stay in the processor's cache); :func:`lfilter_columns` is one call of a
fresh bank.

Filters of order ≤ 2 (every transfer function of the default structure, nk = 0, nb = nf = 2) take a
loop that keeps the two delays of every column in their own arrays and reads each row of the signals
once; higher orders take the general loop. Filters of order < 2 run as order 2 with zero coefficients,
which adds and subtracts exact zeros (the same values, up to the sign of a zero).

For the fit's Gram matrices a bank also writes its results in single precision, values below a floor
as zero, and sums them weighted by the residuals as it goes (Jᵀe in double precision), so the fit
never stores its Jacobian in double (spec §11.4.3).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numpy.lib.stride_tricks import as_strided

from haptify.processing.compiled_loops import compiled_loop


_SIGNATURE = "void(f8[:, ::1], f8[:, ::1], f8[::1], i8, f8[::1], u1[::1], {out}[::1], i8, f8[:, ::1], f8, f8[::1], f8[::1])"


@compiled_loop(_SIGNATURE.format(out="f8"), _SIGNATURE.format(out="f4"))
def _filter_rows(
    b: npt.NDArray[np.float64],
    a: npt.NDArray[np.float64],
    x: npt.NDArray[np.float64],
    x_stride: int,
    gain: npt.NDArray[np.float64],
    rest: npt.NDArray[np.uint8],
    out: npt.NDArray[np.floating],
    out_stride: int,
    state: npt.NDArray[np.float64],
    floor: float,
    weights: npt.NDArray[np.float64],
    sums: npt.NDArray[np.float64],
) -> None:
    """Filter rows 0 … N − 1 of M signals, each by its own filter, in the transposed direct form II of
    ``lfilter`` (the module's docstring says why), continuing from and updating the delays ``state``."""
    # b, a: (order + 1, M) coefficients, order ≥ 2; row t of the M signals is x[t * x_stride:][:M];
    # gain: (N,); rest: (N,) 1 where every filter restarts from rest; row t of the result is
    # out[t * out_stride:][:M] (float64, or float32: rounded), a value whose magnitude once stored is below
    # floor stored as 0; sums (M,) += weights[t] times row t's result before rounding; state: (order, M) the
    # delays before row 0, left as they are after row N − 1
    order = b.shape[0] - 1
    n, m = len(gain), b.shape[1]
    if order == 2:
        z0, z1 = state[0].copy(), state[1].copy()
        b0, b1, b2, a1, a2 = b[0].copy(), b[1].copy(), b[2].copy(), a[1].copy(), a[2].copy()
        for t in range(n):
            if rest[t]:
                z0[:] = 0.0
                z1[:] = 0.0
            xt = x[t * x_stride : t * x_stride + m]
            ot = out[t * out_stride : t * out_stride + m]
            g, wt = gain[t], weights[t]
            for r in range(m):
                xr = xt[r]
                yr = z0[r] + b0[r] * xr
                z0[r] = z1[r] + xr * b1[r] - yr * a1[r]
                z1[r] = 0.0 + xr * b2[r] - yr * a2[r]
                value = yr * g
                sums[r] += value * wt
                ot[r] = value
                if abs(ot[r]) < floor:
                    ot[r] = 0.0
        state[0], state[1] = z0, z1
        return
    z = np.zeros((order + 1, m))  # z[order] stays 0: the last delay has no successor
    z[:order] = state
    y = np.empty(m)
    for t in range(n):
        if rest[t]:
            z[:] = 0.0
        xt = x[t * x_stride : t * x_stride + m]
        z0, b0 = z[0], b[0]
        for r in range(m):
            y[r] = z0[r] + b0[r] * xt[r]
        for k in range(order):
            zk, zk1, bk, ak = z[k], z[k + 1], b[k + 1], a[k + 1]
            for r in range(m):
                zk[r] = zk1[r] + xt[r] * bk[r] - y[r] * ak[r]
        g, wt = gain[t], weights[t]
        ot = out[t * out_stride : t * out_stride + m]
        for r in range(m):
            value = y[r] * g
            sums[r] += value * wt
            ot[r] = value
            if abs(ot[r]) < floor:
                ot[r] = 0.0
    state[:] = z[:order]


def _rows(array: np.ndarray) -> tuple[np.ndarray, int]:
    """A 1-D view of the memory from ``array[0, 0]`` to ``array[-1, -1]`` and its row stride in elements: row t
    of ``array`` (N, M), whose rows are contiguous, is ``flat[t * stride: t * stride + M]``."""
    n, m = array.shape
    if array.flags.c_contiguous:
        return array.reshape(-1), m
    stride = array.strides[0] // array.itemsize
    return as_strided(array, shape=((n - 1) * stride + m,), strides=(array.itemsize,)), stride


def _row_major(array: np.ndarray) -> bool:
    """Whether the rows of a 2-D array are contiguous and do not overlap (what :func:`_rows` needs)."""
    n, m = array.shape
    return (
        array.strides[1] == array.itemsize
        and (n < 2 or array.strides[0] >= array.itemsize * m)
        and array.strides[0] % array.itemsize == 0
    )


class FilterBank:
    """M filters ``b[m] / a[m]`` (spec §11.2: F(q) = 1 + f_1 q^-1 + …) and their delays, which carry over
    from one call to the next: consecutive blocks of rows filtered one after the other give the result of
    filtering all rows at once (the fit forms its Jacobian a block of rows at a time, spec §11.4.3).

    ``b`` (M, nb) and ``a`` (M, na) hold one numerator and one denominator per column, each denominator
    with a leading 1; the shorter of the two is padded with zeros. Raises ValueError when they are not
    one per column or a denominator does not start with 1.
    """

    def __init__(self, b: np.ndarray, a: np.ndarray) -> None:
        b = np.atleast_2d(np.asarray(b, dtype=float))
        a = np.atleast_2d(np.asarray(a, dtype=float))
        if len(b) != len(a):
            raise ValueError(f"one numerator and one denominator per column; got {len(b)} and {len(a)}")
        if not np.all(a[:, 0] == 1.0):
            raise ValueError("every denominator must start with 1 (F(q) = 1 + f_1 q^-1 + …)")
        order = max(b.shape[1], a.shape[1]) - 1
        self.columns = len(b)
        self._b = np.zeros((max(order, 2) + 1, len(b)))  # orders below 2 run as order 2 with zero coefficients
        self._a = np.zeros_like(self._b)
        self._b[: b.shape[1]] = b.T
        self._a[: a.shape[1]] = a.T
        self._delays = np.zeros((max(order, 2), len(b)))  # at rest

    def __call__(
        self,
        x: np.ndarray,
        out: np.ndarray | None = None,
        gain: np.ndarray | None = None,
        starts: np.ndarray | None = None,
        *,
        floor: float = 0.0,
        weights: np.ndarray | None = None,
        sums: np.ndarray | None = None,
    ) -> np.ndarray:
        """Filter the next block of rows: column m of the result is ``x[:, m % S]`` through filter m, continuing
        from the delays the previous block left (at rest before the first), times ``gain[t]`` at row t when a
        gain (N,) is given; every filter restarts from rest at the rows ``starts`` (records stacked one after
        the other, each simulated from zero initial conditions as spec §11.3 requires).

        ``x`` is (N, S) with M a multiple of S (the signals are used in turn; ``x`` is then tiled to M
        columns first). ``x`` and ``out`` (N, M), which receives the result when given, may be views with
        strided rows, e.g. some columns of a Jacobian. ``out`` may be float32: the results are then rounded to
        single precision as they are stored. A stored value whose magnitude is below ``floor`` is stored as 0
        (the fit's Gram matrices, spec §11.4.3). With ``weights`` (N,) and ``sums`` (M,) float64, ``sums[m]``
        is increased by Σ_t weights[t] · result[t, m], the result in double precision before rounding (Jᵀe).
        """
        x = np.asarray(x, dtype=float)
        if x.ndim != 2:
            raise ValueError(f"x must be (samples, signals); got shape {x.shape}")
        n, signals = x.shape
        m = self.columns
        if m % max(signals, 1) or (m and not signals):
            raise ValueError(
                f"{m} filters need one numerator and one denominator per column, a multiple of the {signals} signals"
            )
        if signals and m > signals:
            x = np.tile(x, (1, m // signals))  # the compiled loop reads one signal per column, in order
        elif not _row_major(x):
            x = np.ascontiguousarray(x)
        if out is None:
            out = np.empty((n, m))
        elif out.shape != (n, m) or not _row_major(out) or out.dtype not in (np.float64, np.float32):
            raise ValueError(
                f"out must be float64 or float32 of shape {(n, m)} with contiguous rows; got {out.dtype} {out.shape}"
            )
        gain = np.ones(n) if gain is None else np.ascontiguousarray(gain, dtype=float)
        if gain.shape != (n,):
            raise ValueError(f"gain must hold one factor per sample ({n}); got shape {gain.shape}")
        if (weights is None) != (sums is None):
            raise ValueError("weights and sums go together")
        if weights is None or sums is None:
            weights, sums = np.zeros(n), np.zeros(m)
        weights = np.ascontiguousarray(weights, dtype=float)
        if weights.shape != (n,) or sums.shape != (m,) or sums.dtype != np.float64 or not sums.flags.c_contiguous:
            raise ValueError(
                f"weights must be ({n},) and sums contiguous float64 ({m},); got {weights.shape}, {sums.dtype} {sums.shape}"
            )
        rest = np.zeros(n, dtype=np.uint8)
        if starts is not None and n:
            starts = np.asarray(starts, dtype=np.int64)
            if len(starts) and (starts.min() < 0 or starts.max() >= n):
                raise ValueError(f"starts must be rows of x (0 … {n - 1})")
            rest[starts] = 1
        if out.size:  # then n ≥ 1 and signals ≥ 1
            x_flat, x_stride = _rows(x)
            out_flat, out_stride = _rows(out)
            filters = (self._b, self._a)
            _filter_rows(*filters, x_flat, x_stride, gain, rest, out_flat, out_stride, self._delays, float(floor), weights, sums)
        return out


def lfilter_columns(
    b: np.ndarray,
    a: np.ndarray,
    x: np.ndarray,
    out: np.ndarray | None = None,
    gain: np.ndarray | None = None,
    source: np.ndarray | None = None,
    starts: np.ndarray | None = None,
) -> np.ndarray:
    """Column m of the result is ``x[:, source[m]]`` (default ``x[:, m % S]``) filtered by ``b[m] / a[m]`` from
    zero initial conditions, each output sample t then multiplied by ``gain[t]`` when a gain (N,) is given.
    ``starts`` lists rows where every filter restarts from rest (records stacked one after the other, each
    simulated from zero initial conditions as spec §11.3 requires); row 0 always starts.

    ``b`` (M, nb) and ``a`` (M, na) hold one numerator and one denominator per column, each denominator
    with a leading 1 (F(q) = 1 + f_1 q^-1 + …, as every transfer function of spec §11.2); the shorter of
    the two is padded with zeros. ``x`` is (N, S) with M a multiple of S: the signals are used in turn,
    column m filtering ``x[:, m % S]``. ``source`` (M,) instead picks any signal per column (the picked
    columns are copied first). ``x`` and ``out`` (N, M), which receives the result when given, may be
    views with strided rows, e.g. some columns of a Jacobian. One call of a fresh :class:`FilterBank`;
    raises ValueError on inconsistent shapes or a denominator not starting with 1.
    """
    x = np.asarray(x, dtype=float)
    if source is not None:
        src = np.asarray(source, dtype=np.int64)
        if x.ndim != 2 or (len(src) and (src.min() < 0 or src.max() >= x.shape[1])):
            raise ValueError(f"source must pick signals among the columns of x (shape {x.shape})")
        x = x[:, src]
    return FilterBank(b, a)(x, out=out, gain=gain, starts=starts)
