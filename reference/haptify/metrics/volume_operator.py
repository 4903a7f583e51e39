"""The volume operator (spec §8.4–8.5): a point cloud — the gimbal-centre positions of a boundary sweep, or
dense samples of a device's kinematic model — becomes a voxel solid with sub-voxel fractions; the overlap of
two solids. Parameters: ``schemas/<v>/metrics/workspace.json``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import ndimage as ndi
from scipy.spatial import ConvexHull, QhullError, cKDTree

from haptify.codes import Code
from haptify.errors import fail
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters

FAMILY = "workspace"


class WorkspaceParameters(FamilyParameters):
    """The parameters of ``metrics/workspace.json`` (spec chapter 8), in the units its definition file states."""

    voxel_pitch_m: float
    closing_radius_m: float
    closing_coarsening: int
    erosion_offset_voxels: float
    band_voxels: int
    normal_neighbours: int
    normal_radius_voxels: float
    min_normal_neighbours: int
    min_normal_planarity: float
    surface_search_voxels: float
    normal_smoothing_voxels: float
    min_hull_fraction: float
    hull_block_voxels: int
    max_grid_voxels: int
    min_points: int
    model_max_step_m: float
    model_interior_step_m: float
    model_interior_clearance_m: float


#: The workspace family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = load_parameters(FAMILY, WorkspaceParameters)


@dataclass(frozen=True)
class VoxelSolid:
    """A solid on the W-anchored lattice of pitch ``pitch`` (m): ``fraction[i, j, k]`` ∈ [0, 1] is the share of
    voxel ``origin + (i, j, k)`` inside the solid (spec §8.4)."""

    origin: tuple[int, int, int]
    pitch: float
    fraction: np.ndarray
    hull_volume: float
    n_points: int
    repair_points: int = 0

    @cached_property
    def volume(self) -> float:
        """Volume in m³: h³ · Σ fraction (summed once per solid)."""
        return float(self.fraction.sum(dtype=np.float64)) * self.pitch**3

    @property
    def closed(self) -> bool:
        """True when the shell closed: volume ≥ ``min_hull_fraction`` × convex-hull volume (spec §8.4 step 7)."""
        return self.hull_volume > 0 and self.volume >= PARAMETERS.min_hull_fraction * self.hull_volume

    def centres(self, threshold: float = 0.5) -> np.ndarray:
        """Centres (m, W) of the voxels whose fraction is at least ``threshold`` — for figures."""
        idx = np.argwhere(self.fraction >= threshold)
        centres: np.ndarray = (idx + np.asarray(self.origin) + 0.5) * self.pitch
        return centres


def volume_solid(points: np.ndarray, *, pitch: float | None = None, closing_radius: float | None = None) -> VoxelSolid:
    """Apply the volume operator (spec §8.4) to ``points (N, 3)`` in m; every parameter else from workspace.json.

    Steps: (1) occupied voxels of the W-anchored lattice; (2)–(4) closing by a ball of radius r with hole
    filling between dilation and erosion, on the coarse lattice of pitch c·h; (5) sub-voxel fractions on
    the fine lattice in a band around the boundary, from the boundary samples' signed depth along their
    normals; (6) volume = h³ Σ fraction; (7) closure check against the convex hull.
    """
    h = float(PARAMETERS.voxel_pitch_m if pitch is None else pitch)
    r = float(PARAMETERS.closing_radius_m if closing_radius is None else closing_radius)
    c = PARAMETERS.closing_coarsening
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
        raise ValueError("volume_solid needs finite points of shape (N, 3)")
    if len(pts) < PARAMETERS.min_points:
        raise fail(
            Code.WORKSPACE_CLOUD_UNUSABLE,
            f"a workspace cloud needs at least {PARAMETERS.min_points} finite points",
            expected=f">= {PARAMETERS.min_points}",
            found=len(pts),
        )
    band = PARAMETERS.band_voxels
    rc = r / (c * h)  # closing radius in coarse voxels
    idx = np.floor(pts / h).astype(np.int64)
    pad = int(math.ceil(rc)) + band + 3  # coarse voxels
    lo_c = np.floor_divide(idx.min(axis=0), c) - pad
    shape_c = tuple(int(x) for x in np.floor_divide(idx.max(axis=0), c) - lo_c + pad + 1)
    lo, shape = lo_c * c, tuple(c * x for x in shape_c)
    n_vox = math.prod(shape)
    if n_vox > PARAMETERS.max_grid_voxels:
        extent = (pts.max(axis=0) - pts.min(axis=0)).round(3).tolist()
        raise fail(
            Code.WORKSPACE_CLOUD_UNUSABLE,
            f"the cloud spans {extent} m: its {n_vox} voxels exceed the grid limit",
            expected=f"<= {PARAMETERS.max_grid_voxels} voxels",
            found=n_vox,
        )
    flat = np.ravel_multi_index((idx - lo).T, shape)
    uniq, inv, counts = np.unique(flat, return_inverse=True, return_counts=True)
    means = np.stack([np.bincount(inv, weights=pts[:, k], minlength=len(uniq)) / counts for k in range(3)], axis=1)
    vox = np.stack(np.unravel_index(uniq, shape), axis=1)

    occupied = np.zeros(shape_c, dtype=bool)
    occupied[tuple((vox // c).T)] = True
    dilated = _within(occupied, rc)
    filled = _fill_holes(dilated)
    coarse = ~_within(~filled, rc + PARAMETERS.erosion_offset_voxels)
    # the band: within `band` face-steps of S (dilation) and not `band` steps deep inside it (erosion)
    band_c = _face_steps(coarse, band, outside=False) & _face_steps(~coarse, band, outside=True)

    fraction = _refine(coarse, c).astype(np.float32)
    # the fine lattice as blocks: blockwise[I, J, K] is coarse voxel (I, J, K)'s c × c × c fine voxels
    blockwise = fraction.reshape(shape_c[0], c, shape_c[1], c, shape_c[2], c).transpose(0, 2, 4, 1, 3, 5)
    in_band = band_c[tuple((vox // c).T)]
    blockwise[np.nonzero(band_c)] = _band_fractions(coarse, c, band_c, lo, h, means[in_band])
    return VoxelSolid(
        origin=(int(lo[0]), int(lo[1]), int(lo[2])),
        pitch=h,
        fraction=fraction,
        hull_volume=_hull_volume(vox, means, counts),
        n_points=len(pts),
    )


def _refine(coarse: np.ndarray, c: int) -> np.ndarray:
    """The fine-lattice array in which every coarse voxel becomes its block of c³ fine voxels (last axis
    first: the element-wise repeat runs on the smallest array)."""
    fine: np.ndarray = coarse.repeat(c, axis=2).repeat(c, axis=1).repeat(c, axis=0)
    return fine


def _within(mask: np.ndarray, radius: float) -> np.ndarray:
    """The voxels whose centre lies within ``radius`` (voxels) of the centre of a True voxel of ``mask``:
    ``scipy.ndimage.distance_transform_edt(~mask) <= radius`` (spec §8.4 steps 2 and 4), exactly.

    The squared distance to the nearest True voxel is a minimum over integer offsets, separable by axis
    (d² = min over dz of [min over dy of (min over dx of dx²) + dy²] + dz²), and only whether it is at
    most m — the largest integer whose float square root is ≤ ``radius`` — matters: so offsets up to
    ⌊√m⌋ voxels suffice, one axis after the other, with every value above m held at m + 1."""
    m = int(math.floor(radius * radius)) if radius >= 0 else -1
    while m >= 0 and math.sqrt(m) > radius:
        m -= 1
    while math.sqrt(m + 1) <= radius:
        m += 1
    if m < 0:
        return np.zeros_like(mask, dtype=bool)
    reach = math.isqrt(m)
    dist2 = np.where(mask, 0, m + 1).astype(np.int16 if m + 1 + reach * reach < 2**15 else np.int64)
    for axis in range(mask.ndim):
        n = mask.shape[axis]
        out = dist2.copy()
        for d in range(1, min(reach, n - 1) + 1):
            head, tail = _along(mask.ndim, axis, slice(0, n - d)), _along(mask.ndim, axis, slice(d, n))
            np.minimum(out[head], dist2[tail] + d * d, out=out[head])
            np.minimum(out[tail], dist2[head] + d * d, out=out[tail])
        dist2 = np.minimum(out, m + 1, out=out)
    within: np.ndarray = np.less_equal(dist2, m)
    return within


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """``scipy.ndimage.binary_fill_holes(mask)`` (spec §8.4 step 3), run on the bounding box of ``mask`` only:
    every voxel beyond the box lies outside ``mask`` and is connected to the grid's border, so a component of
    the complement reaches the grid's border exactly when it reaches a face of the box."""
    if not mask.any():
        return mask.copy()
    axes = range(mask.ndim)
    spans = [np.flatnonzero(mask.any(axis=tuple(b for b in axes if b != a))) for a in axes]
    box = tuple(slice(int(span[0]), int(span[-1]) + 1) for span in spans)
    filled = mask.copy()
    filled[box] = ndi.binary_fill_holes(mask[box])
    return filled


def _face_steps(mask: np.ndarray, steps: int, *, outside: bool) -> np.ndarray:
    """``mask`` grown by ``steps`` face-steps (6-connected dilation); beyond the grid counts as ``outside``.
    ``_face_steps(m, n, outside=False)`` is ``binary_dilation(m, iterations=n)`` and
    ``~_face_steps(~m, n, outside=True)`` is ``binary_erosion(m, iterations=n)`` (spec §8.4 step 5's band)."""
    grown = mask.copy()
    for _ in range(steps):
        prev = grown.copy()
        for axis in range(mask.ndim):
            n = mask.shape[axis]
            head, tail = _along(mask.ndim, axis, slice(0, n - 1)), _along(mask.ndim, axis, slice(1, n))
            grown[head] |= prev[tail]
            grown[tail] |= prev[head]
            if outside:
                grown[_along(mask.ndim, axis, slice(0, 1))] = True
                grown[_along(mask.ndim, axis, slice(n - 1, n))] = True
    return grown


def _along(ndim: int, axis: int, part: slice) -> tuple[slice, ...]:
    """The index of ``part`` along ``axis`` of an ``ndim``-dimensional array, everything along the others."""
    return tuple(part if a == axis else slice(None) for a in range(ndim))


def _blocks_near(shape: tuple[int, ...], blocks: np.ndarray, c: int, reach_voxels: float) -> np.ndarray:
    """Mask of the coarse voxels of a lattice of ``shape`` that may hold a fine voxel centre within
    ``reach_voxels`` fine voxels of a point lying in one of the coarse voxels ``blocks`` (n, 3).

    Such a centre and point are at most ⌊reach + ½⌋ fine voxels apart along each axis; one voxel more
    absorbs rounding, and ⌈(that + c − 1) / c⌉ coarse voxels hold it. Outside the mask nothing is in reach."""
    fine = int(math.floor(reach_voxels + 0.5)) + 1
    half = (fine + c - 1) // c
    occupied = np.zeros(shape, dtype=np.uint8)
    occupied[tuple(blocks.T)] = 1
    return ndi.maximum_filter(occupied, size=2 * half + 1, mode="constant").astype(bool)


def _band_fractions(coarse: np.ndarray, c: int, band_c: np.ndarray, lo: np.ndarray, h: float, samples: np.ndarray) -> np.ndarray:
    """Sub-voxel inside-fractions of the band voxels (spec §8.4 step 5): float32 (n, c, c, c), the c³ fine
    voxels of each of the n coarse voxels of the band ``band_c`` (in ``np.argwhere(band_c)`` order).

    ``samples`` are the sample means of the occupied band voxels, each with its normal (:func:`_normals`).
    A band voxel with centre c takes the nearest sample p within ``surface_search_voxels`` and its normal
    n: signed depth s = (p − c)·n, fraction clip(1/2 + s / (h‖n‖₁), 0, 1). Without a sample in reach
    the voxel keeps its solid indicator (0 or 1); the nearest sample is searched only for the voxels of
    coarse voxels near a sample's (:func:`_blocks_near`).
    """
    inside = np.empty((int(band_c.sum()), c, c, c), dtype=np.float32)
    inside[...] = coarse[band_c][:, None, None, None]
    if len(samples) < 3:
        return inside
    ijk = (np.floor(samples / h).astype(np.int64) - lo) // c
    tree = cKDTree(samples)
    normal = _normals(coarse, ijk, h, samples, tree)
    reach = PARAMETERS.surface_search_voxels
    searched = _blocks_near(band_c.shape, ijk, c, reach)[band_c]
    blocks = np.argwhere(band_c)[searched]
    # centre (m) of fine voxel (i, j, k): (i + lo + ½) h, looked up per axis
    offsets = np.stack(np.unravel_index(np.arange(c**3), (c, c, c)), axis=1)
    grid = np.empty((len(blocks), c**3, 3))
    for axis in range(3):
        along = (np.arange(band_c.shape[axis] * c) + lo[axis] + 0.5) * h
        grid[:, :, axis] = along[blocks[:, axis, None] * c + offsets[None, :, axis]]
    centres = grid.reshape(-1, 3)
    dist, nearest = tree.query(centres, k=1, distance_upper_bound=reach * h)
    near = np.asarray(nearest)
    l1 = np.abs(normal).sum(axis=1)
    hit = np.flatnonzero(np.isfinite(dist))
    hit = hit[l1[near[hit]] > 0.5]  # a unit normal has 1 ≤ ‖n‖₁ ≤ √3; 0 where no normal is defined
    p = near[hit]
    s = np.einsum("nj,nj->n", samples[p] - centres[hit], normal[p])
    fractions = inside[searched].reshape(-1)
    fractions[hit] = np.clip(0.5 + s / (h * l1[p]), 0.0, 1.0)
    inside[searched] = fractions.reshape(-1, c, c, c)
    return inside


def _normals(coarse: np.ndarray, ijk: np.ndarray, h: float, samples: np.ndarray, tree: cKDTree) -> np.ndarray:
    """Unit outward normals (n, 3) of the boundary ``samples`` (m) in coarse voxels ``ijk``, ``tree`` their
    k-d tree (spec §8.4 step 5): the eigenvector of the smallest eigenvalue of the covariance of each
    sample's ``normal_neighbours`` nearest samples within ``normal_radius_voxels`` (a local plane fit),
    oriented along the outward direction −∇ of the coarse solid's indicator smoothed by a Gaussian
    (central differences at the sample's coarse voxel); with fewer than ``min_normal_neighbours``
    neighbours, or neighbours along a line (second-largest eigenvalue below ``min_normal_planarity``
    times the largest), −∇ itself (0 where the smoothed indicator is flat)."""
    smooth = ndi.gaussian_filter(coarse.astype(np.float32), PARAMETERS.normal_smoothing_voxels)
    outward = np.empty((len(samples), 3))
    for axis in range(3):
        up, dn = ijk.copy(), ijk.copy()
        up[:, axis] += 1
        dn[:, axis] -= 1
        outward[:, axis] = (smooth[tuple(dn.T)] - smooth[tuple(up.T)]) / 2.0
    outward /= np.maximum(np.linalg.norm(outward, axis=1, keepdims=True), 1e-12)

    k = min(PARAMETERS.normal_neighbours, len(samples))
    dist, j = tree.query(samples, k=k, distance_upper_bound=PARAMETERS.normal_radius_voxels * h)
    dist, j = np.asarray(dist).reshape(len(samples), k), np.asarray(j).reshape(len(samples), k)
    found = np.isfinite(dist)
    count = found.sum(axis=1)
    # a missing neighbour (index len(samples)) is the zero row: it adds nothing to the sums
    nb = np.concatenate([samples, np.zeros((1, 3))])[j]
    mean = nb.sum(axis=1) / count[:, None]
    dev = nb - mean[:, None, :]
    dev[~found] = 0.0
    spread, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", dev, dev))
    normal = vecs[:, :, 0]
    normal = np.where((np.sum(normal * outward, axis=1) < 0)[:, None], -normal, normal)
    untrusted = (count < PARAMETERS.min_normal_neighbours) | (spread[:, 1] < PARAMETERS.min_normal_planarity * spread[:, 2])
    normals: np.ndarray = np.where(untrusted[:, None], outward, normal)
    return normals


def _hull_volume(vox: np.ndarray, means: np.ndarray, counts: np.ndarray) -> float:
    """Convex-hull volume (m³) of the sample means of the occupied blocks of ``hull_block_voxels``³ voxels
    (spec §8.4 step 7), from the occupied voxels' indices, sample means and counts; 0 for flat clouds."""
    block = vox // PARAMETERS.hull_block_voxels
    flat = np.ravel_multi_index(block.T, tuple(int(x) + 1 for x in block.max(axis=0)))
    (
        _,
        inv,
    ) = np.unique(flat, return_inverse=True)
    weight = np.bincount(inv, weights=counts)
    block_means = np.stack([np.bincount(inv, weights=means[:, k] * counts) / weight for k in range(3)], axis=1)
    if len(block_means) < 4:
        return 0.0
    try:
        return float(ConvexHull(block_means).volume)
    except QhullError:
        return 0.0


def overlap_volume(a: VoxelSolid, b: VoxelSolid) -> float:
    """Volume (m³) of the intersection of two solids on the same lattice: h³ Σ min(fa, fb) (spec §8.5)."""
    if not math.isclose(a.pitch, b.pitch, rel_tol=1e-12):
        raise ValueError("overlap_volume needs solids of the same pitch")
    lo = np.maximum(a.origin, b.origin)
    hi = np.minimum(np.add(a.origin, a.fraction.shape), np.add(b.origin, b.fraction.shape))
    if np.any(hi <= lo):
        return 0.0
    sa = tuple(slice(int(low - o), int(up - o)) for low, up, o in zip(lo, hi, a.origin))
    sb = tuple(slice(int(low - o), int(up - o)) for low, up, o in zip(lo, hi, b.origin))
    return float(np.minimum(a.fraction[sa], b.fraction[sb]).sum(dtype=np.float64)) * a.pitch**3
