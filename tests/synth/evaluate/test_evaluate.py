"""Known answers of the quantitative evaluation (texsynth.synth.evaluate, texsynth.synth.output.plots,
texsynth evaluate)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from scipy import ndimage as ndi

from texsynth.synth.cli import main
from texsynth.synth.colour import LUMA_WEIGHTS
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.evaluate import HIST_EPSILON, evaluate_pair, evaluate_volume, kl_divergence, window_sigma
from texsynth.synth.io import save_image, save_volume


def _directional(shape: tuple[int, int], seed: int = 1) -> np.ndarray:
    """Noise smoothed 5x more along x than along y: horizontal streaks (an anisotropic texture)."""
    noise = np.random.default_rng(seed).standard_normal(shape)
    t = ndi.gaussian_filter(noise, (1.0, 5.0), mode="wrap")
    return ((t - t.min()) / np.ptp(t)).astype(np.float32)


def _floats(obj: Any) -> Iterator[Any]:
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _floats(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _floats(v)
    else:
        yield obj


def test_kl_divergence_known_values():
    assert kl_divergence([1, 2, 3], [2, 4, 6]) == 0.0
    p, q = np.array([1.0, 0.0]), np.array([0.5, 0.5])
    e = HIST_EPSILON
    ps = (p + e) / (1 + 2 * e)
    assert kl_divergence(p, q) == pytest.approx(float(np.sum(ps * np.log(ps / 0.5))))
    assert kl_divergence(p, q) == pytest.approx(math.log(2), rel=1e-3)
    # direction: D(exemplar || output) penalises output bins that miss exemplar mass
    assert kl_divergence([1, 1], [1, 0]) > kl_divergence([1, 0], [1, 1])
    with pytest.raises(InvalidParameter):
        kl_divergence([1, 2], [1, 2, 3])


def test_window_sigma_matches_box_variance():
    assert window_sigma(7) == 2.0
    box = np.arange(7) - 3
    assert window_sigma(7) == pytest.approx(box.std())


def test_identical_images_give_zero_distances_and_identical_fringes():
    img = _directional((64, 64))
    m = evaluate_pair(img, img.copy(), pixel_size=0.05)
    assert m["grey"]["kl"] == 0.0
    assert m["structure"]["orientation_kl"] == 0.0
    assert m["structure"]["coherence_kl"] == 0.0
    assert m["structure"]["log_euclidean"] == pytest.approx(0.0, abs=1e-12)
    assert m["moments"]["exemplar"] == m["moments"]["output"]
    fr = m["fringes"]
    assert fr["exemplar"] == fr["output"]
    assert fr["exemplar"]["count"] > 0
    assert fr["ks_length"] == {"statistic": 0.0, "pvalue": 1.0}
    assert fr["ks_tortuosity"] == {"statistic": 0.0, "pvalue": 1.0}
    assert fr["kl_length"] == 0.0 and fr["kl_tortuosity"] == 0.0
    assert fr["exemplar"]["mean_length_nm"] == pytest.approx(fr["exemplar"]["mean_length"] * 0.05)


def test_rotation_keeps_grey_statistics_but_not_orientations():
    tex = _directional((128, 128))
    halves = evaluate_pair(tex[:, :64], tex[:, 64:], fringes=False)
    rotated = evaluate_pair(tex, np.rot90(tex), fringes=False)
    assert rotated["grey"]["kl"] == 0.0  # the same pixels
    assert rotated["moments"]["output"]["std"] == pytest.approx(rotated["moments"]["exemplar"]["std"])
    assert halves["structure"]["orientation_kl"] < 0.2
    assert rotated["structure"]["orientation_kl"] > 1.0
    assert rotated["structure"]["orientation_kl"] > 20 * halves["structure"]["orientation_kl"]
    assert rotated["structure"]["log_euclidean"] > 5 * halves["structure"]["log_euclidean"]
    dirs = rotated["structure"]["dominant_structure_direction_deg"]
    assert abs(dirs["exemplar"]) < 10 and abs(abs(dirs["output"]) - 90) < 10  # horizontal -> vertical


def test_repeated_slice_volume_per_axis_results():
    ex = _directional((32, 40), seed=4)
    depth = 24
    vol = np.repeat(ex[None], depth, axis=0)  # (24, 32, 40): every axis-0 slice is the exemplar
    m = evaluate_volume(ex, vol)
    a0, a1, a2 = m["axes"]["0"], m["axes"]["1"], m["axes"]["2"]
    # axis 0: every slice is the exemplar
    assert a0["slices"]["count"] == depth
    assert a0["grey"]["kl"] == 0.0 and a0["slices"]["grey_kl"]["max"] == 0.0
    assert a0["structure"]["orientation_kl"] == 0.0 and a0["slices"]["orientation_kl"]["max"] == 0.0
    assert a0["fringes"]["ks_length"]["statistic"] == 0.0
    assert a0["fringes"]["output"]["count"] == depth * a0["fringes"]["exemplar"]["count"]
    # axes 1 and 2: slices volume[:, j] and volume[:, :, k] are constant down their columns
    assert (a1["slices"]["count"], a2["slices"]["count"]) == (32, 40)
    for block in (a1, a2):
        # pooled over all slices, the grey levels are the volume's: the exemplar's, 24 times
        assert block["grey"]["kl"] == pytest.approx(0.0, abs=1e-12)
        # ... but each slice holds one exemplar row or column only
        assert block["slices"]["grey_kl"]["mean"] > 0.05
        # every gradient is horizontal: all energy at gradient orientation 0, vertical fringes
        hist = np.array(block["structure"]["orientation_histogram"]["output"])
        assert hist[16:20].sum() > 0.999
        assert block["structure"]["dominant_structure_direction_deg"]["output"] == pytest.approx(90.0)
        assert block["structure"]["coherence_mean"]["output"] > 0.99
        assert block["structure"]["orientation_kl"] > 1.0
        # straight vertical bands: tortuosity 1 up to the one-pixel end kink skeletonize may leave
        assert block["fringes"]["output"]["median_tortuosity"] < 1.03
        assert block["fringes"]["output"]["share_tortuous"] == 0.0
    # the same voxels on every axis: same pooled moments and grey histogram
    assert a0["moments"]["output"] == a1["moments"]["output"] == a2["moments"]["output"]
    strided = evaluate_volume(ex, vol, slice_step=2, fringes=False)
    assert strided["axes"]["0"]["slices"]["count"] == depth // 2
    assert m["overall"]["grey"]["kl"] == pytest.approx(0.0, abs=1e-12)
    assert set(m["summary"]["per_axis"]) == {"0", "1", "2"}
    # grain: the exemplar's own slices are as grainy as it; the columns' slices have no vertical
    # variation, and so a different share
    assert a0["grain"]["ratio"] == pytest.approx(1.0, rel=1e-12)
    assert m["summary"]["per_axis"]["0"]["grain_ratio"] == pytest.approx(1.0, rel=1e-12)
    assert a1["grain"]["ratio"] != pytest.approx(1.0, rel=0.05)


def test_grain_ratio_sees_speckle_that_the_histograms_do_not():
    smooth = _directional((64, 64), seed=2)
    rng = np.random.default_rng(3)
    # the same pixels, one in five swapped with a random other: the grey histogram is unchanged
    speckled = smooth.ravel().copy()
    picked = rng.choice(speckled.size, speckled.size // 5, replace=False)
    speckled[picked] = speckled[rng.permutation(picked)]
    speckled = speckled.reshape(smooth.shape)
    same = evaluate_pair(smooth, smooth, fringes=False)["summary"]
    pair = evaluate_pair(smooth, speckled, fringes=False)
    assert same["grain_ratio"] == pytest.approx(1.0)
    assert pair["summary"]["grey_kl"] == pytest.approx(0.0, abs=1e-12)
    assert pair["summary"]["grain_ratio"] > 2.0
    assert pair["grain"]["exemplar"] < pair["grain"]["output"] < 1.0
    # blurred, the output is smoother than the exemplar
    blurred = ndi.gaussian_filter(smooth, 1.5)
    assert evaluate_pair(smooth, blurred, fringes=False)["summary"]["grain_ratio"] < 0.5
    # a flat exemplar has no share to compare with
    flat = np.full((32, 32), 0.5, dtype=np.float32)
    assert evaluate_pair(flat, smooth[:32, :32], fringes=False)["summary"]["grain_ratio"] is None


def test_metrics_are_plain_json():
    tex = _directional((40, 40))
    for metrics in (
        evaluate_pair(tex, tex[::-1]),
        evaluate_volume(tex, np.stack([tex] * 8 + [tex[::-1]] * 8)),
    ):
        text = json.dumps(metrics, allow_nan=False)
        assert json.loads(text) == metrics
        for value in _floats(metrics):
            assert value is None or type(value) in (bool, int, float, str)


def test_rgb_is_evaluated_as_its_luma():
    rng = np.random.default_rng(5)
    rgb = rng.random((32, 32, 3)).astype(np.float32)
    grey = rgb.astype(np.float64) @ np.asarray(LUMA_WEIGHTS)
    m = evaluate_pair(rgb, grey, fringes=False)
    assert m["grey"]["kl"] == 0.0 and m["structure"]["orientation_kl"] == 0.0


def test_bad_inputs_name_the_argument():
    good = _directional((32, 32))
    with pytest.raises(InvalidInput, match="exemplar"):
        evaluate_pair(np.full((32, 32), np.nan), good)
    with pytest.raises(InvalidInput, match=r"output.*\[0, 1\]"):
        evaluate_pair(good, good * 3)
    with pytest.raises(InvalidInput, match="output"):
        evaluate_pair(good, np.zeros((32, 32, 2)))
    with pytest.raises(InvalidInput, match="too small"):
        evaluate_pair(good, good[:4])
    with pytest.raises(InvalidInput, match="volume"):
        evaluate_volume(good, good)
    with pytest.raises(InvalidParameter, match="axes"):
        evaluate_volume(good, np.stack([good] * 8), axes=(0, 3))
    with pytest.raises(InvalidParameter, match="grey_bins"):
        evaluate_pair(good, good, grey_bins=1)
    with pytest.raises(InvalidParameter, match="fringe_options"):
        evaluate_pair(good, good, fringe_options={"sigmaa": 2})


def test_write_plots_pair_and_volume(tmp_path):
    from texsynth.synth.output.plots import write_plots

    tex = _directional((48, 48))
    metrics = evaluate_pair(tex, tex[:, ::-1], pixel_size=0.05)
    paths = write_plots(tex, tex[:, ::-1], metrics, tmp_path / "pair")
    names = {p.name for p in paths}
    assert names == {
        "grey_histogram.png",
        "orientation_rose.png",
        "fringe_distributions.png",
        "fringes_exemplar.png",
        "fringes_output.png",
    }
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    vol = np.stack([tex] * 8)
    vpaths = write_plots(tex, vol, evaluate_volume(tex, vol), tmp_path / "volume")
    assert len(vpaths) == 5
    no_fringes = write_plots(tex, tex, evaluate_pair(tex, tex, fringes=False), tmp_path / "plain")
    assert {p.name for p in no_fringes} == {"grey_histogram.png", "orientation_rose.png"}


def test_cli_json_table_volume_and_errors(tmp_path, capsys):
    tex = _directional((48, 48))
    ex_path, out_path, vol_path = tmp_path / "ex.png", tmp_path / "out.png", tmp_path / "vol.tif"
    save_image(ex_path, tex)
    save_image(out_path, tex)
    save_volume(vol_path, np.stack([tex] * 10), bit_depth=8)

    assert main(["evaluate", "--exemplar", str(ex_path), "--output", str(out_path), "--json"]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["kind"] == "pair" and metrics["grey"]["kl"] == 0.0

    plots = tmp_path / "plots"
    args = ["evaluate", "--exemplar", str(ex_path), "--output", str(out_path), "--pixel-size", "0.05"]
    assert main([*args, "--plots", str(plots)]) == 0
    table = capsys.readouterr().out
    assert "KL(exemplar || output)" in table and "median tortuosity" in table and "nm" in table
    assert (plots / "fringes_output.png").exists()

    assert main(["evaluate", "--exemplar", str(ex_path), "--output", str(vol_path), "--json"]) == 0
    vm = json.loads(capsys.readouterr().out)
    assert vm["kind"] == "volume" and vm["shape"]["volume"] == [10, 48, 48]
    assert vm["axes"]["0"]["grey"]["kl"] == 0.0

    missing = tmp_path / "missing.png"
    assert main(["evaluate", "--exemplar", str(missing), "--output", str(out_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing.png" in err[0]


def test_moments_and_ks_agree_with_scipy_bit_for_bit():
    """The metrics' moments and exact KS test are computed without importing scipy.stats (a slow
    import): the same numbers, to the last bit, as scipy's, including ties and equal sample sizes."""
    from scipy import stats

    from texsynth.synth.evaluate.measures import _ks, _ks_2samp_exact, _skew_kurtosis

    rng = np.random.default_rng(5)
    for trial in range(120):
        n1 = int(rng.integers(1, 300))
        n2 = n1 if trial % 4 == 0 else int(rng.integers(1, 300))
        if trial % 2:  # integer-like fringe lengths: many ties
            a, b = np.round(rng.gamma(2.0, 10.0, n1)), np.round(rng.gamma(2.3, 10.0, n2))
        else:
            a, b = 1 + rng.exponential(0.3, n1), 1 + rng.exponential(0.4, n2)
        expected = stats.ks_2samp(a, b)
        assert _ks(a, b) == {"statistic": float(expected.statistic), "pvalue": float(expected.pvalue)}
        x = rng.normal(size=int(rng.integers(2, 3000))) ** (1 + trial % 3)
        assert _skew_kurtosis(x) == (float(stats.skew(x)), float(stats.kurtosis(x)))
    # beyond the exact test's reach scipy answers (its asymptotic method)
    big_a, big_b = rng.random(10_001), rng.random(50) + 0.1
    assert _ks_2samp_exact(big_a, big_b) is None
    expected = stats.ks_2samp(big_a, big_b)
    assert _ks(big_a, big_b) == {"statistic": float(expected.statistic), "pvalue": float(expected.pvalue)}


def test_evaluate_pair_fringes_returns_the_metrics_and_the_fringes():
    from texsynth.synth.evaluate.measures import evaluate_pair_fringes

    tex = _directional((48, 48))
    metrics, fringes = evaluate_pair_fringes(tex, tex[:, ::-1], pixel_size=0.05)
    assert metrics == evaluate_pair(tex, tex[:, ::-1], pixel_size=0.05)
    assert set(fringes) == {"exemplar", "output"}
    assert fringes["exemplar"].summary()["count"] == metrics["fringes"]["exemplar"]["count"]
    assert evaluate_pair_fringes(tex, tex, fringes=False)[1] == {}
