"""The exact KS p-value's recursion kernel (texsynth.synth.kernels.ks_exact) against its plain reference,
the Python loop in texsynth.synth.evaluate.measures, and scipy through the whole exact test."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from texsynth.synth.evaluate import measures
from texsynth.synth.kernels.ks_exact import ks_outer_prob_inside


def test_kernel_gives_the_reference_bits() -> None:
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(300):
        m, n = (int(v) for v in rng.integers(1, 400, 2))
        if m == n:
            continue
        g = math.gcd(m, n)
        h = int(rng.integers(1, (m // g) * n + 1))
        ref = measures._ks_outer_prob_inside(m, n, g, h)
        got = ks_outer_prob_inside(m, n, g, h)
        assert got == ref or (math.isnan(got) and not 0 <= ref <= 1), (m, n, g, h)
        checked += 0 < ref < 1
    assert checked > 50  # most cases are inside (0, 1), not at the shortcuts


def test_exact_test_still_matches_scipy() -> None:
    """Through the kernel (numba is loaded here), the exact test gives scipy's statistic and p-value."""
    rng = np.random.default_rng(5)
    for n1, n2 in ((120, 75), (300, 410), (33, 500)):
        a, b = rng.gamma(2.0, 5.0, n1), rng.gamma(2.2, 5.0, n2)
        got = measures._ks_2samp_exact(a, b)
        res = stats.ks_2samp(a, b, method="exact")
        assert got == (float(res.statistic), float(res.pvalue))
