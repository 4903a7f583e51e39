"""Global free-space forces (spec chapter 9).

From the slow free-space wandering with the device off (paper §IV-B, §V-B): statistics of the force the
device applies to the hand, the force-plate force about its mean weight, the examiner's speeds with
protocol-compliance warnings, and the spatial force field (mean force vector per position bin).
Parameters: ``schemas/<v>/metrics/free_space.json``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from haptify.codes import Code
from haptify.errors import fail
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters
from haptify.pipeline.repetitions import TrialValue, aggregate, no_trials, per_trial, unavailable
from haptify.processing import preprocessing
from haptify.processing.caching import cached
from haptify.processing.force_plate import plate_signals
from haptify.processing.preprocessing import MocapTrack, lowpass_resample, mocap_track, segment_interior, uniform_grid
from haptify.processing.signals import handle_signals

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.pipeline.results import MetricResult, Unavailable

FAMILY = "free_space"
PROTOCOL = "free_space"
FORCE_IDS = ("free_space.force_mean", "free_space.force_sd", "free_space.force_min", "free_space.force_max")
SPEED_IDS = ("free_space.speed_mean", "free_space.angular_speed_mean")
PLATE_ID = "free_space.plate_force_mean"


class FreeSpaceParameters(FamilyParameters):
    """The parameters of ``metrics/free_space.json`` (spec chapter 9), in the units its definition file states."""

    speed_limit_m_per_s: float
    angular_speed_limit_rad_per_s: float
    angular_speed_settle_s: float
    max_fraction_over_limit: float
    force_field_bin_m: float
    force_field_min_samples: int


#: The free_space family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = load_parameters(FAMILY, FreeSpaceParameters)


def magnitude_stats(force: np.ndarray) -> dict[str, float]:
    """Mean, sample sd (ddof = 1), min and max of |F| over the rows of ``force (N, 3)`` in N (spec §9.2)."""
    mag = np.linalg.norm(np.asarray(force, dtype=float), axis=1)
    if len(mag) < 2:
        raise fail(Code.MOTION_CAPTURE_UNUSABLE, "fewer than two usable force samples", expected=">= 2", found=len(mag))
    return {"mean": float(mag.mean()), "sd": float(mag.std(ddof=1)), "min": float(mag.min()), "max": float(mag.max())}


def plate_force_about_weight(force: np.ndarray) -> np.ndarray:
    """Plate force minus (0, 0, mean P_z) — the weight of the device parts resting on the plate (spec §9.3)."""
    force = np.asarray(force, dtype=float)
    out: np.ndarray = force - np.array([0.0, 0.0, force[:, 2].mean()])
    return out


def exceedance(values: np.ndarray, limit: float) -> float:
    """Share of ``values`` above ``limit`` (spec §9.4)."""
    values = np.asarray(values, dtype=float)
    return float(np.mean(values > limit)) if len(values) else 0.0


@dataclass
class ForceField:
    """Mean force vector per position bin (spec §9.5): bin centres (m, W), mean force (N), sample counts."""

    bin_m: float
    centres: np.ndarray
    mean_force: np.ndarray
    counts: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {
            "bin_m": self.bin_m,
            "bins": [
                {"centre_m": [round(float(x), 6) for x in c], "mean_force_N": [round(float(x), 6) for x in f], "n": int(n)}
                for c, f, n in zip(self.centres, self.mean_force, self.counts)
            ],
        }


def force_field(
    position: np.ndarray, force: np.ndarray, *, bin_m: float | None = None, min_samples: int | None = None
) -> ForceField:
    """Bin ``force (N, 3)`` by ``position (N, 3)`` on the W-anchored lattice of edge ``force_field_bin_m`` and
    average each bin holding at least ``force_field_min_samples`` samples (spec §9.5); bins sorted by index."""
    b = float(PARAMETERS.force_field_bin_m if bin_m is None else bin_m)
    k_min = int(PARAMETERS.force_field_min_samples if min_samples is None else min_samples)
    position = np.asarray(position, dtype=float)
    force = np.asarray(force, dtype=float)
    if len(position) == 0:
        return ForceField(b, np.empty((0, 3)), np.empty((0, 3)), np.empty(0, dtype=int))
    idx = np.floor(position / b).astype(np.int64)
    keys, inv, counts = np.unique(idx, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    sums = np.stack([np.bincount(inv, weights=force[:, k], minlength=len(keys)) for k in range(3)], axis=1)
    keep = counts >= k_min
    return ForceField(b, (keys[keep] + 0.5) * b, sums[keep] / counts[keep, None], counts[keep])


# --- session level (spec §9.6) -------------------------------------------------------------------


def hand_force_samples(ctx: ComputeContext, trial_id: str) -> tuple[np.ndarray, np.ndarray]:
    """Calibrated hand force (N) and gimbal position (m), W, at a trial's usable samples (chapter 7)."""
    hs = handle_signals(ctx, trial_id)
    if hs.force is None:
        raise fail(
            Code.REQUIRED_STREAM_MISSING,
            f"trial {trial_id!r} has no handle_wrench stream",
            file="session.json",
            expected="handle_wrench",
            found=None,
        )
    ok = hs.valid & np.all(np.isfinite(hs.force), axis=1)
    if ok.sum() < 2:
        raise fail(
            Code.MOTION_CAPTURE_UNUSABLE,
            f"trial {trial_id!r} has no usable samples with motion capture and force",
            expected=">= 2 samples",
            found=int(ok.sum()),
        )
    return hs.force[ok], hs.position[ok]


def plate_force_samples(ctx: ComputeContext, trial_id: str) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and bias-removed total plate force (N, W), low-passed at the handle-force cut-off and
    resampled onto the uniform grid of the plate stream's span at the common rate (spec §9.3; chapter 7)."""

    def build() -> tuple[np.ndarray, np.ndarray]:
        plate = plate_signals(ctx, trial_id)
        grid = uniform_grid(float(plate.t[0]), float(plate.t[-1]), preprocessing.PARAMETERS.rate_hz)
        return grid, lowpass_resample(plate.t, plate.force, grid, preprocessing.PARAMETERS.wrench_cutoff_hz)

    return cached(ctx, ("free_space_plate", trial_id), build)


def speed_samples(track: MocapTrack) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the samples of a processed track (spec §7.4) that ``speed_mean`` and ``angular_speed_mean``
    average (spec §9.4): the usable ones, and of those the ones ``angular_speed_settle_s`` inside their segment."""
    ok = track.valid & np.all(np.isfinite(track.velocity), axis=1) & np.all(np.isfinite(track.angular_velocity), axis=1)
    return ok, ok & segment_interior(track, PARAMETERS.angular_speed_settle_s)


def speeds(ctx: ComputeContext, trial_id: str) -> tuple[np.ndarray, np.ndarray]:
    """Speed (m/s) at the usable motion-capture samples of a trial and angular speed (rad/s) at those of them
    settled past the segment's edges (may be empty); spec §9.4."""
    track = mocap_track(ctx, trial_id)
    ok, settled = speed_samples(track)
    if not ok.any():
        raise fail(
            Code.MOTION_CAPTURE_UNUSABLE,
            f"trial {trial_id!r} has no usable motion-capture samples",
            expected="usable handle_pose samples",
            found=0,
        )
    return np.linalg.norm(track.velocity[ok], axis=1), np.linalg.norm(track.angular_velocity[settled], axis=1)


class SpeedSummary(TypedDict):
    """One trial's mean speeds (m/s, rad/s), the shares of samples over the limits and its warning codes (spec §9.4)."""

    speed: float
    angular: float | None
    codes: list[str]
    over_speed: float
    over_angular: float


def _speed_summary(ctx: ComputeContext, trial_id: str) -> SpeedSummary:
    v, w = speeds(ctx, trial_id)
    out: SpeedSummary = {
        "speed": float(v.mean()),
        "angular": float(w.mean()) if len(w) else None,
        "codes": [],
        "over_speed": exceedance(v, PARAMETERS.speed_limit_m_per_s),
        "over_angular": exceedance(w, PARAMETERS.angular_speed_limit_rad_per_s),
    }
    limit = PARAMETERS.max_fraction_over_limit
    if out["over_speed"] > limit:
        out["codes"].append(Code.SPEED_ABOVE_PROTOCOL)
        ctx.warn(
            Code.SPEED_ABOVE_PROTOCOL,
            f"trial {trial_id!r}: {out['over_speed']:.0%} of the samples exceed {PARAMETERS.speed_limit_m_per_s} m/s",
            metric="free_space.speed_mean",
            trial=trial_id,
        )
    if out["over_angular"] > limit:
        out["codes"].append(Code.ANGULAR_SPEED_ABOVE_PROTOCOL)
        ctx.warn(
            Code.ANGULAR_SPEED_ABOVE_PROTOCOL,
            f"trial {trial_id!r}: {out['over_angular']:.0%} of the samples exceed "
            f"{np.degrees(PARAMETERS.angular_speed_limit_rad_per_s):.3g} deg/s",
            metric="free_space.angular_speed_mean",
            trial=trial_id,
        )
    return out


def _angular_of(summary: SpeedSummary, trial_id: str) -> float:
    """A trial's mean angular speed (rad/s), or E611 when no segment is long enough to settle (spec §9.4)."""
    if summary["angular"] is None:
        settle = PARAMETERS.angular_speed_settle_s
        raise fail(
            Code.MOTION_CAPTURE_UNUSABLE,
            f"trial {trial_id!r}: no motion-capture segment reaches {settle} s past both of its ends",
            expected=f"a segment longer than {2 * float(settle):g} s",
            found="none",
        )
    return summary["angular"]


def compute(ctx: ComputeContext) -> list[MetricResult | Unavailable]:
    """Every free-space metric the session allows (spec §9.6)."""
    trials = [t.id for t in ctx.session.trials_of(PROTOCOL)]
    ids = FORCE_IDS + (PLATE_ID,) + SPEED_IDS
    if not trials:
        err = no_trials(PROTOCOL)
        return [unavailable(m, err) for m in ids if ctx.wants(m)]
    out: list[MetricResult | Unavailable] = []
    compliance: dict[str, list[str]] = {}
    if any(ctx.wants(m) for m in ids):  # the compliance codes concern every free-space value of a trial
        done, first = per_trial(ctx, trials, lambda tid: _speed_summary(ctx, tid), "free_space.speed_mean")
        compliance = {tid: d["codes"] for tid, d in done.items()}
        if done:
            diag = {
                "share_over_speed_limit": [d["over_speed"] for d in done.values()],
                "share_over_angular_speed_limit": [d["over_angular"] for d in done.values()],
            }
            out.append(
                aggregate(
                    FAMILY,
                    "free_space.speed_mean",
                    [TrialValue(t, d["speed"], d["codes"]) for t, d in done.items()],
                    diagnostics=diag,
                )
            )
            ang, first_ang = per_trial(ctx, list(done), lambda tid: _angular_of(done[tid], tid), SPEED_IDS[1])
            if ang:
                out.append(
                    aggregate(
                        FAMILY, SPEED_IDS[1], [TrialValue(t, w, done[t]["codes"]) for t, w in ang.items()], diagnostics=diag
                    )
                )
            else:
                assert first_ang is not None  # per_trial: a trial without a result raised the error it returns
                out.append(unavailable(SPEED_IDS[1], first_ang))
        else:
            assert first is not None  # per_trial: a trial without a result raised the error it returns
            out += [unavailable(m, first) for m in SPEED_IDS]
    if any(ctx.wants(m) for m in FORCE_IDS):
        done, first = per_trial(ctx, trials, lambda tid: hand_force_samples(ctx, tid), "free_space.force_mean")
        if done:
            stats = {tid: magnitude_stats(f) for tid, (f, _) in done.items()}
            field = force_field(np.concatenate([p for _, p in done.values()]), np.concatenate([f for f, _ in done.values()]))
            for metric_id in FORCE_IDS:
                key = metric_id.rsplit("_", 1)[1]
                force_diag = {"force_field": field.to_dict()} if key == "mean" else {}
                out.append(
                    aggregate(
                        FAMILY,
                        metric_id,
                        [TrialValue(t, s[key], compliance.get(t, [])) for t, s in stats.items()],
                        diagnostics=force_diag,
                    )
                )
        else:
            assert first is not None  # per_trial: a trial without a result raised the error it returns
            out += [unavailable(m, first) for m in FORCE_IDS]
    if ctx.wants(PLATE_ID):
        done, first = per_trial(ctx, trials, lambda tid: plate_force_samples(ctx, tid), PLATE_ID)
        if done:
            out.append(
                aggregate(
                    FAMILY,
                    PLATE_ID,
                    [
                        TrialValue(t, float(np.linalg.norm(plate_force_about_weight(f), axis=1).mean()), compliance.get(t, []))
                        for t, (_, f) in done.items()
                    ],
                )
            )
        else:
            assert first is not None  # per_trial: a trial without a result raised the error it returns
            out.append(unavailable(PLATE_ID, first))
    return out
