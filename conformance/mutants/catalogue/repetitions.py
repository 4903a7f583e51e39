"""Mutants of the aggregation over repetitions (spec §15.3): the median, the first, the last or the quadratic mean."""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from haptify.pipeline import repetitions
from haptify_mutants.catalogue.model import Mutant, Patch


def _aggregate_by(pick: Callable[[list[float]], float]) -> tuple[Patch, ...]:
    """Every family's repetition aggregate reports ``pick(per_repetition)`` instead of the mean."""

    def make(real: Callable) -> Callable:
        def aggregate(family_name: str, metric_id: str, values: Any, **kw: Any) -> Any:
            result = real(family_name, metric_id, values, **kw)
            if getattr(result, "per_repetition", None):
                result.value = float(pick(result.per_repetition))
            return result

        return aggregate

    return (Patch(repetitions, "aggregate", make, everywhere=True),)


MUTANTS: tuple[Mutant, ...] = (
    # aggregation over repetitions
    Mutant(
        "median_of_repetitions",
        "15.3",
        "R15.3-1",
        "a metric's value is the arithmetic mean of its per-repetition values",
        "the median of the repetitions (robust to an outlying repetition)",
        _aggregate_by(np.median),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    Mutant(
        "first_repetition_only",
        "15.3",
        "R15.3-1",
        "a metric's value is the arithmetic mean of its per-repetition values",
        "the first repetition's value (the others taken for retries)",
        _aggregate_by(lambda v: v[0]),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    Mutant(
        "last_repetition_only",
        "15.3",
        "R15.3-1",
        "a metric's value is the arithmetic mean of its per-repetition values",
        "the last repetition's value (as §6.4 takes the most recent calibration)",
        _aggregate_by(lambda v: v[-1]),
        ("vibration.rms", "vibration.spectral_centroid"),
        cheap=True,
    ),
    Mutant(
        "quadratic_mean_of_repetitions",
        "15.3",
        "R15.3-1",
        "a metric's value is the arithmetic mean of its per-repetition values",
        "the root mean square of the per-repetition values (pooling their energy)",
        _aggregate_by(lambda v: math.sqrt(float(np.mean(np.square(v))))),
        ("vibration.rms",),
        cheap=True,
    ),
)
