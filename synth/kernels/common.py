"""Small numba helpers that several kernels share, each written once.

- :func:`splitmix`: the counter-based 64-bit hash (SplitMix64's finaliser) that draws every kernel's
  random candidates from ``(seed key, position)``, so chunking and threads do not change them;
  :func:`splitmix_reference` is the same in plain Python integers, for the references.
- :func:`histogram_factor`: the histogram-matching penalty ``1 + weight * max(0, count / target - 1)``
  (Kopf et al. 2007, eq 4; Chen & Wang 2010's position and index histograms).
"""

from __future__ import annotations

import numpy as np

from texsynth.synth.kernels.options import kernel

__all__ = ["histogram_factor", "splitmix", "splitmix_reference"]

_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


@kernel(inline="always")
def splitmix(x: np.uint64) -> np.uint64:
    """SplitMix64's finaliser of ``x + golden ratio`` (uint64 in, uint64 out)."""
    z = x + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


def splitmix_reference(x: int) -> int:
    """:func:`splitmix` in plain Python integers."""
    mask = (1 << 64) - 1
    z = (x + 0x9E3779B97F4A7C15) & mask
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
    return z ^ (z >> 31)


@kernel(inline="always")
def histogram_factor(count, target, weight):
    """Histogram-matching penalty: a candidate whose label (its exemplar position, Chen & Wang's
    position histogram, or its orientation bin) the output already holds ``count`` times, against
    ``target`` wanted, has its distance multiplied by ``1 + weight * max(0, count / target - 1)``:
    over-represented labels lose against equally good, under-represented ones. A verbatim
    continuation (distance 0) is never penalised: the matching acts where copied patches meet."""
    excess = count / target - 1.0
    return 1.0 + weight * excess if excess > 0.0 else 1.0
