"""Mutants of the free-space statistics and the force plate (spec §9.2, §9.3, §14.1, §14.2): the sample SD,
the de-meaned plate force, its filter, the plate bias and the corner frames."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from haptify.metrics import free_space, surface
from haptify.processing import force_plate, preprocessing
from haptify_mutants.catalogue.model import Mutant, Patch, _post, _replace


def _population_sd(stats: dict, values: np.ndarray, *_: Any) -> dict:
    """The standard deviation with ddof = 0 (numpy's default) where the spec says ddof = 1."""
    n = len(values)
    return {**stats, "sd": stats["sd"] * math.sqrt((n - 1) / n)}


MUTANTS: tuple[Mutant, ...] = (
    Mutant(
        "sd_ddof_0",
        "9.2",
        "R9.2-1",
        "force_sd and planar_force_sd are sample standard deviations (ddof = 1)",
        "numpy's default ddof = 0",
        (Patch(free_space, "magnitude_stats", _post(_population_sd)), Patch(surface, "planar_stats", _post(_population_sd))),
        ("free_space.force_sd",),
        cheap=True,
    ),
    # free space: the plate
    Mutant(
        "plate_mean_removed_on_all_axes",
        "9.3",
        "R9.3-1",
        "only the mean VERTICAL plate force is subtracted",
        "the mean force vector is subtracted",
        (Patch(free_space, "plate_force_about_weight", _replace(lambda f: f - np.asarray(f, dtype=float).mean(axis=0))),),
        ("free_space.plate_force_mean",),
        cheap=True,
    ),
    Mutant(
        "plate_force_unfiltered",
        "9.3",
        "R9.3-1",
        "the plate force is low-passed at wrench_cutoff_hz before resampling",
        "it is resampled unfiltered",
        (Patch(free_space, "lowpass_resample", _replace(lambda t, x, grid, fc: preprocessing.interp_columns(t, x, grid))),),
        ("free_space.plate_force_mean",),
        cheap=True,
    ),
    Mutant(
        "plate_bias_ignored",
        "14.2",
        "R14.2-1",
        "the plate bias (record or rig.plate_bias trial) is subtracted from every corner",
        "the bias is left in (the vertical de-meaning of §9.3 taken to remove it)",
        (Patch(force_plate, "plate_bias", _replace(lambda ctx: (np.zeros(24), "none"))),),
        ("free_space.plate_force_mean",),
        cheap=True,
    ),
    Mutant(
        "plate_corner_frames_ignored",
        "14.1",
        "R14.1-1",
        "each corner reading is rotated from its sensor frame into W",
        "the corner frames are taken for W",
        (
            Patch(
                force_plate,
                "corner_geometry",
                _post(lambda r, *_: (r[0], np.broadcast_to(np.eye(3), r[1].shape).copy())),
                everywhere=True,
            ),
        ),
        ("free_space.plate_force_mean",),
        cheap=True,
    ),
)
