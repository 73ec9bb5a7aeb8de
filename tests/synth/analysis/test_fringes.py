"""Known answers of the HRTEM fringe analysis (texsynth.synth.analysis.fringes)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from skimage.draw import circle_perimeter, line

from tests.paths import SHARED_DATA
from texsynth.synth.analysis.fringes import TORTUOUS, extract_fringes, fringe_band_pass, measure_skeleton
from texsynth.synth.errors import InvalidInput, InvalidParameter

SOOT = SHARED_DATA / "hrtem-soot-256.png"


def _lines(shape: tuple[int, int], *segments: tuple[int, int, int, int]) -> np.ndarray:
    skel = np.zeros(shape, dtype=bool)
    for r0, c0, r1, c1 in segments:
        skel[line(r0, c0, r1, c1)] = True
    return skel


@pytest.mark.parametrize(
    ("segment", "length", "angle_deg"),
    [
        ((10, 5, 10, 44), 39.0, 0.0),  # horizontal, 40 pixels
        ((5, 20, 34, 20), 29.0, 90.0),  # vertical, 30 pixels
        ((5, 5, 30, 30), 25 * math.sqrt(2), -45.0),  # down-right on screen = -45 deg with y up
        ((30, 5, 5, 30), 25 * math.sqrt(2), 45.0),  # up-right
    ],
)
def test_straight_lines_have_their_drawn_length_and_tortuosity_one(segment, length, angle_deg):
    f = measure_skeleton(_lines((48, 48), segment))
    assert f.count == 1
    assert f.lengths[0] == pytest.approx(length, abs=1e-9)
    assert f.end_to_end[0] == pytest.approx(length, abs=1e-9)
    assert f.tortuosity[0] == 1.0
    assert math.degrees(f.orientation[0]) == pytest.approx(angle_deg)
    assert f.labels.max() == 1 and (f.labels > 0).sum() == np.count_nonzero(_lines((48, 48), segment))


def test_bent_line_length_and_tortuosity():
    # an L: 20 steps right then 15 steps down, one fringe (a corner is not a junction); the corner
    # pixel is redundant in 8-connectivity, so the path cuts it with one diagonal step
    f = measure_skeleton(_lines((40, 40), (5, 5, 5, 25), (5, 25, 20, 25)))
    assert f.count == 1
    expected = 19 + math.sqrt(2) + 14
    assert f.lengths[0] == pytest.approx(expected)
    assert f.tortuosity[0] == pytest.approx(expected / math.hypot(20, 15))


def test_four_connected_staircase_is_one_fringe_measured_with_diagonal_steps():
    skel = np.zeros((20, 24), dtype=bool)
    k = 12
    for i in range(k):
        skel[3 + i, 3 + i] = skel[3 + i, 4 + i] = True  # (0,0) (0,1) (1,1) (1,2) ...: 3 neighbours each
    f = measure_skeleton(skel, min_length=5)
    assert f.count == 1
    assert f.lengths[0] == pytest.approx(1 + (k - 1) * math.sqrt(2))


def test_junctions_break_fringes_and_short_branches_are_pruned():
    long_t = _lines((50, 50), (10, 5, 10, 44), (11, 25, 40, 25))  # 30-pixel stem: a real branch
    f = measure_skeleton(long_t, min_length=9)
    assert f.count == 3
    spur = _lines((50, 50), (10, 5, 10, 44), (11, 25, 14, 25))  # 4-pixel spur: pruned
    g = measure_skeleton(spur, min_length=9)
    assert g.count == 1
    assert g.lengths[0] == pytest.approx(39.0) and g.tortuosity[0] == 1.0


def test_specks_and_loops_are_not_fringes():
    skel = _lines((60, 60), (5, 5, 5, 7))  # a 3-pixel speck
    rr, cc = circle_perimeter(35, 35, 12)
    skel[rr, cc] = True
    f = measure_skeleton(skel, min_length=9)
    assert f.count == 0
    assert f.n_loops == 1
    assert not f.skeleton.any()


def test_extract_fringes_on_drawn_dark_lines():
    img = np.ones((64, 64), dtype=np.float32)
    img[line(10, 8, 10, 47)] = 0.0  # horizontal, 40 px
    img[line(25, 10, 54, 39)] = 0.0  # diagonal, 30 px
    f = extract_fringes(img, pixel_size=0.05)
    assert f.count == 2
    # filtering and skeletonisation may shorten a line by one step at an end, never bend it
    horizontal, diagonal = (f.lengths[0], f.lengths[1]) if f.endpoints[0, 0, 0] == 10 else f.lengths[::-1]
    assert 38.0 <= horizontal <= 39.0
    assert 28 * math.sqrt(2) - 1e-9 <= diagonal <= 29 * math.sqrt(2) + 1e-9
    np.testing.assert_array_equal(f.tortuosity, [1.0, 1.0])
    np.testing.assert_allclose(f.lengths_nm, f.lengths * 0.05)
    s = f.summary()
    assert s["count"] == 2 and s["median_tortuosity"] == 1.0 and s["share_tortuous"] == 0.0
    assert s["mean_length_nm"] == pytest.approx(s["mean_length"] * 0.05)


def test_polarity_selects_dark_or_bright_lines():
    img = np.zeros((48, 48), dtype=np.float32)
    img[line(20, 5, 20, 40)] = 1.0  # a bright line
    assert extract_fringes(img, polarity="bright").count == 1
    assert extract_fringes(img, polarity="dark").count == 0
    assert extract_fringes(img, polarity="bright", filter="dog").count == 1


def test_identical_images_identical_fringes_and_no_fringes_in_flat_image():
    rng = np.random.default_rng(3)
    img = rng.random((48, 48))
    a, b = extract_fringes(img), extract_fringes(img.copy())
    np.testing.assert_array_equal(a.lengths, b.lengths)
    np.testing.assert_array_equal(a.labels, b.labels)
    flat = extract_fringes(np.full((32, 32), 0.5))
    assert flat.count == 0 and flat.summary()["median_tortuosity"] is None


def test_band_pass_is_high_on_dark_lines():
    img = np.ones((32, 32))
    img[16, :] = 0.0
    r = fringe_band_pass(img)
    assert r[16].mean() > 5 * r[8].mean()


def test_errors_name_the_input_or_parameter():
    with pytest.raises(InvalidInput, match="grey"):
        extract_fringes(np.zeros((16, 16, 3)))
    with pytest.raises(InvalidInput, match="NaN"):
        extract_fringes(np.full((16, 16), np.nan))
    with pytest.raises(InvalidParameter, match="filter"):
        extract_fringes(np.zeros((16, 16)), filter="gabor")  # type: ignore[arg-type]
    with pytest.raises(InvalidParameter, match="sigma"):
        extract_fringes(np.zeros((16, 16)), sigma=0)
    with pytest.raises(InvalidParameter, match="min_length"):
        measure_skeleton(np.zeros((8, 8), bool), min_length=-1)


@pytest.mark.skipif(not SOOT.exists(), reason="shared test image not available")
def test_soot_fringes_are_plausible():
    from PIL import Image

    img = np.asarray(Image.open(SOOT), dtype=np.float32) / 255.0
    s = extract_fringes(img, pixel_size=1 / 18).summary()
    # docs/evaluation.md reports these figures; published soot: median tortuosity ~1.1
    assert 150 <= s["count"] <= 300
    assert 1.05 <= s["median_tortuosity"] <= 1.2
    assert 0.5 <= s["median_length_nm"] <= 1.5
    assert s["share_tortuous"] < 0.2
    assert TORTUOUS == 1.5


def test_stack_extraction_is_the_extraction_of_each_image() -> None:
    """extract_fringes_stack filters the whole stack at once: every image's fringes as extract_fringes
    gives them alone, with both filters and a fixed threshold, and the same errors."""
    from texsynth.synth.analysis.fringes import extract_fringes_stack

    rng = np.random.default_rng(2)
    yy, xx = np.mgrid[0:40, 0:48].astype(np.float64)
    waves = [np.cos(2 * np.pi * (xx + k * yy / 5) / 7) for k in range(5)]
    stack = np.stack([0.5 + 0.4 * w + rng.normal(0, 0.05, xx.shape) for w in waves])
    for options in ({}, {"filter": "dog", "background": 2.5}, {"threshold": 0.02, "min_length": 4.0}):
        together = extract_fringes_stack(stack, **options)
        assert sum(f.count for f in together) > 10
        for image, fr in zip(stack, together, strict=True):
            alone = extract_fringes(image, **options)
            for name in ("lengths", "tortuosity", "endpoints", "labels", "binary"):
                assert np.array_equal(getattr(fr, name), getattr(alone, name)), name
            assert fr.n_loops == alone.n_loops
    with pytest.raises(InvalidInput, match="grey"):
        extract_fringes_stack(stack[0])
    with pytest.raises(InvalidParameter, match="threshold"):
        extract_fringes_stack(stack, threshold="mean")
