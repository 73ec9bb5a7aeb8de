"""Bucketed chamfer matching (texsynth.synth.analysis.feature_matching; Wu & Yu 2004, eqs 1-2) against brute
force."""

from __future__ import annotations

import time

import numpy as np
import pytest

from texsynth.synth.analysis.feature_matching import (
    Correspondences,
    build_feature_index,
    context_features,
    feature_correspondences,
    match_features,
    match_features_reference,
    matching_cost,
    matching_cost_reference,
    matching_costs,
    orientation_bucket,
    reverse_cost_reference,
    reverse_costs,
    tangent_difference,
    thin_correspondences,
    unmatched_penalty,
)
from texsynth.synth.analysis.feature_matching import _window_sums as window_sums
from texsynth.synth.errors import InvalidInput, InvalidParameter


def _random_features(rng: np.random.Generator, shape: tuple[int, int], density: float):
    mask = rng.random(shape) < density
    return mask, np.where(mask, rng.uniform(-np.pi / 2, np.pi / 2, shape), np.nan)


def _l_region(w: int, k: int) -> np.ndarray:
    region = np.zeros((w, w), dtype=bool)
    region[:k] = True
    region[:, :k] = True
    return region


def _tied(cp: np.ndarray, cb: np.ndarray, fp: np.ndarray, fb: np.ndarray) -> np.ndarray:
    """Context points whose nearest feature in one of their buckets is not unique."""
    tied = np.zeros(len(cp), dtype=bool)
    for i in range(len(cp)):
        for step in (0, -1, 1):
            sel = fb == (cb[i] + step) % 4
            if sel.sum() >= 2:
                d = np.sort(np.hypot(*(fp[sel] - cp[i]).T))
                tied[i] |= d[1] - d[0] < 1e-9
    return tied


def test_buckets_and_tangent_differences_known_answers():
    deg = np.radians([0.0, 22.0, 23.0, 45.0, 67.0, 68.0, 90.0, -90.0, -67.0, -45.0, -23.0, -22.0, 180.0])
    assert orientation_bucket(deg).tolist() == [0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 0, 0]
    t = tangent_difference(np.radians([10.0, 0.0, 80.0]), np.radians([10.0 + 180.0, 90.0, -80.0]))
    np.testing.assert_allclose(t, [0.0, np.sqrt(2.0), 2 * np.sin(np.radians(10.0))], atol=1e-12)


def test_bucketed_cost_equals_the_brute_force_reference_on_random_feature_sets():
    rng = np.random.default_rng(7)
    H = W = 24
    w = 10
    region = _l_region(w, 3)
    compared = points_compared = 0
    for _ in range(60):
        index = build_feature_index(*_random_features(rng, (H, W), 0.08))
        context = context_features(*_random_features(rng, (w, w), 0.15), region)
        off = np.array([rng.integers(0, H - w + 1), rng.integers(0, W - w + 1)])
        fp = np.stack([index.rows - off[0], index.cols - off[1]], axis=1)
        cp = np.stack([context.rows, context.cols], axis=1)
        inside = (fp[:, 0] >= 0) & (fp[:, 0] < w) & (fp[:, 1] >= 0) & (fp[:, 1] < w)
        in_region = inside.copy()
        in_region[inside] = region[fp[inside, 0], fp[inside, 1]]
        penalty = unmatched_penalty(index.shape, 0.1)
        tied = _tied(cp, context.bucket, fp, index.bucket)
        # W_f point by point (NumPy path) wherever the nearest features are unique
        match, g = match_features(context, index, off)
        ref_match, ref_g = match_features_reference(cp, context.tangent, fp, index.tangent, penalty=penalty)
        np.testing.assert_array_equal(match[~tied], ref_match[~tied])
        np.testing.assert_allclose(g[~tied], ref_g[~tied], rtol=0, atol=1e-9)
        points_compared += int((~tied).sum())
        # eq 2 (numba kernel) on the trials without ties
        if not tied.any():
            ref = matching_cost_reference(cp, context.tangent, fp, index.tangent, in_region, penalty=penalty)
            assert matching_cost(context, index, off) == pytest.approx(ref, abs=1e-9)
            compared += 1
    assert compared >= 15 and points_compared >= 300


def test_batched_costs_equal_single_costs():
    rng = np.random.default_rng(3)
    index = build_feature_index(*_random_features(rng, (40, 40), 0.1))
    context = context_features(*_random_features(rng, (16, 16), 0.1), _l_region(16, 4))
    offsets = np.stack(np.meshgrid(np.arange(25), np.arange(25), indexing="ij"), -1).reshape(-1, 2)
    batch = matching_costs(context, index, offsets)
    for k in (0, 7, 300, 624):
        assert batch[k] == pytest.approx(matching_cost(context, index, offsets[k]), abs=1e-12)


def test_identical_features_cost_zero_and_correspond_to_themselves():
    rng = np.random.default_rng(5)
    mask, tangent = _random_features(rng, (64, 64), 0.1)
    index = build_feature_index(mask, tangent)
    region = _l_region(32, 8)
    window = (slice(20, 52), slice(12, 44))
    context = context_features(mask[window], tangent[window], region)
    assert context.count > 0
    assert matching_cost(context, index, (20, 12)) == 0.0
    assert matching_cost(context, index, (21, 12)) > 0.0
    pairs = feature_correspondences(mask[window], tangent[window], mask[window], tangent[window], region)
    assert pairs.count == context.count
    np.testing.assert_array_equal(pairs.sources, pairs.targets)


def test_correspondences_follow_a_shifted_line_one_to_one():
    mask = np.zeros((24, 24), dtype=bool)
    mask[6, :] = True
    tangent = np.where(mask, 0.0, np.nan)
    patch_mask = np.roll(mask, 2, axis=0)  # the patch's line is 2 rows lower
    patch_tangent = np.where(patch_mask, 0.0, np.nan)
    extra = mask.copy()
    extra[7, :] = True  # a doubled context line: both rows map onto the same patch pixels
    pairs = feature_correspondences(
        extra, np.where(extra, 0.0, np.nan), patch_mask, np.where(patch_mask, 0.0, np.nan)
    )
    assert pairs.count == 24  # one-to-one: each patch pixel used once
    assert len({tuple(p) for p in pairs.sources}) == 24
    np.testing.assert_array_equal(pairs.targets[:, 0], 7.0)  # the nearer context row wins
    np.testing.assert_array_equal(pairs.sources[:, 0], 8.0)
    np.testing.assert_array_equal(pairs.sources[:, 1], pairs.targets[:, 1])
    # perpendicular tangents are never matched (bucket l + 2)
    vertical = feature_correspondences(mask, np.where(mask, np.pi / 2, np.nan), patch_mask, patch_tangent)
    assert vertical.count == 0
    assert feature_correspondences(mask, tangent, patch_mask, patch_tangent, max_distance=1.0).count == 0


def test_correspondences_with_no_patch_feature_are_none():
    """A context with features against a patch with none (filters on): no pair, no IndexError."""
    mask = np.zeros((16, 16), dtype=bool)
    mask[4, :] = True
    empty = np.zeros_like(mask)
    pairs = feature_correspondences(
        mask,
        np.where(mask, 0.0, np.nan),
        empty,
        np.full(mask.shape, np.nan),
        max_distance=4.0,
        max_angle=0.5,
    )
    assert pairs.count == 0


def test_candidate_cost_is_well_under_a_millisecond():
    rng = np.random.default_rng(11)
    index = build_feature_index(*_random_features(rng, (128, 128), 0.1))
    context = context_features(*_random_features(rng, (64, 64), 0.1), _l_region(64, 11))
    offsets = np.stack(np.meshgrid(np.arange(65), np.arange(65), indexing="ij"), -1).reshape(-1, 2)
    matching_costs(context, index, offsets[:2])  # compile / load the cached kernel
    start = time.process_time()
    matching_costs(context, index, offsets)
    per_candidate = (time.process_time() - start) / len(offsets)
    assert per_candidate < 1e-3


def test_bad_inputs_are_named():
    mask = np.zeros((16, 16), dtype=bool)
    mask[4, :] = True
    tangent = np.where(mask, 0.0, np.nan)
    index = build_feature_index(mask, tangent)
    context = context_features(mask[:8, :8], tangent[:8, :8])
    with pytest.raises(InvalidParameter, match="tau"):
        matching_cost(context, index, (0, 0), tau=-1.0)
    with pytest.raises(InvalidParameter, match="beta"):
        matching_cost(context, index, (0, 0), beta=float("nan"))
    with pytest.raises(InvalidParameter, match=r"offsets.*inside"):
        matching_cost(context, index, (9, 0))
    with pytest.raises(InvalidInput, match="boolean"):
        build_feature_index(mask.astype(np.uint8), tangent)
    with pytest.raises(InvalidInput, match="finite tangent"):
        build_feature_index(mask, np.full((16, 16), np.nan))
    with pytest.raises(InvalidInput, match="region"):
        context_features(mask, tangent, np.ones((4, 4), dtype=bool))
    with pytest.raises(InvalidParameter, match="max_distance"):
        feature_correspondences(mask, tangent, mask, tangent, max_distance=-1)


def _line(shape, row, cols, angle_deg):
    mask = np.zeros(shape, dtype=bool)
    mask[row, cols] = True
    return mask, np.where(mask, np.radians(angle_deg), np.nan)


def test_pairing_rejects_tangents_that_disagree():
    ctx = _line((24, 24), 6, slice(None), 0.0)
    agree = _line((24, 24), 8, slice(None), 10.0)  # 2 px lower, 10 degrees off
    cross = _line((24, 24), 8, slice(None), 40.0)  # 2 px lower, 40 degrees off: adjacent bucket
    limit = np.radians(30.0)
    assert feature_correspondences(*ctx, *agree, max_angle=limit).count == 24
    assert feature_correspondences(*cross[:1], *cross[1:], *ctx).count == 24  # the buckets admit it ...
    assert feature_correspondences(*ctx, *cross).count == 24
    assert feature_correspondences(*ctx, *cross, max_angle=limit).count == 0  # ... the gate does not
    with pytest.raises(InvalidParameter, match="max_angle"):
        feature_correspondences(*ctx, *agree, max_angle=2.0)


def test_normal_only_keeps_the_displacement_across_the_feature():
    ctx = _line((24, 24), 6, [8], 0.0)  # the end of a horizontal context feature
    patch = _line((24, 24), 8, [9, 10, 11], 0.0)  # a patch feature 2 rows lower, 1 col on
    raw = feature_correspondences(*ctx, *patch, max_distance=4.0)
    np.testing.assert_array_equal(raw.sources - raw.targets, [[2.0, 1.0]])  # nearest pixel: slides too
    pairs = feature_correspondences(*ctx, *patch, max_distance=4.0, normal_only=True)
    np.testing.assert_allclose(pairs.sources - pairs.targets, [[2.0, 0.0]], atol=1e-12)  # across only
    diagonal = feature_correspondences(
        *_line((24, 24), 6, [8], 45.0), *_line((24, 24), 8, [8], 45.0), normal_only=True
    )
    # a 45-degree feature (y up: rising to the right), moved 2 rows down: across it, (1, 1)
    np.testing.assert_allclose(diagonal.sources - diagonal.targets, [[1.0, 1.0]], atol=1e-12)


def test_thinning_keeps_spaced_controls_with_the_median_displacement():
    targets = np.array([[5.0, c] for c in range(12)])
    moves = np.zeros((12, 2))
    moves[:, 0] = 2.0
    moves[4] = [3.0, 0.0]  # a pixel of jitter
    pairs = Correspondences(targets=targets, sources=targets + moves, gdist=np.zeros(12))
    thin = thin_correspondences(pairs, 3.0)
    np.testing.assert_array_equal(thin.targets[:, 1], [0.0, 3.0, 6.0, 9.0])
    np.testing.assert_array_equal(thin.sources - thin.targets, [[2.0, 0.0]] * 4)  # the jitter is gone
    gaps = np.diff(thin.targets[:, 1])
    assert (gaps >= 3.0).all()
    assert thin_correspondences(pairs, 0.0) is pairs
    with pytest.raises(InvalidParameter, match="spacing"):
        thin_correspondences(pairs, -1.0)


def test_reverse_term_equals_the_brute_force_reference_on_random_feature_sets():
    """The reverse chamfer term (kernel) and eq 2 + lambda * it against the O(mn) references."""
    rng = np.random.default_rng(17)
    H = W = 24
    w = 10
    region = _l_region(w, 3)
    compared = 0
    for _ in range(80):
        index = build_feature_index(*_random_features(rng, (H, W), 0.08))
        context = context_features(*_random_features(rng, (w, w), 0.15), region)
        off = np.array([rng.integers(0, H - w + 1), rng.integers(0, W - w + 1)])
        fp = np.stack([index.rows - off[0], index.cols - off[1]], axis=1)
        cp = np.stack([context.rows, context.cols], axis=1)
        inside = (fp[:, 0] >= 0) & (fp[:, 0] < w) & (fp[:, 1] >= 0) & (fp[:, 1] < w)
        in_region = inside.copy()
        in_region[inside] = region[fp[inside, 0], fp[inside, 1]]
        # skip trials with ties either way (which of two equally near features is taken is arbitrary)
        if _tied(fp[in_region], index.bucket[in_region], cp, context.bucket).any():
            continue
        if _tied(cp, context.bucket, fp, index.bucket).any():
            continue
        back_penalty = unmatched_penalty((w, w), 0.1)
        ref = reverse_cost_reference(cp, context.tangent, fp, index.tangent, in_region, penalty=back_penalty)
        assert reverse_costs(context, index, off[None, :])[0] == pytest.approx(ref, abs=1e-9)
        full = matching_cost_reference(
            cp,
            context.tangent,
            fp,
            index.tangent,
            in_region,
            penalty=unmatched_penalty(index.shape, 0.1),
            reverse_weight=0.7,
            reverse_penalty=back_penalty,
        )
        assert matching_cost(context, index, off, reverse_weight=0.7) == pytest.approx(full, abs=1e-9)
        compared += int(in_region.any())
    assert compared >= 15


def test_reverse_term_penalises_spurious_candidate_features_and_eq_2_does_not():
    """A candidate with extra features that continue nothing costs more with lambda > 0, the same with 0."""
    w = 16
    region = _l_region(w, 5)
    ctx_mask, ctx_tan = _line((w, w), 2, slice(None), 0.0)  # one horizontal context fringe in the top strip
    context = context_features(ctx_mask, ctx_tan, region)
    clean = np.zeros((w, 3 * w), dtype=bool)
    clean[2, :] = True  # the input continues the fringe exactly
    cluttered = clean.copy()
    cluttered[4, 2 * w + 4 : 2 * w + 7] = True  # short pieces 2 rows below, in the second window only
    cluttered[8:11, 2 * w + 1] = True  # and a vertical piece in the left strip
    tangent_c = np.where(clean, 0.0, np.nan)
    tangent_x = np.where(cluttered, 0.0, np.nan)
    tangent_x[8:11, 2 * w + 1] = np.pi / 2
    clean_index = build_feature_index(clean, tangent_c)
    cluttered_index = build_feature_index(cluttered, tangent_x)
    offsets = np.array([[0, 2 * w]])
    # the paper's eq 2 (beta 0: the bijectivity term would count the extra features too): blind to them
    paper_clean = matching_costs(context, clean_index, offsets, beta=0.0)
    paper_cluttered = matching_costs(context, cluttered_index, offsets, beta=0.0)
    assert paper_clean[0] == 0.0 and paper_cluttered[0] == 0.0
    # the reverse term: 0 for the clean candidate, the mean distance of the extra features for the other
    assert reverse_costs(context, clean_index, offsets)[0] == 0.0
    back = reverse_costs(context, cluttered_index, offsets)[0]
    n = 16 + 3 + 3
    vertical = unmatched_penalty((w, w), 0.1)  # perpendicular to every context feature: no partner
    assert back == pytest.approx((3 * 2.0 + 3 * vertical) / n, abs=1e-12)
    sym = matching_costs(context, cluttered_index, offsets, beta=0.0, reverse_weight=0.5)
    assert sym[0] == pytest.approx(0.5 * back, abs=1e-12)
    assert matching_costs(context, clean_index, offsets, beta=0.0, reverse_weight=0.5)[0] == 0.0
    # lambda = 0 is eq 2 exactly (the same numbers, with the paper's beta too)
    np.testing.assert_array_equal(
        matching_costs(context, cluttered_index, offsets, reverse_weight=0.0),
        matching_costs(context, cluttered_index, offsets),
    )


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf"), True, "1"])
def test_reverse_weight_bad_values_are_named(bad):
    mask, tangent = _line((16, 16), 4, slice(None), 0.0)
    index = build_feature_index(mask, tangent)
    context = context_features(mask[:8, :8], tangent[:8, :8])
    with pytest.raises(InvalidParameter, match="reverse_weight"):
        matching_cost(context, index, (0, 0), reverse_weight=bad)


@pytest.mark.parametrize(
    ("image_shape", "window_shape", "density"),
    [
        ((128, 128), (40, 40), 0.1),  # a feature map and an L-shaped context's bounding window
        ((127, 93), (33, 17), 0.5),
        ((256, 256), (64, 64), 1.0),  # every pixel a feature: the largest counts
        ((50, 60), (50, 7), 0.3),  # the window as tall as the image: one row of offsets
        ((31, 29), (1, 1), 0.2),
    ],
)
def test_window_sums_round_to_scipy_signals_counts(image_shape, window_shape, density):
    """The region counts' correlation (FFT on the image's grid) gives, rounded, SciPy's integers."""
    from scipy.signal import correlate

    rng = np.random.default_rng(sum(image_shape) + sum(window_shape))
    image = (rng.random(image_shape) < density).astype(np.float64)
    window = (rng.random(window_shape) < 0.6).astype(np.float64)
    ours = window_sums(image, window)
    theirs = correlate(image, window, mode="valid")
    assert ours.shape == theirs.shape
    assert np.array_equal(np.rint(ours).astype(np.int64), np.rint(theirs).astype(np.int64))
    assert np.max(np.abs(ours - np.rint(ours))) < 1e-6  # counts, far from a rounding boundary
    r, c = rng.integers(0, theirs.shape[0]), rng.integers(0, theirs.shape[1])
    h, w = window_shape
    assert round(ours[r, c]) == int(np.sum(image[r : r + h, c : c + w] * window))
