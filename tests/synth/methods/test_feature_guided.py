"""The ``feature-guided`` method (Wu & Yu 2004) end to end: options, seeds, errors, artifacts, variants."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.analysis.features import feature_map
from texsynth.synth.api import synthesize
from texsynth.synth.errors import Cancelled, InvalidParameter
from texsynth.synth.io.patterns import undulating_laminae, voronoi_cells
from texsynth.synth.patch.feature_guided import (
    WARPED_CODE,
    FeatureGuidedSettings,
    combined_cost,
    synthesize_feature_guided,
    variants,
)

SIZE = (64, 64)
BASE = {"patch_size": 16, "overlap": 4, "features": "ridges", "polarity": "dark", "presmooth": 1.0}


@pytest.fixture(scope="module")
def laminae() -> np.ndarray:
    return undulating_laminae((48, 48), 7, 8, 48, noise=0.1)


@pytest.fixture(scope="module")
def runs(laminae):
    """One run per option setting, shared by the tests that compare them."""
    return {
        "on": synthesize("feature-guided", laminae, size=SIZE, params={**BASE, "deform": True}, seed=3),
        "off": synthesize("feature-guided", laminae, size=SIZE, params={**BASE, "deform": False}, seed=3),
    }


def test_same_seed_same_bytes_grey_and_colour(laminae, runs):
    again = synthesize("feature-guided", laminae, size=SIZE, params={**BASE, "deform": True}, seed=3)
    other = synthesize("feature-guided", laminae, size=SIZE, params={**BASE, "deform": True}, seed=4)
    a = runs["on"]
    assert a.image.dtype == np.float32 and a.image.shape == SIZE
    assert a.image.min() >= 0.0 and a.image.max() <= 1.0
    assert a.image.tobytes() == again.image.tobytes()
    assert a.image.tobytes() != other.image.tobytes()
    rgb = np.stack([laminae, laminae[::-1], 1 - laminae], axis=-1)
    c1 = synthesize("feature-guided", rgb, size=(40, 52), params=BASE, seed=1)
    c2 = synthesize("feature-guided", rgb, size=(40, 52), params=BASE, seed=1)
    assert c1.image.shape == (40, 52, 3) and c1.image.tobytes() == c2.image.tobytes()


def test_deform_changes_the_output_and_reports_its_warps(runs):
    on, off = runs["on"], runs["off"]
    assert on.image.tobytes() != off.image.tobytes()
    warps = on.stats["warps"]
    assert warps["tps"] + warps["shepard"] > 0 and on.stats["mean_correspondences"] > 0
    assert "warps" not in off.stats


def test_features_edges_and_ridges_differ(laminae, runs):
    edges = synthesize("feature-guided", laminae, size=SIZE, params={**BASE, "features": "edges"}, seed=3)
    assert edges.image.tobytes() != runs["on"].image.tobytes()
    assert edges.stats["exemplar_features"] != runs["on"].stats["exemplar_features"]


def test_feature_weight_reranks_the_colour_candidates(laminae):
    colour_only = synthesize(
        "feature-guided",
        laminae,
        size=SIZE,
        params={**BASE, "deform": False, "feature_weight": 0.0, "tolerance": 0.0},
        seed=2,
    )
    mixed = synthesize(
        "feature-guided", laminae, size=SIZE, params={**BASE, "deform": False, "tolerance": 0.0}, seed=2
    )
    assert colour_only.stats["reranked_share"] == 0.0  # least SSD always wins
    assert mixed.stats["reranked_share"] > 0.0
    assert colour_only.image.tobytes() != mixed.image.tobytes()


def test_reverse_weight_changes_the_choice_and_zero_is_the_papers_cost(laminae):
    """``reverse_weight`` adds the candidate-to-context chamfer term; 0 leaves eq 2 (and the bytes) alone."""
    common = {**BASE, "deform": False, "tolerance": 0.0}
    paper = synthesize("feature-guided", laminae, size=SIZE, params={**common, "reverse_weight": 0.0}, seed=2)
    again = synthesize("feature-guided", laminae, size=SIZE, params={**common, "reverse_weight": 0.0}, seed=2)
    both = synthesize("feature-guided", laminae, size=SIZE, params={**common, "reverse_weight": 4.0}, seed=2)
    assert paper.image.tobytes() == again.image.tobytes()
    assert both.image.tobytes() != paper.image.tobytes()
    assert both.params["reverse_weight"] == 4.0


def test_rotations_add_the_seven_copies(laminae):
    res = synthesize("feature-guided", laminae, size=SIZE, params={**BASE, "rotations": True}, seed=3)
    assert len(res.stats["variants"]) == 8 and res.stats["variants"][0] == "identity"


def test_variant_tangents_match_features_detected_on_the_copies():
    img = np.zeros((40, 40), dtype=np.float32)
    rr = np.arange(5, 35)
    img[rr, rr // 2 + 5] = 1.0  # a bright line, about 63 degrees below +x (y up: -63.4)
    opts = {"features": "ridges"}
    fmap = feature_map(img, **opts)
    for v in variants(img, fmap, rotations=True):
        seen = feature_map(v.image[..., 0], **opts)
        assert np.array_equal(v.mask, v.mask & np.isfinite(v.tangent))
        # same tangents (mod pi) where both maps have a feature
        both = v.mask & seen.mask
        assert both.sum() > 10, v.name
        diff = np.abs(np.angle(np.exp(2j * (v.tangent[both] - seen.tangent[both])))) / 2
        assert np.median(diff) < np.radians(5), v.name


def test_combined_cost_scales_each_term_by_its_mean():
    np.testing.assert_allclose(
        combined_cost(np.array([2.0, 0.0]), np.array([1.0, 3.0]), 0.5), [1.0 + 0.25, 0.75]
    )
    np.testing.assert_allclose(combined_cost(np.zeros(3), np.array([1.0, 2.0, 3.0]), 0.5), [0.25, 0.5, 0.75])


def test_extras_and_the_broken_feature_measure(runs):
    res = runs["on"]
    for key in ("features_exemplar", "features_output", "seams"):
        extra = res.extras[key]
        assert extra.shape[-1] == 3 and extra.dtype == np.float32 and extra.min() >= 0 and extra.max() <= 1
    assert res.extras["features_output"].shape[:2] == SIZE and res.extras["features_exemplar"].shape[:2] == (
        48,
        48,
    )
    seams = res.extras["seams"]
    assert (np.all(seams == np.array([1.0, 0.1, 0.1], np.float32), axis=-1)).any()  # seams drawn in red
    broken = res.stats["broken_features"]
    assert np.isfinite(broken["ratio"]) and broken["seam_length"] > 0
    assert res.stats["layout"]["patch_size"] == 16


def test_artifacts_are_written_by_the_one_writer(tmp_path, runs, laminae):
    from texsynth.synth.output.artifacts import write_artifacts

    names, _ = write_artifacts(tmp_path, runs["on"], laminae, plots=False)
    for name in ("features_exemplar.png", "features_output.png", "seams.png"):
        assert name in names and (tmp_path / name).is_file()


def test_cells_pattern_has_closed_walls():
    img = voronoi_cells((64, 64), 16, 1.2, noise=0.0, seed=2)
    assert img.dtype == np.float32 and img.min() == 0.0 and img.max() == 1.0
    dark = img < 0.3
    assert 0.05 < dark.mean() < 0.4  # walls are a minority of pixels, spread over the image
    assert dark[:, :32].any() and dark[:, 32:].any()


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"patch_size": 64}, "patch_size.*larger than the exemplar"),
        ({"patch_size": 16, "overlap": 16}, "overlap.*must be smaller than patch_size"),
        ({"features": "corners"}, "features"),
        ({"feature_weight": 1.5}, "feature_weight"),
        ({"reverse_weight": -1.0}, "reverse_weight"),
        ({"candidates": 0}, "candidates"),
        ({"alpha": 0.0}, "alpha"),
        ({"max_shift": -1}, "max_shift"),
        ({"warp_angle": 100}, "warp_angle"),
        ({"warp_band": -1}, "warp_band"),
        ({"bogus": 1}, "bogus"),
    ],
)
def test_errors_name_the_field_before_any_work(params, match):
    ex = np.zeros((40, 40), dtype=np.float32)
    calls = []
    with pytest.raises(InvalidParameter, match=match):
        synthesize("feature-guided", ex, size=SIZE, params=params, progress=lambda s, f: calls.append(s))
    assert calls == []


def test_progress_and_cancel(laminae):
    seen = []
    synthesize("feature-guided", laminae, size=SIZE, params=BASE, progress=lambda s, f: seen.append((s, f)))
    fractions = [f for s, f in seen if s == "feature-guided"]
    assert fractions == sorted(fractions) and seen[-1] == ("done", 1.0)

    def cancel(stage, fraction):
        if stage == "feature-guided" and fraction > 0.3:
            raise Cancelled("stop")

    with pytest.raises(Cancelled):
        synthesize("feature-guided", laminae, size=SIZE, params=BASE, progress=cancel)


def test_the_warp_moves_only_the_overlap_and_a_band_beyond_it(laminae):
    """Pixels a warp moved lie within overlap + warp band of the patch's leading edges; the rest of
    a warped patch (its far side, its fixed bottom and right borders) is a verbatim copy."""
    fmap = feature_map(laminae, features="ridges", polarity="dark", presmooth=1.0)
    settings = FeatureGuidedSettings(patch_size=16, overlap=4, deform=True, warp_band=3.0, min_shift=0.0)
    made = synthesize_feature_guided(
        laminae, fmap, SIZE, settings, np.random.default_rng(1), lambda stage, fraction: None
    )
    moved = made.sources[..., 0] >= WARPED_CODE
    assert moved.any() and made.stats["warps"]["tps"] + made.stats["warps"]["shepard"] > 0
    corners = {n: (y, x) for n, (_, _, y, x, _) in enumerate(made.layout.patches())}
    rows, cols = np.nonzero(moved)
    for r, c in zip(rows, cols, strict=True):
        n = int(made.sources[r, c, 0] // WARPED_CODE) - 1
        assert made.labels[r, c] == n
        y, x = corners[n]
        lr, lc = r - y, c - x
        assert min(lr, lc) < 4 + 3  # inside the overlap or its band
        assert lr < 15 and lc < 15  # never on the fixed bottom/right border
    # unmoved pixels of warped patches are verbatim: one exemplar copy, row + ROW_CODE * copy
    assert (made.sources[~moved][:, 0] < WARPED_CODE).all()


def test_warp_stats_and_the_kink_measure_are_reported(runs):
    on = runs["on"]
    assert set(on.stats["warps"]) == {"tps", "shepard", "identity", "folded", "small"}
    assert on.stats["mean_warp_shift"] >= 0.5  # the applied warps move something by half a pixel
    broken = on.stats["broken_features"]
    assert {"end_ratio", "kink_ratio", "seam_kinks", "seam_crossings", "density_ratio"} <= set(broken)


def test_reverse_weight_none_follows_the_exemplars_orientation(laminae):
    """``reverse_weight=None`` (the default): 2 for weakly oriented exemplars, 0 (eq 2) for strongly
    oriented ones, and the run records the weight it used."""
    from texsynth.synth.methods.feature_guided import reverse_weight_for

    noise = np.random.default_rng(3).random((64, 64)).astype(np.float32)
    assert reverse_weight_for(laminae) == 0.0
    assert reverse_weight_for(noise) == 2.0
    ran = synthesize("feature-guided", laminae, size=SIZE, params=BASE, seed=2)
    assert ran.params["reverse_weight"] == 0.0
    paper = synthesize("feature-guided", laminae, size=SIZE, params={**BASE, "reverse_weight": 0}, seed=2)
    assert ran.image.tobytes() == paper.image.tobytes()
