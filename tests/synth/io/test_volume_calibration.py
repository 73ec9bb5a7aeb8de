"""save_volume's ImageJ calibration (voxel size) read back with tifffile, and its bad inputs."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile

from texsynth.synth.errors import InvalidParameter
from texsynth.synth.io import load_volume, save_volume


@pytest.mark.parametrize("bit_depth", [8, 16])
def test_voxel_size_round_trips_as_imagej_calibration(tmp_path, bit_depth):
    volume = np.random.default_rng(0).random((5, 12, 16), dtype=np.float32)
    path = tmp_path / "cal.tif"
    save_volume(path, volume, bit_depth=bit_depth, voxel_size=(2.0, 0.25, 0.5), unit="nm")
    with tifffile.TiffFile(path) as tif:
        meta = tif.imagej_metadata
        page = tif.pages[0]
        assert len(tif.pages) == 5 and tif.series[0].axes == "ZYX"
        assert page.dtype == (np.uint8 if bit_depth == 8 else np.uint16)
        assert meta["spacing"] == 2.0 and meta["unit"] == "nm" and meta["slices"] == 5
        x_res, y_res = page.resolution  # pixels per unit
        assert x_res == pytest.approx(1 / 0.5) and y_res == pytest.approx(1 / 0.25)
    back = load_volume(path)
    assert np.max(np.abs(back - volume)) <= 0.5 / (2**bit_depth - 1) + 1e-6


def test_one_voxel_size_is_cubic_and_none_writes_no_calibration(tmp_path):
    volume = np.zeros((3, 8, 8), np.float32)
    save_volume(tmp_path / "cubic.tif", volume, voxel_size=0.0556, unit="um")
    with tifffile.TiffFile(tmp_path / "cubic.tif") as tif:
        assert tif.imagej_metadata["spacing"] == pytest.approx(0.0556)
        assert tif.imagej_metadata["unit"] == "um"
        assert tif.pages[0].resolution == pytest.approx((1 / 0.0556, 1 / 0.0556))
    save_volume(tmp_path / "plain.tif", volume)
    with tifffile.TiffFile(tmp_path / "plain.tif") as tif:
        assert "spacing" not in tif.imagej_metadata and "unit" not in tif.imagej_metadata


@pytest.mark.parametrize("voxel_size", [0.0, -1.0, (1.0, 2.0), (1.0, float("nan"), 1.0), "big", ((1, 2, 3),)])
def test_bad_voxel_sizes_are_refused(tmp_path, voxel_size):
    with pytest.raises(
        InvalidParameter, match=r"'voxel_size' = .*: must be one positive size or three, \(z, y, x\)"
    ):
        save_volume(tmp_path / "v.tif", np.zeros((2, 8, 8)), voxel_size=voxel_size)
    assert not (tmp_path / "v.tif").exists()


@pytest.mark.parametrize("unit", ["", "n\nm", "a=b"])
def test_bad_units_are_refused(tmp_path, unit):
    with pytest.raises(InvalidParameter, match=r"'unit' = .*: must be a non-empty length unit"):
        save_volume(tmp_path / "v.tif", np.zeros((2, 8, 8)), voxel_size=1.0, unit=unit)
