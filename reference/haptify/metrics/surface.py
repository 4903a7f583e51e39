"""Frictionless surface rendering (spec chapter 12), and the contact rule chapter 13 shares.

The device renders a stiff, frictionless plane (paper §IV-E, §V-D); every force the hand feels in the
plane's tangent directions comes from the device itself. Contact is read from the commanded force (the
renderer's own contact state), the planar force from the calibrated hand force.
Parameters: ``schemas/<v>/metrics/surface.json``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from haptify.codes import Code
from haptify.errors import fail
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters
from haptify.pipeline.repetitions import TrialValue, aggregate, protocol_trials
from haptify.processing.caching import cached, session_of
from haptify.processing.preprocessing import interp_columns
from haptify.processing.signals import handle_signals

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.pipeline.results import MetricResult, Unavailable

FAMILY = "surface"
PROTOCOL = "frictionless_surface"
IDS = ("surface.planar_force_mean", "surface.planar_force_sd")
FORCE_COLUMNS = ["fx", "fy", "fz"]


class SurfaceParameters(FamilyParameters):
    """The parameters of ``metrics/surface.json`` (spec chapter 12), in the units its definition file states."""

    contact_force_threshold_N: float
    contact_guard_s: float


#: The surface family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = load_parameters(FAMILY, SurfaceParameters)


def unit_normal(normal: Any, trial_id: str = "") -> np.ndarray:
    """The rendering's outward normal scaled to unit length (E303 when it is zero or not finite).
    Spec §12.2."""
    n = np.asarray(normal, dtype=float)
    norm = float(np.linalg.norm(n))
    if not np.isfinite(norm) or norm < 1e-9:
        raise fail(
            Code.RENDERING_MISSING,
            f"trial {trial_id!r}: the rendering's surface_normal {list(n)} has no direction",
            file="session.json",
            pointer="/trials/*/rendering/surface_normal",
            expected="a non-zero vector",
            found=list(n),
        )
    return n / norm


def planar_force(force: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Tangential part F − (F·n)n of ``force (N, 3)`` for the unit normal ``n`` (spec §12.3), N."""
    force = np.asarray(force, dtype=float)
    return force - np.outer(force @ normal, normal)


def contact_of(commanded_normal_force: np.ndarray) -> np.ndarray:
    """Contact where the commanded force along the outward normal exceeds ``contact_force_threshold_N`` (spec §12.2)."""
    return np.asarray(commanded_normal_force, dtype=float) > PARAMETERS.contact_force_threshold_N


def guarded(t_cmd: np.ndarray, contact: np.ndarray, t_grid: np.ndarray, guard_s: float | None = None) -> np.ndarray:
    """True at grid times t whose window [t − g, t + g] holds commanded samples, all in contact (spec §12.2)."""
    g = float(PARAMETERS.contact_guard_s if guard_s is None else guard_s)
    t_cmd = np.asarray(t_cmd, dtype=float)
    t_grid = np.asarray(t_grid, dtype=float)
    out_of_contact = np.r_[0, np.cumsum(~np.asarray(contact, dtype=bool))]
    lo = np.searchsorted(t_cmd, t_grid - g, side="left")
    hi = np.searchsorted(t_cmd, t_grid + g, side="right")
    inside = (t_grid - g >= t_cmd[0]) & (t_grid + g <= t_cmd[-1])
    out: np.ndarray = inside & (hi > lo) & (out_of_contact[hi] - out_of_contact[lo] == 0)
    return out


@dataclass
class ContactSignals:
    """An active trial on the handle-signal grid (chapter 7), with the rendering's plane (spec §12.2).

    ``force``: calibrated hand force (N, W); ``position``: gimbal centre (m, W); ``commanded_normal``:
    commanded force along n, interpolated (N); ``contact``: the contact rule on the grid; ``used``:
    the guarded contact samples; ``valid``: motion capture and force usable.
    """

    trial_id: str
    t: np.ndarray
    position: np.ndarray
    force: np.ndarray
    valid: np.ndarray
    commanded_normal: np.ndarray
    contact: np.ndarray
    used: np.ndarray
    normal: np.ndarray
    plane_point: np.ndarray
    stiffness_N_per_m: float

    @property
    def penetration(self) -> np.ndarray:
        """(p0 − p)·n in m: positive below the rendered plane (spec §13.2)."""
        out: np.ndarray = (self.plane_point - self.position) @ self.normal
        return out

    @property
    def normal_force(self) -> np.ndarray:
        """F·n in N: positive when the device pushes the hand out of the surface (spec §13.2)."""
        out: np.ndarray = self.force @ self.normal
        return out


def contact_signals(ctx_or_session: Any, trial_id: str) -> ContactSignals:
    """The :class:`ContactSignals` of an active trial (spec §12.2); cached on a ComputeContext.

    E303 without rendering parameters, E302 without a commanded_wrench or handle_wrench stream.
    """

    def build() -> ContactSignals:
        session = session_of(ctx_or_session)
        trial = session.trial(trial_id)
        if trial.rendering is None:
            raise fail(
                Code.RENDERING_MISSING,
                f"active trial {trial_id!r} has no rendering parameters",
                file="session.json",
                pointer="/trials/*/rendering",
                expected="surface_point_m, surface_normal, stiffness_N_per_m",
                found=None,
            )
        n = unit_normal(trial.rendering.surface_normal, trial_id)
        cmd = session.read(trial_id, "commanded_wrench")
        hs = handle_signals(ctx_or_session, trial_id)
        if hs.force is None:
            raise fail(
                Code.REQUIRED_STREAM_MISSING,
                f"trial {trial_id!r} has no handle_wrench stream",
                file="session.json",
                expected="handle_wrench",
                found=None,
            )
        t_cmd = cmd["t"].to_numpy()
        cmd_n = cmd[FORCE_COLUMNS].to_numpy() @ n
        on_grid = interp_columns(t_cmd, cmd_n, hs.t)
        valid = hs.valid & np.all(np.isfinite(hs.force), axis=1) & (hs.t >= t_cmd[0]) & (hs.t <= t_cmd[-1])
        contact = contact_of(on_grid) & valid
        used = guarded(t_cmd, contact_of(cmd_n), hs.t) & valid
        return ContactSignals(
            trial_id=trial_id,
            t=hs.t,
            position=hs.position,
            force=hs.force,
            valid=valid,
            commanded_normal=on_grid,
            contact=contact,
            used=used,
            normal=n,
            plane_point=np.asarray(trial.rendering.surface_point_m, float),
            stiffness_N_per_m=float(trial.rendering.stiffness_N_per_m),
        )

    return cached(ctx_or_session, ("contact_signals", trial_id), build)


def planar_stats(force: np.ndarray, normal: np.ndarray) -> dict[str, float]:
    """Mean and sample sd (ddof = 1) of |F − (F·n)n| over the rows of ``force`` (spec §12.3), N."""
    mag = np.linalg.norm(planar_force(force, normal), axis=1)
    if len(mag) < 2:
        raise fail(Code.NO_CONTACT, "fewer than two contact samples", expected=">= 2", found=len(mag))
    return {"mean": float(mag.mean()), "sd": float(mag.std(ddof=1))}


def _trial(ctx: ComputeContext, trial_id: str) -> dict[str, Any]:
    cs = contact_signals(ctx, trial_id)
    if cs.used.sum() < 2:
        raise fail(
            Code.NO_CONTACT,
            f"trial {trial_id!r}: no sample is in contact with the rendered surface "
            f"(commanded normal force above {PARAMETERS.contact_force_threshold_N} N for ± {PARAMETERS.contact_guard_s} s)",
            expected=">= 2 contact samples",
            found=int(cs.used.sum()),
        )
    stats = planar_stats(cs.force[cs.used], cs.normal)
    stats["contact_share"] = float(cs.used.sum() / max(cs.valid.sum(), 1))
    stats["normal_force_mean"] = float(cs.normal_force[cs.used].mean())
    return stats


def compute(ctx: ComputeContext) -> list[MetricResult | Unavailable]:
    """surface.planar_force_mean and surface.planar_force_sd (spec §12.4)."""
    if not any(ctx.wants(m) for m in IDS):
        return []
    done, missing = protocol_trials(ctx, PROTOCOL, IDS, lambda tid: _trial(ctx, tid), "surface.planar_force_mean")
    if missing:
        return list(missing)
    diag = {
        "contact_share": [d["contact_share"] for d in done.values()],
        "normal_force_mean_N": [d["normal_force_mean"] for d in done.values()],
    }
    return [
        aggregate(FAMILY, "surface.planar_force_mean", [TrialValue(t, d["mean"]) for t, d in done.items()], diagnostics=diag),
        aggregate(FAMILY, "surface.planar_force_sd", [TrialValue(t, d["sd"]) for t, d in done.items()]),
    ]
