"""Thin-plate-spline warps with Shepard fallback (synth.analysis.warp; Wu & Yu 2004, section 2.2)."""

from __future__ import annotations

import numpy as np
import pytest

from synth.analysis.warp import shepard_displacement, warp_coordinates, warp_patch
from synth.errors import InvalidInput, InvalidParameter

SOURCES = np.array([[10.0, 10.0], [20.0, 30.0], [5.0, 40.0], [30.0, 12.0]])
TARGETS = SOURCES + np.array([[2.0, 1.0], [-1.0, 2.0], [1.0, -2.0], [0.0, 1.5]])


def test_tps_maps_control_points_exactly_and_keeps_the_fixed_borders():
    patch = np.random.default_rng(0).random((48, 48)).astype(np.float32)
    res = warp_patch(patch, SOURCES, TARGETS)
    assert res.method == "tps" and res.reason is None and not res.folds
    # exact interpolation of the constraints (non-integer target: evaluated through the fitted map)
    for src, dst in zip(SOURCES, TARGETS, strict=True):
        if (dst == np.rint(dst)).all():
            r, c = dst.astype(int)
            np.testing.assert_allclose(res.coordinates[:, r, c], src, atol=1e-6)
            assert res.image[r, c] == patch[int(src[0]), int(src[1])]
    # the bottom and right borders stay in place, bit for bit
    np.testing.assert_array_equal(res.image[-1], patch[-1])
    np.testing.assert_array_equal(res.image[:, -1], patch[:, -1])
    assert res.image.dtype == np.float32


def test_tps_with_non_integer_targets_and_other_fixed_sides():
    coords, method, _ = warp_coordinates((32, 32), [[10.0, 10.0]], [[11.5, 9.25]], fixed=("top", "left"))
    assert method == "tps"
    np.testing.assert_array_equal(coords[:, 0, :], np.stack([np.zeros(32), np.arange(32.0)]))
    np.testing.assert_array_equal(coords[:, :, 0], np.stack([np.arange(32.0), np.zeros(32)]))


def test_a_feature_moves_where_it_is_told():
    patch = np.zeros((24, 24))
    patch[:, 6] = 1.0  # a vertical line at column 6
    res = warp_patch(patch, [[8, 6]], [[8, 9]])
    assert res.image[8, 9] == 1.0 and res.image[8, 6] < 0.5
    assert res.image[23, 6] == 1.0  # the fixed bottom border keeps the line where it was


def test_duplicated_targets_fall_back_to_shepard():
    patch = np.random.default_rng(1).random((32, 32))
    res = warp_patch(patch, [[10, 10], [12, 12]], [[11, 11], [11, 11]])
    assert res.method == "shepard" and "spline" in res.reason
    np.testing.assert_allclose(res.coordinates[:, 11, 11], [11.0, 11.0])  # mean of the two sources
    np.testing.assert_array_equal(res.image[-1], patch[-1])


def test_collinear_points_without_fixed_borders_fall_back_to_shepard():
    src = np.array([[10.0, 10.0], [12.0, 12.0], [14.0, 14.0]])
    coords, method, reason = warp_coordinates((32, 32), src, src + 1.0, fixed=None)
    assert method == "shepard" and "cannot be solved" in reason
    for s in src:  # Shepard interpolates its data exactly too
        np.testing.assert_allclose(coords[:, int(s[0]) + 1, int(s[1]) + 1], s, atol=1e-12)
    with pytest.raises(InvalidInput, match="thin-plate spline failed"):
        warp_coordinates((32, 32), src, src + 1.0, fixed=None, method="tps")


def test_a_folding_spline_is_rejected():
    res = warp_patch(np.zeros((32, 32)), [[8, 8], [20, 20]], [[20, 20], [8, 8]])  # swap two points
    assert res.method == "shepard" and "folds" in res.reason


def test_nothing_to_move_is_the_identity():
    patch = np.random.default_rng(2).random((16, 16, 3))
    for src, dst in (([], []), ([[3, 3]], [[3, 3]])):
        res = warp_patch(patch, np.array(src).reshape(-1, 2), np.array(dst).reshape(-1, 2))
        assert res.method == "identity"
        np.testing.assert_array_equal(res.image, patch)


def test_shepard_known_answer():
    pts = np.array([[0.0, 0.0], [0.0, 2.0]])
    vals = np.array([[1.0], [3.0]])
    np.testing.assert_allclose(
        shepard_displacement(pts, vals, np.array([[0.0, 1.0], [0.0, 0.0]])), [[2.0], [1.0]]
    )


def test_bad_inputs_are_named():
    patch = np.zeros((16, 16))
    with pytest.raises(InvalidInput, match="inside the 16x16 patch"):
        warp_patch(patch, [[3, 3]], [[3, 20]])
    with pytest.raises(InvalidInput, match="pair up"):
        warp_patch(patch, [[3, 3], [4, 4]], [[3, 4]])
    with pytest.raises(InvalidParameter, match="order"):
        warp_patch(patch, [[3, 3]], [[3, 4]], order=2)
    with pytest.raises(InvalidParameter, match="fixed"):
        warp_patch(patch, [[3, 3]], [[3, 4]], fixed=("middle",))
    with pytest.raises(InvalidParameter, match="method"):
        warp_patch(patch, [[3, 3]], [[3, 4]], method="bspline")
    with pytest.raises(InvalidInput, match="NaN"):
        warp_patch(np.full((4, 4), np.nan), [[1, 1]], [[1, 2]])
