"""Mutants of the stiffness (spec chapter 13): the contact transient, the fitted range, the peak force and the
line's intercept."""

from __future__ import annotations

import dataclasses
from typing import Any

from haptify.metrics import stiffness
from haptify_mutants.catalogue.model import Mutant, Patch, _parameters, _post, _replace


def _through_origin(fit: Any, *_: Any) -> Any:
    """f = k·d without an intercept."""
    x, y = fit.penetration, fit.normal_force
    return dataclasses.replace(fit, stiffness=float(x @ y / (x @ x)), intercept=0.0)


MUTANTS: tuple[Mutant, ...] = (
    # stiffness
    Mutant(
        "stiffness_contact_transient_kept",
        "13.2",
        "R13.2-1",
        "the first contact_settle_s of a press (the contact transient) enter neither the fit nor the peak",
        "the fit and the peak start at the first contact sample",
        (Patch(stiffness, "PARAMETERS", _parameters(contact_settle_s=0.0)),),
        ("stiffness.measured", "stiffness.peak_force"),
    ),
    Mutant(
        "stiffness_fit_to_the_peak",
        "13.2",
        "R13.2-1",
        "the fit ends at fit_high_fraction of the rise, where the force stops rising",
        "every loading-stroke sample up to the largest force",
        (Patch(stiffness, "PARAMETERS", _parameters(fit_high_fraction=1.0, rise_hold_s=1e9)),),
        ("stiffness.measured",),
    ),
    Mutant(
        "peak_force_largest_press",
        "13.4",
        "R13.4-1",
        "stiffness.peak_force is the MEAN of the qualifying presses' peaks",
        "the largest press's peak",
        (Patch(stiffness.StiffnessFit, "peak_force", _replace(property(lambda fit: max(p.peak_force for p in fit.presses)))),),
        ("stiffness.peak_force",),
    ),
    Mutant(
        "stiffness_through_origin",
        "13.3",
        "R13.3-1",
        "the line f = k·d + c has an intercept",
        "f = k·d through the origin",
        (Patch(stiffness, "fit_stiffness", _post(_through_origin)),),
        ("stiffness.measured",),
    ),
)
