"""Tests of texsynth.synth.io: round trips, conversions, and one test per kind of bad input (message
included)."""

from __future__ import annotations

import io
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest
import tifffile
from PIL import Image

from tests.paths import SHARED_DATA
from texsynth.synth.colour import LUMA_WEIGHTS
from texsynth.synth.errors import (
    InputTooLarge,
    InvalidInput,
    InvalidParameter,
    StorageError,
    UnsupportedFormat,
)
from texsynth.synth.io import (
    DEFAULT_MAX_PIXELS,
    MAX_ASPECT_RATIO,
    MIN_SIDE,
    atomic_write_json,
    image_to_png_bytes,
    load_image,
    load_volume,
    save_image,
    save_volume,
    to_uint,
)

DATA = SHARED_DATA
H, W = 24, 32  # small, but above MIN_SIDE and well within the aspect-ratio limit


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


def pil_bytes(image: Image.Image, fmt: str, **kwargs) -> bytes:
    buf = io.BytesIO()
    image.save(buf, format=fmt, **kwargs)
    return buf.getvalue()


def tiff_bytes(array: np.ndarray, **kwargs) -> bytes:
    buf = io.BytesIO()
    tifffile.imwrite(buf, array, **kwargs)
    return buf.getvalue()


def write(tmp_path: Path, name: str, data: bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


def assert_image(arr: np.ndarray, shape: tuple[int, ...]) -> None:
    assert arr.shape == shape
    assert arr.dtype == np.float32
    assert arr.flags.c_contiguous
    assert arr.min() >= 0.0 and arr.max() <= 1.0


# ---------------------------------------------------------------------------------------------
# round trips


@pytest.mark.parametrize("shape", [(H, W), (H, W, 3)], ids=["grey", "rgb"])
def test_png_8bit_round_trip_within_half_a_step(tmp_path, rng, shape):
    image = rng.random(shape, dtype=np.float32)
    save_image(tmp_path / "out.png", image)
    back = load_image(tmp_path / "out.png")
    assert_image(back, shape)
    assert np.max(np.abs(back - image)) <= 0.5 / 255 + 1e-6
    np.testing.assert_array_equal(back, to_uint(image, 8) / np.float32(255))


@pytest.mark.parametrize(
    ("suffix", "shape"),
    [(".png", (H, W)), (".tif", (H, W)), (".tiff", (H, W, 3))],
    ids=["png-grey", "tif-grey", "tiff-rgb"],
)
def test_16bit_round_trip_within_half_a_step(tmp_path, rng, suffix, shape):
    image = rng.random(shape, dtype=np.float32)
    path = tmp_path / f"out{suffix}"
    save_image(path, image, bit_depth=16)
    back = load_image(path)
    assert_image(back, shape)
    assert np.max(np.abs(back - image)) <= 0.5 / 65535 + 1e-7
    np.testing.assert_array_equal(to_uint(back, 16), to_uint(image, 16))


def test_16bit_file_holds_16bit_samples(tmp_path, rng):
    image = rng.random((H, W), dtype=np.float32)
    save_image(tmp_path / "a.png", image, bit_depth=16)
    save_image(tmp_path / "a.tif", image, bit_depth=16)
    with Image.open(tmp_path / "a.png") as im:
        assert im.mode == "I;16"
    assert tifffile.imread(tmp_path / "a.tif").dtype == np.uint16


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_float_tiff_in_unit_range_is_exact(tmp_path, rng, dtype):
    image = rng.random((H, W)).astype(dtype)
    back = load_image(write(tmp_path, "f.tif", tiff_bytes(image)))
    assert_image(back, (H, W))
    np.testing.assert_array_equal(back, image.astype(np.float32))


def test_float_tiff_outside_unit_range_is_rescaled_min_max(tmp_path, rng):
    counts = (rng.random((H, W)) * 5000 + 100).astype(np.float32)
    back = load_image(write(tmp_path, "counts.tif", tiff_bytes(counts)))
    expected = (counts.astype(np.float64) - counts.min()) / (counts.max() - counts.min())
    np.testing.assert_allclose(back, expected, atol=1e-6)
    assert back.min() == 0.0 and back.max() == 1.0


@pytest.mark.parametrize("value", [0.0, 7.5])
def test_constant_float_tiff_is_fine(tmp_path, value):
    back = load_image(write(tmp_path, "c.tif", tiff_bytes(np.full((H, W), value, np.float32))))
    assert_image(back, (H, W))
    np.testing.assert_array_equal(back, 0.0)


def test_signed_int_tiff_counts_are_rescaled(tmp_path):
    counts = np.arange(H * W, dtype=np.int16).reshape(H, W) - 100
    back = load_image(write(tmp_path, "s.tif", tiff_bytes(counts)))
    assert back[0, 0] == 0.0 and back[-1, -1] == 1.0


def test_uint16_tiff_scales_by_65535(tmp_path):
    raw = (np.arange(H * W, dtype=np.uint16) * 83).reshape(H, W)
    back = load_image(write(tmp_path, "u16.tif", tiff_bytes(raw)))
    np.testing.assert_array_equal(back, raw.astype(np.float32) / np.float32(65535))


def test_rgba_png_drops_alpha(tmp_path, rng):
    rgba = rng.integers(0, 256, (H, W, 4), dtype=np.uint8)
    back = load_image(write(tmp_path, "rgba.png", pil_bytes(Image.fromarray(rgba, "RGBA"), "PNG")))
    assert_image(back, (H, W, 3))
    np.testing.assert_array_equal(back, rgba[..., :3] / np.float32(255))


def test_rgba_tiff_drops_alpha(tmp_path, rng):
    rgba = rng.integers(0, 65536, (H, W, 4), dtype=np.uint16)
    back = load_image(
        write(tmp_path, "rgba.tif", tiff_bytes(rgba, photometric="rgb", extrasamples=["unassalpha"]))
    )
    np.testing.assert_array_equal(back, rgba[..., :3] / np.float32(65535))


def test_la_png_becomes_grey(tmp_path, rng):
    la = rng.integers(0, 256, (H, W, 2), dtype=np.uint8)
    back = load_image(write(tmp_path, "la.png", pil_bytes(Image.fromarray(la, "LA"), "PNG")))
    assert_image(back, (H, W))
    np.testing.assert_array_equal(back, la[..., 0] / np.float32(255))


def test_palette_png_is_expanded(tmp_path):
    indices = (np.arange(H * W) % 3).reshape(H, W).astype(np.uint8)
    im = Image.fromarray(indices, "P")
    im.putpalette([255, 0, 0, 0, 255, 0, 0, 0, 255])
    back = load_image(write(tmp_path, "p.png", pil_bytes(im, "PNG", transparency=0)))
    assert_image(back, (H, W, 3))
    np.testing.assert_array_equal(back[indices == 0], [[1, 0, 0]] * int((indices == 0).sum()))
    np.testing.assert_array_equal(back[indices == 2], [[0, 0, 1]] * int((indices == 2).sum()))


def test_palette_of_greys_is_grey_in_auto_mode(tmp_path):
    grey = (np.arange(H * W) % 256).reshape(H, W).astype(np.uint8)
    back = load_image(write(tmp_path, "pg.png", pil_bytes(Image.fromarray(grey).convert("P"), "PNG")))
    assert_image(back, (H, W))
    np.testing.assert_array_equal(back, grey / np.float32(255))


def test_palette_tiff_uses_the_colour_map(tmp_path):
    indices = (np.arange(H * W) % 2).reshape(H, W).astype(np.uint8)
    im = Image.fromarray(indices, "P")
    im.putpalette([255, 0, 0, 0, 0, 255])
    back = load_image(write(tmp_path, "p.tif", pil_bytes(im, "TIFF")))
    np.testing.assert_array_equal(back[0, 0], [1, 0, 0])
    np.testing.assert_array_equal(back[0, 1], [0, 0, 1])


def test_one_bit_png_gives_zeros_and_ones(tmp_path):
    bits = np.eye(H, W, dtype=bool)
    back = load_image(write(tmp_path, "b.png", pil_bytes(Image.fromarray(bits), "PNG")))
    np.testing.assert_array_equal(back, bits.astype(np.float32))


def test_min_is_white_tiff_is_inverted(tmp_path):
    raw = np.zeros((H, W), np.uint8)
    raw[0, 0] = 255
    back = load_image(write(tmp_path, "w.tif", tiff_bytes(raw, photometric="miniswhite")))
    assert back[0, 0] == 0.0 and back[1, 1] == 1.0


def test_planar_rgb_tiff(tmp_path, rng):
    rgb = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    data = tiff_bytes(np.moveaxis(rgb, -1, 0), photometric="rgb", planarconfig="separate")
    np.testing.assert_array_equal(load_image(data), rgb / np.float32(255))


def test_lzw_tiff_falls_back_to_pillow_exactly(tmp_path, rng):
    raw = rng.integers(0, 65536, (H, W), dtype=np.uint16)
    back = load_image(
        write(tmp_path, "lzw.tif", pil_bytes(Image.fromarray(raw), "TIFF", compression="tiff_lzw"))
    )
    np.testing.assert_array_equal(back, raw / np.float32(65535))


def test_cmyk_tiff_falls_back_to_pillow(tmp_path):
    cmyk = np.zeros((H, W, 4), np.uint8)
    cmyk[..., 0] = 255  # full cyan: red 0, green and blue 1
    back = load_image(write(tmp_path, "cmyk.tif", tiff_bytes(cmyk, photometric="separated")))
    assert_image(back, (H, W, 3))
    np.testing.assert_array_equal(back[0, 0], [0, 1, 1])


def test_identical_channels_become_grey_in_auto_mode(tmp_path, rng):
    grey = rng.integers(0, 256, (H, W), dtype=np.uint8)
    path = write(tmp_path, "g3.png", pil_bytes(Image.fromarray(np.dstack([grey] * 3)), "PNG"))
    back = load_image(path)
    assert_image(back, (H, W))
    np.testing.assert_array_equal(back, grey / np.float32(255))
    assert load_image(path, mode="rgb").shape == (H, W, 3)


def test_mode_grey_uses_bt601_luma(tmp_path):
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[:, : W // 2] = (255, 0, 0)
    rgb[:, W // 2 :] = (10, 200, 30)
    back = load_image(write(tmp_path, "c.png", pil_bytes(Image.fromarray(rgb), "PNG")), mode="grey")
    assert_image(back, (H, W))
    np.testing.assert_allclose(back[0, 0], LUMA_WEIGHTS[0], atol=1e-6)
    expected = np.dot(LUMA_WEIGHTS, [10, 200, 30]) / 255
    np.testing.assert_allclose(back[0, -1], expected, atol=1e-6)
    # Pillow's "L" is the same luma, rounded to 8 bits
    pillow_l = np.asarray(Image.fromarray(rgb).convert("L")) / 255
    assert np.max(np.abs(back - pillow_l)) <= 0.5 / 255 + 1e-6


def test_mode_rgb_repeats_grey(tmp_path, rng):
    grey = rng.random((H, W), dtype=np.float32)
    save_image(tmp_path / "g.png", grey)
    back = load_image(tmp_path / "g.png", mode="rgb")
    assert_image(back, (H, W, 3))
    assert np.array_equal(back[..., 0], back[..., 1]) and np.array_equal(back[..., 1], back[..., 2])


def test_mode_rgb_keeps_colour_and_auto_keeps_colour(tmp_path, rng):
    rgb = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    path = write(tmp_path, "c.png", pil_bytes(Image.fromarray(rgb), "PNG"))
    np.testing.assert_array_equal(load_image(path, mode="rgb"), load_image(path))


@pytest.mark.parametrize(("mode", "shape"), [("RGB", (H, W, 3)), ("L", (H, W)), ("CMYK", (H, W, 3))])
def test_jpeg_loads(tmp_path, mode, shape):
    yy, xx = np.mgrid[0:H, 0:W]
    ramp = (xx * 255 // (W - 1)).astype(np.uint8)
    rgb = np.dstack([ramp, (yy * 255 // (H - 1)).astype(np.uint8), 255 - ramp])
    im = Image.fromarray(rgb).convert(mode)
    back = load_image(write(tmp_path, "photo.jpg", pil_bytes(im, "JPEG", quality=95)))
    assert_image(back, shape)
    if mode == "RGB":
        assert np.mean(np.abs(back - rgb / 255)) < 0.03


def test_bytes_source_and_name(rng):
    image = rng.random((H, W), dtype=np.float32)
    np.testing.assert_array_equal(load_image(image_to_png_bytes(image)), to_uint(image) / np.float32(255))
    with pytest.raises(UnsupportedFormat, match=r"^image: "):
        load_image(b"hello")
    with pytest.raises(UnsupportedFormat, match=r"^exemplar: "):
        load_image(b"hello", name="exemplar")


@pytest.mark.skipif(
    not (DATA / "hrtem-soot-128.png").exists(),
    reason=f"shared test images not found in {DATA} (set TEXSYNTH_SHARED_DATA)",
)
def test_real_hrtem_exemplar_loads():
    image = load_image(DATA / "hrtem-soot-128.png")
    assert_image(image, (128, 128))
    assert image.std() > 0.01


# ---------------------------------------------------------------------------------------------
# bad inputs: each error names the file and the problem


def test_text_file_named_png_is_unsupported(tmp_path):
    path = write(tmp_path, "notes.png", b"these are my lab notes, not an image\n")
    with pytest.raises(UnsupportedFormat, match=r"notes\.png: not an image in a supported format"):
        load_image(path)


def test_truncated_png_is_invalid_input(tmp_path, rng):
    data = pil_bytes(Image.fromarray(rng.integers(0, 256, (64, 64), dtype=np.uint8)), "PNG")
    with pytest.raises(InvalidInput, match=r"cut\.png: corrupt or truncated PNG") as excinfo:
        load_image(write(tmp_path, "cut.png", data[: len(data) // 2]))
    assert excinfo.type is InvalidInput
    # cut inside the header: still "truncated PNG", not "unsupported format"
    with pytest.raises(InvalidInput, match=r"head\.png: corrupt or truncated PNG") as excinfo:
        load_image(write(tmp_path, "head.png", data[:20]))
    assert excinfo.type is InvalidInput


def test_truncated_jpeg_and_tiff_are_invalid_input(tmp_path, rng):
    noise = rng.integers(0, 256, (64, 64), dtype=np.uint8)
    jpeg = pil_bytes(Image.fromarray(noise), "JPEG")
    with pytest.raises(InvalidInput, match=r"cut\.jpg: corrupt or truncated JPEG"):
        load_image(write(tmp_path, "cut.jpg", jpeg[: len(jpeg) // 2]))
    tiff = tiff_bytes(noise.astype(np.float32) / 255)
    with pytest.raises(InvalidInput, match=r"cut\.tif: corrupt or truncated TIFF"):
        load_image(write(tmp_path, "cut.tif", tiff[: len(tiff) // 2]))


def test_empty_file(tmp_path):
    with pytest.raises(InvalidInput, match=r"empty\.png: empty file \(0 bytes\)"):
        load_image(write(tmp_path, "empty.png", b""))
    with pytest.raises(InvalidInput, match=r"upload: empty file"):
        load_image(b"", name="upload")


def test_zero_size_tiff(tmp_path):
    with warnings.catch_warnings():
        # tifffile warns "writing zero-size array to nonconformant TIFF": that is the point
        warnings.simplefilter("ignore", UserWarning)
        data = tiff_bytes(np.zeros((0, 10), np.uint8))
    with pytest.raises(InvalidInput, match=r"zero\.tif: the image has zero size"):
        load_image(write(tmp_path, "zero.tif", data))


def test_too_many_pixels_checked_from_header(tmp_path):
    path = write(tmp_path, "big.png", pil_bytes(Image.new("L", (64, 64)), "PNG"))
    with pytest.raises(InputTooLarge, match=r"big\.png: 64x64 = 4096 pixels is more than the limit of 4000"):
        load_image(path, max_pixels=4000)
    assert load_image(path, max_pixels=4096).shape == (64, 64)


def test_too_many_pixels_in_tiff(tmp_path):
    path = write(tmp_path, "big.tif", tiff_bytes(np.zeros((64, 64), np.float32)))
    with pytest.raises(InputTooLarge, match=r"big\.tif: 64x64 = 4096 pixels is more than the limit"):
        load_image(path, max_pixels=1000)


def test_max_pixels_from_environment(tmp_path, monkeypatch):
    path = write(tmp_path, "big.png", pil_bytes(Image.new("L", (64, 64)), "PNG"))
    monkeypatch.setenv("TEXSYNTH_MAX_PIXELS", "1000")
    with pytest.raises(InputTooLarge, match=r"big\.png: .*limit of 1000"):
        load_image(path)
    assert load_image(path, max_pixels=DEFAULT_MAX_PIXELS).shape == (64, 64)  # explicit beats env
    monkeypatch.setenv("TEXSYNTH_MAX_PIXELS", "lots")
    with pytest.raises(InvalidParameter, match="TEXSYNTH_MAX_PIXELS"):
        load_image(path)


@pytest.mark.parametrize("bad", [0, -5, 2.5, True])
def test_max_pixels_must_be_positive_integer(bad):
    with pytest.raises(InvalidParameter, match="max_pixels"):
        load_image(b"x", max_pixels=bad)


def test_decompression_bomb_warning_range_is_an_error(tmp_path, monkeypatch):
    path = write(tmp_path, "bomb.png", pil_bytes(Image.new("L", (64, 64)), "PNG"))
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 3000)  # 4096 is between 1x and 2x: Pillow only warns
    filters_before = list(warnings.filters)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the caller ignores warnings: load_image must still refuse
        with pytest.raises(InputTooLarge, match=r"bomb\.png: .*decompression bomb"):
            load_image(path)
    assert warnings.filters == filters_before  # no global change


def test_decompression_bomb_error_range(tmp_path, monkeypatch):
    path = write(tmp_path, "bomb.png", pil_bytes(Image.new("L", (64, 64)), "PNG"))
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 1000)  # above 2x: Pillow raises
    with pytest.raises(InputTooLarge, match=r"bomb\.png: .*decompression bomb"):
        load_image(path)


@pytest.mark.parametrize(("value", "word"), [(np.nan, "NaN"), (np.inf, "inf"), (-np.inf, "inf")])
def test_non_finite_float_tiff(tmp_path, rng, value, word):
    data = rng.random((H, W)).astype(np.float32)
    data[3, 4] = value
    with pytest.raises(InvalidInput, match=rf"hrtem\.tif: contains .*{word}"):
        load_image(write(tmp_path, "hrtem.tif", tiff_bytes(data)))


def test_absurd_aspect_ratio(tmp_path):
    width = MIN_SIDE * MAX_ASPECT_RATIO + 1
    path = write(tmp_path, "strip.png", pil_bytes(Image.new("L", (width, MIN_SIDE)), "PNG"))
    with pytest.raises(InvalidInput, match=rf"strip\.png: {width}x{MIN_SIDE} pixels is too elongated"):
        load_image(path)
    ok = write(tmp_path, "ok.png", pil_bytes(Image.new("L", (width - 1, MIN_SIDE)), "PNG"))
    assert load_image(ok).shape == (MIN_SIDE, width - 1)


def test_tiny_image(tmp_path):
    path = write(tmp_path, "tiny.png", pil_bytes(Image.new("RGB", (MIN_SIDE - 1, 32)), "PNG"))
    with pytest.raises(InvalidInput, match=rf"tiny\.png: {MIN_SIDE - 1}x32 pixels is too small"):
        load_image(path)


def test_missing_file(tmp_path):
    with pytest.raises(InvalidInput, match=r"nowhere\.png: no such file"):
        load_image(tmp_path / "nowhere.png")


def test_directory_is_not_an_image(tmp_path):
    with pytest.raises(InvalidInput, match="is a directory"):
        load_image(tmp_path)


@pytest.mark.parametrize("fmt", ["BMP", "GIF"])
def test_other_image_formats_are_unsupported(tmp_path, fmt):
    path = write(tmp_path, "pic.png", pil_bytes(Image.new("RGB", (32, 32)), fmt))  # extension lies
    with pytest.raises(UnsupportedFormat, match=rf"pic\.png: {fmt} images are not supported"):
        load_image(path)


def test_four_dimensional_tiff(tmp_path):
    path = write(tmp_path, "4d.tif", tiff_bytes(np.zeros((2, 3, 16, 16), np.uint8), photometric="minisblack"))
    with pytest.raises(InvalidInput, match=r"4d\.tif: has shape \(2, 3, 16, 16\).*2-D grey or RGB image"):
        load_image(path)


def test_stack_given_to_load_image(tmp_path):
    path = write(tmp_path, "stack.tif", tiff_bytes(np.zeros((5, 16, 16), np.uint8), photometric="minisblack"))
    with pytest.raises(InvalidInput, match=r"stack\.tif: .*use load_volume"):
        load_image(path)


def test_too_many_channels(tmp_path):
    data = tiff_bytes(np.zeros((16, 16, 5), np.uint8), photometric="minisblack", planarconfig="contig")
    with pytest.raises(InvalidInput, match=r"five\.tif: has 5 channels"):
        load_image(write(tmp_path, "five.tif", data))


def test_bad_mode_and_source_type():
    with pytest.raises(InvalidParameter, match="mode"):
        load_image(b"x", mode="gray")
    with pytest.raises(InvalidParameter, match="source"):
        load_image(42)


# ---------------------------------------------------------------------------------------------
# volumes


@pytest.mark.parametrize("bit_depth", [8, 16])
def test_volume_round_trip_and_imagej_metadata(tmp_path, rng, bit_depth):
    volume = rng.random((6, 16, 20), dtype=np.float32)
    path = tmp_path / "solid.tif"
    save_volume(path, volume, bit_depth=bit_depth)
    back = load_volume(path)
    assert back.shape == (6, 16, 20) and back.dtype == np.float32 and back.flags.c_contiguous
    assert np.max(np.abs(back - volume)) <= 0.5 / (2**bit_depth - 1) + 1e-6
    with tifffile.TiffFile(path) as tif:
        assert len(tif.pages) == 6
        assert tif.is_imagej
        assert tif.imagej_metadata["images"] == 6
        assert tif.imagej_metadata["slices"] == 6
        assert tif.pages[0].dtype == (np.uint8 if bit_depth == 8 else np.uint16)


def test_volume_with_three_columns_stays_grey(tmp_path):
    # tifffile's default would store a (D, H, 3) array as RGB; the saver must not
    volume = np.linspace(0, 1, 4 * 16 * 3, dtype=np.float32).reshape(4, 16, 3)
    save_volume(tmp_path / "thin.tif", volume)
    with tifffile.TiffFile(tmp_path / "thin.tif") as tif:
        assert len(tif.pages) == 4 and tif.series[0].shape == (4, 16, 3)


def test_float_volume_is_rescaled(tmp_path, rng):
    counts = (rng.random((4, 16, 16)) * 300 - 20).astype(np.float32)
    back = load_volume(tiff_bytes(counts, photometric="minisblack"))
    assert back.min() == 0.0 and back.max() == 1.0


def test_2d_file_given_to_load_volume(tmp_path, rng):
    path = tmp_path / "slice.tif"
    save_image(path, rng.random((H, W), dtype=np.float32), bit_depth=16)
    with pytest.raises(
        InvalidInput, match=rf"slice\.tif: a single 2-D image \({W}x{H} pixels\), not a volume"
    ):
        load_volume(path)


def test_load_volume_rejects_png_colour_and_too_many_voxels(tmp_path, rng):
    with pytest.raises(
        UnsupportedFormat, match=r"vol\.png: a PNG image: volumes are read from multi-page TIFF"
    ):
        load_volume(write(tmp_path, "vol.png", pil_bytes(Image.new("L", (16, 16)), "PNG")))
    colour = tiff_bytes(np.zeros((3, 16, 16, 3), np.uint8), photometric="rgb")
    with pytest.raises(InvalidInput, match=r"rgb\.tif: a colour stack"):
        load_volume(write(tmp_path, "rgb.tif", colour))
    with pytest.raises(InputTooLarge, match=r"big\.tif: 16x16x4 = 1024 voxels"):
        big = tiff_bytes(np.zeros((4, 16, 16), np.uint8), photometric="minisblack")
        load_volume(write(tmp_path, "big.tif", big), max_voxels=1000)
    with pytest.raises(InvalidInput, match=r"nowhere\.tif: no such file"):
        load_volume(tmp_path / "nowhere.tif")


def test_save_volume_rejects_bad_shape_and_extension(tmp_path):
    with pytest.raises(InvalidParameter, match="volume"):
        save_volume(tmp_path / "v.tif", np.zeros((16, 16)))
    with pytest.raises(InvalidParameter, match="path"):
        save_volume(tmp_path / "v.png", np.zeros((2, 16, 16)))


# ---------------------------------------------------------------------------------------------
# saving


def test_to_uint_rounds_and_clips():
    values = np.array([-0.3, 0.4 / 255, 0.6 / 255, 0.5, 254.4 / 255, 1.0, 7.0])
    np.testing.assert_array_equal(to_uint(values, 8), [0, 0, 1, 128, 254, 255, 255])
    assert to_uint(values, 16).dtype == np.uint16
    assert to_uint(np.array([0.6 / 65535]), 16)[0] == 1


@pytest.mark.parametrize("bit_depth", [1, 12, 32, True])
def test_bit_depth_must_be_8_or_16(tmp_path, bit_depth):
    with pytest.raises(InvalidParameter, match="bit_depth"):
        save_image(tmp_path / "x.png", np.zeros((H, W)), bit_depth=bit_depth)
    with pytest.raises(InvalidParameter, match="bit_depth"):
        to_uint(np.zeros(3), bit_depth)


def test_16bit_rgb_png_is_refused_with_advice(tmp_path):
    with pytest.raises(InvalidParameter, match=r"bit_depth.*\.tif"):
        save_image(tmp_path / "x.png", np.zeros((H, W, 3)), bit_depth=16)


def test_save_rejects_bad_images_and_extensions(tmp_path):
    with pytest.raises(InvalidParameter, match="extension"):
        save_image(tmp_path / "x.jpg", np.zeros((H, W)))
    with pytest.raises(InvalidParameter, match="image"):
        save_image(tmp_path / "x.png", np.zeros((H, W, 4)))
    with pytest.raises(InvalidParameter, match="finite"):
        save_image(tmp_path / "x.png", np.full((H, W), np.nan))
    assert list(tmp_path.iterdir()) == []


def test_save_is_atomic_and_overwrites(tmp_path, rng):
    path = tmp_path / "out.png"
    save_image(path, np.zeros((H, W)))
    image = rng.random((H, W), dtype=np.float32)
    save_image(path, image)
    assert [p.name for p in tmp_path.iterdir()] == ["out.png"]  # no temporary file left behind
    np.testing.assert_array_equal(to_uint(load_image(path), 8), to_uint(image, 8))


def test_save_into_missing_directory_is_a_storage_error_without_the_folders(tmp_path):
    with pytest.raises(StorageError, match=r"^cannot write dir\.png: No such file or directory$") as info:
        save_image(tmp_path / "no" / "such" / "dir.png", np.zeros((H, W)))
    assert str(tmp_path) not in str(info.value)
    assert not isinstance(info.value, ValueError)  # the machine's fault: not an input error (4xx)


def test_failed_write_leaves_no_temporary_file_and_keeps_the_old_one(tmp_path, monkeypatch):
    path = tmp_path / "out.json"
    atomic_write_json(path, {"a": 1})

    def full_disk(fd: int) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("texsynth.synth.io.atomic.os.fsync", full_disk)
    with pytest.raises(StorageError, match=r"cannot write out\.json: No space left on device"):
        atomic_write_json(path, {"a": 2})
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]
    assert path.read_text() == '{\n  "a": 1\n}\n'


def test_save_accepts_trailing_single_channel(tmp_path, rng):
    image = rng.random((H, W, 1), dtype=np.float32)
    save_image(tmp_path / "g.png", image)
    assert load_image(tmp_path / "g.png").shape == (H, W)


def test_png_bytes_are_deterministic_png(rng):
    image = rng.random((H, W, 3), dtype=np.float32)
    data = image_to_png_bytes(image)
    assert data.startswith(b"\x89PNG\r\n\x1a\n")
    assert data == image_to_png_bytes(image.copy())
    grey16 = image_to_png_bytes(image[..., 0], bit_depth=16)
    with Image.open(io.BytesIO(grey16)) as im:
        assert im.mode == "I;16" and im.size == (W, H)


def test_a_png_declaring_zero_pixels_is_an_invalid_input_not_an_unknown_format():
    def chunk(kind: bytes, payload: bytes) -> bytes:
        crc = struct.pack(">I", zlib.crc32(kind + payload))
        return struct.pack(">I", len(payload)) + kind + payload + crc

    header = struct.pack(">IIBBBBB", 0, 16, 8, 0, 0, 0, 0)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IEND", b"")
    with pytest.raises(InvalidInput, match=r"^upload: the image has zero size \(0x16 pixels\)$") as info:
        load_image(png, name="upload")
    assert not isinstance(info.value, UnsupportedFormat)
