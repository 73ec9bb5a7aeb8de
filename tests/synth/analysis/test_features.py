"""Known answers of the curvilinear feature maps (texsynth.synth.analysis.features; Wu & Yu 2004, section
2.3)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from texsynth.synth.analysis.features import _classify, feature_map, feature_overlay
from texsynth.synth.analysis.tensor import wrap_angle
from texsynth.synth.errors import InvalidInput, InvalidParameter


def _line_image(angle_deg: float, size: int = 48, width: float = 1.2, bright: bool = True) -> np.ndarray:
    """A line through the centre at ``angle_deg`` (counter-clockwise from +x, y up), Gaussian profile."""
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    x, y = cols - size / 2, -(rows - size / 2)
    t = math.radians(angle_deg)
    dist = np.abs(-math.sin(t) * x + math.cos(t) * y)  # distance to the line through the centre
    line = np.exp(-(dist**2) / (2 * width**2))
    return line if bright else 1.0 - line


def _interior(size: int = 48, margin: int = 8) -> np.ndarray:
    inner = np.zeros((size, size), dtype=bool)
    inner[margin:-margin, margin:-margin] = True
    return inner


def _no_2x2_block(mask: np.ndarray) -> bool:
    return not (mask[:-1, :-1] & mask[1:, :-1] & mask[:-1, 1:] & mask[1:, 1:]).any()


@pytest.mark.parametrize("angle_deg", [0.0, 90.0, 30.0])
def test_ridge_of_a_drawn_line_is_one_pixel_wide_on_the_line_with_its_tangent(angle_deg):
    img = _line_image(angle_deg)
    fmap = feature_map(img, features="ridges")
    inner = fmap.mask & _interior()
    assert inner.sum() >= 25
    # on the line: every feature pixel within one pixel of the drawn centre line
    rows, cols = np.nonzero(fmap.mask)
    x, y = cols - 24.0, -(rows - 24.0)
    t = math.radians(angle_deg)
    assert np.abs(-math.sin(t) * x + math.cos(t) * y).max() <= 1.0
    # one pixel wide: one pixel per column (rows for the vertical line) inside, and no 2x2 block
    per_line = inner.sum(axis=1 if angle_deg == 90.0 else 0)
    assert set(per_line[8:-8].tolist()) == {1}
    assert _no_2x2_block(fmap.mask)
    # tangent: the line's direction in the project's convention (y up, wrapped to (-pi/2, pi/2])
    error = np.degrees(np.abs(wrap_angle(fmap.tangent[inner] - t)))
    assert error.max() < 2.0
    assert np.isnan(fmap.tangent[~fmap.mask]).all()


@pytest.mark.parametrize("angle_deg", [0.0, 90.0, 30.0])
def test_edge_of_a_step_follows_the_step_with_its_tangent(angle_deg):
    rows, cols = np.mgrid[0:48, 0:48].astype(np.float64)
    t = math.radians(angle_deg)
    side = -math.sin(t) * (cols - 24) + math.cos(t) * (-(rows - 24))
    img = np.clip(0.5 + side, 0.2, 0.8)  # a step (one-pixel ramp) along the line
    fmap = feature_map(img, features="edges")
    inner = fmap.mask & _interior()
    assert inner.sum() >= 25
    assert np.abs(side[fmap.mask]).max() <= 1.0
    assert _no_2x2_block(fmap.mask)
    assert np.degrees(np.abs(wrap_angle(fmap.tangent[inner] - t))).max() < 2.0


def test_a_bright_line_has_one_ridge_at_its_centre_and_two_edges_beside_it():
    img = _line_image(0.0)  # centre row 24
    ridge_rows = set(np.nonzero(feature_map(img, features="ridges").mask & _interior())[0].tolist())
    edge_rows = set(np.nonzero(feature_map(img, features="edges").mask & _interior())[0].tolist())
    assert ridge_rows == {24}
    assert len(edge_rows) == 2 and min(edge_rows) < 24 < max(edge_rows)
    assert max(edge_rows) - min(edge_rows) <= 4


def test_ridge_polarity_picks_bright_or_dark_lines():
    dark = _line_image(0.0, bright=False)
    # the bright polarity finds at most the line's shoulders, never its centre
    assert not feature_map(dark, features="ridges", polarity="bright").mask[24].any()
    rows = set(
        np.nonzero(feature_map(dark, features="ridges", polarity="dark").mask & _interior())[0].tolist()
    )
    assert rows == {24}


def test_flat_image_has_no_features_and_rgb_is_accepted():
    assert feature_map(np.full((20, 20), 0.5)).count == 0
    rgb = np.repeat(_line_image(0.0)[..., None], 3, axis=2)
    assert feature_map(rgb, features="ridges").count > 0


def test_two_pass_classification_joins_weak_gaps_next_to_strong_features_only():
    response = np.zeros((20, 40))
    response[10, 5:35] = 1.0
    response[10, 18:23] = 0.4  # a 5-pixel weak stretch in a strong line
    response[3, 5:10] = 0.4  # the same weak response far from any strong pixel
    everywhere = np.ones_like(response, dtype=bool)
    kept = _classify(response, everywhere, high=0.8, alpha=0.3, radius=3)
    assert kept[10, 5:35].all()  # pass 2: 0.4 >= 0.3 * 1.0 within 3 px of strong pixels
    assert not kept[3].any()  # no strong pixel nearby: not a feature
    assert not _classify(response, everywhere, high=0.8, alpha=0.5, radius=3)[10, 18:23].all()  # 0.4 < 0.5 R


def test_overlay_colours_feature_pixels_by_tangent():
    img = _line_image(0.0)
    fmap = feature_map(img, features="ridges")
    rgb = feature_overlay(img, fmap)
    assert rgb.shape == (48, 48, 3) and rgb.dtype == np.uint8
    assert tuple(rgb[24, 24]) == (0, 255, 255)  # 0 degrees: cyan, the project's orientation palette
    assert rgb[5, 5, 0] == rgb[5, 5, 1] == rgb[5, 5, 2]  # grey elsewhere


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"sigma_d": -1.0}, "sigma_d"),
        ({"sigma_r": 0.0}, "sigma_r"),
        ({"high_percentile": 100}, "high_percentile"),
        ({"high_threshold": -0.1}, "high_threshold"),
        ({"alpha": 0.0}, "alpha"),
        ({"alpha": 1.5}, "alpha"),
        ({"radius": float("nan")}, "radius"),
        ({"features": "corners"}, "features"),
        ({"polarity": "grey"}, "polarity"),
        ({"tangent_sigma": (1.0,)}, "tangent_sigma"),
        ({"presmooth": -1.0}, "presmooth"),
    ],
)
def test_bad_parameters_are_named(kwargs, match):
    with pytest.raises(InvalidParameter, match=match):
        feature_map(_line_image(0.0, size=16), **kwargs)


def test_bad_images_are_refused():
    with pytest.raises(InvalidInput, match=r"\(H, W\) or \(H, W, 3\)"):
        feature_map(np.zeros((4, 8, 8)))
    with pytest.raises(InvalidInput, match="NaN"):
        feature_map(np.full((8, 8), np.nan))
    with pytest.raises(InvalidInput, match="too small"):
        feature_map(np.zeros((2, 8)))
    fmap = feature_map(_line_image(0.0, size=16))
    with pytest.raises(InvalidInput, match="does not match"):
        feature_overlay(np.zeros((8, 8)), fmap)
