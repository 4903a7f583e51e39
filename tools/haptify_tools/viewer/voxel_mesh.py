"""Boundary surface of a voxel solid as a triangle mesh, with numpy only (the workspace solids of spec §8.4).

The workspace chapter's volume operator (``haptify.metrics.workspace.volume_solid``, spec §8.4) yields a
voxel solid on a W-anchored lattice. The viewer draws it as the set of exposed voxel faces: every
face between a voxel inside the solid (fraction ≥ threshold) and one outside becomes a square, split
into two triangles, wound counter-clockwise seen from outside (outward normals). The surface is
closed and its enclosed volume is exactly ``pitch³ × (number of inside voxels)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Corners of a unit square in the (u, v) plane, counter-clockwise: e_u × e_v = +e_axis.
_SQUARE = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])


@dataclass(frozen=True)
class SurfaceMesh:
    """Vertices (m, W), triangles (vertex indices) and per-vertex unit normals of a closed surface."""

    vertices: np.ndarray  # (4·F, 3)
    triangles: np.ndarray  # (2·F, 3) uint32
    normals: np.ndarray  # (4·F, 3)

    def enclosed_volume(self) -> float:
        """Signed enclosed volume (m³) by the divergence theorem: Σ v0 · (v1 × v2) / 6 (positive when outward)."""
        v = self.vertices[self.triangles]
        return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)

    def shared(self, pitch: float) -> tuple[np.ndarray, np.ndarray]:
        """The same surface with each lattice corner stored once (vertices (m, W), triangles): about a quarter
        of the vertices, without normals (faces meeting at a corner no longer share one) — the compact form."""
        keys = np.round(self.vertices / pitch).astype(np.int64)
        unique, inverse = np.unique(keys, axis=0, return_inverse=True)
        return unique * pitch, inverse.reshape(-1)[self.triangles].astype(np.uint32)


def boundary_mesh(inside: np.ndarray, origin: tuple[int, int, int], pitch: float) -> SurfaceMesh:
    """The exposed faces of the boolean voxel grid ``inside`` as a triangle mesh.

    Voxel ``(i, j, k)`` of the grid spans ``[(origin + (i, j, k))·pitch, (origin + (i, j, k) + 1)·pitch]``
    in metres, as in ``haptify.metrics.workspace.VoxelSolid`` (spec §8.4).
    """
    padded = np.pad(np.asarray(inside, dtype=bool), 1)
    corners, normals = [], []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for step in (1, -1):
            neighbour = np.roll(padded, -step, axis=axis)
            faces = np.argwhere(padded & ~neighbour) - 1  # voxel indices in the unpadded grid
            if not len(faces):
                continue
            base = faces.astype(np.float64)
            base[:, axis] += 1.0 if step == 1 else 0.0
            square = _SQUARE if step == 1 else _SQUARE[::-1]
            quad = np.repeat(base[:, None, :], 4, axis=1)
            quad[:, :, u] += square[:, 0]
            quad[:, :, v] += square[:, 1]
            corners.append(quad.reshape(-1, 3))
            n = np.zeros(3)
            n[axis] = step
            normals.append(np.broadcast_to(n, (len(faces) * 4, 3)))
    if not corners:
        empty = np.zeros((0, 3))
        return SurfaceMesh(empty, np.zeros((0, 3), dtype=np.uint32), empty)
    vertices = (np.concatenate(corners) + np.asarray(origin, dtype=np.float64)) * pitch
    first = np.arange(0, len(vertices), 4, dtype=np.uint32)[:, None]
    triangles = np.concatenate([first + np.array([0, 1, 2], dtype=np.uint32), first + np.array([0, 2, 3], dtype=np.uint32)])
    return SurfaceMesh(vertices, triangles, np.concatenate(normals))
