"""Renderings of :mod:`texsynth.synth.output.render`: palette colours, the wrap at +-90 degrees, legends,
dtypes."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.analysis.tensor import coherence, structure_direction, structure_tensor
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.output.render import (
    LEGEND_KINDS,
    coherence_image,
    composite_image,
    legend_shape,
    orientation_hue,
    orientation_image,
    with_legend,
)

RED, YELLOW, CYAN, MAGENTA = (255, 0, 0), (255, 255, 0), (0, 255, 255), (255, 0, 255)
YELLOW_GREEN, VIOLET = (128, 255, 0), (128, 0, 255)


def colour_of(theta: float, **kwargs: np.ndarray) -> tuple[int, ...]:
    return tuple(int(v) for v in orientation_image(np.array([[theta]]), **kwargs)[0, 0])


@pytest.mark.parametrize(
    ("degrees", "rgb"),
    [
        (0.0, CYAN),  # hue 0.5
        (90.0, RED),  # hue 1 == 0
        (-90.0, RED),  # the same orientation
        (-60.0, YELLOW),  # hue 1/6
        (-45.0, YELLOW_GREEN),  # hue 1/4
        (45.0, VIOLET),  # hue 3/4
        (60.0, MAGENTA),  # hue 5/6
        (180.0, CYAN),  # orientations are modulo 180 degrees
        (135.0, YELLOW_GREEN),
    ],
)
def test_colours_of_known_angles(degrees: float, rgb: tuple[int, int, int]) -> None:
    assert colour_of(np.radians(degrees)) == rgb


def test_hue_formula() -> None:
    theta = np.linspace(-np.pi / 2 + 1e-9, np.pi / 2 - 1e-9, 101)
    np.testing.assert_allclose(orientation_hue(theta), (theta + np.pi / 2) / np.pi, atol=1e-12)
    assert orientation_hue(np.pi / 2) == 0.0


def test_palette_is_cyclic_and_continuous_across_the_wrap() -> None:
    eps = np.radians(0.5)
    near_plus = np.array(colour_of(np.pi / 2 - eps), dtype=int)
    near_minus = np.array(colour_of(-np.pi / 2 + eps), dtype=int)
    assert np.abs(near_plus - near_minus).max() <= 2 * 255 * 6 * 0.5 / 180 + 1
    # A fine sweep over two full turns: neighbouring angles never jump, including at +-90 degrees.
    sweep = np.linspace(-np.pi, np.pi, 3601)
    rgb = orientation_image(sweep[None, :]).astype(int)[0]
    steps = np.abs(np.diff(rgb, axis=0)).max()
    assert steps <= 2  # 0.1 degree -> at most ~1 level per channel (+ rounding)


def test_orientation_image_dtype_shape_and_coherence_saturation() -> None:
    theta = np.zeros((5, 7), dtype=np.float32)
    out = orientation_image(theta)
    assert out.dtype == np.uint8 and out.shape == (5, 7, 3)
    assert colour_of(0.0, coherence=np.array([[0.0]])) == (255, 255, 255)  # no structure: white
    assert colour_of(0.0, coherence=np.array([[1.0]])) == CYAN
    half = colour_of(np.pi / 2, coherence=np.array([[0.5]]))
    assert half == (255, 128, 128)


def test_non_finite_angles_are_black() -> None:
    out = orientation_image(np.array([[np.nan, np.inf, 0.0]]))
    assert out[0, 0].tolist() == [0, 0, 0] and out[0, 1].tolist() == [0, 0, 0]
    assert out[0, 2].tolist() == list(CYAN)


def test_coherence_image_grey_levels() -> None:
    c = np.array([[0.0, 0.25, 0.5, 1.0, 1.5, -0.2, np.nan]])
    out = coherence_image(c)
    assert out.dtype == np.uint8 and out.shape == c.shape
    assert out.tolist() == [[0, 64, 128, 255, 255, 0, 0]]


def test_composite_hsv() -> None:
    theta = np.radians(np.array([[0.0, 0.0, 90.0, -45.0]]))
    coh = np.array([[1.0, 0.0, 1.0, 1.0]])
    value = np.array([[1.0, 0.6, 0.5, 0.0]])
    out = composite_image(theta, coh, value)
    assert out.dtype == np.uint8 and out.shape == (1, 4, 3)
    assert out[0, 0].tolist() == list(CYAN)  # full coherence, full value
    assert out[0, 1].tolist() == [153, 153, 153]  # no coherence: the image's grey
    assert out[0, 2].tolist() == [128, 0, 0]  # red at half brightness
    assert out[0, 3].tolist() == [0, 0, 0]  # value 0 is black whatever the angle


def test_composite_takes_luminance_of_rgb_value() -> None:
    theta = np.zeros((2, 2))
    rgb = np.zeros((2, 2, 3))
    rgb[..., 1] = 1.0  # pure green: luma 0.587 (ITU-R BT.601, the engine's one grey conversion)
    out = composite_image(theta, np.zeros((2, 2)), rgb)
    assert out[0, 0].tolist() == [150, 150, 150]


def test_composite_shapes_must_match() -> None:
    with pytest.raises(InvalidParameter, match="coherence"):
        composite_image(np.zeros((4, 4)), np.zeros((4, 5)), np.zeros((4, 4)))
    with pytest.raises(InvalidParameter, match="value"):
        composite_image(np.zeros((4, 4)), np.zeros((4, 4)), np.zeros((3, 4)))
    with pytest.raises(InvalidParameter, match="theta"):
        orientation_image(np.zeros((4, 4, 3)))


@pytest.mark.parametrize("kind", LEGEND_KINDS)
@pytest.mark.parametrize("width", [40, 300, 700, 1400])
def test_legend_size_and_placement(kind: str, width: int) -> None:
    h_leg, w_leg = legend_shape(kind, width)  # type: ignore[arg-type]
    assert w_leg == max(width, w_leg) and w_leg >= 300
    channels = () if kind == "coherence" else (3,)
    image = np.full((30, width, *channels), 7, dtype=np.uint8)
    out = with_legend(image, kind)  # type: ignore[arg-type]
    assert out.dtype == np.uint8
    assert out.shape == (30 + h_leg, max(width, w_leg), *channels)
    assert np.all(out[:30, :width] == 7)  # the image, untouched, top-left
    assert np.all(out[:30, width:] == 255)  # padded with white when narrower than the legend
    assert np.any(out[30:] < 64)  # text and ticks are drawn


def test_legend_grows_with_wide_images() -> None:
    assert legend_shape("orientation", 2000)[0] > legend_shape("orientation", 500)[0]


def test_orientation_legend_shows_the_palette() -> None:
    out = orientation_image(np.zeros((8, 8)), legend=True)
    legend = out[8:].reshape(-1, 3).astype(int)
    for colour in (RED, CYAN, YELLOW, MAGENTA):
        distance = np.abs(legend - np.array(colour)).sum(axis=1)
        assert distance.min() <= 12, colour


def test_coherence_legend_is_a_grey_ramp() -> None:
    out = coherence_image(np.zeros((8, 8)), legend=True)
    assert out.ndim == 2
    assert out[8:].min() == 0 and out[8:].max() == 255
    levels = np.unique(out[8:])
    assert levels.size > 200  # a ramp, not a few steps


def test_composite_legend_is_a_hue_saturation_chart() -> None:
    out = composite_image(np.zeros((8, 8)), np.ones((8, 8)), np.ones((8, 8)), legend=True)
    legend = out[8:].reshape(-1, 3).astype(int)
    saturation = legend.max(axis=1) - legend.min(axis=1)
    assert np.any(saturation > 250) and np.any((saturation > 60) & (saturation < 190))


def test_legend_flag_equals_with_legend() -> None:
    theta = np.random.default_rng(0).uniform(-2, 2, (20, 30))
    coh = np.random.default_rng(1).uniform(0, 1, (20, 30))
    assert np.array_equal(
        orientation_image(theta, legend=True), with_legend(orientation_image(theta), "orientation")
    )
    assert np.array_equal(coherence_image(coh, legend=True), with_legend(coherence_image(coh), "coherence"))
    assert np.array_equal(
        orientation_image(theta, coherence=coh, legend=True),
        with_legend(orientation_image(theta, coherence=coh), "composite"),
    )


def test_custom_title_changes_the_legend() -> None:
    img = orientation_image(np.zeros((8, 8)))
    assert not np.array_equal(
        with_legend(img, "orientation"), with_legend(img, "orientation", title="gradient")
    )


def test_with_legend_rejects_bad_input() -> None:
    with pytest.raises(InvalidParameter, match="kind"):
        with_legend(np.zeros((4, 4), dtype=np.uint8), "hue")  # type: ignore[arg-type]
    with pytest.raises(InvalidParameter, match="uint8"):
        with_legend(np.zeros((4, 4)), "coherence")


def test_rendering_a_grating_field() -> None:
    """Horizontal fringes (gradient up) render at fringe direction 0: cyan, fully coherent."""
    rows = np.arange(64, dtype=np.float64)[:, None]
    image = np.tile(0.5 + 0.5 * np.sin(2 * np.pi * -rows / 8), (1, 64))
    S = structure_tensor(image)
    out = composite_image(structure_direction(S), coherence(S), np.ones_like(image))
    centre = out[24:40, 24:40].reshape(-1, 3).astype(int)
    assert np.abs(centre - np.array(CYAN)).max() <= 3
    assert np.array_equal(out, composite_image(structure_direction(S), coherence(S), np.ones_like(image)))


def test_renderings_in_blocks_of_rows_equal_the_whole_field_at_once():
    """Fields taller than one block (issue 25): the same bytes as the per-pixel formula on the whole field."""
    from skimage.color import hsv2rgb

    from texsynth.synth.output import render

    rng = np.random.default_rng(3)
    shape = (3 * (render._BLOCK_PIXELS // 100) + 7, 100)  # three blocks of rows and a bit
    theta = (rng.random(shape) * 4 - 2).astype(np.float32)
    coh = (rng.random(shape) * 1.4 - 0.2).astype(np.float32)
    theta[0, 0], theta[-1, -1], coh[5, 5] = np.nan, np.inf, np.nan
    assert len(list(render._row_blocks(shape))) >= 3
    t = theta.astype(np.float64)
    finite = np.isfinite(t)
    sat = np.clip(np.nan_to_num(coh.astype(np.float64), nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    hsv = np.stack([np.mod((np.where(finite, t, 0.0) + np.pi / 2) / np.pi, 1.0), sat, finite], axis=-1)
    whole = np.round(np.clip(hsv2rgb(hsv), 0.0, 1.0) * 255.0).astype(np.uint8)
    assert np.array_equal(render.orientation_image(theta, coherence=coh), whole)
    assert np.array_equal(render.coherence_image(coh), np.round(sat * 255.0).astype(np.uint8))


def test_the_colour_conversion_gives_scikit_image_hsv2rgb_floats_bit_for_bit():
    """``_hsv_uint8`` (one channel at a time) against ``skimage.color.hsv2rgb`` then the same quantisation:
    random HSV, the sectors' edges (hue k/6 and its neighbouring floats, 1.0), grey (saturation 0), black,
    values outside [0, 1], and mixed dtypes and scalars broadcast together."""
    from skimage.color import hsv2rgb

    from texsynth.synth.output.render import _hsv_uint8, _to_uint8

    def reference(h, s, v):
        hsv = np.stack(np.broadcast_arrays(h, s, v), axis=-1).astype(np.float64)
        return _to_uint8(hsv2rgb(hsv))

    rng = np.random.default_rng(11)
    edges = np.array([k / 6 for k in range(7)])
    hue = np.concatenate([rng.random(5000), edges, np.nextafter(edges, 2.0), np.nextafter(edges, -1.0)])
    sat = np.concatenate([rng.random(5000), np.zeros(7), np.ones(7), rng.random(7) * 1.4 - 0.2])
    val = np.concatenate([rng.random(5000), np.zeros(7), np.ones(7), rng.random(7)])
    got = _hsv_uint8(hue, sat, val)
    assert got.dtype == np.uint8 and got.shape == (len(hue), 3)
    assert np.array_equal(got, reference(hue, sat, val))
    square = rng.random((40, 30)).astype(np.float32)
    assert np.array_equal(_hsv_uint8(square, 1.0, 1.0), reference(square, 1.0, 1.0))
    rows = np.linspace(0, 1, 40, dtype=np.float32).reshape(-1, 1)
    assert np.array_equal(_hsv_uint8(square.astype(np.float64), rows, 0.5), reference(square, rows, 0.5))


def test_an_orientation_picture_needs_no_float64_copies_of_its_field():
    """Traced peak of a 1024^2 orientation picture with coherence: about 4.5 MB of temporaries per
    block and the 3 MB picture (main: 360 bytes per pixel, 380 MB)."""
    import tracemalloc

    rng = np.random.default_rng(0)
    theta, coh = rng.random((1024, 1024), dtype=np.float32), rng.random((1024, 1024), dtype=np.float32)
    tracemalloc.start()
    try:
        orientation_image(theta, coherence=coh)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 40 * 2**20, peak / 2**20


def _zlib_level_class(png: bytes) -> int:
    """The compression level class (FLEVEL, 0-3) in the zlib header of a PNG's first IDAT chunk."""
    start = png.index(b"IDAT") + 4
    return png[start + 1] >> 6


def test_the_tensor_pictures_are_lossless_pngs_at_the_pictures_zlib_effort():
    """The pictures made for people (tensor images, plots) are encoded at ``PICTURE_PNG_LEVEL`` (3: zlib's
    'fast' class, levels 2-5), the outputs at Pillow's default (6: the 'default' class); pixels exact."""
    import io as _io

    from PIL import Image

    from texsynth.synth.io import PICTURE_PNG_LEVEL, image_to_png_bytes
    from texsynth.synth.output.artifacts import _png_bytes

    rng = np.random.default_rng(5)
    picture = orientation_image(rng.random((64, 48)) * np.pi - np.pi / 2, legend=True)
    png = _png_bytes(picture)
    assert np.array_equal(np.asarray(Image.open(_io.BytesIO(png))), picture)
    assert PICTURE_PNG_LEVEL == 3 and _zlib_level_class(png) == 1
    assert _zlib_level_class(image_to_png_bytes(rng.random((64, 48)).astype(np.float32))) == 2
