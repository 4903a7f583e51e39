"""The library of candidate effects (discrepancy README §2, "name"): one entry per simulator effect id.

Every candidate is the twin's own component (:mod:`haptify_tools.twin.model`), switched on with ONE
identified parameter — the same value on every drive axis — while its other parameters keep the values
stored in the twin file (a disabled component still carries them); affine effects marked ``per_drive`` may be
identified with one value per drive (:func:`.identify.fit_per_drive`). Its prediction of the residual is
always obtained by simulation along the measured path, ``δ(p) = sim(twin + effect(p)) − sim(twin)``:

- ``affine`` candidates (weights, inertia, friction levels, link length): δ is affine in the parameter,
  ``δ(p) = a + p·b``, so two simulations give the regressor and least squares gives ``p``;
- ``search`` candidates (series-elastic stiffness, torque limit, cut-off trip force, backlash width, the
  base-collision box's top height): a logarithmic grid of simulations, then a bounded Brent refinement in
  ``log p`` (a 1-D search). The base collision is fitted to the workspace sweep (:mod:`.workspace`),
  every other candidate to the hand-force residual.

Effects the calibrated hand force cannot see are listed in :data:`NOT_OBSERVABLE` with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Literal

import numpy as np

from haptify_tools.discrepancy import workspace as ws
from haptify_tools.twin.model import TwinFile, set_param

#: Effect ids of the simulator that the hand-force residual cannot reveal, and why (reported as such).
NOT_OBSERVABLE: dict[str, str] = {
    "sensor.bias": "removed by the session's own handle calibration (spec §6.4) before any comparison",
    "vibration.device": "acts above the force comparison band; judged by the vibration benchmark, not the force residual",
}


@dataclass(frozen=True)
class Candidate:
    """One library effect: its id, the identified parameter (twin-file name, unit), how δ(p) is found,
    which trials it acts in (``all`` or only ``active`` ones) and how to make the twin that has it (discrepancy README §2).
    """

    effect_id: str
    parameter: str
    unit: str
    kind: Literal["affine", "search"]
    scope: Literal["all", "active", "workspace"]
    probe: Callable[[TwinFile], float]  # affine: a typical value; search: the grid's centre
    grid_factors: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0, 4.0)
    lower: float = 0.0
    #: the parameter is a force level compared with the commanded force: the grid is relative to the largest
    #: commanded force of the active trials, and values above it (the cut-off never trips) need no simulation
    commanded_scale: bool = False
    #: secant re-linearisations of an affine fit (for effects that are affine only to first order)
    relinearise: int = 0
    #: the parameter holds one value per drive and may be identified per drive (an affine fit, discrepancy README §2)
    per_drive: bool = False

    def apply(self, twin: TwinFile, value: float | list[float]) -> TwinFile:
        """A copy of ``twin`` with this effect on and its parameter set to ``value`` (one number: every axis; a list:
        one value per drive)."""
        v = [float(x) for x in value] if isinstance(value, (list, tuple, np.ndarray)) else float(value)
        if self.effect_id == ws.EFFECT_ID:
            return ws.apply(twin, self._one(v))
        t = twin
        if self.effect_id == "drive.force_cutoff":  # keep the re-arm level below the new trip level
            rearm = min(t.effects.drive_force_cutoff.rearm_force_N, 0.5 * self._one(v))
            t = set_param(t, "drive.force_cutoff.rearm_force_N", rearm)
        t = set_param(t, f"{self.effect_id}.{self.parameter}", v)
        return set_param(t, f"{self.effect_id}.enabled", True)

    def _one(self, value: float | list[float]) -> float:
        """The one value of an effect whose parameter is not per drive; ValueError for a list."""
        if isinstance(value, list):
            raise ValueError(f"{self.effect_id}.{self.parameter} takes one value, not one per drive")
        return value

    def available(self, twin: TwinFile) -> bool:
        """True when the twin lacks this effect (the library proposes only what the twin does not have)."""
        if self.effect_id == ws.EFFECT_ID:
            return ws.available(twin)
        if self.effect_id == "drive.backlash" and not twin.on("drive.series_elasticity"):
            return False  # without an elastic cable the twin's drive has no play to model
        if self.effect_id == "kinematics.link_length":
            e = twin.effects.kinematics_link_length
            return not e.enabled or not any(e.delta_a_m)
        return not twin.on(self.effect_id)


@dataclass(frozen=True)
class _MeanOf:
    """Probe: the mean magnitude of the parameter stored in the twin file, or ``fallback`` when it is zero."""

    effect_id: str
    parameter: str
    fallback: float

    def __call__(self, twin: TwinFile) -> float:
        v = getattr(twin.effect(self.effect_id), self.parameter)
        m = float(np.mean(np.abs(v))) if isinstance(v, list) else float(v)
        return m if m > 0 else self.fallback


@dataclass(frozen=True)
class _Fixed:
    """Probe: a fixed typical value."""

    value: float

    def __call__(self, twin: TwinFile) -> float:
        return self.value


_mean_of = _MeanOf


@dataclass(frozen=True)
class _BoxTop:
    """Probe: the stored top height of the collision box (device frame, m)."""

    def __call__(self, twin: TwinFile) -> float:
        return ws.box_top(twin)[0]


#: The library, in the order of the simulator's effect ids (discrepancy README §2).
LIBRARY: tuple[Candidate, ...] = (
    Candidate("gravity", "g_m_per_s2", "m/s²", "affine", "all", _mean_of("gravity", "g_m_per_s2", 9.80665)),
    Candidate(
        "inertia",
        "rotor_inertia_kg_m2",
        "kg·m²",
        "affine",
        "all",
        _mean_of("inertia", "rotor_inertia_kg_m2", 1e-6),
        per_drive=True,
    ),
    Candidate(
        "friction.coulomb", "torque_Nm", "N·m", "affine", "all", _mean_of("friction.coulomb", "torque_Nm", 0.03), per_drive=True
    ),
    Candidate(
        "friction.viscous",
        "damping_Nms_per_rad",
        "N·m·s/rad",
        "affine",
        "all",
        _mean_of("friction.viscous", "damping_Nms_per_rad", 0.01),
        per_drive=True,
    ),
    Candidate(
        "friction.stribeck",
        "excess_torque_Nm",
        "N·m",
        "affine",
        "all",
        _mean_of("friction.stribeck", "excess_torque_Nm", 0.01),
        per_drive=True,
    ),
    Candidate(
        "drive.series_elasticity",
        "stiffness_Nm_per_rad",
        "N·m/rad",
        "search",
        "active",
        _mean_of("drive.series_elasticity", "stiffness_Nm_per_rad", 10.0),
    ),
    Candidate(
        "drive.torque_saturation",
        "max_torque_Nm",
        "N·m",
        "search",
        "active",
        _mean_of("drive.torque_saturation", "max_torque_Nm", 0.3),
    ),
    Candidate(
        "drive.force_cutoff",
        "trip_force_N",
        "N",
        "search",
        "active",
        _Fixed(2.0),
        grid_factors=(0.02, 0.05, 0.1, 0.2, 0.4, 0.8),
        commanded_scale=True,
    ),
    Candidate("drive.backlash", "width_rad", "rad", "search", "active", _mean_of("drive.backlash", "width_rad", 0.002)),
    Candidate("kinematics.link_length", "delta_a_m", "m", "affine", "all", _Fixed(0.005), relinearise=2, lower=-np.inf),
    Candidate("handle.connector_mass", "mass_kg", "kg", "affine", "all", _mean_of("handle.connector_mass", "mass_kg", 0.03)),
    Candidate(ws.EFFECT_ID, ws.PARAMETER, "m", "search", "workspace", _BoxTop(), grid_factors=ws.GRID_FACTORS),
)

LIBRARY_IDS: tuple[str, ...] = tuple(c.effect_id for c in LIBRARY)


def candidate(effect_id: str) -> Candidate:
    """The library entry of ``effect_id`` (KeyError when the id has no force-residual candidate) (discrepancy README §2)."""
    for c in LIBRARY:
        if c.effect_id == effect_id:
            return c
    raise KeyError(effect_id)
