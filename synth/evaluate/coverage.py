"""Exemplar coverage: how much of the exemplar a patch-based output drew from, and how evenly.

A patch method that keeps picking one region of the exemplar (on a crop that mixes an ordered shell with a
disordered, low-contrast core, quilting and the Gaussian patch models settle in the core, docs/patch.md)
repeats that region and loses what the rest of the exemplar holds. Given the top-left exemplar positions
of the patches an output was built from (``Result.stats['patch_sources']`` of the patch methods), each
patch covers a ``w x w`` footprint of the exemplar; :func:`exemplar_coverage` reports

- ``share``: the fraction of exemplar pixels inside at least one used footprint;
- ``evenness``: how evenly the used pixels were used: the effective number of pixels, ``exp(H)`` with
  ``H`` the entropy of the footprint counts normalised to a distribution, over the number of pixels used
  (1 = every used pixel drawn equally often; every position of a 128^2 exemplar used once scores 0.80
  with w = 32, since the border pixels lie in fewer footprints);
- ``spread``: the RMS distance of the used positions from their mean over the RMS distance of all the
  candidate positions from theirs (1 = as spread as uniform draws, 0 = one position).

Weights (``Result.stats['patch_weights']`` of the Gaussian models' mean estimates, whose patch is learnt
from ``N`` neighbours at once) count a position fractionally. Chen & Wang (2010) balance the same usage
with their position histogram (the pixel methods' ``position`` weighting).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["exemplar_coverage", "footprint_counts"]


def _positions(sources: np.ndarray | Sequence[Sequence[int]]) -> np.ndarray:
    pos = np.asarray(sources, dtype=np.int64).reshape(-1, 2) if len(sources) else np.zeros((0, 2), np.int64)
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise ValueError(f"sources: expected (n, 2) positions, got shape {pos.shape}")
    return pos


def footprint_counts(
    sources: np.ndarray | Sequence[Sequence[int]],
    exemplar_shape: tuple[int, ...],
    patch_size: int,
    weights: np.ndarray | Sequence[float] | None = None,
) -> np.ndarray:
    """How many used patches (weighted) cover each exemplar pixel, ``(h, w)`` float64.

    Parameters
    ----------
    sources : (n, 2) ints
        Top-left exemplar positions (row, column) of the patches used.
    exemplar_shape : tuple
        The exemplar's shape (its first two entries are used).
    patch_size : int
        Side of the square patches.
    weights : (n,) floats, optional
        Weight of each position (default 1).
    """
    h, w = int(exemplar_shape[0]), int(exemplar_shape[1])
    p = int(patch_size)
    if not 1 <= p <= min(h, w):
        raise ValueError(f"patch_size: {patch_size} does not fit the exemplar ({h} x {w})")
    pos = _positions(sources)
    if pos.size and (pos.min() < 0 or pos[:, 0].max() > h - p or pos[:, 1].max() > w - p):
        raise ValueError("sources: a patch position lies outside the exemplar")
    wts = np.ones(len(pos)) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    if wts.shape != (len(pos),):
        raise ValueError(f"weights: expected {len(pos)} values, got {wts.size}")
    # a 2-D difference array of the footprints, then cumulative sums
    diff = np.zeros((h + 1, w + 1))
    np.add.at(diff, (pos[:, 0], pos[:, 1]), wts)
    np.add.at(diff, (pos[:, 0] + p, pos[:, 1]), -wts)
    np.add.at(diff, (pos[:, 0], pos[:, 1] + p), -wts)
    np.add.at(diff, (pos[:, 0] + p, pos[:, 1] + p), wts)
    return np.cumsum(np.cumsum(diff, axis=0), axis=1)[:h, :w]


def exemplar_coverage(
    sources: np.ndarray | Sequence[Sequence[int]],
    exemplar_shape: tuple[int, ...],
    patch_size: int,
    weights: np.ndarray | Sequence[float] | None = None,
) -> dict[str, float]:
    """Share of the exemplar used, evenness of its use and spread of the positions (module docstring).

    Returns
    -------
    dict
        ``share``, ``evenness`` and ``spread`` in [0, 1] (``spread`` can exceed 1 when the positions
        crowd the exemplar's borders), and ``patches``: the number of positions.

    Examples
    --------
    >>> cov = exemplar_coverage([(0, 0)] * 10, (64, 64), 16)
    >>> cov["share"], round(cov["evenness"], 6), cov["spread"]
    (0.0625, 1.0, 0.0)
    """
    h, w = int(exemplar_shape[0]), int(exemplar_shape[1])
    pos = _positions(sources)
    counts = footprint_counts(pos, exemplar_shape, patch_size, weights)
    total = counts.sum()
    if not len(pos) or total <= 0:
        return {"share": 0.0, "evenness": 0.0, "spread": 0.0, "patches": float(len(pos))}
    share = float(np.mean(counts > 0))
    prob = counts.ravel() / total
    nz = prob[prob > 0]
    evenness = float(np.exp(-(nz * np.log(nz)).sum()) / nz.size)
    wts = np.ones(len(pos)) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    centre = (wts[:, None] * pos).sum(axis=0) / wts.sum()
    rms = float(np.sqrt((wts * ((pos - centre) ** 2).sum(axis=1)).sum() / wts.sum()))
    # RMS distance of uniform positions over the (h - p + 1) x (w - p + 1) grid from its centre
    ny, nx = h - int(patch_size) + 1, w - int(patch_size) + 1
    uniform = float(np.sqrt((ny**2 - 1) / 12.0 + (nx**2 - 1) / 12.0))
    spread = rms / uniform if uniform > 0 else 1.0
    return {"share": share, "evenness": evenness, "spread": spread, "patches": float(len(pos))}
