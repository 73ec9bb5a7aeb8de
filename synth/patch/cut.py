"""Efros-Freeman minimum-error boundary cut over a patch's overlap (Efros & Freeman 2001, sec. 2.1).

The error surface ``e = ||old - new||^2`` (summed over channels) over a vertical overlap strip (``rows x
overlap``) is crossed top to bottom by the 8-connected path of least total error (dynamic programming:
``E(i, j) = e(i, j) + min(E(i-1, j-1), E(i-1, j), E(i-1, j+1))``); pixels left of the path keep the old
values, the path and the pixels right of it take the new patch's. A horizontal cut is the vertical cut of
the transposed strip. For an L-shaped overlap, the two cuts meet at the corner pixel where the sum of
their costs-to-go (counting the shared pixel once) is least, and each is traced from there.

A wrapped patch of a periodic layout (:class:`texsynth.synth.patch.layout.Strips`) is also known along its
right and/or bottom border: each of those strips gets its own cut, a DP across that strip alone (the strip
mirrored so that the cut runs from its outer border inward, the same kernel), and the new patch wins where
it wins for every cut (the intersection of their new sides: where two cuts cross in a corner square, the
seam follows one up to the crossing and the other from there). The strips' cuts are not optimised jointly.

The DP, the cuts of a top / left / L overlap and the error surface are numba kernels
(:mod:`texsynth.synth.kernels.patch_search`, ``nogil``: the patches of a wave cut at once on the job's
threads); :func:`min_cut_reference`, :func:`raster_cut_reference` and :func:`error_surface_reference` are
the plain NumPy versions the tests compare them with.
"""

from __future__ import annotations

import numpy as np

from texsynth.synth.kernels import patch_search as kernels
from texsynth.synth.patch.layout import Strips

__all__ = [
    "boundary_cut_mask",
    "cut_cost",
    "error_surface",
    "error_surface_reference",
    "min_cut",
    "min_cut_reference",
    "raster_cut_reference",
    "strips_cut_mask",
]


def min_cut_reference(errors: np.ndarray) -> np.ndarray:
    """Plain NumPy DP of the vertical minimum-error cut (top-down accumulation, then backtrack).

    Parameters
    ----------
    errors : ndarray, shape (rows, cols)
        Error surface of a vertical overlap strip.

    Returns
    -------
    ndarray of int, shape (rows,)
        The cut's column in every row.
    """
    e = np.asarray(errors, dtype=np.float64)
    rows, cols = e.shape
    acc = e.copy()
    for i in range(1, rows):
        prev = acc[i - 1]
        left = np.concatenate(([np.inf], prev[:-1]))
        right = np.concatenate((prev[1:], [np.inf]))
        acc[i] += np.minimum(np.minimum(left, prev), right)
    path = np.empty(rows, dtype=np.int64)
    path[-1] = int(np.argmin(acc[-1]))
    for i in range(rows - 2, -1, -1):
        j = path[i + 1]
        lo, hi = max(0, j - 1), min(cols, j + 2)
        path[i] = lo + int(np.argmin(acc[i, lo:hi]))
    return path


def _min_cut(errors: np.ndarray, row0: int = 0, col0: int = -1) -> np.ndarray:
    """The least-error 8-connected path from ``(row0, col0)`` to the last row (``col0 < 0``: the best start
    in ``row0``): its column in every row ``>= row0``, ``-1`` above (numba)."""
    e = np.ascontiguousarray(errors, dtype=np.float64)
    return kernels.trace_cut(kernels.cost_to_go(e), row0, col0)


def min_cut(errors: np.ndarray) -> np.ndarray:
    """The vertical minimum-error cut of ``errors`` (rows x cols): its column in every row (numba)."""
    return _min_cut(errors)


def cut_cost(errors: np.ndarray, path: np.ndarray) -> float:
    """Total error along a vertical ``path`` (entries ``< 0`` are skipped)."""
    rows = np.flatnonzero(np.asarray(path) >= 0)
    return float(np.asarray(errors, dtype=np.float64)[rows, np.asarray(path)[rows]].sum())


def error_surface(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """``||old - new||^2`` per pixel, summed over channels, float64 ``(h, w)`` (numba for ``(h, w, C)``
    float64 inputs; :func:`error_surface_reference` otherwise, the same bytes)."""
    if np.ndim(old) == 3 and np.shape(old) == np.shape(new):
        o = np.ascontiguousarray(old, dtype=np.float64)
        n = np.ascontiguousarray(new, dtype=np.float64)
        return kernels.error_surface(o, n)
    return error_surface_reference(old, new)


def error_surface_reference(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """:func:`error_surface` in NumPy."""
    d = np.asarray(old, dtype=np.float64) - np.asarray(new, dtype=np.float64)
    return (d * d).sum(axis=2) if d.ndim == 3 else d * d


def boundary_cut_mask(errors: np.ndarray, overlap: int, kind: str) -> np.ndarray:
    """Where the new patch wins: boolean ``(w, w)`` mask after the minimum-error boundary cut.

    Parameters
    ----------
    errors : ndarray, shape (w, w)
        ``||old - new||^2`` over the whole patch (only the overlap is read).
    overlap : int
        Overlap width.
    kind : {'none', 'left', 'top', 'L'}
        Which borders overlap earlier patches.

    Returns
    -------
    ndarray of bool, shape (w, w)
        True where the output takes the new patch (the cut itself included).
    """
    if kind == "none" or overlap == 0:
        return np.ones(np.shape(errors)[:2], dtype=bool)
    return strips_cut_mask(errors, Strips.of_kind(overlap, kind))


def raster_cut_reference(e: np.ndarray, top: int, left: int) -> np.ndarray:
    """The new side of the cut of a left (``left`` wide) and/or top (``top`` rows) overlap, in NumPy
    (:func:`texsynth.synth.kernels.patch_search.raster_cut` is the kernel the cuts use)."""
    w = e.shape[0]
    new = np.ones((w, w), dtype=bool)
    cols = np.arange(w)
    if top == 0 and left == 0:
        return new
    if top == 0:
        path = _trace_reference(_cost_to_go_reference(e[:, :left]), 0, -1)
        return cols[None, :] >= path[:, None]
    if left == 0:
        path = _trace_reference(_cost_to_go_reference(e[:top, :].T), 0, -1)
        return cols[:, None] >= path[None, :]
    # L: vertical strip (w x left) and horizontal strip (top x w) share the top x left corner.
    vert = np.ascontiguousarray(e[:, :left])
    horiz = np.ascontiguousarray(e[:top, :].T)  # transposed: rows = patch columns
    cv = _cost_to_go_reference(vert)
    ch = _cost_to_go_reference(horiz)
    corner = cv[:top, :left] + ch[:left, :top].T - e[:top, :left]
    i0, j0 = (int(v) for v in np.unravel_index(int(np.argmin(corner)), corner.shape))
    pv = _trace_reference(cv, i0, j0)  # rows i0.. : column of the vertical cut
    ph = _trace_reference(ch, j0, i0)  # patch columns j0.. : row of the horizontal cut
    rows = np.arange(w)
    v_side = np.where(rows[:, None] >= i0, cols[None, :] >= pv[:, None], cols[None, :] >= j0)
    h_side = np.where(cols[None, :] >= j0, rows[:, None] >= ph[None, :], rows[:, None] >= i0)
    new &= v_side & h_side
    return new


def _cost_to_go_reference(errors: np.ndarray) -> np.ndarray:
    """``C[i, j]``: least error of an 8-connected path from ``(i, j)`` down to the last row (NumPy)."""
    cost = np.array(errors, dtype=np.float64)
    for i in range(cost.shape[0] - 2, -1, -1):
        below = cost[i + 1]
        left = np.concatenate((below[:1], below[:-1]))
        right = np.concatenate((below[1:], below[-1:]))
        cost[i] += np.minimum(np.minimum(below, left), right)
    return cost


def _trace_reference(cost: np.ndarray, row0: int, col0: int) -> np.ndarray:
    """The path of least cost-to-go from ``(row0, col0)`` down (``col0 < 0``: the first best start in
    ``row0``; ties: the straight step, then left)."""
    rows, cols = cost.shape
    path = np.full(rows, -1, dtype=np.int64)
    j = col0 if col0 >= 0 else int(np.argmin(cost[row0]))
    path[row0] = j
    for i in range(row0 + 1, rows):
        best = j
        if j > 0 and cost[i, j - 1] < cost[i, best]:
            best = j - 1
        if j + 1 < cols and cost[i, j + 1] < cost[i, best]:
            best = j + 1
        j = best
        path[i] = j
    return path


def strips_cut_mask(errors: np.ndarray, strips: Strips) -> np.ndarray:
    """Where the new patch wins after the boundary cuts of any known strips (module docstring).

    Parameters
    ----------
    errors : ndarray, shape (w, w)
        ``||old - new||^2`` over the whole patch (only the strips are read).
    strips : Strips
        Widths of the known top, left, bottom and right strips; the top / left pair is cut as in
        :func:`boundary_cut_mask` (an L meets at its cheapest corner point), a right or bottom strip by its
        own cut from the patch's border inward.

    Returns
    -------
    ndarray of bool, shape (w, w)
        True where the output takes the new patch (the cuts included).

    Examples
    --------
    >>> e = np.ones((6, 6)); e[:, 1] = 0; e[:, 4] = 0  # a zero column in each strip
    >>> strips_cut_mask(e, Strips(left=2, right=2))[0].astype(int).tolist()
    [0, 1, 1, 1, 1, 0]
    """
    e = np.ascontiguousarray(errors, dtype=np.float64)
    w = e.shape[0]
    new = kernels.raster_cut(e, strips.top, strips.left)
    cols = np.arange(w)
    if strips.right:
        # mirrored strip: column c' is patch column w - 1 - c'; the new side is c' >= path
        path = _min_cut(e[:, ::-1][:, : strips.right])
        new &= cols[None, :] <= (w - 1 - path)[:, None]
    if strips.bottom:
        path = _min_cut(e[::-1, :][: strips.bottom, :].T)
        new &= cols[:, None] <= (w - 1 - path)[None, :]
    return new
