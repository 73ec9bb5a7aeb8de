"""Thin-plate-spline warps with Shepard fallback (texsynth.synth.analysis.warp; Wu & Yu 2004, section 2.2)."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.analysis.warp import (
    band_falloff,
    resample,
    shepard_displacement,
    warp_coordinates,
    warp_patch,
)
from texsynth.synth.errors import InvalidInput, InvalidParameter

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


def test_band_falloff_is_one_on_the_region_and_zero_beyond_the_width():
    region = np.zeros((32, 32), dtype=bool)
    region[:, :8] = True  # a left overlap
    w = band_falloff(region, 4.0)
    assert (w[:, :8] == 1.0).all() and (w[:, 12:] == 0.0).all()
    np.testing.assert_allclose(w[0, 8:12], 0.5 * (1 + np.cos(np.pi * np.arange(1, 5) / 4)))
    assert (np.diff(w[0]) <= 0).all()  # decays monotonically
    assert (band_falloff(region, 0.0) == region).all()
    with pytest.raises(InvalidParameter, match="width"):
        band_falloff(region, -1.0)


def test_banded_warp_moves_the_control_exactly_and_leaves_the_far_side_in_place():
    region = np.zeros((32, 32), dtype=bool)
    region[:, :8] = True
    falloff = band_falloff(region, 4.0)
    coords, method, _ = warp_coordinates((32, 32), [[12.0, 5.0]], [[12.0, 3.0]], falloff=falloff)
    grid = np.stack(np.mgrid[0:32, 0:32]).astype(float)
    assert method == "tps"
    np.testing.assert_allclose(coords[:, 12, 3], [12.0, 5.0], atol=1e-9)  # the control, exactly
    np.testing.assert_array_equal(coords[:, :, 12:], grid[:, :, 12:])  # beyond the band: not moved
    np.testing.assert_array_equal(coords[:, -1], grid[:, -1])  # the fixed bottom border
    np.testing.assert_array_equal(coords[:, :, -1], grid[:, :, -1])  # and the right one
    assert np.abs(coords - grid).max() > 1.0
    with pytest.raises(InvalidInput, match="falloff"):
        warp_coordinates((32, 32), [[12.0, 5.0]], [[12.0, 3.0]], falloff=falloff * 2)


def test_smoothing_approximates_the_features_but_keeps_the_fixed_borders_exact():
    src = np.array([[10.0, 10.0], [11.0, 10.0], [12.0, 10.0]])
    dst = src + np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 0.0]])  # one pixel of jitter
    exact, _, _ = warp_coordinates((32, 32), src, dst)
    smooth, method, _ = warp_coordinates((32, 32), src, dst, smoothing=5.0)
    assert method == "tps"
    np.testing.assert_allclose(exact[:, 11, 11], [11.0, 10.0], atol=1e-9)
    # regularised: the jittered control is only partly followed, so the field wobbles less
    assert abs(smooth[1, 11, 11] - 11.0) < abs(exact[1, 11, 11] - 11.0) - 0.05
    grid = np.stack(np.mgrid[0:32, 0:32]).astype(float)
    np.testing.assert_array_equal(smooth[:, -1], grid[:, -1])
    np.testing.assert_array_equal(smooth[:, :, -1], grid[:, :, -1])
    with pytest.raises(InvalidParameter, match="smoothing"):
        warp_coordinates((32, 32), src, dst, smoothing=-1.0)


def test_cubic_resampling_is_exact_on_pixel_centres_and_does_not_ring():
    img = np.zeros((16, 16, 1))
    img[:, 8:] = 1.0  # a step edge
    grid = np.stack(np.mgrid[0:16, 0:16]).astype(float)
    np.testing.assert_allclose(resample(img, grid, order=3), img, atol=1e-12)
    half = resample(img, grid + np.array([0.0, 0.5])[:, None, None], order=3)
    assert half.min() >= 0.0 and half.max() <= 1.0  # no overshoot next to the edge
    assert half[4, 7, 0] == pytest.approx(0.5, abs=0.05)
    # sharper than bilinear a quarter pixel off a fine grating (bilinear averages it away)
    grating = np.zeros((8, 16, 1))
    grating[:, ::2] = 1.0
    quarter = grid[:, :8] + np.array([0.0, 0.25])[:, None, None]
    cubic = resample(grating, quarter, order=3)[2:-2, 2:-2]
    linear = resample(grating, quarter, order=1)[2:-2, 2:-2]
    assert np.ptp(cubic) > np.ptp(linear)
