"""Mutants of the frictionless surface (spec chapter 12): the contact guard and the planar force's projection."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from haptify.metrics import surface
from haptify_mutants.catalogue.model import Mutant, Patch, _post, _replace


def _contact_unguarded(cs: Any, *_: Any) -> Any:
    """Every contact sample used: the §12.2 guard around contact transitions left out."""
    return dataclasses.replace(cs, used=cs.contact & cs.valid)


def _contact_from_measured(cs: Any, *_: Any) -> Any:
    """Contact decided from the measured normal force F·n instead of the commanded one."""
    with np.errstate(invalid="ignore"):
        touching = surface.contact_of(np.nan_to_num(cs.normal_force, nan=-np.inf))
    return dataclasses.replace(cs, contact=touching & cs.valid, used=surface.guarded(cs.t, touching, cs.t) & cs.valid)


MUTANTS: tuple[Mutant, ...] = (
    # surface
    Mutant(
        "contact_guard_ignored",
        "12.2",
        "R12.2-1",
        "a sample is used only when every commanded sample within ±0.05 s is in contact",
        "every contact sample is used",
        (Patch(surface, "contact_signals", _post(_contact_unguarded), everywhere=True),),
        ("surface.planar_force_mean",),
        cheap=True,
    ),
    Mutant(
        "contact_from_measured_force",
        "12.2",
        "R12.2-1",
        "contact is decided on the COMMANDED normal force",
        "on the measured normal force F·n",
        (Patch(surface, "contact_signals", _post(_contact_from_measured), everywhere=True),),
        ("surface.planar_force_mean",),
        cheap=True,
    ),
    Mutant(
        "planar_force_not_projected",
        "12.3",
        "R12.3-1",
        "the planar force is F − (F·n)n",
        "the whole force |F|",
        (Patch(surface, "planar_force", _replace(lambda force, normal: np.asarray(force, dtype=float))),),
        ("surface.planar_force_mean",),
        cheap=True,
    ),
)
