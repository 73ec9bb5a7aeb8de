"""Minimum-error boundary cut: numba kernel vs NumPy reference vs brute force."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from synth.patch.cut import boundary_cut_mask, cut_cost, min_cut, min_cut_reference


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
