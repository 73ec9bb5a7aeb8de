"""evaluate_volume with per-plane exemplars and two-point correlations; texsynth evaluate on volumes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from texsynth.synth.cli import main
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.evaluate import PLANES, evaluate_volume, image_s2, volume_s2
from texsynth.synth.io import save_image, save_volume
from texsynth.synth.io.patterns import gaussian_random_field

LENGTHS = (2.0, 4.0, 8.0)  # along z, y, x


@pytest.fixture(scope="module")
def grf() -> np.ndarray:
    return gaussian_random_field((24, 32, 48), LENGTHS, 0.4, seed=3)


@pytest.fixture(scope="module")
def planes() -> dict[str, np.ndarray]:
    """Per-plane exemplars: 2-D fields with the medium's correlation lengths along their rows and columns.

    The correlation along one axis of a level-cut field is ``exp(-(r / l)^2)`` whatever the other
    axes: a 2-D field with the plane's two lengths has the volume's S2 along both.
    """
    z, y, x = LENGTHS
    return {
        "xy": gaussian_random_field((64, 64), (y, x), 0.4, seed=11),
        "xz": gaussian_random_field((64, 64), (z, x), 0.4, seed=12),
        "yz": gaussian_random_field((64, 64), (z, y), 0.4, seed=13),
    }


def test_planes_match_the_api():
    from texsynth.synth.api import PLANES as API_PLANES

    assert PLANES == API_PLANES


def test_per_plane_exemplars_are_compared_plane_by_plane(grf, planes):
    m = evaluate_volume(planes, grf, fringes=False)
    assert m["isotropic"] is False
    assert m["shape"]["exemplars"] == {"xy": [64, 64], "xz": [64, 64], "yz": [64, 64]}
    assert [m["axes"][k]["plane"] for k in ("0", "1", "2")] == ["xy", "xz", "yz"]
    # the S2 curves in the metrics are the module's own, along the same physical axis
    t = m["s2"]["thresholds"]["xz"]
    comp = m["s2"]["axes"]["z"]["xz"]
    assert comp["exemplar_direction"] == "row"
    np.testing.assert_array_equal(comp["s2"]["exemplar"], image_s2(planes["xz"], threshold=t)["row"])
    np.testing.assert_array_equal(comp["s2"]["volume"], volume_s2(grf, threshold=t)["z"])
    assert m["s2"]["axes"]["x"].keys() == {"xy", "xz"}
    assert m["s2"]["axes"]["y"].keys() == {"xy", "yz"}
    assert m["s2"]["axes"]["z"].keys() == {"xz", "yz"}
    assert m["axes"]["1"]["s2"].keys() == {"x", "z"}
    # the same medium: every axis's correlation length matches its exemplars', S2 errors are small
    for axis, comps in m["s2"]["axes"].items():
        for c in comps.values():
            # (one 64 px slice of a medium correlated over 8 px is a small sample)
            assert abs(c["correlation_length"]["exemplar"] - c["correlation_length"]["output"]) <= 2, axis
            assert c["relative_error"] < 0.15
    assert m["summary"]["s2_relative_error"] < 0.1
    assert m["summary"]["per_axis"]["0"]["s2_relative_error"] == pytest.approx(
        np.mean([m["axes"]["0"]["s2"][a]["relative_error"] for a in ("x", "y")])
    )


def test_one_exemplar_for_an_anisotropic_volume_shows_in_s2(grf, planes):
    per_plane = evaluate_volume(planes, grf, fringes=False)
    one = evaluate_volume(planes["xy"], grf, fringes=False)  # y-x statistics asked of every plane
    assert one["isotropic"] is True
    # z (length 2) is compared with the xy exemplar's rows (length 4): the error doubles at least
    assert one["s2"]["summary"]["z"] > 2 * per_plane["s2"]["summary"]["z"]
    # x (8) is compared with the xy exemplar's columns either way: the same curve and error
    assert one["s2"]["axes"]["x"]["xy"] == per_plane["s2"]["axes"]["x"]["xy"]


def test_the_same_exemplar_thrice_is_one_exemplar(grf, planes):
    ex = planes["xy"]
    single = evaluate_volume(ex, grf, fringes=False)
    thrice = evaluate_volume({p: ex.copy() for p in PLANES}, grf, fringes=False)
    assert thrice["isotropic"] is True
    assert thrice["overall"] == single["overall"] and thrice["s2"] == single["s2"]


def test_s2_options_and_settings(grf, planes):
    m = evaluate_volume(planes, grf, fringes=False, threshold=0.5, s2_periodic=True, axes=(1,))
    assert m["s2"]["thresholds"] == {"xz": 0.5}
    assert m["s2"]["axes"].keys() == {"x", "z"}
    assert m["settings"]["s2"]["periodic"] is True and m["settings"]["s2"]["threshold"] == "given"
    # the volume is periodic: the periodic estimate is the wrapped definition
    np.testing.assert_array_equal(
        m["s2"]["axes"]["x"]["xz"]["s2"]["volume"], volume_s2(grf >= 0.5, periodic=True)["x"]
    )
    off = evaluate_volume(planes["xy"], grf, fringes=False, s2=False)
    assert "s2" not in off and off["settings"]["s2"] is None and "s2_relative_error" not in off["summary"]


def test_bad_exemplars_and_threshold_name_the_argument(grf, planes):
    with pytest.raises(InvalidInput, match="exemplar_xw: unknown plane"):
        evaluate_volume({**planes, "xw": planes["xy"]}, grf)
    with pytest.raises(InvalidInput, match="exemplar_yz: missing"):
        evaluate_volume({"xy": planes["xy"], "xz": planes["xz"]}, grf)
    with pytest.raises(InvalidInput, match=r"exemplar_xz: values must lie in \[0, 1\]"):
        evaluate_volume({**planes, "xz": planes["xz"] * 3}, grf)
    with pytest.raises(InvalidParameter, match=r"'threshold' = 2.0: must be a grey level in \[0, 1\]"):
        evaluate_volume(planes, grf, threshold=2.0)
    # only the planes of the evaluated axes are needed
    assert evaluate_volume({"xy": planes["xy"]}, grf, axes=(0,), fringes=False)["axes"].keys() == {"0"}


def test_cli_per_plane_table_json_and_errors(tmp_path, capsys):
    vol_path = tmp_path / "vol.tif"
    save_volume(vol_path, gaussian_random_field((16, 24, 32), LENGTHS, 0.4, seed=3), bit_depth=8)
    other = gaussian_random_field((24, 24, 32), LENGTHS, 0.4, seed=5)
    paths = {}
    for plane, img in {"xy": other[12], "xz": other[:, 12], "yz": other[:, :, 12]}.items():
        paths[plane] = tmp_path / f"{plane}.png"
        save_image(paths[plane], img)
    per_plane = [f"--exemplar-{p}={paths[p]}" for p in PLANES]
    base = ["evaluate", "--output", str(vol_path), "--no-fringes"]
    assert main([*base, *per_plane]) == 0
    table = capsys.readouterr().out
    assert "exemplars xy 32x24, xz 32x24, yz 24x24 vs volume 32x24x16" in table
    for text in ("ex xz", "axis 2 (yz)", "relative error along z", "correlation length along x, vox"):
        assert text in table
    assert main([*base, *per_plane, "--json", "--threshold", "0.5"]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["isotropic"] is False and metrics["s2"]["thresholds"]["yz"] == 0.5

    plots = tmp_path / "plots"
    assert main([*base, f"--exemplar={paths['xy']}", "--plots", str(plots)]) == 0
    capsys.readouterr()
    assert (plots / "s2.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    for args, message in (
        ([f"--exemplar={paths['xy']}", per_plane[0]], "give either one exemplar or one per plane"),
        (per_plane[:2], "--exemplar-yz: missing"),
        ([], "--exemplar: missing"),
    ):
        assert main([*base, *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0]
    assert main(["evaluate", "--output", str(paths["xy"]), *per_plane]) == 2
    assert "per-plane exemplars are for volumes" in capsys.readouterr().err


def _wavy_volume() -> np.ndarray:
    z, y, x = np.mgrid[0:20, 0:24, 0:28].astype(np.float32)
    rng = np.random.default_rng(0)
    vol = 0.5 + 0.4 * np.cos(2 * np.pi * (x + 0.5 * y + 2 * np.sin(z / 5)) / 6) + rng.normal(0, 0.03, x.shape)
    return np.clip(vol, 0.0, 1.0).astype(np.float32)


def test_slices_evaluated_on_threads_give_the_same_metrics(monkeypatch):
    """The slices' statistics run on the work's threads (in order): the same JSON with 1, 2 and 4 threads
    (4 for the evaluation's own pool: numba's is capped at this machine's cores), fringes included, and the
    progress still counts every slice once, in order."""
    from texsynth.synth.evaluate import measures

    vol = _wavy_volume()
    seen: list[float] = []
    one = evaluate_volume(vol[10], vol, threads=1)
    two = evaluate_volume(vol[10], vol, threads=2, progress=lambda _stage, f: seen.append(f))
    monkeypatch.setattr(measures, "current_threads", lambda: 4)
    four = evaluate_volume(vol[10], vol, threads=2)
    assert one["axes"]["0"]["fringes"]["output"]["count"] > 0  # the fringe analysis ran on the threads too
    assert json.dumps(one, sort_keys=True) == json.dumps(two, sort_keys=True)
    assert json.dumps(one, sort_keys=True) == json.dumps(four, sort_keys=True)
    assert seen == sorted(seen) and seen[-1] == 1.0


@pytest.mark.parametrize("chunk_pixels", [1, 700, 1 << 30])
def test_runs_of_slices_give_the_metrics_of_one_slice_at_a_time(monkeypatch, chunk_pixels):
    """The slices are measured in runs (stack filters); however the runs are cut (one slice each, a few,
    a whole axis), every slice's statistics and so the JSON are those of the images one at a time."""
    from texsynth.synth.evaluate import measures

    vol = _wavy_volume()
    settings = measures.MeasureSettings()
    for axis in (0, 1, 2):
        view = np.moveaxis(vol, axis, 0)
        runs = measures._chunk_stats(view, settings)
        for k, (stats, moment) in enumerate(runs):
            grey = view[k].astype(np.float64)
            alone = measures.image_stats(grey, settings)
            for name in ("grey", "orientation", "coherence", "tensor_sum", "lengths", "tortuosity"):
                assert np.array_equal(getattr(stats, name), getattr(alone, name)), (axis, k, name)
            assert (stats.coherence_sum, stats.n_loops) == (alone.coherence_sum, alone.n_loops)
            assert moment == measures.moments(grey)
    reference = evaluate_volume(vol[10], vol, threads=2)
    monkeypatch.setattr(measures, "CHUNK_PIXELS", chunk_pixels)
    cut = evaluate_volume(vol[10], vol, threads=2)
    assert json.dumps(cut, sort_keys=True) == json.dumps(reference, sort_keys=True)
