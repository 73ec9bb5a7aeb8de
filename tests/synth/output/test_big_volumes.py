"""Big outputs after the synthesis (issue 25): no whole-volume float64 copy in the writer, the volume's
pictures or its evaluation, the TIFF stack written page by page with the same bytes, and progress."""

from __future__ import annotations

import io
import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import tifffile

from texsynth.synth.errors import InvalidParameter
from texsynth.synth.evaluate import correlation, measures
from texsynth.synth.evaluate.measures import evaluate_volume, moments
from texsynth.synth.io import save_volume
from texsynth.synth.io.images import to_uint
from texsynth.synth.output.volume import write_volume_images


def _volume(shape: tuple[int, int, int], seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.random(shape, dtype=np.float32) ** 2).astype(np.float32)


def _peak(fn: Callable[[], Any]) -> int:
    """Peak bytes numpy and Python allocate while ``fn`` runs (numpy reports to tracemalloc)."""
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def _in_memory_moments(values: np.ndarray) -> dict[str, float | None]:
    flat = np.asarray(values, dtype=np.float64).ravel()
    skew, kurt = measures._skew_kurtosis(flat)
    return {"mean": float(flat.mean()), "std": float(flat.std()), "skewness": skew, "kurtosis": kurt}


@pytest.mark.parametrize("n", [999, 1000, 1001, 5003, 65536, 123457])
def test_streamed_moments_have_the_bits_of_one_float64_copy(monkeypatch, n):
    monkeypatch.setattr(measures, "MOMENT_CHUNK", 1000)
    values = np.random.default_rng(n).random(n, dtype=np.float32) ** 3
    assert moments(values) == _in_memory_moments(values)


def test_streamed_moments_of_pooled_slices_have_the_bits_of_their_concatenation(monkeypatch):
    monkeypatch.setattr(measures, "MOMENT_CHUNK", 777)
    vol = _volume((23, 29, 31))
    for axis in (0, 1, 2):
        slices = list(np.moveaxis(vol, axis, 0)[::2])  # strided views, as evaluate_volume pools them
        assert moments(slices) == _in_memory_moments(np.concatenate([s.ravel() for s in slices]))
    constant = np.full((40, 40), 0.25, dtype=np.float32)
    assert moments(constant)["skewness"] is None and moments(constant) == moments(constant.astype(np.float64))


@pytest.mark.parametrize(
    ("voxel_size", "used_bits", "bit_depth"), [(None, None, 16), (0.055, 12, 16), (None, None, 8)]
)
def test_volume_stack_is_written_page_by_page_with_the_bytes_of_one_write(
    tmp_path, voxel_size, used_bits, bit_depth
):
    vol = _volume((9, 17, 3)) * 1.2 - 0.1  # a last axis of 3 must stay a grey stack, values clipped
    seen: list[tuple[str, float]] = []
    save_volume(
        tmp_path / "v.tiff",
        vol,
        bit_depth=bit_depth,
        voxel_size=voxel_size,
        used_bits=used_bits,
        progress=lambda stage, f: seen.append((stage, f)),
    )
    metadata: dict[str, Any] = {"axes": "ZYX"}
    options: dict[str, Any] = {}
    if voxel_size is not None:
        metadata.update(spacing=voxel_size, unit="nm")
        options["resolution"] = (1 / voxel_size, 1 / voxel_size)
    whole = io.BytesIO()
    quantised = to_uint(vol, bit_depth, used_bits=used_bits)
    tifffile.imwrite(whole, quantised, imagej=True, photometric="minisblack", metadata=metadata, **options)
    assert (tmp_path / "v.tiff").read_bytes() == whole.getvalue()
    assert seen[-1] == ("writing output.tiff", 1.0)


def test_a_bad_slice_leaves_no_file(tmp_path):
    vol = _volume((6, 10, 10))
    vol[4, 2, 3] = np.nan
    with pytest.raises(InvalidParameter, match="NaN"):
        save_volume(tmp_path / "v.tiff", vol)
    assert list(tmp_path.iterdir()) == []


def test_writer_pictures_and_evaluation_make_no_float64_copy_of_the_volume(tmp_path, monkeypatch):
    # pieces far smaller than the volume, as they are at 512^3 (1M values, 4M samples for S2)
    monkeypatch.setattr(measures, "MOMENT_CHUNK", 1 << 16)
    monkeypatch.setattr(correlation, "_CHUNK_SAMPLES", 1 << 16)
    exemplar = np.random.default_rng(1).random((64, 64))
    small = _volume((16, 16, 16))
    save_volume(tmp_path / "warm.tiff", small)  # first calls load fonts and caches: not measured
    write_volume_images(tmp_path, small, exemplar)
    evaluate_volume(exemplar, small, fringes=False)
    vol = _volume((160, 176, 192))
    half_of_float64 = vol.size * 8 // 2
    assert _peak(lambda: save_volume(tmp_path / "v.tiff", vol)) < vol.nbytes // 16
    assert _peak(lambda: write_volume_images(tmp_path, vol, exemplar)) < half_of_float64
    assert _peak(lambda: evaluate_volume(exemplar, vol, fringes=False)) < half_of_float64


def test_volume_evaluation_reports_its_slices():
    vol = _volume((16, 20, 24))
    seen: list[tuple[str, float]] = []
    evaluate_volume(
        np.random.default_rng(2).random((32, 32)),
        vol,
        fringes=False,
        progress=lambda stage, f: seen.append((stage, f)),
    )
    fractions = [f for _, f in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0 and len(fractions) >= 3
