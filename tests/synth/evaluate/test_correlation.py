"""Known answers of the two-point correlation S2(r) and of the Gaussian random field."""

from __future__ import annotations

import math

import numpy as np
import pytest

from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.evaluate.correlation import (
    binarize,
    compare_s2,
    correlation_length,
    image_s2,
    level_cut_s2,
    otsu_threshold,
    two_point_correlation,
    volume_s2,
)
from texsynth.synth.io.patterns import gaussian_random_field


def s2_reference(phase: np.ndarray, axis: int, max_lag: int, periodic: bool) -> np.ndarray:
    """The definition, by loops over lags: the share of phase-1 pairs r apart along ``axis``."""
    f = np.moveaxis(np.asarray(phase, dtype=np.float64), axis, -1)
    n = f.shape[-1]
    out = []
    for r in range(max_lag + 1):
        if periodic:
            out.append(float(np.mean(f * np.roll(f, -r, axis=-1))))
        else:
            out.append(float(np.mean(f[..., : n - r] * f[..., r:])))
    return np.array(out)


@pytest.mark.parametrize("periodic", [True, False])
def test_checkerboard_is_phi_at_even_and_zero_at_odd_lags(periodic):
    board2 = np.indices((10, 12)).sum(axis=0) % 2
    for axis in (0, 1):
        s2 = two_point_correlation(board2, axis, periodic=periodic, max_lag=5)
        assert s2.tolist() == [0.5, 0.0, 0.5, 0.0, 0.5, 0.0]
    board3 = np.indices((6, 8, 10)).sum(axis=0) % 2
    curves = volume_s2(board3, periodic=periodic)
    assert [len(curves[a]) for a in ("z", "y", "x")] == [4, 5, 6]  # lags up to N // 2
    for curve in curves.values():
        assert np.array_equal(curve, np.where(np.arange(len(curve)) % 2 == 0, 0.5, 0.0))


def test_stripes_have_the_triangle_wave_s2():
    period, width, n = 8, 3, 64
    stripes = np.tile(
        (np.arange(n) % period < width).astype(np.uint8), (5, 1)
    )  # phase 1 on 3 of every 8 columns
    s2 = two_point_correlation(stripes, 1, periodic=True, max_lag=20)
    m = np.arange(21) % period
    expected = (np.maximum(0, width - m) + np.maximum(0, width - (period - m))) / period
    np.testing.assert_allclose(s2, expected, atol=1e-15)
    assert s2[0] == width / period
    # along the stripes nothing changes: S2 stays at phi
    np.testing.assert_array_equal(
        two_point_correlation(stripes, 0, periodic=True), np.full(3, width / period)
    )


@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("shape", [(13, 17), (6, 9, 11)])
def test_fft_equals_the_definition(periodic, shape):
    phase = np.random.default_rng(1).random(shape) < 0.37
    for axis in range(len(shape)):
        lag = shape[axis] - 1
        np.testing.assert_allclose(
            two_point_correlation(phase, axis, periodic=periodic, max_lag=lag),
            s2_reference(phase, axis, lag, periodic),
            atol=1e-14,
        )


def test_random_medium_starts_at_phi_and_settles_at_phi_squared():
    phase = np.random.default_rng(2).random((40, 50, 60)) < 0.3
    phi = float(phase.mean())
    for curve in volume_s2(phase).values():
        assert curve[0] == pytest.approx(phi, abs=1e-15)
        np.testing.assert_allclose(curve[1:], phi**2, atol=0.004)  # white noise: no correlation at r >= 1


def test_grey_images_are_cut_at_otsu_or_the_given_threshold():
    rng = np.random.default_rng(3)
    two_level = np.where(rng.random((32, 40)) < 0.25, 0.8, 0.2) + rng.uniform(-0.05, 0.05, (32, 40))
    t = otsu_threshold(two_level)
    assert np.array_equal(two_level >= t, two_level > 0.5)  # Otsu splits the two grey levels
    np.testing.assert_array_equal(binarize(two_level), two_level >= t)
    grey = image_s2(two_level)
    binary = image_s2(two_level >= t)
    assert grey.keys() == {"row", "col"}
    for key in grey:
        np.testing.assert_array_equal(grey[key], binary[key])
    assert grey["col"][0] == pytest.approx(0.25, abs=0.03)
    # a given threshold is used as it is: everything above 0.1 is phase 1
    assert image_s2(two_level, threshold=0.1)["row"][0] == 1.0
    # a 0/1 image is taken as it is
    np.testing.assert_array_equal(image_s2((two_level >= t).astype(np.float32))["col"], binary["col"])


def test_correlation_length_of_a_debye_medium_and_of_one_phase():
    r = np.arange(30)
    phi = 0.4
    for length in (2.0, 4.0, 7.5):
        debye = phi**2 + phi * (1 - phi) * np.exp(-r / length)  # Torquato 2002, eq. 2.25
        assert correlation_length(debye) == math.floor(length) + 1  # the first lag beyond the e-fold
    assert correlation_length(np.full(10, 1.0)) is None  # one phase
    assert correlation_length(np.full(10, 0.0)) is None
    assert correlation_length(np.array([0.5, 0.5, 0.5])) is None  # never decorrelates


def test_compare_s2_known_values():
    ex = np.array([0.5, 0.4, 0.3, 0.25, 0.25, 0.25])  # excess 0.25, 0.15, 0.05: length 2 (0.05 < 0.25 / e)
    same = compare_s2(ex, ex)
    assert same["relative_error"] == 0.0 and same["max_abs_error"] == 0.0
    assert same["correlation_length"] == {"exemplar": 2, "output": 2} and same["window"] == 2
    out = ex + np.array([0.0, 0.06, 0.03, 0.5, 0.5, 0.5])  # errors beyond the window do not count
    cmp = compare_s2(ex, out[:5])
    assert cmp["relative_error"] == pytest.approx(0.09 / 1.2)
    assert cmp["max_abs_error"] == pytest.approx(0.06)
    assert cmp["volume_fraction"] == {"exemplar": 0.5, "output": 0.5}
    empty = compare_s2(np.zeros(4), np.full(4, 0.1))
    assert empty["relative_error"] is None and empty["window"] == 3


def test_level_cut_s2_closed_forms():
    r = np.arange(0, 15, dtype=np.float64)
    # the median cut (t = 0): S2 = 1/4 + arcsin(rho) / (2 pi)
    rho = np.exp(-((r / 3.0) ** 2))
    np.testing.assert_allclose(level_cut_s2(r, 3.0, 0.5), 0.25 + np.arcsin(rho) / (2 * np.pi), atol=1e-10)
    curve = level_cut_s2(r, 2.0, 0.3)
    assert curve[0] == pytest.approx(0.3, abs=1e-9)
    assert curve[-1] == pytest.approx(0.09, abs=1e-9)
    assert np.all(np.diff(curve) <= 1e-12)


def test_gaussian_random_field_has_the_s2_of_its_correlation_lengths():
    lengths, phi = (2.0, 4.0, 8.0), 0.4
    vol = gaussian_random_field((64, 64, 64), lengths, phi, seed=3)
    assert vol.dtype == np.float32 and set(np.unique(vol)) == {0.0, 1.0}
    assert vol.sum() == round(phi * vol.size)  # exactly phi
    curves = volume_s2(vol)
    measured = []
    for name, length in zip(("z", "y", "x"), lengths, strict=True):
        theory = level_cut_s2(np.arange(len(curves[name])), length, phi)
        np.testing.assert_allclose(curves[name], theory, atol=0.025)
        measured.append(correlation_length(curves[name]))
        assert abs(measured[-1] - correlation_length(theory)) <= 1
    # S2 per axis differs as the correlation lengths do: about 0.8 l each (2, 4, 7 here)
    assert measured[0] < measured[1] < measured[2]
    assert measured[2] / measured[0] == pytest.approx(4.0, rel=0.3)


def test_gaussian_random_field_is_seeded_and_takes_2d_shapes():
    a = gaussian_random_field((32, 48), 3.0, 0.5, seed=7)
    assert a.shape == (32, 48) and a.mean() == 0.5
    assert np.array_equal(a, gaussian_random_field((32, 48), (3.0, 3.0), 0.5, seed=7))
    assert not np.array_equal(a, gaussian_random_field((32, 48), 3.0, 0.5, seed=8))


def test_bad_inputs_name_the_argument():
    with pytest.raises(InvalidInput, match="phase: must hold only 0 and 1"):
        two_point_correlation(np.full((8, 8), 0.5), 0)
    with pytest.raises(InvalidParameter, match="'axis' = 2: must be an axis of the 2-D array"):
        two_point_correlation(np.zeros((8, 8), bool), 2)
    with pytest.raises(InvalidParameter, match=r"'max_lag' = 8: must be an integer in \[0, 7\]"):
        two_point_correlation(np.zeros((8, 8), bool), 0, max_lag=8)
    with pytest.raises(InvalidInput, match="no lines"):
        two_point_correlation(np.zeros((0, 8), bool), 0)
    with pytest.raises(InvalidParameter, match="already two-phase"):
        binarize(np.zeros((8, 8), bool), 0.5)
    with pytest.raises(InvalidInput, match=r"image: expected a grey \(H, W\) image"):
        image_s2(np.zeros((4, 8, 8)))
    with pytest.raises(InvalidInput, match=r"volume: expected a grey \(D, H, W\) volume"):
        volume_s2(np.zeros((8, 8)))
    with pytest.raises(InvalidInput, match="NaN"):
        otsu_threshold(np.array([0.1, np.nan]))
    with pytest.raises(InvalidParameter, match="must be a 1-D curve"):
        correlation_length(np.zeros((2, 2)))
    with pytest.raises(InvalidParameter, match="strictly between 0 and 1"):
        level_cut_s2([0.0], 2.0, 1.0)
    with pytest.raises(InvalidParameter, match="correlation_length"):
        level_cut_s2([0.0], -1.0, 0.5)
    with pytest.raises(InvalidParameter, match=r"'shape' = \(8,\)"):
        gaussian_random_field((8,), 2.0)
    with pytest.raises(InvalidParameter, match="needs one value or 3"):
        gaussian_random_field((8, 8, 8), (2.0, 2.0))
    with pytest.raises(InvalidParameter, match="positive lengths"):
        gaussian_random_field((8, 8), (2.0, 0.0))
    with pytest.raises(InvalidParameter, match="volume_fraction"):
        gaussian_random_field((8, 8), 2.0, 0.0)


def test_otsu_agrees_with_scikit_image_to_a_bin():
    from skimage.filters import threshold_otsu

    img = np.random.default_rng(4).beta(2.0, 5.0, (64, 64))
    assert abs(otsu_threshold(img) - threshold_otsu(img)) <= np.ptp(img) / 256 + 1e-12
    assert otsu_threshold(np.full((4, 4), 0.3)) == 0.3
