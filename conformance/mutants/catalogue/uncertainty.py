"""Mutants of the measurement uncertainty (spec chapter 19): Type A without √n (§19.2) and the normal
coverage factor (§19.4)."""

from __future__ import annotations

import math
from typing import Any, Callable

from haptify.metrics import uncertainty
from haptify_mutants.catalogue.model import Mutant, Patch


def _sd_as_type_a(real: Callable) -> Callable:
    """Type A = the sample standard deviation itself, not that of the mean."""

    def type_a(per_repetition: Any) -> Any:
        u, dof = real(per_repetition)
        return u * math.sqrt(len(per_repetition)), dof

    return type_a


def _normal_coverage(real: Callable) -> Callable:
    """k from the normal distribution whatever the degrees of freedom."""
    return lambda dof, p: real(math.inf, p)


MUTANTS: tuple[Mutant, ...] = (
    # uncertainty
    Mutant(
        "type_a_without_root_n",
        "19.2",
        "R19.2-1",
        "Type A of a mean of n repetitions is s/√n",
        "the repetitions' standard deviation s (the spread of one repetition)",
        (Patch(uncertainty, "type_a", _sd_as_type_a),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "coverage_factor_normal",
        "19.4",
        "R19.4-1",
        "k is Student's t at the effective degrees of freedom",
        "k = 1.96 from the normal distribution (the large-sample value)",
        (Patch(uncertainty, "coverage_factor", _normal_coverage),),
        ("free_space.force_mean",),
        cheap=True,
    ),
)
