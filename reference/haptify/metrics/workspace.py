"""Workspace shape and volume (spec chapter 8).

One deterministic volume operator (§8.4, :mod:`haptify.metrics.volume_operator`) serves the measured and the
modeled workspace (paper §IV-A, §VI-A): this module gives it the device's kinematic model (§8.3) and
each trial's repaired cloud (§8.7), and computes the family's metrics.
Parameters: ``schemas/<v>/metrics/workspace.json``.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial import cKDTree

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.conventions import pose_apply
from haptify.formats.session_format import Kinematics
from haptify.metrics import volume_operator
from haptify.metrics.volume_operator import VoxelSolid as VoxelSolid
from haptify.metrics.volume_operator import overlap_volume as overlap_volume
from haptify.metrics.volume_operator import volume_solid as volume_solid
from haptify.pipeline.repetitions import TrialValue, aggregate, no_trials, per_trial, single, unavailable
from haptify.processing.kinematics import (
    RANGE_LATTICE_POINTS,
    configurations_from_unit,
    forward_positions,
    joint_limits,
    unit_lattice,
)

if TYPE_CHECKING:
    from haptify.pipeline.context import ComputeContext
    from haptify.pipeline.results import MetricResult, Unavailable

FAMILY = "workspace"
PROTOCOL = "workspace"


# --- the modeled workspace (spec §8.3) ---------------------------------------------------------


def _levers(kin: Kinematics) -> list[float]:
    """Upper bound (m) of the distance from joint j's axis to the gimbal centre: Σ_{i ≥ j} (|a_i| + |d_i|)."""
    lengths = [abs(j.a) + abs(j.d) for j in kin.joints]
    return [sum(lengths[i:]) for i in range(len(lengths))]


def _joint_ranges(kin: Kinematics) -> np.ndarray:
    """Largest range (rad) of each joint over the unit cube's ``RANGE_LATTICE_POINTS``-per-joint lattice
    (coupled limits evaluated; spec §8.3 step 1)."""
    q = configurations_from_unit(kin, unit_lattice([RANGE_LATTICE_POINTS] * len(kin.joints)))
    q = q[~np.isnan(q).any(axis=1)]
    if len(q) == 0:  # every coupled range of the lattice is empty (e.g. an upper limit below the lower one)
        raise fail(
            Code.DEVICE_KINEMATICS_MISSING,
            "the device's joint limits admit no configuration (every sampled coupled range is empty)",
            file="session.json",
            pointer="/device/kinematics/joints",
            expected="lower <= upper for some configuration",
            found="none",
        )
    lower, upper = joint_limits(kin, q)
    spans: np.ndarray = np.max(upper - lower, axis=0)
    return spans


def _counts(kin: Kinematics, step: float) -> list[int]:
    """Samples per joint so that neighbouring samples are at most ``step`` apart in space (spec §8.3)."""
    return [int(math.ceil(rng * lever / step)) + 1 for rng, lever in zip(_joint_ranges(kin), _levers(kin))]


def _boundary_lattice(counts: list[int]) -> np.ndarray:
    """Unit-cube samples on the cube's faces: each face a full lattice of the other joints' counts."""
    n = len(counts)
    faces = []
    for axis in range(n):
        others = [c for i, c in enumerate(counts) if i != axis]
        sub = unit_lattice(others) if others else np.zeros((1, 0))
        for value in (0.0, 1.0):
            face = np.empty((len(sub), n))
            face[:, [i for i in range(n) if i != axis]] = sub
            face[:, axis] = value
            faces.append(face)
    return np.concatenate(faces)


def modeled_points(kin: Kinematics, *, step: float | None = None, interior_step: float | None = None) -> np.ndarray:
    """Deterministic samples (m, device frame) of the modeled reachable workspace (spec §8.3).

    The faces of the joint-limit box (unit cube mapped through the coupled limits joint by joint) at
    ``model_max_step_m``, plus the whole box at ``model_interior_step_m`` without the interior samples that
    lie within ``model_interior_clearance_m`` of a face sample, through the DH forward kinematics.
    """
    step = float(volume_operator.PARAMETERS.model_max_step_m if step is None else step)
    interior_step = float(volume_operator.PARAMETERS.model_interior_step_m if interior_step is None else interior_step)
    faces = _positions(kin, _boundary_lattice(_counts(kin, step)))
    interior = _positions(kin, unit_lattice(_counts(kin, interior_step)))
    # only whether a face sample lies within the clearance matters: any tree answers alike, and the
    # sliding-midpoint one without median balancing suits samples on a lattice
    tree = cKDTree(faces, balanced_tree=False, compact_nodes=False)
    dist, _ = tree.query(interior, k=1, distance_upper_bound=volume_operator.PARAMETERS.model_interior_clearance_m)
    return np.concatenate([faces, interior[~np.isfinite(dist)]])


def _positions(kin: Kinematics, unit: np.ndarray) -> np.ndarray:
    q = configurations_from_unit(kin, unit)
    return forward_positions(kin, q[~np.isnan(q).any(axis=1)])


def modeled_solid(
    kin: Kinematics, placement_position: Any = (0.0, 0.0, 0.0), placement_quaternion: Any = (1.0, 0.0, 0.0, 0.0)
) -> VoxelSolid:
    """The modeled workspace as a solid in W: :func:`modeled_points` placed by ``device_placement`` (spec §8.3)."""
    pts = pose_apply(np.asarray(placement_position, float), np.asarray(placement_quaternion, float), modeled_points(kin))
    return volume_solid(pts)


def spec_box_volume(box: Any) -> float:
    """Volume (m³) of the datasheet's rectangular workspace (spec §8.6)."""
    return float(np.prod(np.asarray(box, dtype=float)))


# --- session level (spec §8.7) -------------------------------------------------------------------


def trial_positions(session: Any, trial_id: str) -> np.ndarray:
    """The gimbal-centre positions (m, W) of a workspace trial's handle_pose stream in time order, NaN where
    occluded (spec §8.7)."""
    positions: np.ndarray = session.read(trial_id, "handle_pose")[["px", "py", "pz"]].to_numpy()
    return positions


def measured_points(session: Any, trial_id: str) -> np.ndarray:
    """The finite gimbal-centre positions (m, W) of a workspace trial's handle_pose stream (spec §8.7)."""
    p = trial_positions(session, trial_id)
    return p[np.all(np.isfinite(p), axis=1)]


def longest_occlusion_gap(position: np.ndarray) -> float:
    """The longest occlusion gap of a trial's positions ``(N, 3)`` in time order, m (spec §8.7): the largest
    distance between two consecutive finite rows with occluded (non-finite) rows between them; 0 when no
    occluded row lies between finite ones. The boundary along that stretch of the sweep went unrecorded."""
    finite = np.all(np.isfinite(position), axis=1)
    idx = np.flatnonzero(finite)
    around = np.diff(idx) > 1
    if not around.any():
        return 0.0
    return float(np.linalg.norm(position[idx[1:][around]] - position[idx[:-1][around]], axis=1).max())


def occlusion_gaps(position: np.ndarray) -> list[tuple[int | None, int | None]]:
    """The occlusion gaps of a trial's positions ``(N, 3)`` in time order (spec §8.7): per run of occluded
    (non-finite) rows, the indices of the finite rows before and after it — None for a run at the start or
    the end of the trial. Empty when no row is occluded or none is finite."""
    finite = np.all(np.isfinite(position), axis=1)
    idx = np.flatnonzero(finite)
    if len(idx) == 0:
        return []
    gaps: list[tuple[int | None, int | None]] = [] if idx[0] == 0 else [(None, int(idx[0]))]
    gaps += [(int(a), int(b)) for a, b in zip(idx[:-1], idx[1:]) if b - a > 1]
    if idx[-1] < len(position) - 1:
        gaps.append((int(idx[-1]), None))
    return gaps


def edge_speed(t: np.ndarray, position: np.ndarray, i: int, toward: int) -> float:
    """Speed (m/s) of the hand at the finite row ``i`` on the side away from its gap: the distance to the
    neighbouring finite row in direction ``toward`` (−1 before, +1 after) over their time apart; 0 when
    there is none (spec §8.7)."""
    j = i + toward
    while 0 <= j < len(position) and not np.all(np.isfinite(position[j])):
        j += toward
    if not 0 <= j < len(position):
        return 0.0
    return float(np.linalg.norm(position[j] - position[i]) / abs(t[j] - t[i]))


def gap_regions(
    t: np.ndarray, position: np.ndarray, closing_radius: float | None = None
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The region each occlusion gap may have hidden (spec §8.7), as ``(a, b, reach)``: every point ``x`` with
    ``|x − a| + |x − b| ≤ reach``. For a gap between finite rows a and b, lasting T = t_b − t_a, the hand's
    path inside is at most L = max(|b − a|, v·T) long, v the larger of the speeds at the gap's two edges
    (:func:`edge_speed`, each measured away from the gap); so every point of it, and every point within the
    closing radius r of it, satisfies ``|x − a| + |x − b| ≤ L + 2 r``. A gap at the start or the end of the
    trial has one edge e: ``a = b = e`` and ``reach = 2 (v·T + r)`` (the ball of radius v·T + r)."""
    r = float(volume_operator.PARAMETERS.closing_radius_m if closing_radius is None else closing_radius)
    out = []
    for i, j in occlusion_gaps(position):
        if i is not None and j is not None:
            v = max(edge_speed(t, position, i, -1), edge_speed(t, position, j, +1))
            chord = float(np.linalg.norm(position[j] - position[i]))
            out.append((position[i], position[j], max(chord, v * float(t[j] - t[i])) + 2.0 * r))
        else:
            e = i if i is not None else j
            assert e is not None  # occlusion_gaps: a gap has at least one finite edge
            edge_t = t[-1] if i is not None else t[0]
            v = edge_speed(t, position, e, -1 if i is not None else +1)
            out.append((position[e], position[e], 2.0 * (v * abs(float(edge_t - t[e])) + r)))
    return out


def repaired_points(
    t: np.ndarray, position: np.ndarray, donors: np.ndarray, *, closing_radius: float | None = None, pitch: float | None = None
) -> tuple[np.ndarray, int]:
    """A trial's cloud with its occlusion gaps repaired from the session's other repetitions (spec §8.7): its
    finite positions plus every donor (a finite position of another workspace trial, m, W) that lies in a
    region one of its gaps may have hidden (:func:`gap_regions`) and farther than ``surface_search_voxels · h``
    from every finite position of the trial itself — where the trial has a sample that near, the
    sub-voxel boundary (§8.4 step 5) is placed by its own samples. Returns the cloud and how many donors
    it took."""
    h = float(volume_operator.PARAMETERS.voxel_pitch_m if pitch is None else pitch)
    own = position[np.all(np.isfinite(position), axis=1)]
    regions = gap_regions(t, position, closing_radius)
    if not regions or len(donors) == 0 or len(own) == 0:
        return own, 0
    tree = cKDTree(donors)
    take = np.zeros(len(donors), dtype=bool)
    for a, b, reach in regions:
        near = np.asarray(tree.query_ball_point((a + b) / 2.0, reach / 2.0), dtype=np.int64)
        if len(near):
            d = donors[near]
            take[near[np.linalg.norm(d - a, axis=1) + np.linalg.norm(d - b, axis=1) <= reach]] = True
    candidates = donors[take]
    if len(candidates):
        dist, _ = cKDTree(own).query(candidates, k=1, distance_upper_bound=volume_operator.PARAMETERS.surface_search_voxels * h)
        candidates = candidates[~np.isfinite(dist)]
    return np.concatenate([own, candidates]), len(candidates)


def _modeled(ctx: ComputeContext, device: Any, placement: Any) -> tuple[VoxelSolid | None, HaptifyError | None]:
    """The device's modeled workspace solid (spec §8.3), or the coded error that leaves it unavailable: E311
    without kinematics or when they reach no volume; None and None when no metric that needs it is wanted."""
    model: VoxelSolid | None = None
    model_error: HaptifyError | None = None
    if device.kinematics is None:
        model_error = fail(
            Code.DEVICE_KINEMATICS_MISSING,
            f"device {device.manufacturer} {device.model} has no kinematics",
            pointer="/device/kinematics",
        )
    elif any(ctx.wants(m) for m in ("workspace.modeled_volume", "workspace.volume_ratio", "workspace.coverage")):
        try:
            model = ctx.cached(
                ("workspace_model",), lambda: modeled_solid(device.kinematics, placement.position, placement.quaternion)
            )
        except HaptifyError as exc:
            model_error = exc
        if model is not None and not model.volume > 0:
            model, model_error = (
                None,
                fail(
                    Code.DEVICE_KINEMATICS_MISSING,
                    "the device's kinematics reach no volume (empty or degenerate joint ranges)",
                    pointer="/device/kinematics",
                    expected="a modeled volume > 0",
                    found=0.0,
                ),
            )
    return model, model_error


def trial_track(ctx: ComputeContext, trial_id: str) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and gimbal-centre positions (m, W; NaN where occluded) of a workspace trial, cached."""
    track: tuple[np.ndarray, np.ndarray] = ctx.cached(
        ("workspace_track", trial_id),
        lambda: (ctx.session.read(trial_id, "handle_pose")["t"].to_numpy(float), trial_positions(ctx.session, trial_id)),
    )
    return track


def trial_cloud(ctx: ComputeContext, trials: list[str], trial_id: str) -> tuple[np.ndarray, int]:
    """A trial's cloud (m, W) repaired from the other trials ``trials`` and how many donors it took (spec §8.7),
    cached. The trial itself must hold ``min_points`` finite positions (E313); a donor trial that cannot be
    read gives nothing."""

    def build() -> tuple[np.ndarray, int]:
        t, position = trial_track(ctx, trial_id)
        own = int(np.all(np.isfinite(position), axis=1).sum())
        if own < volume_operator.PARAMETERS.min_points:
            raise fail(
                Code.WORKSPACE_CLOUD_UNUSABLE,
                f"a workspace cloud needs at least {volume_operator.PARAMETERS.min_points} finite points",
                expected=f">= {volume_operator.PARAMETERS.min_points}",
                found=own,
            )
        donors = []
        for other in trials:
            if other == trial_id:
                continue
            try:
                q = trial_track(ctx, other)[1]
            except HaptifyError:
                continue
            donors.append(q[np.all(np.isfinite(q), axis=1)])
        return repaired_points(t, position, np.concatenate(donors) if donors else np.zeros((0, 3)))

    cloud: tuple[np.ndarray, int] = ctx.cached(("workspace_cloud", trial_id), build)
    return cloud


def trial_solid(ctx: ComputeContext, trials: list[str], trial_id: str) -> VoxelSolid:
    """The volume operator on a trial's repaired cloud (:func:`trial_cloud`, spec §8.7)."""
    cloud, taken = trial_cloud(ctx, trials, trial_id)
    return replace(volume_solid(cloud), repair_points=taken)


def trial_values(solid: VoxelSolid, model: VoxelSolid | None) -> dict[str, float]:
    """One trial's measured_volume (m³) and, with the modeled solid, its volume_ratio and coverage (spec §8.7)."""
    values = {"workspace.measured_volume": solid.volume}
    if model is not None:
        values["workspace.volume_ratio"] = solid.volume / model.volume
        values["workspace.coverage"] = overlap_volume(solid, model) / model.volume
    return values


def noisy_trial_values(ctx: ComputeContext, trial_id: str, noise_sd: np.ndarray, rng: np.random.Generator) -> dict[str, float]:
    """:func:`trial_values` of a trial's repaired cloud with white Gaussian noise of sd ``noise_sd`` (m, per
    axis of W) added to every point: one draw of the motion-capture noise's SIMEX bias (spec §19.3)."""
    trials = [t.id for t in ctx.session.trials_of(PROTOCOL)]
    cloud, _ = trial_cloud(ctx, trials, trial_id)
    model, _ = _modeled(ctx, ctx.session.device(), ctx.session.manifest.device_placement)
    return trial_values(volume_solid(cloud + rng.standard_normal(cloud.shape) * noise_sd), model)


def compute(ctx: ComputeContext) -> list[MetricResult | Unavailable]:
    """Every workspace metric the session allows (spec §8.7)."""
    session = ctx.session
    out: list[MetricResult | Unavailable] = []
    device = session.device()
    model, model_error = _modeled(ctx, device, session.manifest.device_placement)
    if model is not None:
        out.append(
            single(
                FAMILY,
                "workspace.modeled_volume",
                model.volume,
                diagnostics={"voxels": int(model.fraction.size), "samples": model.n_points, "hull_volume_m3": model.hull_volume},
                warnings=[] if model.closed else [Code.WORKSPACE_SHELL_OPEN],
            )
        )
    elif model_error is not None:
        out.append(unavailable("workspace.modeled_volume", model_error))

    box = device.datasheet.workspace_box_m
    if box is not None:
        out.append(single(FAMILY, "workspace.spec_box_volume", spec_box_volume(box), diagnostics={"box_m": list(box)}))
    else:
        out.append(
            unavailable(
                "workspace.spec_box_volume",
                fail(
                    Code.DATASHEET_VALUE_MISSING,
                    "the device datasheet has no workspace_box_m",
                    pointer="/device/datasheet/workspace_box_m",
                ),
            )
        )

    trials = [t.id for t in session.trials_of(PROTOCOL)]
    measured_ids = ("workspace.measured_volume", "workspace.volume_ratio", "workspace.coverage")
    if not any(ctx.wants(m) for m in measured_ids):
        return out
    if not trials:
        err = no_trials(PROTOCOL)
        return out + [unavailable(m, err) for m in measured_ids]
    solids, first_error = per_trial(
        ctx,
        trials,
        lambda tid: ctx.cached(("workspace_solid", tid), lambda: trial_solid(ctx, trials, tid)),
        "workspace.measured_volume",
    )
    if not solids:
        assert first_error is not None  # per_trial: a trial without a result raised the error it returns
        return out + [unavailable(m, first_error) for m in measured_ids]
    for tid, s in solids.items():
        if not s.closed:
            ctx.warn(
                Code.WORKSPACE_SHELL_OPEN,
                f"the boundary sweep of trial {tid!r} did not close: volume {s.volume * 1e6:.0f} cm³ is "
                f"{s.volume / s.hull_volume if s.hull_volume else 0:.0%} of its convex hull",
                metric="workspace.measured_volume",
                trial=tid,
            )
    closed = {tid: s for tid, s in solids.items() if s.closed}
    if closed:  # open sweeps are left out when a closed one exists (spec §8.7)
        for tid in solids.keys() - closed.keys():
            ctx.warn(
                Code.TRIAL_SKIPPED, f"workspace.measured_volume: trial {tid!r} skipped (W410: its sweep did not close)", trial=tid
            )
        solids = closed
    codes: dict[str, list[str]] = {tid: [] if s.closed else [Code.WORKSPACE_SHELL_OPEN] for tid, s in solids.items()}
    values = {tid: trial_values(s, model) for tid, s in solids.items()}
    out.append(
        aggregate(
            FAMILY,
            "workspace.measured_volume",
            [TrialValue(tid, v["workspace.measured_volume"], codes[tid]) for tid, v in values.items()],
            diagnostics={
                "hull_volume_m3": [s.hull_volume for s in solids.values()],
                "points": [s.n_points for s in solids.values()],
                "longest_occlusion_gap_m": [longest_occlusion_gap(trial_track(ctx, tid)[1]) for tid in solids],
                "repair_points": [s.repair_points for s in solids.values()],
            },
        )
    )
    if model is None:
        if model_error is None:  # neither ratio nor coverage was asked for
            return out
        return out + [unavailable(m, model_error) for m in ("workspace.volume_ratio", "workspace.coverage")]
    for metric_id in ("workspace.volume_ratio", "workspace.coverage"):
        out.append(aggregate(FAMILY, metric_id, [TrialValue(tid, v[metric_id], codes[tid]) for tid, v in values.items()]))
    return out
