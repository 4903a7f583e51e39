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
    dilated = ndi.distance_transform_edt(~occupied) <= rc
    filled = ndi.binary_fill_holes(dilated)
    coarse = ndi.distance_transform_edt(filled) > rc + PARAMETERS.erosion_offset_voxels
    band_c = ndi.binary_dilation(coarse, iterations=band) & ~ndi.binary_erosion(coarse, iterations=band)

    fraction = _refine(coarse, c).astype(np.float32)
    in_band = band_c[tuple((vox // c).T)]
    fine, band_fraction = _band_fractions(coarse, c, band_c, lo, h, means[in_band])
    fraction[tuple(fine.T)] = band_fraction
    return VoxelSolid(
        origin=(int(lo[0]), int(lo[1]), int(lo[2])),
        pitch=h,
        fraction=fraction,
        hull_volume=_hull_volume(vox, means, counts),
        n_points=len(pts),
    )


def _refine(coarse: np.ndarray, c: int) -> np.ndarray:
    """The fine-lattice array in which every coarse voxel becomes its block of c³ fine voxels."""
    return coarse.repeat(c, axis=0).repeat(c, axis=1).repeat(c, axis=2)


def _block_voxels(blocks: np.ndarray, c: int) -> np.ndarray:
    """Fine-lattice indices (n·c³, 3) of the fine voxels of the coarse voxels ``blocks`` (n, 3), block by block."""
    offsets = np.stack(np.unravel_index(np.arange(c**3), (c, c, c)), axis=1)
    return (blocks[:, None, :] * c + offsets[None]).reshape(-1, 3)


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


def _band_fractions(
    coarse: np.ndarray, c: int, band_c: np.ndarray, lo: np.ndarray, h: float, samples: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sub-voxel inside-fractions of the band voxels (spec §8.4 step 5): the fine indices (n, 3) of the
    fine voxels of the coarse band ``band_c`` and their fractions (n,).

    ``samples`` are the sample means of the occupied band voxels. Each sample's normal: the eigenvector
    of the smallest eigenvalue of the covariance of its ``normal_neighbours`` nearest samples within
    ``normal_radius_voxels`` (a local plane fit), oriented along the outward direction −∇ of the coarse
    solid's indicator smoothed by a Gaussian (central differences at the sample's coarse voxel); with
    fewer than ``min_normal_neighbours`` neighbours, or neighbours along a line (second-largest eigenvalue
    below ``min_normal_planarity`` times the largest), −∇ itself.
    A band voxel with centre c takes the nearest sample p within ``surface_search_voxels`` and its normal
    n: signed depth s = (p − c)·n, fraction clip(1/2 + s / (h‖n‖₁), 0, 1). Without a sample in reach
    the voxel keeps its solid indicator (0 or 1); the nearest sample is searched only for the voxels of
    coarse voxels near a sample's (:func:`_blocks_near`).
    """
    blocks = np.argwhere(band_c)
    fine = _block_voxels(blocks, c)
    inside = np.repeat(coarse[band_c].astype(np.float32), c**3)
    if len(samples) < 3:
        return fine, inside
    smooth = ndi.gaussian_filter(coarse.astype(np.float32), PARAMETERS.normal_smoothing_voxels)
    ijk = (np.floor(samples / h).astype(np.int64) - lo) // c
    outward = np.empty((len(samples), 3))
    for axis in range(3):
        up, dn = ijk.copy(), ijk.copy()
        up[:, axis] += 1
        dn[:, axis] -= 1
        outward[:, axis] = (smooth[tuple(dn.T)] - smooth[tuple(up.T)]) / 2.0
    outward /= np.maximum(np.linalg.norm(outward, axis=1, keepdims=True), 1e-12)

    tree = cKDTree(samples)
    k = min(PARAMETERS.normal_neighbours, len(samples))
    dist, j = tree.query(samples, k=k, distance_upper_bound=PARAMETERS.normal_radius_voxels * h)
    dist, j = np.asarray(dist).reshape(len(samples), k), np.asarray(j).reshape(len(samples), k)
    w = np.isfinite(dist).astype(float)
    count = w.sum(axis=1)
    nb = samples[np.where(w > 0, j, 0)]
    mean = (nb * w[..., None]).sum(axis=1) / count[:, None]
    dev = (nb - mean[:, None, :]) * w[..., None]
    spread, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", dev, dev))
    normal = vecs[:, :, 0]
    normal = np.where((np.sum(normal * outward, axis=1) < 0)[:, None], -normal, normal)
    untrusted = (count < PARAMETERS.min_normal_neighbours) | (spread[:, 1] < PARAMETERS.min_normal_planarity * spread[:, 2])
    normal = np.where(untrusted[:, None], outward, normal)

    reach = PARAMETERS.surface_search_voxels
    searched = np.repeat(_blocks_near(band_c.shape, ijk, c, reach)[band_c], c**3)
    centres = (fine[searched] + lo + 0.5) * h
    dist, near = tree.query(centres, k=1, distance_upper_bound=reach * h)
    ok = np.isfinite(dist)
    near = np.where(ok, near, 0)
    n = normal[near]
    s = np.einsum("nj,nj->n", samples[near] - centres, n)
    l1 = np.abs(n).sum(axis=1)
    ok &= l1 > 0.5  # a unit normal has 1 ≤ ‖n‖₁ ≤ √3; 0 where no normal is defined
    frac = np.clip(0.5 + s / (h * np.where(ok, l1, 1.0)), 0.0, 1.0)
    inside[searched] = np.where(ok, frac, inside[searched])
    return fine, inside


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
