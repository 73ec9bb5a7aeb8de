"""Arrays and files in the dtypes people have (issue 29): uint8, uint16, bool and 12-bit-in-16 data give
the outputs and metrics of the same picture as float in [0, 1]; floats outside [0, 1] are a clear error."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from PIL import Image

from texsynth.synth.api import synthesize
from texsynth.synth.errors import InvalidInput
from texsynth.synth.evaluate import evaluate_pair
from texsynth.synth.io import InputBits, array_to_unit, load_image_bits, to_uint, used_bits
from texsynth.synth.pipeline import load_inputs, synthesize_to_folder

METHOD = "random-phase"
SHAPE = (32, 40)


def _picture() -> np.ndarray:
    """Fringes with noise, values in [0, 1] (float64)."""
    y, x = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    rng = np.random.default_rng(7)
    image = 0.5 + 0.35 * np.sin(2 * np.pi * (0.8 * x + 0.6 * y) / 7) + 0.1 * rng.standard_normal(SHAPE)
    return np.clip(image, 0, 1)


def _as(kind: str) -> tuple[np.ndarray, np.ndarray, InputBits]:
    """The picture as ``kind`` and as the float32 in [0, 1] it stands for, and its depth."""
    picture = _picture()
    if kind == "uint8":
        raw = np.rint(picture * 255).astype(np.uint8)
        return raw, raw.astype(np.float32) / np.float32(255), InputBits(8, 8)
    if kind == "uint16":
        raw = np.rint(picture * 65535).astype(np.uint16)
        return raw, raw.astype(np.float32) / np.float32(65535), InputBits(16, 16)
    if kind == "12-in-16":
        raw = np.rint(picture * 4095).astype(np.uint16)
        assert raw.max() == 4095
        return raw, raw.astype(np.float32) / np.float32(4095), InputBits(16, 12)
    if kind == "bool":
        raw = picture > 0.5
        return raw, raw.astype(np.float32), InputBits(1, 1)
    if kind == "rgb-uint8":
        raw = np.rint(np.stack([picture, picture[::-1], 1 - picture], axis=-1) * 255).astype(np.uint8)
        return raw, raw.astype(np.float32) / np.float32(255), InputBits(8, 8)
    raise AssertionError(kind)


KINDS = ["uint8", "uint16", "12-in-16", "bool", "rgb-uint8"]


@pytest.mark.parametrize("kind", KINDS)
def test_arrays_give_the_output_and_metrics_of_the_same_picture_as_float(kind):
    raw, unit, depth = _as(kind)
    from_raw = synthesize(METHOD, raw, size=(48, 48), seed=5)
    from_float = synthesize(METHOD, unit, size=(48, 48), seed=5)
    assert from_raw.image.tobytes() == from_float.image.tobytes()
    assert from_raw.input_bits == depth
    assert from_float.input_bits == InputBits(32, 32)
    if raw.ndim == 2 or kind == "rgb-uint8":
        m_raw = evaluate_pair(raw, from_raw.image, fringes=False)
        m_float = evaluate_pair(unit, from_float.image, fringes=False)
        assert m_raw == m_float
        if kind != "bool":  # random-phase does not keep a binary histogram
            assert m_raw["grey"]["kl"] < 0.5  # the picture, not an all-white one


def test_an_8_bit_array_is_no_longer_white():
    raw, _, _ = _as("uint8")
    out = synthesize(METHOD, raw, size=(48, 48), seed=5).image
    assert 0.3 < float(out.mean()) < 0.7 and float(out.min()) < 0.2


@pytest.mark.parametrize(
    ("values", "hint"),
    [
        (np.linspace(0, 255, 32 * 40, dtype=np.float32), "divide by 255"),
        (np.linspace(0, 4000, 32 * 40), "divide by 65535"),
        (np.linspace(-1, 1, 32 * 40), r"\(a - a.min\(\)\) / \(a.max\(\) - a.min\(\)\)"),
    ],
)
def test_floats_outside_0_1_are_an_error_that_says_how_to_scale(values, hint):
    image = values.reshape(SHAPE)
    with pytest.raises(InvalidInput, match=rf"^exemplar: float values span .*outside \[0, 1\].*{hint}"):
        synthesize(METHOD, image, size=(48, 48))
    good = _picture()
    scale = r"^output: values must lie in \[0, 1\].*scale float data first, e.g. a / 255"
    with pytest.raises(InvalidInput, match=scale):
        evaluate_pair(good, np.abs(image) + 1.5, fringes=False)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_and_inf_are_errors(bad):
    image = _picture().astype(np.float32)
    image[3, 4] = bad
    with pytest.raises(InvalidInput, match=r"^exemplar: contains (NaN|infinite)"):
        synthesize(METHOD, image, size=(48, 48))
    with pytest.raises(InvalidInput, match=r"^constraint: contains"):
        array_to_unit(image, "constraint")


def test_signed_integer_arrays_are_refused_with_what_to_give():
    with pytest.raises(InvalidInput, match=r"^exemplar: int64 array: give uint8/uint16"):
        synthesize(METHOD, np.zeros(SHAPE, np.int64), size=(48, 48))


def test_used_bits_of_a_16_bit_container():
    assert used_bits(np.array([0, 4095], np.uint16), 16) == 12
    assert used_bits(np.array([0, 4096], np.uint16), 16) == 14
    assert used_bits(np.array([0, 1023], np.uint16), 16) == 10
    assert used_bits(np.array([0, 255], np.uint16), 16) == 8
    assert used_bits(np.array([0, 65535], np.uint16), 16) == 16
    assert used_bits(np.array([0, 3], np.uint8), 8) == 8  # a dark 8-bit image stays 8-bit


def _write(kind: str, raw: np.ndarray, folder) -> object:
    if kind == "bool":
        path = folder / "in.png"
        Image.fromarray(raw).save(path)  # a 1-bit PNG
    elif kind in ("uint8", "rgb-uint8"):
        path = folder / "in.png"
        Image.fromarray(raw).save(path)
    else:
        path = folder / "in.tiff"
        tifffile.imwrite(path, raw, photometric="minisblack")
    return path


@pytest.mark.parametrize("kind", KINDS)
def test_files_give_the_outputs_and_metrics_of_the_same_picture_as_float(kind, tmp_path):
    raw, unit, depth = _as(kind)
    path = _write(kind, raw, tmp_path)
    image, file_depth = load_image_bits(path)
    np.testing.assert_array_equal(image, unit)
    assert file_depth == depth

    from_file = synthesize_to_folder(
        METHOD, load_inputs({"exemplar": path}), tmp_path / "file", size=(48, 48), seed=2, plots=False
    )
    from_float = synthesize_to_folder(
        METHOD, {"exemplar": unit}, tmp_path / "float", size=(48, 48), seed=2, plots=False
    )
    assert from_file.result.image.tobytes() == from_float.result.image.tobytes()
    doc_file = json.loads((tmp_path / "file" / "metrics.json").read_text())
    doc_float = json.loads((tmp_path / "float" / "metrics.json").read_text())
    assert doc_file["metrics"] == doc_float["metrics"]
    assert doc_file["input_bits"] == depth.as_json()
    assert "input_bits" not in doc_float

    # the outputs keep the input's depth: 12-bit data come back as 12-bit data in 16 bits
    tiff = tifffile.imread(tmp_path / "file" / "output.tiff")
    png = np.asarray(Image.open(tmp_path / "file" / "output.png"))
    out = from_file.result.image
    assert tiff.dtype == np.uint16
    if kind == "12-in-16":
        assert tiff.max() <= 4095 and tiff.max() > 2048
        np.testing.assert_array_equal(tiff, to_uint(out, 16, used_bits=12))
        np.testing.assert_array_equal(png, to_uint(out, 16))  # the picture to look at: full scale
    elif kind == "uint16":
        np.testing.assert_array_equal(tiff, to_uint(out, 16))
        np.testing.assert_array_equal(png, to_uint(out, 16))
    else:
        np.testing.assert_array_equal(tiff, to_uint(out, 16))
        np.testing.assert_array_equal(png, to_uint(out, 8))


def test_arrays_written_to_a_folder_keep_their_depth(tmp_path):
    raw, unit, _ = _as("12-in-16")
    from_raw = synthesize_to_folder(
        METHOD, {"exemplar": raw}, tmp_path / "raw", size=(48, 48), seed=2, plots=True
    )
    from_float = synthesize_to_folder(
        METHOD, {"exemplar": unit}, tmp_path / "f", size=(48, 48), seed=2, plots=False
    )
    doc = json.loads((tmp_path / "raw" / "metrics.json").read_text())
    assert doc["input_bits"] == {"container": 16, "used": 12}
    assert from_raw.metrics == from_float.metrics
    tiff = tifffile.imread(tmp_path / "raw" / "output.tiff")
    np.testing.assert_array_equal(tiff, to_uint(from_raw.result.image, 16, used_bits=12))
    assert (tmp_path / "raw" / "plots").is_dir()
