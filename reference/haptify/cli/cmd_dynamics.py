"""``haptify dynamics fit|predict`` — the local dynamic model from the command line (spec §11.8).

    haptify dynamics fit SESSION [--trial ID] -o model.json [--mat model.mat]
    haptify dynamics predict model.json SESSION [--trial ID] -o prediction.parquet

Outputs are written atomically (spec §3.6) and never overwrite an existing file without ``--overwrite``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from haptify.codes import Code
from haptify.dynamics import (
    OUTPUT_NAMES,
    export_mat,
    fit_trial,
    load_model,
    predict_trial,
    rmse,
    save_model,
    training_trial,
    trial_data,
)
from haptify.errors import fail
from haptify.formats.storage import write_atomically
from haptify.pipeline.gate import require_valid_session

if TYPE_CHECKING:
    from haptify.cli.ui import UI, Subcommands


def register(sub: Subcommands) -> None:
    """Add ``dynamics fit`` and ``dynamics predict`` (spec §11.8)."""
    p = sub.add_parser("dynamics", help="fit or run the local dynamic (Hammerstein–Wiener) model")
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    f = verbs.add_parser("fit", help="fit the model to a local_dynamic trial and write its parameter file")
    f.add_argument("session", type=Path)
    f.add_argument("--trial", help="trial id (default: the local_dynamic trial with the lowest repetition)")
    f.add_argument("-o", "--output", type=Path, required=True, help="parameter file to write (JSON, hw-model schema)")
    f.add_argument("--mat", type=Path, help="also write the model as a MATLAB .mat file")
    f.add_argument("--overwrite", action="store_true", help="replace existing output files")
    f.set_defaults(func=run_fit)
    q = verbs.add_parser("predict", help="simulate a model on a trial's measured motion")
    q.add_argument("model", type=Path)
    q.add_argument("session", type=Path)
    q.add_argument("--trial", help="trial id (default: the local_dynamic trial with the lowest repetition)")
    q.add_argument("-o", "--output", type=Path, required=True, help="Parquet file: t, predicted fx…tz, measured_fx…tz")
    q.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    q.set_defaults(func=run_predict)
    p.set_defaults(func=lambda args, ui: _usage(p))


def _usage(parser: argparse.ArgumentParser) -> int:
    raise fail(
        Code.USAGE, "say 'haptify dynamics fit …' or 'haptify dynamics predict …'", expected=["fit", "predict"], found=None
    )


def _check_free(paths: list[Path | None], overwrite: bool) -> None:
    for path in paths:
        if path is not None and path.exists() and not overwrite:
            raise fail(
                Code.OUTPUT_EXISTS,
                f"{str(path)!r} already exists",
                file=str(path),
                expected="a new path or --overwrite",
                found=str(path),
            )


def run_fit(args: argparse.Namespace, ui: UI) -> int:
    """Fit and write the parameter file (and .mat); prints the training RMS errors (N and N·m; spec §11.8)."""
    _check_free([args.output, args.mat], args.overwrite)
    session, _ = require_valid_session(args.session)
    trial_id = args.trial or training_trial(session).id
    session.trial(trial_id)
    model, _ = fit_trial(session, trial_id)
    fit = model.fit
    assert fit is not None  # fit_trial records how its fit went
    save_model(model, args.output)
    if args.mat:
        export_mat(model, args.mat)
    summary = {
        "trial": trial_id,
        "model": str(args.output),
        "mat": str(args.mat) if args.mat else None,
        "iterations": fit.iterations,
        "stop_reason": fit.stop_reason,
        "rmse": dict(zip(OUTPUT_NAMES, fit.rmse)),
        "fit_percent": dict(zip(OUTPUT_NAMES, fit.fit_percent)),
    }
    ui.emit_json(summary)
    ui.say(f"fitted {trial_id}: {fit.iterations} iterations ({fit.stop_reason})")
    for name, e, pct in zip(OUTPUT_NAMES, fit.rmse, fit.fit_percent):
        ui.say(f"  {name}: RMS error {e:.4g}  fit {pct:.1f} %")
    ui.say(f"wrote {args.output}" + (f" and {args.mat}" if args.mat else ""))
    return 0


def run_predict(args: argparse.Namespace, ui: UI) -> int:
    """Simulate the model on a trial; write t, the predicted and the measured wrench as Parquet.
    Units s, N, N·m; spec §11.8."""
    _check_free([args.output], args.overwrite)
    model = load_model(args.model)
    session, _ = require_valid_session(args.session)
    trial_id = args.trial or training_trial(session).id
    session.trial(trial_id)
    data = trial_data(session, trial_id, model.sample_rate_hz)
    predicted = predict_trial(model, data)
    frame = {"t": data.t}
    for k, name in enumerate(OUTPUT_NAMES):
        frame[name] = predicted[:, k]
    for k, name in enumerate(OUTPUT_NAMES):
        frame[f"measured_{name}"] = np.where(data.valid, data.y[:, k], np.nan)
    table = pd.DataFrame(frame)
    write_atomically(args.output, lambda tmp: table.to_parquet(tmp, index=False))
    ok = data.valid & np.all(np.isfinite(predicted), axis=1)
    errors = rmse(data.y[ok], predicted[ok]) if ok.any() else np.full(len(OUTPUT_NAMES), np.nan)
    ui.emit_json(
        {
            "trial": trial_id,
            "output": str(args.output),
            "samples": int(ok.sum()),
            "rmse": {n: (float(e) if np.isfinite(e) else None) for n, e in zip(OUTPUT_NAMES, errors)},
        }
    )
    ui.say(f"predicted {trial_id}: {int(ok.sum())} valid samples of {len(data.t)}")
    for name, e in zip(OUTPUT_NAMES, errors):
        ui.say(f"  {name}: RMS error {e:.4g}")
    ui.say(f"wrote {args.output}")
    return 0
