"""The local dynamic model's peer (issue 21): a polynomial NARX identified by sysidentpy's FROLS.

Runs in its own environment (``.venv-peers``: sysidentpy pins numpy ≤ 2.3.5, the project needs a newer
numpy; ``make bench`` creates it). Reads the training and held-out records written by
``bench_local_dynamics.py`` (an .npz with ``train_u<k>``, ``train_y<k>``, ``test_u<k>``, ``test_y<k>``; u
(N, 13), y (N, 6) at 100 Hz), fits one MISO NARX per output (degree 2, lags 2 of the output and of every
input, terms chosen by FROLS with the AIC), simulates every held-out record free-running from its first
two measured samples, and prints one JSON line: the fit's process CPU time and the held-out RMS error per
output (the same definition as the Hammerstein–Wiener side).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from sysidentpy.basis_function import Polynomial
from sysidentpy.model_structure_selection import FROLS
from sysidentpy.parameter_estimation import LeastSquares

LAGS = 2
DEGREE = 2
TERMS = int(sys.argv[2]) if len(sys.argv) > 2 else 12


def records(data, prefix: str) -> list[tuple[np.ndarray, np.ndarray]]:
    count = len([k for k in data.files if k.startswith(f"{prefix}_u")])
    return [(data[f"{prefix}_u{k}"], data[f"{prefix}_y{k}"]) for k in range(count)]


def main(path: str) -> None:
    data = np.load(path)
    train, test = records(data, "train"), records(data, "test")
    nu, ny = train[0][0].shape[1], train[0][1].shape[1]
    # One training record: the runs joined (as sysidentpy takes one), longest first.
    u = np.vstack([a for a, _ in train])
    y = np.vstack([b for _, b in train])
    start = time.process_time()
    models = []
    for j in range(ny):
        model = FROLS(order_selection=False, n_terms=TERMS, ylag=LAGS, xlag=[[1, LAGS]] * nu,
                      estimator=LeastSquares(), basis_function=Polynomial(degree=DEGREE))
        model.fit(X=u, y=y[:, j:j + 1])
        models.append(model)
    cpu = time.process_time() - start
    sq = np.zeros(ny)
    count = 0
    for a, b in test:
        if len(a) <= LAGS:
            continue
        for j, model in enumerate(models):
            pred = model.predict(X=a, y=b[:LAGS, j:j + 1])[:, 0]
            err = b[:, j] - pred
            sq[j] += float(np.sum(err[LAGS:] ** 2))
        count += len(a) - LAGS
    rmse = np.sqrt(sq / count)
    print(json.dumps({"fit_cpu_s": cpu, "heldout_rmse": rmse.tolist(), "samples": int(count),
                      "model": f"polynomial NARX, degree {DEGREE}, lags {LAGS}, {TERMS} FROLS terms per output"}))


if __name__ == "__main__":
    main(sys.argv[1])
