"""The grain measure and the blend that matches it (texsynth.synth.analysis.grain)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage as ndi

from texsynth.synth.analysis.grain import (
    BLEND_STEPS,
    FINE_SIGMA,
    GrainSums,
    blend_weight,
    blended,
    fine_share,
    grain_sums,
    match_grain,
)


def test_fine_share_of_a_sinusoid_is_its_high_pass_gain_squared() -> None:
    # A cosine of period P keeps (1 - G(1/P))^2 of its variance after the high-pass, G the Gaussian's
    # transfer function exp(-2 pi^2 sigma^2 f^2); wrapped, 8 whole periods.
    period = 8.0
    image = np.tile(np.cos(2 * np.pi * np.arange(64) / period), (64, 1))
    gain = 1.0 - np.exp(-2 * np.pi**2 * FINE_SIGMA**2 / period**2)
    assert fine_share(image, mode="wrap") == pytest.approx(gain**2, rel=2e-3)


def test_fine_share_of_white_noise_is_the_high_pass_energy() -> None:
    # White noise keeps sum((delta - g)^2) of its variance: g the filter's own discrete kernel.
    delta = np.zeros((33, 33))
    delta[16, 16] = 1.0
    expected = float(np.sum((delta - ndi.gaussian_filter(delta, FINE_SIGMA)) ** 2))
    noise = np.random.default_rng(1).normal(size=(512, 512))
    assert fine_share(noise, mode="wrap") == pytest.approx(expected, rel=0.01)
    assert 0.7 < expected < 0.8


def test_fine_share_is_zero_for_flat_and_small_for_smooth_images() -> None:
    assert fine_share(np.full((16, 16), 0.3)) == 0.0
    smooth = ndi.gaussian_filter(np.random.default_rng(2).normal(size=(128, 128)), 3.0)
    assert fine_share(smooth) < 0.01


def test_sums_give_the_share_of_any_blend() -> None:
    rng = np.random.default_rng(3)
    d = rng.normal(size=(12, 20, 16))
    m = ndi.gaussian_filter(d, 1.5) + 0.1 * rng.normal(size=d.shape)
    sums = grain_sums(d, m, axes=[0, 2], periodic=False)
    for a in (0.0, 0.3, 1.0):
        blend = (1 - a) * d + a * m
        num = den = 0.0
        for axis in (0, 2):
            for i in range(blend.shape[axis]):  # every slice: fewer than SLICES_PER_AXIS per axis here
                s = np.take(blend, i, axis=axis)
                s = s - s.mean()
                num += np.sum((s - ndi.gaussian_filter(s, FINE_SIGMA)) ** 2)
                den += np.sum(s * s)
        assert float(sums.share(a)) == pytest.approx(num / den, rel=1e-9)


def test_blend_weight_is_the_least_step_that_reaches_the_target() -> None:
    sums = GrainSums(hdd=4.0, hdm=0.5, hmm=0.25, dd=10.0, dm=5.0, mm=5.0)  # shares 0.4 -> 0.05
    a = blend_weight(sums, 0.2)
    assert 0 < a < 1 and a * BLEND_STEPS == round(a * BLEND_STEPS)
    assert sums.share(a) <= 0.2 < sums.share(a - 1 / BLEND_STEPS)
    assert blend_weight(sums, 0.5) == 0.0  # already no grainier: nothing changes
    assert blend_weight(sums, 0.01) == 1.0  # even the average is grainier: all of it


def test_grain_sums_need_two_volumes_of_one_shape() -> None:
    with pytest.raises(ValueError, match="one shape"):
        grain_sums(np.zeros((4, 4, 4)), np.zeros((4, 4, 5)), axes=[0], periodic=False)


def test_blended_is_the_whole_array_expression_slab_by_slab() -> None:
    rng = np.random.default_rng(6)
    d = rng.random((19, 6, 5)).astype(np.float32)  # not a multiple of the slab
    m = rng.random((19, 6, 5))  # float64, as the solver's averages
    got = blended(d, m, 0.37)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, ((1.0 - 0.37) * d + 0.37 * m).astype(np.float32))


def test_match_grain_blends_by_the_weight_given_or_the_least_that_reaches_the_exemplars() -> None:
    rng = np.random.default_rng(7)
    smooth = ndi.gaussian_filter(rng.normal(size=(16, 16, 16)), 1.2)
    speckled = smooth + 0.4 * smooth.std() * rng.normal(size=smooth.shape)
    average = ndi.gaussian_filter(smooth, 0.8)  # smoother than the exemplar
    exemplar = smooth[8]
    volume, a, ratios = match_grain(speckled, average, [exemplar], [0, 1, 2], periodic=False)
    sums = grain_sums(speckled, average, [0, 1, 2], periodic=False)
    assert a == blend_weight(sums, fine_share(exemplar)) and 0 < a < 1
    assert ratios["discrete"] > 1.0 >= ratios["final"]
    np.testing.assert_array_equal(volume, blended(speckled, average, a))
    whole, one, _ = match_grain(speckled, average, [exemplar], [0], periodic=False, blend=1.0)
    assert one == 1.0 and np.allclose(whole, average.astype(np.float32))
    kept, zero, _ = match_grain(smooth, speckled, [speckled[8]], [0], periodic=False)
    assert zero == 0.0 and kept is smooth
