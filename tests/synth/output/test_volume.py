"""Volume pictures (texsynth.synth.output.volume) and the artifacts of a volume result
(texsynth.synth.output.artifacts)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile

from texsynth.synth.api import Result
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.io.patterns import gaussian_random_field
from texsynth.synth.output.volume import cube_image, mid_slices, slices_image, write_volume_images


def test_mid_slices_follow_the_plane_convention():
    vol = np.arange(4 * 5 * 6, dtype=np.float64).reshape(4, 5, 6)  # (z, y, x)
    s = mid_slices(vol)
    np.testing.assert_array_equal(s["xy"], vol[2])  # rows y, columns x
    np.testing.assert_array_equal(s["xz"], vol[:, 2])  # rows z, columns x
    np.testing.assert_array_equal(s["yz"], vol[:, :, 3])  # rows z, columns y
    assert mid_slices(vol, (0, 4, 5))["yz"].tolist() == vol[:, :, 5].tolist()


def _count(img: np.ndarray, value: int) -> int:
    return int(np.all(img == value, axis=2).sum())


@pytest.mark.parametrize("scale", [1, 3])
def test_slices_image_shows_every_slice_and_exemplar_at_one_scale(scale):
    d, h, w = 10, 14, 18
    vol = np.full((d, h, w), 0.4)
    exemplars = {"xy": np.full((20, 24), 0.8), "xz": np.full((12, 24), 0.8), "yz": np.full((12, 20), 0.8)}
    img = slices_image(vol, exemplars, scale=scale)
    assert img.dtype == np.uint8 and img.shape[2] == 3
    slice_area = scale**2 * (h * w + d * w + d * h)
    exemplar_area = scale**2 * sum(e.size for e in exemplars.values())
    # antialiased captions may add a few pixels of the same grey, never fewer pixels
    assert slice_area <= _count(img, 102) <= 1.03 * slice_area  # round(0.4 * 255)
    assert exemplar_area <= _count(img, 204) <= 1.03 * exemplar_area  # 0.8
    # no exemplars: the top row only
    alone = slices_image(vol, scale=scale)
    assert alone.shape[0] < img.shape[0] and _count(alone, 204) < 0.03 * exemplar_area


def test_cube_image_faces_are_shaded_by_direction():
    d, h, w = 12, 16, 20
    img = cube_image(np.full((d, h, w), 0.5), views=("outside",))
    grey = 0.12 + 0.88 * 0.5  # the lifted floor keeps black visible
    top, front, right = (round(255 * grey * shade) for shade in (1.0, 0.82, 0.64))
    counts = {name: _count(img, v) for name, v in (("top", top), ("front", front), ("right", right))}
    assert min(counts.values()) > 0
    # the front face keeps its true size: x by z at the common scale
    scale = 340 / max(w + 0.5 * np.cos(np.radians(35)) * h, d + 0.5 * np.sin(np.radians(35)) * h)
    assert counts["front"] == pytest.approx(scale**2 * d * w, rel=0.08)
    assert counts["top"] > counts["right"]  # the receding faces are halved in depth
    cut = cube_image(np.full((d, h, w), 0.5), views=("cut",))
    orange = int(np.all(cut == (230, 120, 20), axis=2).sum())
    assert orange > 0 and int(np.all(img == (230, 120, 20), axis=2).sum()) == 0
    both = cube_image(np.full((d, h, w), 0.5))
    assert both.shape[1] > 1.8 * img.shape[1] - 40


def test_write_volume_images_names_and_pngs(tmp_path):
    vol = gaussian_random_field((12, 16, 20), (1.5, 3.0, 5.0), 0.4, seed=1)
    names = write_volume_images(tmp_path, vol, vol[6])
    assert names == [
        "slices.png",
        "cube.png",
        *(f"{kind}_{plane}.png" for plane in ("xy", "xz", "yz") for kind in ("coherence", "orientation")),
    ]
    for name in names:
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_inputs_name_the_argument():
    vol = np.zeros((8, 8, 8))
    with pytest.raises(InvalidInput, match=r"volume: expected a grey \(D, H, W\) volume"):
        slices_image(np.zeros((8, 8)))
    with pytest.raises(InvalidInput, match="volume: holds NaN"):
        cube_image(np.full((8, 8, 8), np.nan))
    with pytest.raises(InvalidParameter, match=r"'index' = \(8, 0, 0\): must be \(z, y, x\) inside"):
        slices_image(vol, index=(8, 0, 0))
    with pytest.raises(InvalidParameter, match="'scale' = 0"):
        slices_image(vol, scale=0)
    with pytest.raises(InvalidInput, match="exemplar_yz: missing"):
        slices_image(vol, {"xy": vol[0], "xz": vol[0]})
    with pytest.raises(InvalidInput, match="exemplar_zz: unknown plane"):
        slices_image(vol, {"xy": vol[0], "xz": vol[0], "yz": vol[0], "zz": vol[0]})
    with pytest.raises(InvalidParameter, match="'views'"):
        cube_image(vol, views=("inside",))


def test_write_artifacts_of_a_volume(tmp_path, monkeypatch):
    from texsynth.synth.output import artifacts

    # the 2-D comparison charts are tested with write_plots itself: here only that they are asked for
    # with the per-plane exemplars, beside the real s2.png
    calls = []
    monkeypatch.setattr(artifacts, "write_plots", lambda ex, out, m, folder, **_: calls.append(ex) or [])

    vol = gaussian_random_field((16, 20, 24), (1.5, 3.0, 5.0), 0.4, seed=2)
    planes = {
        "xy": gaussian_random_field((32, 32), (3.0, 5.0), 0.4, seed=3),
        "xz": gaussian_random_field((32, 32), (1.5, 5.0), 0.4, seed=4),
        "yz": gaussian_random_field((32, 32), (1.5, 3.0), 0.4, seed=5),
    }
    result = Result(method="test", image=vol, params={}, seed=0, timings={"total": 1.0})
    names, metrics = artifacts.write_artifacts(
        tmp_path, result, planes["xy"], exemplars=planes, voxel_size=(2.0, 0.5, 0.5), unit="nm"
    )
    for name in (
        "output.png",
        "output.tiff",
        "slices.png",
        "cube.png",
        "coherence_xz.png",
        "orientation_yz.png",
        "metrics.json",
        "manifest.json",
        "plots/s2.png",
    ):
        assert name in names and (tmp_path / name).exists(), name
    assert calls == [planes]
    assert metrics["isotropic"] is False and metrics["s2"]["axes"]["z"].keys() == {"xz", "yz"}
    assert json.loads((tmp_path / "metrics.json").read_text())["metrics"] == metrics
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["voxel_size"] == [2.0, 0.5, 0.5] and manifest["exemplar_shapes"]["xz"] == [32, 32]
    with tifffile.TiffFile(tmp_path / "output.tiff") as tif:
        assert len(tif.pages) == 16 and tif.imagej_metadata["spacing"] == 2.0
        assert tif.pages[0].resolution == pytest.approx((2.0, 2.0))
    # not cubic: fringe lengths stay in pixels
    assert metrics["settings"]["pixel_size_nm"] is None
