"""Exemplar-usage penalty for patch searches: Chen & Wang's position histogram, carried to patches.

Every time a patch is pasted, the exemplar pixels it copied (or, for a Gaussian model, the pixels of the
neighbour it was built on) are counted. A candidate position ``q`` whose ``w x w`` footprint holds more
uses than its share has its search error multiplied by

    1 + weight * max(0, U(q) / T(q) - 1),

with ``U(q)`` the uses inside the footprint and ``T(q)`` the uses that footprint would hold if every
candidate position had been drawn equally often (the pixels' "reach", the number of positions whose
footprint covers them, times the uses so far over the total reach; so border pixels, which fewer
footprints cover, are not favoured). This is the factor of :func:`texsynth.synth.kernels.pixel_search` with
positions as labels (Chen & Wang 2010, "Texture synthesis with ... position histogram"; the pixel methods'
``position`` weighting). Over-used regions lose against equally good, under-used ones; a weight of 0 is
off. Measured in docs/patch.md: on HRTEM crops that mix ordered shells with a disordered core, the
overlap search otherwise keeps returning to one region of the exemplar.

References
----------
J. Chen, B. Wang, "High quality solid texture synthesis using position and index histogram matching",
The Visual Computer 26, 2010, pp. 253-262.
"""

from __future__ import annotations

import numpy as np

from texsynth.synth.kernels.patch_search import usage_factors

__all__ = ["UsagePenalty"]


def _box_sums(image: np.ndarray, w: int) -> np.ndarray:
    """Sums of ``image`` over every ``w x w`` window fully inside it, ``(h - w + 1, wd - w + 1)``."""
    cs = np.pad(image, ((1, 0), (1, 0))).cumsum(axis=0).cumsum(axis=1)
    return cs[w:, w:] - cs[:-w, w:] - cs[w:, :-w] + cs[:-w, :-w]


class UsagePenalty:
    """Uses of every exemplar pixel, and the factor they give each candidate position (module docstring).

    Parameters
    ----------
    exemplar_shape : tuple
        ``(h, w, ...)`` of the exemplar searched.
    w : int
        Patch side.
    weight : float
        Gain of the penalty, >= 0 (0: the factors are all 1).

    Examples
    --------
    >>> u = UsagePenalty((8, 8), 4, weight=1.0)
    >>> u.add(0, 0)
    >>> f = u.factors()
    >>> float(f[0, 0]) > 1.0, float(f[4, 4])
    (True, 1.0)
    """

    def __init__(self, exemplar_shape: tuple[int, ...], w: int, weight: float) -> None:
        if weight < 0:
            raise ValueError(f"weight: must be >= 0, got {weight}")
        h, wd = int(exemplar_shape[0]), int(exemplar_shape[1])
        self.w = int(w)
        self.weight = float(weight)
        self.uses = np.zeros((h, wd), dtype=np.float64)
        ones = np.ones((h - self.w + 1, wd - self.w + 1))
        # reach: how many candidate footprints cover each pixel (a full correlation of ones with the box)
        reach = np.zeros((h + 1, wd + 1))
        reach[: ones.shape[0], : ones.shape[1]] = ones
        reach = _box_sums(np.pad(reach, ((self.w - 1, 0), (self.w - 1, 0))), self.w)[:h, :wd]
        self.reach = reach
        self._reach_box = _box_sums(reach, self.w)
        self._reach_total = float(reach.sum())

    def add(self, y: int, x: int, mask: np.ndarray | None = None) -> None:
        """Count one use of the footprint at ``(y, x)`` (only its ``mask`` pixels when given)."""
        use = np.ones((self.w, self.w)) if mask is None else np.asarray(mask, dtype=np.float64)
        self.uses[y : y + self.w, x : x + self.w] += use

    def factors(self) -> np.ndarray:
        """``1 + weight * max(0, U/T - 1)`` at every candidate position, ``(h - w + 1, wd - w + 1)``
        (a numba kernel; :meth:`factors_reference` in NumPy)."""
        total = float(self.uses.sum())
        if self.weight == 0.0 or total == 0.0:
            return np.ones(self._reach_box.shape)
        return usage_factors(self.uses, self._reach_box, total / self._reach_total, self.weight, self.w)

    def factors_reference(self) -> np.ndarray:
        """:meth:`factors` in NumPy."""
        total = float(self.uses.sum())
        if self.weight == 0.0 or total == 0.0:
            return np.ones(self._reach_box.shape)
        target = self._reach_box * (total / self._reach_total)
        excess = np.maximum(_box_sums(self.uses, self.w) / target - 1.0, 0.0)
        return 1.0 + self.weight * excess
