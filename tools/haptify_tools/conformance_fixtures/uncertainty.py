"""The measurement-uncertainty fixtures and cases (spec chapter 19): free-space repetitions with known forces,
their Type A uncertainty, coverage factor and expanded uncertainty (§19.2, §19.4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from haptify.formats.storage import SessionWriter
from haptify_tools import rig_builders as rb
from haptify_tools.conformance_fixtures.free_space import felt
from haptify_tools.conformance_fixtures.records import Fixture, case
from haptify_tools.conformance_fixtures.truth import circle, grid, handle_trial, manifest, spin
from haptify_tools.example_session import example_rig


def free_space_repetitions(
    w: SessionWriter, gains: tuple[float, ...], truth: rb.HandleTruth, duration_s: float, fmt: str = "parquet"
) -> None:
    """Free-space trials 1, 2, … whose hand force is ``gain ×`` the fs-typical force :func:`felt` of the
    trial's own clock (each trial starts 20 s after the previous one), on the fs-typical circle and spin."""
    for rep, gain in enumerate(gains, start=1):
        t0 = 20.0 * (rep - 1)

        def force_w(t: np.ndarray, g: float = gain, t0: float = t0) -> np.ndarray:
            return g * felt(t - t0)

        handle_trial(
            w,
            f"free_space-{rep}",
            "free_space",
            duration_s=duration_s,
            position=circle(0.05, 1.0),
            quaternion=spin(0.07),
            force_w=force_w,
            truth=truth,
            repetition=rep,
            start_s=t0,
            fmt=fmt,
        )


def uncertainty_fixtures() -> list[Fixture]:
    """Type A uncertainty with a known answer (spec §19.2, §19.4): two free-space repetitions whose forces are
    the fs-typical force and 1.1 × it, so their mean magnitudes are x₁ and 1.1·x₁ (x₁ analytic). CSV streams, so
    that an implementation without a Parquet reader (the JavaScript example) can answer them too."""
    from scipy import stats

    truth = rb.HandleTruth(force_noise=0.0, torque_noise=0.0, accel_noise=0.0, mass=0.06)
    T = 12.0
    x1 = float(np.linalg.norm(felt(grid(T)), axis=1).mean())
    u = 0.05 * x1  # s = 0.1·x₁/√2, u = s/√2
    k = float(stats.t.ppf(0.975, 1))

    def two_reps(path: Path) -> None:
        w = manifest("conf-unc-fs-two-reps", example_rig(), truth=truth)
        free_space_repetitions(w, (1.0, 1.1), truth, T, fmt="csv")
        w.write(path)

    fx = Fixture("unc-fs-two-reps", two_reps)
    why = (
        f"x₁ = {x1:.6f} N, the fs-typical mean |F| (analytic), and x₂ = 1.1·x₁; no rig trial, so no Type B source "
        "is available (sources_missing) and u is Type A only"
    )
    params = {"uncertainty": True}
    m = "free_space.force_mean"
    fx.cases += [
        case(
            f"{m}.uncertainty-u.two-reps",
            m,
            "19.2",
            fx.name,
            u,
            "N",
            "analytic",
            f"u = s/√2 = |x₂ − x₁|/2 = 0.05·x₁; {why}",
            "Type A of two repetitions.",
            parameters=params,
            quantity="u",
        ),
        case(
            f"{m}.uncertainty-k.two-reps",
            m,
            "19.4",
            fx.name,
            k,
            "1",
            "analytic",
            "k = t_0.975(ν_eff) with ν_eff = n − 1 = 1 (one Type A term): 12.706",
            "Coverage factor of two repetitions.",
            parameters=params,
            quantity="k",
        ),
        case(
            f"{m}.uncertainty-expanded.two-reps",
            m,
            "19.4",
            fx.name,
            k * u,
            "N",
            "analytic",
            f"U = k·u = 12.706 × 0.05·x₁; {why}",
            "Expanded uncertainty of two repetitions.",
            parameters=params,
            quantity="U",
        ),
    ]
    return [fx]
