"""The volume operator's morphology (spec §8.4 steps 2–5) against its definitions: the distance transform,
hole filling, dilation and erosion of ``scipy.ndimage`` that the spec names, and analytic balls."""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import ndimage as ndi

from haptify.metrics.volume_operator import _face_steps, _fill_holes, _refine, _within

masks = arrays(bool, st.tuples(*[st.integers(1, 9)] * 3), elements=st.booleans())
sparse_masks = st.builds(
    lambda shape, seed, density: np.random.default_rng(seed).random(shape) < density,
    st.tuples(*[st.integers(1, 14)] * 3),
    st.integers(0, 2**32 - 1),
    st.floats(0.0, 0.2),
)


@settings(max_examples=60, deadline=None)
@given(st.one_of(masks, sparse_masks), st.floats(0.0, 7.5))
def test_within_is_the_thresholded_euclidean_distance_transform(mask, radius):
    if not mask.any():  # the transform of a mask without a True voxel is undefined; _within says none is near
        assert not _within(mask, radius).any()
        return
    expected = ndi.distance_transform_edt(~mask) <= radius
    np.testing.assert_array_equal(_within(mask, radius), expected)


@given(st.floats(0.0, 6.0), st.tuples(*[st.integers(0, 12)] * 3))
@settings(max_examples=30, deadline=None)
def test_within_one_voxel_is_the_lattice_ball(radius, where):
    mask = np.zeros((13, 13, 13), dtype=bool)
    mask[where] = True
    idx = np.indices(mask.shape)
    d2 = sum((idx[a] - where[a]) ** 2 for a in range(3))
    np.testing.assert_array_equal(_within(mask, radius), np.sqrt(d2) <= radius)


def test_within_radius_exactly_on_a_lattice_distance():
    mask = np.zeros((15, 15, 15), dtype=bool)
    mask[7, 7, 7] = True
    # 6 = |(6, 0, 0)| = |(4, 4, 2)|: both lie on the sphere and are inside; 6 - 1e-12 excludes them
    assert _within(mask, 6.0)[13, 7, 7] and _within(mask, 6.0)[11, 11, 9]
    assert not _within(mask, 6.0 - 1e-12)[13, 7, 7] and not _within(mask, 6.0 - 1e-12)[11, 11, 9]
    assert not _within(mask, -0.5).any()
    np.testing.assert_array_equal(_within(mask, 0.0), mask)


@settings(max_examples=60, deadline=None)
@given(st.one_of(masks, sparse_masks.map(lambda m: ~m)))
def test_fill_holes_is_scipys(mask):
    np.testing.assert_array_equal(_fill_holes(mask), ndi.binary_fill_holes(mask))


def test_fill_holes_fills_a_hollow_cube_and_not_an_open_one():
    shell = np.zeros((7, 7, 7), dtype=bool)
    shell[1:6, 1:6, 1:6] = True
    shell[2:5, 2:5, 2:5] = False
    assert _fill_holes(shell)[1:6, 1:6, 1:6].all() and _fill_holes(shell).sum() == 125
    shell[3, 3, 1] = False  # a face-adjacent hole to the outside
    assert _fill_holes(shell).sum() == shell.sum()


@settings(max_examples=60, deadline=None)
@given(st.one_of(masks, sparse_masks), st.integers(0, 3))
def test_face_steps_are_scipys_dilation_and_erosion(mask, steps):
    np.testing.assert_array_equal(
        _face_steps(mask, steps, outside=False), ndi.binary_dilation(mask, iterations=steps) if steps else mask
    )
    np.testing.assert_array_equal(
        ~_face_steps(~mask, steps, outside=True), ndi.binary_erosion(mask, iterations=steps) if steps else mask
    )


def test_face_steps_grow_a_voxel_into_the_city_block_ball():
    mask = np.zeros((9, 9, 9), dtype=bool)
    mask[4, 4, 4] = True
    grown = _face_steps(mask, 2, outside=False)
    assert {tuple(int(v) for v in p) for p in np.argwhere(grown)} == {
        (4 + i, 4 + j, 4 + k) for i, j, k in itertools.product(range(-2, 3), repeat=3) if abs(i) + abs(j) + abs(k) <= 2
    }


@settings(max_examples=30, deadline=None)
@given(masks, st.integers(1, 3))
def test_refine_gives_every_coarse_voxel_its_block(mask, c):
    fine = _refine(mask, c)
    assert fine.shape == tuple(c * s for s in mask.shape)
    for offset in itertools.product(range(c), repeat=3):
        np.testing.assert_array_equal(fine[offset[0] :: c, offset[1] :: c, offset[2] :: c], mask)
