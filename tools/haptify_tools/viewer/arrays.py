"""Array helpers of the viewer recording: quaternion order for rerun (spec §1.3), the unfiltered pose at
given times (spec §7.4), stream columns as arrays, finite-row masks, polylines split at NaN rows (spec §2.7
occlusions) and the rectangle drawn for a rendered plane (spec §2.5)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
from numpy.lib.stride_tricks import as_strided
from numpy.typing import ArrayLike

from haptify_tools.viewer.plan import SURFACE_MARGIN_M, SURFACE_MIN_HALF_M


def xyzw(q_wxyz: ArrayLike) -> np.ndarray:
    """Our quaternions [w, x, y, z] (spec §1.3) → rerun's [x, y, z, w]."""
    q = np.asarray(q_wxyz, dtype=np.float64)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def raw_pose_at(t_pose: np.ndarray, p: np.ndarray, q: np.ndarray, t: np.ndarray) -> Any:
    """The unfiltered pose stream at times ``t`` (s): linear in position, slerp in orientation (spec §7.4).

    Every finite sample counts as one segment, so a time is valid only between two finite samples;
    nothing is bridged or filtered (the viewer's "raw" quantities stay raw). A ``preprocessing.PoseOnGrid``.
    """
    from haptify.processing import preprocessing

    ok = finite_rows(p, q)
    nan3 = np.full((len(t_pose), 3), np.nan)
    track = preprocessing.MocapTrack(
        t=np.asarray(t_pose, dtype=np.float64),
        position=p,
        quaternion=q,
        velocity=nan3,
        angular_velocity=nan3,
        segment=np.where(ok, 0, -1),
    )
    return preprocessing.resample_track(track, t)


def columns_of(frame: pd.DataFrame, names: list[str]) -> np.ndarray:
    """The columns ``names`` of a stream table as one float64 array (rows × names): a read-only view when they
    lie side by side in one block of memory (:func:`side_by_side`; the stream reader lays a table out so,
    ``haptify.formats.storage.stream_files.arrow_frame``), else a copy (selecting a list of columns through
    pandas builds an index each time and costs more than the copy). The copy is column-major: each column
    is copied whole, which is several times faster than writing rows of interleaved values."""
    columns = [frame[name].to_numpy(dtype=np.float64) for name in names]
    if not columns:
        return np.empty((len(frame), 0))
    view = side_by_side(columns)
    return np.vstack(columns).T if view is None else view


def _owner(array: np.ndarray) -> object:
    """The object that owns the memory of ``array`` (the end of its chain of bases)."""
    while isinstance(array.base, np.ndarray):
        array = array.base
    return array if array.base is None else array.base


def side_by_side(columns: list[np.ndarray]) -> np.ndarray | None:
    """The read-only (rows × k) view whose column i is ``columns[i]`` (1-D, same length and dtype) when they
    are evenly spaced in the memory of one owner — the rows of a (columns × rows) block, in order — else
    None. Every element the view reads is an element of one of the columns, and the view keeps their
    owner alive."""
    first = columns[0]
    step = columns[1].ctypes.data - first.ctypes.data if len(columns) > 1 else first.itemsize
    owner = _owner(first)
    for i, column in enumerate(columns):
        same_layout = column.dtype == first.dtype and column.shape == first.shape and column.strides == first.strides
        if not same_layout or column.ctypes.data != first.ctypes.data + i * step or _owner(column) is not owner:
            return None
    return as_strided(first, shape=(len(first), len(columns)), strides=(first.strides[0], step), writeable=False)


def finite_rows(*arrays: np.ndarray) -> np.ndarray:
    """Boolean mask of rows where every given array is finite."""
    mask = np.ones(len(arrays[0]), dtype=bool)
    for a in arrays:
        mask &= np.all(np.isfinite(np.asarray(a).reshape(len(a), -1)), axis=1)
    return mask


def nan_split(points: np.ndarray) -> list[np.ndarray]:
    """Split a polyline at NaN rows into runs of at least two finite points."""
    ok = finite_rows(points)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return [points[a:b] for a, b in zip(edges[::2], edges[1::2]) if b - a >= 2]


def plane_rectangle(point: np.ndarray, normal: np.ndarray, around: np.ndarray | None) -> np.ndarray:
    """Four corners (m, W) of a rectangle in the plane through ``point`` with ``normal``.
    The trial's ``rendering`` plane, spec §2.5.

    Centred on the projection of the finite points ``around`` (else on ``point``), large enough to
    hold their projections plus ``SURFACE_MARGIN_M``, at least ``2·SURFACE_MIN_HALF_M`` a side.
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    point = np.asarray(point, dtype=np.float64)
    centre = point
    hu = hv = SURFACE_MIN_HALF_M
    if around is not None and len(around):
        rel = around - point
        centre = point + rel.mean(axis=0) @ np.outer(u, u) + rel.mean(axis=0) @ np.outer(v, v)
        d = around - centre
        hu = max(hu, float(np.max(np.abs(d @ u))) + SURFACE_MARGIN_M)
        hv = max(hv, float(np.max(np.abs(d @ v))) + SURFACE_MARGIN_M)
    return np.array([centre - hu * u - hv * v, centre + hu * u - hv * v, centre + hu * u + hv * v, centre - hu * u + hv * v])
