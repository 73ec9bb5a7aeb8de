"""Gaussian patch models against dense NumPy/SciPy references (explicit Gaussian conditioning)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg

from texsynth.synth.patch.gaussian import (
    GaussianPatchModel,
    clg_patch,
    lg_patch,
    localisation_taper,
    mend_inner_edges,
    rclg_draw,
    rclg_neighbour,
    rclg_patch,
    restore_contrast,
)
from texsynth.synth.patch.layout import Strips, overlap_mask


def _case(seed: int = 0, n: int = 8, w: int = 5, channels: int = 1):
    rng = np.random.default_rng(seed)
    patches = rng.random((n, w, w, channels))
    model = GaussianPatchModel.from_patches(patches)
    known = np.repeat(overlap_mask(w, 2, "L")[..., None], channels, axis=2).ravel()
    y0 = rng.random(int(known.sum()))
    return patches, model, known, y0


def test_model_is_eq1():
    patches, model, _, _ = _case()
    P = patches.reshape(len(patches), -1)
    np.testing.assert_allclose(model.mu, P.mean(axis=0))
    np.testing.assert_allclose(model.covariance(), np.cov(P.T, bias=True), atol=1e-12)


@pytest.mark.parametrize("channels", [1, 3])
def test_clg_is_the_dense_conditional_mean(channels):
    _, model, known, y0 = _case(channels=channels)
    sigma = 0.05
    G = model.covariance(sigma)
    S = ~known
    want = model.mu[S] + G[np.ix_(S, known)] @ linalg.solve(G[np.ix_(known, known)], y0 - model.mu[known])
    got = clg_patch(model, known, y0, sigma)
    np.testing.assert_allclose(got[S], want, atol=1e-10)
    np.testing.assert_array_equal(got[known], y0)


def test_rclg_is_eq7():
    _, model, known, y0 = _case(seed=2)
    sigma, theta = 0.05, 0.2
    G = model.covariance(sigma)
    M = np.eye(G.shape[0])[known]
    Ginv_mu = linalg.solve(G, model.mu)
    lhs = theta**2 * linalg.solve(G, np.eye(G.shape[0])) + M.T @ M
    want = linalg.solve(lhs, M.T @ y0 + theta**2 * Ginv_mu)
    np.testing.assert_allclose(rclg_patch(model, known, y0, sigma, theta), want, atol=1e-9)


def test_rclg_limits():
    _, model, known, y0 = _case(seed=3)
    clg = clg_patch(model, known, y0, 0.05)
    np.testing.assert_allclose(rclg_patch(model, known, y0, 0.05, 1e-6), clg, atol=1e-8)
    np.testing.assert_allclose(rclg_patch(model, known, y0, 0.05, 1e6), model.mu, atol=1e-8)


def test_lg_draws_have_the_model_statistics():
    _, model, _, _ = _case(n=6)
    rng = np.random.default_rng(0)
    draws = np.array([lg_patch(model, rng) for _ in range(20000)])
    np.testing.assert_allclose(draws.mean(axis=0), model.mu, atol=0.01)
    np.testing.assert_allclose(np.cov(draws.T, bias=True), model.covariance(), atol=0.01)


@pytest.mark.parametrize("theta", [0.0, 0.3])
def test_conditional_draws_average_to_the_most_probable_patch(theta):
    _, model, known, y0 = _case(seed=4, n=6)
    rng = np.random.default_rng(0)
    draws = np.array([rclg_draw(model, known, y0, 0.1, theta, rng) for _ in range(4000)])
    np.testing.assert_allclose(draws.mean(axis=0), rclg_patch(model, known, y0, 0.1, theta), atol=0.025)
    if theta == 0.0:
        np.testing.assert_allclose(draws[:, known], np.broadcast_to(y0, draws[:, known].shape), atol=1e-12)


class _Pick:
    """An rng stand-in whose ``integers`` returns a chosen index (to enumerate the neighbours)."""

    def __init__(self, j: int):
        self.j = j

    def integers(self, n):
        assert 0 <= self.j < n
        return self.j


@pytest.mark.parametrize("theta", [0.0, 0.2])
def test_neighbour_estimate_is_a_corrected_neighbour_whose_average_is_the_mean(theta):
    """Untapered, the corrected neighbours average to the most probable patch (the correction is linear);
    with a taper that is 0 on the new part, the new part is the neighbour itself and the overlap is as
    untapered; with a taper of 1 everywhere, nothing changes."""
    patches, model, known, y0 = _case(seed=5, n=6)
    P = patches.reshape(len(patches), -1)
    sigma = 0.1
    members = np.array([rclg_neighbour(model, known, y0, sigma, theta, _Pick(j)) for j in range(len(P))])
    np.testing.assert_allclose(members.mean(axis=0), rclg_patch(model, known, y0, sigma, theta), atol=1e-10)
    if theta == 0.0:
        np.testing.assert_allclose(members[:, known], np.tile(y0, (len(P), 1)), atol=1e-12)
    off = known.astype(np.float64)
    for j in (0, 3):
        cut = rclg_neighbour(model, known, y0, sigma, theta, _Pick(j), off)
        np.testing.assert_allclose(cut[~known], P[j, ~known], atol=1e-12)
        np.testing.assert_allclose(cut[known], members[j, known], atol=1e-12)
        ones = rclg_neighbour(model, known, y0, sigma, theta, _Pick(j), np.ones(known.size))
        np.testing.assert_allclose(ones, members[j], atol=1e-12)


def test_localisation_taper_is_one_on_the_overlap_and_falls_with_the_distance():
    known = overlap_mask(9, 2, "L")
    taper = localisation_taper(known, 3.0)
    np.testing.assert_array_equal(taper[known], 1.0)
    assert taper[-1, -1] == pytest.approx(np.exp(-0.5 * (7 / 3.0) ** 2))  # 7 px from both strips
    assert np.all(np.diff(taper[8, 2:]) < 0)  # along the last row, away from the left strip
    np.testing.assert_array_equal(localisation_taper(np.zeros((3, 3), bool), 1.0), 0.0)


def test_restore_contrast_gives_the_new_part_the_neighbours_spread_and_keeps_the_overlap():
    rng = np.random.default_rng(4)
    patches = rng.random((12, 6, 6))
    model = GaussianPatchModel.from_patches(patches)
    known = np.zeros(36, dtype=bool)
    known[:12] = True  # the first two rows are the overlap
    blurred = model.mu.copy()  # the conditional mean's typical failure: the neighbours' average
    out = restore_contrast(model, known, blurred)
    np.testing.assert_array_equal(out[known], blurred[known])
    want = patches.reshape(12, 36)[:, ~known].std(axis=1).mean()
    assert out[~known].std() == pytest.approx(want, rel=1e-12)
    assert out[~known].mean() == pytest.approx(blurred[~known].mean(), rel=1e-12)
    # a flat estimate stays flat (nothing to scale), and a patch with no new part is returned as is
    flat = np.full(36, 0.5)
    np.testing.assert_array_equal(restore_contrast(model, known, flat), flat)
    np.testing.assert_array_equal(restore_contrast(model, np.ones(36, bool), blurred), blurred)


@pytest.mark.parametrize("channels", [0, 3])
def test_mend_inner_edges_removes_the_jumps_and_keeps_the_rest(channels):
    """A smooth field whose new part is off by a constant (the jump a two-sided conditional patch leaves at
    its strips' inner edges) comes back exactly; the known part is never changed, and a patch without a
    jump is left as it is."""
    w = 12
    y, x = np.mgrid[0:w, 0:w].astype(np.float64)
    smooth = 0.3 + 0.02 * x + 0.01 * y
    if channels:
        smooth = np.stack([smooth, 1 - smooth, 0.5 * smooth], axis=-1)
    known = Strips(top=3, left=3, bottom=2, right=2).mask(w)
    jumpy = smooth.copy()
    jumpy[~known] += 0.25
    mended = mend_inner_edges(jumpy, known)
    assert mended.shape == smooth.shape
    np.testing.assert_allclose(mended, smooth, atol=1e-9)
    np.testing.assert_array_equal(mended[known], jumpy[known])
    np.testing.assert_allclose(mend_inner_edges(smooth, known), smooth, atol=1e-9)
