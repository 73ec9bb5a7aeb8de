"""Minimum-error boundary cut: numba kernel vs NumPy reference vs brute force."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from texsynth.synth.patch.cut import boundary_cut_mask, cut_cost, min_cut, min_cut_reference, strips_cut_mask
from texsynth.synth.patch.layout import Strips


def _brute_vertical(errors: np.ndarray) -> float:
    rows, cols = errors.shape
    best = np.inf
    for start in range(cols):
        for steps in itertools.product((-1, 0, 1), repeat=rows - 1):
            path = [start]
            for s in steps:
                path.append(path[-1] + s)
            if min(path) < 0 or max(path) >= cols:
                continue
            best = min(best, float(errors[np.arange(rows), path].sum()))
    return best


@pytest.mark.parametrize("seed", range(5))
def test_min_cut_is_the_brute_force_minimum(seed):
    errors = np.random.default_rng(seed).random((6, 4))
    best = _brute_vertical(errors)
    for path in (min_cut(errors), min_cut_reference(errors)):
        assert np.all(np.abs(np.diff(path)) <= 1)
        assert cut_cost(errors, path) == pytest.approx(best)


def test_cut_follows_a_zero_valley():
    errors = np.ones((12, 5))
    valley = [1, 2, 3, 3, 2, 1, 0, 0, 1, 2, 3, 4]
    errors[np.arange(12), valley] = 0.0
    assert list(min_cut(errors)) == valley
    mask = boundary_cut_mask(np.pad(errors, ((0, 0), (0, 7)), constant_values=5.0), 5, "left")
    assert all(mask[i, valley[i]] and not mask[i, : valley[i]].any() for i in range(12))


def test_l_cut_meets_at_cheapest_corner_point():
    """Brute force: every meeting point and every pair of paths from it; the DP's total is the minimum."""
    rng = np.random.default_rng(3)
    w, o = 5, 2
    errors = rng.random((w, w))
    best = np.inf
    for i0, j0 in itertools.product(range(o), range(o)):
        for sv in itertools.product((-1, 0, 1), repeat=w - 1 - i0):
            pv = [j0]
            for s in sv:
                pv.append(pv[-1] + s)
            if min(pv) < 0 or max(pv) >= o:
                continue
            for sh in itertools.product((-1, 0, 1), repeat=w - 1 - j0):
                ph = [i0]
                for s in sh:
                    ph.append(ph[-1] + s)
                if min(ph) < 0 or max(ph) >= o:
                    continue
                cost = (
                    errors[np.arange(i0, w), pv].sum() + errors[ph, np.arange(j0, w)].sum() - errors[i0, j0]
                )
                best = min(best, float(cost))
    mask = boundary_cut_mask(errors, o, "L")
    # The DP's cut: read back its two paths from the mask and sum them like the brute force.
    i0 = int(np.argmax(mask[:o, :o].any(axis=1)))
    j0 = int(np.argmax(mask[i0, :o]))
    pv = [int(np.argmax(mask[i, :])) for i in range(i0, w)]
    ph = [int(np.argmax(mask[:, j])) for j in range(j0, w)]
    got = errors[np.arange(i0, w), pv].sum() + errors[ph, np.arange(j0, w)].sum() - errors[i0, j0]
    assert got == pytest.approx(best)
    assert mask[o:, o:].all() and not mask[0, 0]


def test_two_sided_cut_follows_a_valley_in_each_strip():
    """Left and right strips (a wrapped patch of a periodic layout): one cut per strip, each along its zero
    valley; left of the left cut and right of the right cut keep the old values."""
    w, left, right = 12, 4, 3
    errors = np.full((w, w), 5.0)
    lv = [1, 2, 2, 3, 2, 1, 0, 0, 1, 2, 3, 3]  # columns inside the left strip
    rv = [w - 1, w - 2, w - 3, w - 3, w - 2, w - 2, w - 1, w - 1, w - 2, w - 3, w - 2, w - 1]  # right strip
    errors[np.arange(w), lv] = 0.0
    errors[np.arange(w), rv] = 0.0
    mask = strips_cut_mask(errors, Strips(left=left, right=right))
    for i in range(w):
        assert (
            not mask[i, : lv[i]].any() and mask[i, lv[i] : rv[i] + 1].all() and not mask[i, rv[i] + 1 :].any()
        )
    # the same, transposed: top and bottom strips
    np.testing.assert_array_equal(strips_cut_mask(errors.T, Strips(top=left, bottom=right)), mask.T)


@pytest.mark.parametrize("seed", range(3))
def test_each_strip_cut_is_its_brute_force_minimum(seed):
    """A right strip's cut is the vertical minimum cut of the mirrored strip (brute force); the raster
    kinds give the masks they gave before (``boundary_cut_mask``)."""
    rng = np.random.default_rng(seed)
    w, o = 6, 3
    errors = rng.random((w, w))
    mask = strips_cut_mask(errors, Strips(left=2, right=o))
    # the right cut: the last new column in each row, mirrored into the strip's own frame
    last_new = np.array([int(np.flatnonzero(mask[i])[-1]) for i in range(w)])
    path = (w - 1) - last_new
    assert np.all((path >= 0) & (path < o)) and np.all(np.abs(np.diff(path)) <= 1)
    assert cut_cost(errors[:, ::-1][:, :o], path) == pytest.approx(_brute_vertical(errors[:, ::-1][:, :o]))
    for kind in ("left", "top", "L"):
        np.testing.assert_array_equal(
            strips_cut_mask(errors, Strips.of_kind(2, kind)), boundary_cut_mask(errors, 2, kind)
        )


@pytest.mark.parametrize("seed", range(3))
def test_four_sided_cut_takes_one_run_per_line_around_the_middle(seed):
    """All four strips: the new part is the patch's own pixels plus, in every row between the top and
    bottom strips (every column between the left and right ones), one run between the two cuts."""
    w = 10
    errors = np.random.default_rng(seed).random((w, w)) + 1.0
    mask = strips_cut_mask(errors, Strips(top=3, left=3, bottom=2, right=2))
    assert mask[3:-2, 3:-2].all()  # the patch's own pixels
    for line in (*mask[3:-2], *mask.T[3:-2]):
        runs = np.flatnonzero(np.diff(np.concatenate([[0], line.astype(int), [0]])))
        assert len(runs) <= 2  # at most one run of new pixels
    assert not mask.all()
