"""A bank of linear filters: each column of a signal through its own B(q)/F(q) (spec §11.3, §11.4.3).

The Hammerstein–Wiener fit of spec §11.4 filters ny · nu · (breakpoints + 2) signals per Jacobian, each
by a different transfer function B_ji(q)/F_ji(q). ``scipy.signal.lfilter`` takes one denominator per
call, so a Python loop over transfer functions made the calls' overhead and its generic inner loop the
fit's main cost (issue 21). :func:`lfilter_columns` runs them all in one compiled loop (numba, compiled
on first use and cached on disk) over time-major data, one SIMD lane per column, with exactly
``lfilter``'s arithmetic: the transposed direct form II in the same order of operations and without
fused multiply-adds, so column m equals ``lfilter(b[m], a[m], x[:, m])`` to the last bit whenever F has an
order ≥ 1 (scipy computes a pure FIR filter by convolution, which sums in another order).

Filters of order ≤ 2 (every transfer function of the default structure, nk = 0, nb = nf = 2) take a
loop that keeps the two delays of every column in their own arrays and reads each sample once; higher
orders take the general loop. Filters of order < 2 are padded with zero coefficients, which adds and
subtracts exact zeros (the same values, up to the sign of a zero).
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import as_strided

_KERNEL = None


def _kernel():
    """The compiled loop (numba is imported, and the cached machine code loaded, on the first filtering)."""
    global _KERNEL
    if _KERNEL is None:
        from numba import njit

        @njit("void(f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], u1[::1], f8[::1], i8)", cache=True, nogil=True)
        def run(b, a, x, gain, rest, out, stride):
            # b, a: (order + 1, M) coefficients, order ≥ 2; x: (N, M) signals; gain: (N,); rest: (N,) 1 where
            # every filter restarts from rest; out: row t of the result is out[t * stride: t * stride + M]
            order = b.shape[0] - 1
            n, m = x.shape[0], b.shape[1]
            if order == 2:
                z0, z1 = np.zeros(m), np.zeros(m)
                b0, b1, b2, a1, a2 = b[0].copy(), b[1].copy(), b[2].copy(), a[1].copy(), a[2].copy()
                for t in range(n):
                    if rest[t]:
                        z0[:] = 0.0
                        z1[:] = 0.0
                    xt = x[t]
                    g = gain[t]
                    ot = out[t * stride: t * stride + m]
                    for r in range(m):
                        xr = xt[r]
                        yr = z0[r] + b0[r] * xr
                        z0[r] = z1[r] + xr * b1[r] - yr * a1[r]
                        z1[r] = 0.0 + xr * b2[r] - yr * a2[r]
                        ot[r] = yr * g
                return
            z = np.zeros((order + 1, m))          # z[order] stays 0: the last delay has no successor
            y = np.empty(m)
            for t in range(n):
                if rest[t]:
                    z[:] = 0.0
                xt = x[t]
                z0, b0 = z[0], b[0]
                for r in range(m):
                    y[r] = z0[r] + b0[r] * xt[r]
                for k in range(order):
                    zk, zk1, bk, ak = z[k], z[k + 1], b[k + 1], a[k + 1]
                    for r in range(m):
                        zk[r] = zk1[r] + xt[r] * bk[r] - y[r] * ak[r]
                g = gain[t]
                ot = out[t * stride: t * stride + m]
                for r in range(m):
                    ot[r] = y[r] * g

        _KERNEL = run
    return _KERNEL


def _rows(out: np.ndarray) -> tuple[np.ndarray, int]:
    """A 1-D view of the memory from ``out[0, 0]`` to ``out[-1, -1]`` and its row stride in elements: row t of
    ``out`` (N, M), whose rows are contiguous, is ``flat[t * stride: t * stride + M]``."""
    n, m = out.shape
    stride = out.strides[0] // out.itemsize if n > 1 else m
    return as_strided(out, shape=((n - 1) * stride + m,), strides=(out.itemsize,)), stride


def lfilter_columns(b: np.ndarray, a: np.ndarray, x: np.ndarray, out: np.ndarray | None = None,
                    gain: np.ndarray | None = None, source: np.ndarray | None = None,
                    starts: np.ndarray | None = None) -> np.ndarray:
    """Column m of the result is ``x[:, source[m]]`` (default ``x[:, m]``) filtered by ``b[m] / a[m]`` from
    zero initial conditions, each output sample t then multiplied by ``gain[t]`` when a gain (N,) is given.
    ``starts`` lists rows where every filter restarts from rest (records stacked one after the other, each
    simulated from zero initial conditions as spec §11.3 requires); row 0 always starts.

    ``b`` (M, nb) and ``a`` (M, na) hold one numerator and one denominator per column, each denominator
    with a leading 1 (F(q) = 1 + f_1 q^-1 + …, as every transfer function of spec §11.2); the shorter of
    the two is padded with zeros. ``x`` is (N, S); ``source`` (M,) picks a signal per column, so one
    signal may feed several filters (the picked columns are copied first: the compiled loop reads
    ``x`` column by column). ``out`` (N, M), if given, receives the result; it may be a view with
    strided rows, e.g. some columns of a Jacobian. Raises ValueError on inconsistent shapes or a
    denominator not starting with 1.
    """
    b = np.atleast_2d(np.asarray(b, dtype=float))
    a = np.atleast_2d(np.asarray(a, dtype=float))
    x = np.asarray(x, dtype=float)
    if x.ndim != 2:
        raise ValueError(f"x must be (samples, signals); got shape {x.shape}")
    if source is not None:
        src = np.asarray(source, dtype=np.int64)
        if len(src) and (src.min() < 0 or src.max() >= x.shape[1]):
            raise ValueError(f"source must pick signals among the {x.shape[1]} columns of x")
        x = x[:, src]
    x = np.ascontiguousarray(x)
    if len(b) != x.shape[1] or len(a) != x.shape[1]:
        raise ValueError(f"{x.shape[1]} columns need one numerator and one denominator per column; got {len(b)} and {len(a)}")
    if not np.all(a[:, 0] == 1.0):
        raise ValueError("every denominator must start with 1 (F(q) = 1 + f_1 q^-1 + …)")
    width = max(b.shape[1], a.shape[1], 3)
    coef_b = np.zeros((width, len(b)))
    coef_a = np.zeros((width, len(a)))
    coef_b[: b.shape[1]] = b.T
    coef_a[: a.shape[1]] = a.T
    shape = x.shape
    if out is None:
        out = np.empty(shape)
    elif out.shape != shape or out.strides[1] != out.itemsize or out.strides[0] < out.itemsize * shape[1]:
        raise ValueError(f"out must have shape {shape} with contiguous rows; got {out.shape}")
    gain = np.ones(len(x)) if gain is None else np.ascontiguousarray(gain, dtype=float)
    if gain.shape != (len(x),):
        raise ValueError(f"gain must hold one factor per sample ({len(x)}); got shape {gain.shape}")
    rest = np.zeros(len(x), dtype=np.uint8)
    if starts is not None and len(x):
        starts = np.asarray(starts, dtype=np.int64)
        if len(starts) and (starts.min() < 0 or starts.max() >= len(x)):
            raise ValueError(f"starts must be rows of x (0 … {len(x) - 1})")
        rest[starts] = 1
    if out.size:
        flat, stride = _rows(out)
        _kernel()(coef_b, coef_a, x, gain, rest, flat, stride)
    return out
