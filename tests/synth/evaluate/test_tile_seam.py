"""The tile-seam measure: 1 where an image wraps like its interior, large where its borders jump."""

import numpy as np
import pytest

from texsynth.synth.errors import InvalidInput
from texsynth.synth.evaluate import tile_seam


def test_periodic_image_measures_one():
    y, x = np.mgrid[0:32, 0:48]
    wave = np.abs(x % 16 - 8.0) + 2 * np.abs(y % 8 - 4.0)  # triangle waves: every step is 1 or 2, wraps too
    out = tile_seam(wave)
    assert out["ratio"] == pytest.approx(1.0, abs=1e-9)
    assert out["rows"] == pytest.approx(1.0, abs=1e-9) and out["cols"] == pytest.approx(1.0, abs=1e-9)


def test_rolled_periodic_noise_stays_near_one_and_a_cut_crop_does_not():
    rng = np.random.default_rng(0)
    spectrum = np.fft.fft2(rng.standard_normal((128, 128)))
    f = np.fft.fftfreq(128)
    smooth = np.real(np.fft.ifft2(spectrum * np.exp(-((f[:, None] ** 2 + f[None, :] ** 2) * 400))))
    rolled = tile_seam(np.roll(smooth, (40, 70), axis=(0, 1)))  # periodic: no seam
    assert 0.7 < rolled["ratio"] < 1.3
    assert 0.05 < rolled["rows_rank"] < 0.95 and 0.05 < rolled["cols_rank"] < 0.95
    crop = tile_seam(smooth[:90, :90])  # a crop of it does not tile
    assert crop["ratio"] > 5 and crop["rows_rank"] == 1.0 and crop["cols_rank"] == 1.0


def test_known_ratio_of_a_single_jump():
    img = np.tile(np.arange(10.0), (6, 1))  # steps of 1 inside, a jump of 9 at the vertical border
    out = tile_seam(img)
    assert out["cols"] == pytest.approx(81.0)
    assert out["cols_rank"] == 1.0 and out["rows_rank"] == 0.0
    assert np.isnan(out["rows"])  # no vertical change anywhere
    assert np.isnan(out["ratio"])


def test_colour_is_measured_on_grey_and_tiny_images_are_refused():
    tri = np.abs(np.arange(16) % 8 - 4.0)
    rgb = np.dstack([tri[None, :] + tri[:, None]] * 3) / 8.0
    assert tile_seam(rgb)["ratio"] == pytest.approx(1.0, abs=1e-9)
    with pytest.raises(InvalidInput, match="2 x 2"):
        tile_seam(np.zeros((1, 5)))
