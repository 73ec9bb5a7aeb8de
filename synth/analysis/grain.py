"""Grain: the share of an image's variance finer than a pixel-scale Gaussian, and a blend that matches it.

``fine_share(x) = var(x - G_s * x) / var(x)`` with ``G_s`` a Gaussian of ``s`` = :data:`FINE_SIGMA` px: near 0
for smooth fringes, larger where neighbouring pixels disagree (speckle, noise). A synthesis whose slices
have a larger share than the exemplar's shows salt-and-pepper grain that the grey histogram (kept by a rank
remap), the structure tensor (smoothed over a window) and the fringe statistics do not see.

The fix this module serves (``solid-chen-wang``'s ``final_step``, docs/solid.md): a discrete volume ``D``
(every voxel one exemplar pixel) is blended with the least-squares average ``M`` of the same matches (Kopf et
al. 2007, eq 1's voxel), ``(1 - a) D + a M``. The high-pass is linear, so the blend's share is a ratio of two
quadratics in ``a`` whose six coefficients are sums over the sampled slices (:class:`GrainSums`, one pass);
:func:`blend_weight` returns the least ``a`` whose share is at most the exemplar's (0 when ``D`` is already
no grainier: nothing changes).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from texsynth.synth.analysis.split import gaussian_filter

__all__ = [
    "BLEND_SLAB",
    "BLEND_STEPS",
    "FINE_SIGMA",
    "SLICES_PER_AXIS",
    "GrainSums",
    "blend_weight",
    "blended",
    "fine_energies",
    "fine_share",
    "grain_sums",
    "match_grain",
]

#: Scale of the smoothing whose residual is the grain, pixels.
FINE_SIGMA = 1.0
#: Resolution of :func:`blend_weight`: ``a`` is a multiple of ``1 / BLEND_STEPS``.
BLEND_STEPS = 1000
#: Slices sampled per axis by :func:`grain_sums` (evenly spaced).
SLICES_PER_AXIS = 16
#: Planes blended at a time by :func:`blended`.
BLEND_SLAB = 8


def _high(image: np.ndarray, mode: str) -> np.ndarray:
    return image - gaussian_filter(image, FINE_SIGMA, mode=mode)


def fine_energies(image: np.ndarray, mode: str = "reflect") -> tuple[float, float]:
    """``(sum of the high-passed squares, sum of the centred squares)`` of a 2D image: the two sums whose
    ratio is :func:`fine_share`, kept apart so that several images pool."""
    x = np.asarray(image, dtype=np.float64)
    x = x - x.mean()
    return float(np.sum(_high(x, mode) ** 2)), float(np.sum(x * x))


def fine_share(image: np.ndarray, mode: str = "reflect") -> float:
    """The share of a 2D image's variance left after a Gaussian of :data:`FINE_SIGMA` px; 0 for a flat image.

    >>> fine_share(np.zeros((8, 8)))
    0.0
    >>> round(fine_share(np.tile([0.0, 1.0], (16, 8))), 3)  # a one-pixel grating: mostly grain
    0.919
    """
    fine, total = fine_energies(image, mode)
    return fine / total if total > 0 else 0.0


@dataclass(frozen=True)
class GrainSums:
    """Sums over slices of two volumes ``D`` and ``M``: high-passed (``hdd``, ``hdm``, ``hmm``) and centred
    (``dd``, ``dm``, ``mm``) products, from which the share of any blend ``(1 - a) D + a M`` follows."""

    hdd: float
    hdm: float
    hmm: float
    dd: float
    dm: float
    mm: float

    def share(self, a: np.ndarray | float) -> np.ndarray:
        """The blend's fine share at weight(s) ``a`` (0 where the blend is flat)."""
        a = np.asarray(a, dtype=np.float64)
        b = 1.0 - a
        num = b * b * self.hdd + 2.0 * a * b * self.hdm + a * a * self.hmm
        den = b * b * self.dd + 2.0 * a * b * self.dm + a * a * self.mm
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def _slices(shape: tuple[int, ...], axes: Iterable[int]) -> Iterable[tuple[int, int]]:
    for axis in axes:
        n = shape[axis]
        for i in np.unique(np.linspace(0, n - 1, min(n, SLICES_PER_AXIS)).round().astype(int)):
            yield axis, int(i)


def grain_sums(discrete: np.ndarray, average: np.ndarray, axes: Iterable[int], periodic: bool) -> GrainSums:
    """:class:`GrainSums` of two volumes of one shape over up to :data:`SLICES_PER_AXIS` slices normal to
    each of ``axes`` (one slice in memory at a time; the slices wrap when ``periodic``)."""
    if discrete.shape != average.shape or discrete.ndim != 3:
        raise ValueError(f"two volumes of one shape expected, got {discrete.shape} and {average.shape}")
    mode = "wrap" if periodic else "reflect"
    s = np.zeros(6)
    for axis, i in _slices(discrete.shape, axes):
        d = np.take(discrete, i, axis=axis).astype(np.float64)
        m = np.take(average, i, axis=axis).astype(np.float64)
        d -= d.mean()
        m -= m.mean()
        hd, hm = _high(d, mode), _high(m, mode)
        s += [np.sum(hd * hd), np.sum(hd * hm), np.sum(hm * hm), np.sum(d * d), np.sum(d * m), np.sum(m * m)]
    return GrainSums(*(float(v) for v in s))


def blended(discrete: np.ndarray, average: np.ndarray, a: float) -> np.ndarray:
    """``(1 - a) * discrete + a * average`` as float32, a slab of :data:`BLEND_SLAB` planes at a time (a
    volume's float64 average is not copied whole)."""
    out = np.empty(discrete.shape, dtype=np.float32)
    for z in range(0, discrete.shape[0], BLEND_SLAB):
        out[z : z + BLEND_SLAB] = (1.0 - a) * discrete[z : z + BLEND_SLAB] + a * average[z : z + BLEND_SLAB]
    return out


def blend_weight(sums: GrainSums, target: float) -> float:
    """The least ``a`` (a multiple of ``1 / BLEND_STEPS``) whose blend has a fine share at most ``target``:
    0 when the discrete volume's is already, 1 when even the average's is above it."""
    a = np.arange(BLEND_STEPS + 1) / BLEND_STEPS
    ok = np.flatnonzero(sums.share(a) <= target)
    return float(a[ok[0]]) if len(ok) else 1.0


def match_grain(
    discrete: np.ndarray,
    average: np.ndarray,
    exemplars: Iterable[np.ndarray],
    axes: Iterable[int],
    periodic: bool,
    blend: float | None = None,
) -> tuple[np.ndarray, float, dict[str, float]]:
    """``discrete`` blended with ``average`` by ``blend``, or (None) by the least weight whose slices normal
    to ``axes`` are no grainier than the ``exemplars``' mean :func:`fine_share`: ``(volume, weight, ratios)``,
    ``ratios`` the slices' grain over the exemplars' before (``'discrete'``) and after (``'final'``)."""
    target = float(np.mean([fine_share(image) for image in exemplars]))
    sums = grain_sums(discrete, average, list(axes), periodic)
    a = blend_weight(sums, target) if blend is None else float(blend)
    scale = max(target, 1e-12)
    ratios = {"discrete": float(sums.share(0.0)) / scale, "final": float(sums.share(a)) / scale}
    return (discrete if a == 0.0 else blended(discrete, average, a)), a, ratios
