"""Exemplar coverage, the usage penalty, the variance-normalised overlap error, and what they change on a
laminar HRTEM crop that mixes ordered shells with a disordered core."""

from __future__ import annotations

import numpy as np
import pytest

from tests.paths import REPO
from texsynth.synth.api import synthesize
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.evaluate.coverage import exemplar_coverage, footprint_counts
from texsynth.synth.io import load_image
from texsynth.synth.patch.layout import overlap_mask
from texsynth.synth.patch.search import PatchSearcher
from texsynth.synth.patch.usage import UsagePenalty

ONION_CORE = REPO / "benchmarks" / "data" / "hrtem-onion-core-128.png"


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("kind", ["left", "L"])
def test_normalised_ssd_matches_direct(channels, kind):
    rng = np.random.default_rng(1)
    ex = rng.random((17, 21, channels))
    template = rng.random((6, 6, channels))
    mask = overlap_mask(6, 2, kind)
    searcher = PatchSearcher(ex, 6)
    got = searcher.normalised_ssd(template, mask)
    m = np.repeat(mask[..., None], channels, axis=2)
    n = m.sum()
    var_t = template[m].var()
    eps = 1e-3 * ex.var() + 1e-12
    want = np.empty(got.shape)
    for y in range(got.shape[0]):
        for x in range(got.shape[1]):
            cand = ex[y : y + 6, x : x + 6]
            ssd = np.sum(m * (cand - template) ** 2)
            want[y, x] = ssd / (n * (var_t + cand[m].var() + eps))
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-10)
    # the plain SSD prefers a flat candidate to an uncorrelated one of the template's contrast; this does not
    flat = np.full((6, 6, channels), template[m].mean())
    other = rng.random((6, 6, channels))
    ex2 = np.concatenate([flat, other], axis=1)
    s2 = PatchSearcher(ex2, 6)
    plain, norm = s2.ssd(template, mask), s2.normalised_ssd(template, mask)
    assert plain[0, 0] < plain[0, 6] and norm[0, 0] > 0.9 * norm[0, 6]


def test_footprints_reach_and_usage_factors():
    pos = np.stack(np.mgrid[0:12, 0:9], axis=-1).reshape(-1, 2)
    reach = footprint_counts(pos, (16, 13), 5)
    direct = np.zeros((16, 13))
    for y, x in pos:
        direct[y : y + 5, x : x + 5] += 1
    np.testing.assert_array_equal(reach, direct)
    u = UsagePenalty((16, 13), 5, weight=2.0)
    np.testing.assert_array_equal(u.reach, direct)
    assert np.all(u.factors() == 1.0)
    # every position used once: usage as planned, no penalty anywhere
    for y, x in pos:
        u.add(y, x)
    np.testing.assert_allclose(u.factors(), 1.0)
    u.add(0, 0)
    u.add(0, 0)
    f = u.factors()
    assert f[0, 0] > f[5, 5] >= 1.0 and f[-1, -1] == 1.0
    assert np.all(UsagePenalty((16, 13), 5, weight=0.0).factors() == 1.0)
    with pytest.raises(ValueError, match="weight"):
        UsagePenalty((16, 13), 5, weight=-1.0)


def test_exemplar_coverage():
    one = exemplar_coverage([(3, 4)] * 5, (40, 40), 10)
    assert one["share"] == pytest.approx(100 / 1600) and one["spread"] == 0.0
    assert one["evenness"] == pytest.approx(1.0)
    twice = exemplar_coverage([(0, 0), (0, 0), (0, 0), (5, 5)], (40, 40), 10)
    assert twice["evenness"] < 0.9
    pos = np.stack(np.mgrid[0:31, 0:31], axis=-1).reshape(-1, 2)
    full = exemplar_coverage(pos, (40, 40), 10)
    assert full["share"] == 1.0 and full["spread"] == pytest.approx(1.0) and full["evenness"] > 0.8
    corner = exemplar_coverage(pos[(pos[:, 0] < 8) & (pos[:, 1] < 8)], (40, 40), 10)
    assert corner["share"] < 0.2 and corner["spread"] < 0.3
    assert exemplar_coverage([], (40, 40), 10)["share"] == 0.0
    with pytest.raises(ValueError, match="outside"):
        exemplar_coverage([(35, 0)], (40, 40), 10)
    with pytest.raises(ValueError, match="weights"):
        footprint_counts([(0, 0)], (40, 40), 10, weights=[1.0, 2.0])


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"usage_weight": -1}, "usage_weight"),
        ({"usage_weight": 1000}, "usage_weight"),
        ({"error": "ncc"}, "error"),
    ],
)
def test_quilting_bad_values_name_the_field(params, field):
    ex = np.zeros((40, 40), dtype=np.float32)
    with pytest.raises(InvalidParameter, match=field):
        synthesize("quilting", ex, size=(64, 64), params=params)


def test_quilting_reports_its_sources():
    rng = np.random.default_rng(2)
    ex = rng.random((40, 44)).astype(np.float32)
    r = synthesize("quilting", ex, size=(60, 60), params={"patch_size": 12}, seed=1)
    src = np.array(r.stats["patch_sources"])
    assert src.ndim == 2 and src.shape[1] == 2 and len(src) == 36  # 6 x 6 patches of step 10
    assert src.min() >= 0 and src[:, 0].max() <= 40 - 12 and src[:, 1].max() <= 44 - 12
    assert r.stats["coverage"] == exemplar_coverage(src, ex.shape, 12)
    # the first patch's pixels are copied verbatim from its source
    y, x = src[0]
    np.testing.assert_array_equal(r.image[:5, :5], ex[y : y + 5, x : x + 5])


@pytest.mark.skipif(not ONION_CORE.exists(), reason=f"{ONION_CORE} missing")
def test_quilting_defaults_use_the_whole_laminar_exemplar():
    """On the onion crop (ordered shells around a disordered core) the paper's error settles in the core.

    Over seeds 1-3 (one seed's contrast varies by about 0.03: the paper's was 0.80-0.91 over seeds 1-6,
    ours 0.94-0.97): ours covers more of the exemplar and keeps its contrast, the paper's loses some."""
    ex = load_image(ONION_CORE)
    cover: dict[str, list[float]] = {"paper": [], "ours": []}
    contrast: dict[str, list[float]] = {"paper": [], "ours": []}
    for seed in (1, 2, 3):
        for name, params in (("paper", {"error": "ssd", "usage_weight": 0}), ("ours", {})):
            r = synthesize("quilting", ex, size=(192, 192), seed=seed, params=params)
            cover[name].append(r.stats["coverage"]["share"])
            contrast[name].append(float(r.image.std() / ex.std()))
    assert np.mean(cover["ours"]) > np.mean(cover["paper"]) + 0.1
    assert min(contrast["ours"]) > 0.9 > np.mean(contrast["paper"])
    assert np.mean(contrast["ours"]) > np.mean(contrast["paper"]) + 0.05


@pytest.mark.parametrize("method", ["gaussian-patch", "feature-guided"])
@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"usage_weight": -0.5}, "usage_weight"),
        ({"usage_weight": 101}, "usage_weight"),
        ({"error": "l1"}, "error"),
    ],
)
def test_search_options_bad_values_name_the_field(method, params, field):
    ex = np.zeros((64, 64), dtype=np.float32)
    with pytest.raises(InvalidParameter, match=field):
        synthesize(method, ex, size=(64, 64), params=params)


def test_gaussian_patch_reports_its_neighbours():
    rng = np.random.default_rng(3)
    ex = rng.random((40, 40)).astype(np.float32)
    base = {"patch_size": 12, "neighbours": 4}
    mean = synthesize("gaussian-patch", ex, size=(48, 48), seed=2, params={**base, "estimate": "mean"})
    kept = synthesize("gaussian-patch", ex, size=(48, 48), seed=2, params=base)
    # one position per patch in the stats; the coverage counts all N at 1/N for the mean
    n_patches = len(kept.stats["patch_sources"])
    assert len(mean.stats["patch_sources"]) == n_patches == 25  # 5 x 5 patches of step 9
    assert mean.stats["coverage"]["patches"] == 1 + 4 * (n_patches - 1)
    assert kept.stats["coverage"]["patches"] == n_patches
    y, x = kept.stats["patch_sources"][0]
    np.testing.assert_array_equal(kept.image[:4, :4], ex[y : y + 4, x : x + 4])
    assert kept.stats["coverage"] == exemplar_coverage(kept.stats["patch_sources"], ex.shape, 12)


def test_feature_guided_search_follows_the_exemplar_orientation():
    from texsynth.synth.methods.feature_guided import search_for

    rng = np.random.default_rng(4)
    noise = rng.random((64, 64))
    stripes = 0.5 + 0.4 * np.sin(2 * np.pi * np.arange(64) / 7.0)[:, None] * np.ones((1, 64))
    assert search_for(noise) == ("normalised", 1.0)
    assert search_for(stripes) == ("ssd", 0.0)
    r = synthesize(
        "feature-guided", noise.astype(np.float32), size=(64, 64), seed=1, params={"patch_size": 16}
    )
    assert r.params["error"] == "normalised" and r.params["usage_weight"] == 1.0
    assert r.stats["coverage"]["patches"] == len(r.stats["patch_sources"])


@pytest.mark.skipif(not ONION_CORE.exists(), reason=f"{ONION_CORE} missing")
def test_gaussian_patch_defaults_keep_the_laminar_contrast():
    ex = load_image(ONION_CORE)
    before = {"error": "ssd", "usage_weight": 0, "blending": "none"}
    old = synthesize("gaussian-patch", ex, size=(160, 160), seed=1, params=before)
    new = synthesize("gaussian-patch", ex, size=(160, 160), seed=1)
    assert new.image.std() / ex.std() > 0.85 > old.image.std() / ex.std()
    assert new.stats["coverage"]["share"] > old.stats["coverage"]["share"]
