"""Per-patch kernels of the patch methods: the overlap search's arithmetic, the raster cut, the paste.

A patch of quilting, the Gaussian-patch models or feature-guided synthesis is searched by masked SSD
(:class:`texsynth.synth.patch.search.PatchSearcher`: ``SSD(q) = sum M E^2 - 2 sum M T E + sum M T^2``, the
middle term by FFT) and stitched along the Efros-Freeman cut (:mod:`texsynth.synth.patch.cut`). Written
as a few dozen small NumPy calls, one patch held Python's lock (GIL) between them for most of its time,
so the patches of a wave (:meth:`texsynth.synth.patch.layout.PatchLayout.waves`) ran one after the other
whatever the thread count. Here each step is one ``nogil`` numba call on contiguous arrays: the template's
masked terms (:func:`template_terms`), the error of every candidate position with the variance
normalisation and the usage factors (:func:`finish_errors`, ``SSD / (n (var_T + var_E(q)) + eps)``,
times ``1 + weight * excess use``), the candidates within ``(1 + tolerance)`` of the best
(:func:`candidates_within`, Efros & Freeman 2001, sec. 2.1), the region's gather, the top / left / L cut
(:func:`raster_cut`) and the paste with its source map (:func:`paste`). The FFTs stay in SciPy (which
releases the lock while it transforms).

Every kernel gives the bytes of the NumPy code it replaced: sums of many values use NumPy's pairwise
order (:func:`pairwise_sum`), the element-wise arithmetic is written in NumPy's operation order, and the
tests compare each kernel with its plain reference (NumPy, or :mod:`texsynth.synth.patch.cut`'s).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from texsynth.synth.kernels.options import kernel

__all__ = [
    "candidates_within",
    "cost_to_go",
    "error_surface",
    "finish_errors",
    "gather",
    "gather_many",
    "pairwise_sum",
    "paste",
    "raster_cut",
    "search_many",
    "search_many_serial",
    "stitch_many",
    "stitch_many_serial",
    "template_terms",
    "template_terms_many",
    "trace_cut",
    "usage_factors",
]

#: NumPy's block below which a pairwise sum is one unrolled loop (``PW_BLOCKSIZE``).
_BLOCK = 128


@kernel(nogil=True)
def _block_sum(a: np.ndarray, lo: int, n: int) -> float:  # pragma: no cover - numba
    """NumPy's ``pairwise_sum`` of ``a[lo:lo + n]`` for ``n <= 128``: eight running sums, then the rest."""
    if n < 8:
        res = -0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    end = n - n % 8
    while i < end:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@kernel(nogil=True)
def _pairwise(a: np.ndarray, lo: int, n: int) -> float:  # pragma: no cover - numba
    """NumPy's ``pairwise_sum`` of ``a[lo:lo + n]`` (a flat float64 array), the same rounding: blocks of at
    most 128 split in halves (each a multiple of 8 but the last), added as the recursion would, here with
    explicit stacks (a recursive kernel loaded from numba's cache crashes)."""
    todo = np.empty((128, 3), dtype=np.int64)  # (start, length, 1 = add the two values on top)
    values = np.empty(128, dtype=np.float64)
    top, nv = 0, 0
    todo[0, 0], todo[0, 1], todo[0, 2] = lo, n, 0
    top = 1
    while top > 0:
        top -= 1
        start, length, join = todo[top, 0], todo[top, 1], todo[top, 2]
        if join:
            nv -= 1
            values[nv - 1] = values[nv - 1] + values[nv]
        elif length <= _BLOCK:
            values[nv] = _block_sum(a, start, length)
            nv += 1
        else:
            half = length // 2
            half -= half % 8
            todo[top, 0], todo[top, 1], todo[top, 2] = 0, 0, 1
            todo[top + 1, 0], todo[top + 1, 1], todo[top + 1, 2] = start + half, length - half, 0
            todo[top + 2, 0], todo[top + 2, 1], todo[top + 2, 2] = start, half, 0
            top += 3
    return values[0]


@kernel(nogil=True)
def pairwise_sum(a: np.ndarray) -> float:  # pragma: no cover - numba
    """``np.sum(a)`` of a flat, contiguous float64 array, bit for bit (the reduction starts from 0)."""
    return 0.0 + _pairwise(a, 0, a.size)


@kernel(nogil=True)
def template_terms(
    weights: np.ndarray, template: np.ndarray
) -> tuple[np.ndarray, float, float]:  # pragma: no cover - numba
    """``M T`` (``(w, w, C)``), ``sum M T`` and ``sum M T^2`` of a template on its weights (NumPy's sums)."""
    mt = weights * template
    mtt = mt * template
    return mt, pairwise_sum(mt.ravel()), pairwise_sum(mtt.ravel())


@kernel(nogil=True)
def _finish_into(
    sums: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    terms: tuple[float, float, float, float],
    flags: tuple[bool, bool],
    err: np.ndarray,
    ssd: np.ndarray,
) -> None:  # pragma: no cover - numba
    """:func:`finish_errors` into ``err`` and ``ssd``."""
    energy, cross, first, factors = sums
    sum_t, sum_tt, n, eps = terms
    normalised, weighted = flags
    rows, cols = energy.shape
    mean_t = sum_t / n
    var_t = max(sum_tt / n - mean_t * mean_t, 0.0)  # x * x: what ** 2 compiles to (also unjitted)
    for i in range(rows):
        for j in range(cols):
            v = energy[i, j] - 2.0 * cross[i, j] + sum_tt
            if not (v >= 0.0 or np.isnan(v)):  # np.maximum(v, 0.0)
                v = 0.0
            ssd[i, j] = v
            if normalised:
                mean_e = first[i, j] / n
                var_e = energy[i, j] / n - mean_e * mean_e
                if not (var_e >= 0.0 or np.isnan(var_e)):
                    var_e = 0.0
                v = v / (n * (var_t + var_e + eps))
            if weighted:
                v = v * factors[i, j]
            err[i, j] = v


@kernel(nogil=True)
def finish_errors(
    sums: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    terms: tuple[float, float, float, float],
    flags: tuple[bool, bool],
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """The search error of every candidate position and its plain SSD, ``(P, Q)`` float64 each.

    ``sums = (energy, cross, first, factors)``, the ``(P, Q)`` fields; ``terms = (sum_t, sum_tt, n,
    eps)``, the template's; ``flags = (normalised, weighted)``. ``ssd = max(energy - 2 cross + sum_tt,
    0)``; with ``normalised``, the error is ``ssd / (n (var_T + var_E + eps))`` (``var_T`` from ``sum_t``,
    ``sum_tt``; ``var_E`` from ``energy`` and ``first``, the masked sums of ``E^2`` and ``E``), else
    ``ssd``; with ``weighted``, times ``factors``. ``first`` and ``factors`` are read only when asked for
    (pass any 2-D array otherwise).
    """
    shape = sums[0].shape
    ssd = np.empty(shape, dtype=np.float64)
    err = np.empty(shape, dtype=np.float64)
    _finish_into(sums, terms, flags, err, ssd)
    return err, ssd


@kernel(nogil=True)
def _candidates_into(errors: np.ndarray, tolerance: float, out: np.ndarray) -> int:  # pragma: no cover
    """:func:`candidates_within` into ``out`` (at least ``errors.size`` long); returns how many."""
    rows, cols = errors.shape
    best = np.inf
    for i in range(rows):
        for j in range(cols):
            if errors[i, j] < best:
                best = errors[i, j]
    bound = best * (1.0 + tolerance) + 1e-12 * max(1.0, best)
    count = 0
    for i in range(rows):
        for j in range(cols):
            if errors[i, j] <= bound:
                out[count] = i * cols + j
                count += 1
    return count


@kernel(nogil=True)
def candidates_within(errors: np.ndarray, tolerance: float) -> np.ndarray:  # pragma: no cover - numba
    """Flat indices (row-major) of the values of ``errors`` (2-D) within ``(1 + tolerance)`` of the
    least, ascending; with an exact match (least 0) every exact match."""
    out = np.empty(errors.size, dtype=np.int64)
    return out[: _candidates_into(errors, tolerance, out)].copy()


@kernel(nogil=True, parallel=True)
def search_many(
    masks: tuple[np.ndarray, np.ndarray],
    templates: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    factors: np.ndarray,
    settings: tuple[float, float],
    flags: tuple[bool, bool],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """:func:`finish_errors` and :func:`candidates_within` of ``k`` templates at once (numba's threads).

    ``masks = (energy, first)``: ``(u, P, Q)``, the masked sums of each mask; ``templates = (which, cross,
    sum_t, sum_tt, n)``: ``which`` (``k``) each template's mask, ``cross`` ``(k, >= P, >= Q)`` its FFT
    correlation (the first ``P x Q`` read), the sums and weights per template; ``settings = (eps,
    tolerance)``; ``flags = (normalised, weighted)``. Returns the errors and SSDs ``(k, P, Q)``, the
    candidates ``(k, P Q)`` (row ``b``'s first ``counts[b]``) and ``counts``.
    """
    energy, first = masks
    which, cross, sum_t, sum_tt, n = templates
    eps, tolerance = settings
    k = which.size
    _, rows, cols = energy.shape
    err = np.empty((k, rows, cols), dtype=np.float64)
    ssd = np.empty((k, rows, cols), dtype=np.float64)
    pools = np.empty((k, rows * cols), dtype=np.int64)
    counts = np.zeros(k, dtype=np.int64)
    for b in prange(k):
        u = which[b]
        sums = (energy[u], cross[b, :rows, :cols], first[u], factors)
        _finish_into(sums, (sum_t[b], sum_tt[b], n[b], eps), flags, err[b], ssd[b])
        counts[b] = _candidates_into(err[b], tolerance, pools[b])
    return err, ssd, pools, counts


#: :func:`search_many` on the calling thread alone: one chunk of a wave, several chunks at once on the
#: job's Python threads (the same body; :func:`texsynth.synth.kernels.options.kernel` names it apart).
search_many_serial = kernel(nogil=True)(getattr(search_many, "py_func", search_many))


@kernel(nogil=True)
def gather(image: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """``image[np.ix_(rows, cols)]``, a contiguous copy (``image``: ``(H, W, C)``)."""
    out = np.empty((rows.size, cols.size, image.shape[2]), dtype=image.dtype)
    for a in range(rows.size):
        for b in range(cols.size):
            for c in range(image.shape[2]):
                out[a, b, c] = image[rows[a], cols[b], c]
    return out


@kernel(nogil=True)
def error_surface(old: np.ndarray, new: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """``((old - new)^2).sum(axis=2)``, channels added in order (NumPy's sum over a short last axis)."""
    h, w, channels = old.shape
    e = np.empty((h, w), dtype=np.float64)
    for i in range(h):
        for j in range(w):
            acc = 0.0
            for c in range(channels):
                d = old[i, j, c] - new[i, j, c]
                acc += d * d
            e[i, j] = acc
    return e


@kernel(nogil=True)
def cost_to_go(errors: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """``C[i, j]``: least error of an 8-connected path from ``(i, j)`` down to the last row."""
    rows, cols = errors.shape
    cost = np.empty((rows, cols), dtype=np.float64)
    for j in range(cols):
        cost[rows - 1, j] = errors[rows - 1, j]
    for i in range(rows - 2, -1, -1):
        for j in range(cols):
            best = cost[i + 1, j]
            if j > 0 and cost[i + 1, j - 1] < best:
                best = cost[i + 1, j - 1]
            if j + 1 < cols and cost[i + 1, j + 1] < best:
                best = cost[i + 1, j + 1]
            cost[i, j] = errors[i, j] + best
    return cost


@kernel(nogil=True)
def trace_cut(cost: np.ndarray, row0: int, col0: int) -> np.ndarray:  # pragma: no cover - numba
    """The path of least cost-to-go from ``(row0, col0)`` (``col0 < 0``: the best start in ``row0``) down
    to the last row: its column in every row ``>= row0``, ``-1`` above."""
    rows, cols = cost.shape
    path = np.full(rows, -1, dtype=np.int64)
    j = col0
    if j < 0:
        j = 0
        for c in range(1, cols):
            if cost[row0, c] < cost[row0, j]:
                j = c
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


@kernel(nogil=True)
def raster_cut(e: np.ndarray, top: int, left: int) -> np.ndarray:  # pragma: no cover - numba
    """Where the new patch wins after the minimum-error cut of a top and/or left overlap: ``(w, w)``
    bool, from the error surface ``e`` (``(w, w)``, :func:`error_surface`).

    A left strip is cut top to bottom, a top strip left to right; an L's two cuts start at the corner
    pixel whose summed costs-to-go (the shared pixel once) are least (the first such in raster order).
    """
    w = e.shape[0]
    mask = np.ones((w, w), dtype=np.bool_)
    if top == 0 and left == 0:
        return mask
    if top == 0:
        path = trace_cut(cost_to_go(np.ascontiguousarray(e[:, :left])), 0, -1)
        for i in range(w):
            for j in range(path[i]):
                mask[i, j] = False
        return mask
    if left == 0:
        path = trace_cut(cost_to_go(np.ascontiguousarray(e[:top, :].T)), 0, -1)
        for j in range(w):
            for i in range(path[j]):
                mask[i, j] = False
        return mask
    vert = np.ascontiguousarray(e[:, :left])
    horiz = np.ascontiguousarray(e[:top, :].T)
    cv = cost_to_go(vert)
    ch = cost_to_go(horiz)
    i0, j0 = 0, 0
    best = np.inf
    for i in range(top):
        for j in range(left):
            v = cv[i, j] + ch[j, i] - e[i, j]
            if v < best:
                best = v
                i0, j0 = i, j
    pv = trace_cut(cv, i0, j0)  # rows >= i0: the vertical cut's column
    ph = trace_cut(ch, j0, i0)  # columns >= j0: the horizontal cut's row
    for i in range(w):
        for j in range(w):
            v_side = j >= pv[i] if i >= i0 else j >= j0
            h_side = i >= ph[j] if j >= j0 else i >= i0
            mask[i, j] = v_side and h_side
    return mask


@kernel(nogil=True)
def paste(
    image: np.ndarray,
    source: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    patch: np.ndarray,
    mask: np.ndarray,
    py: int,
    px: int,
) -> None:  # pragma: no cover - numba
    """Write ``patch`` (``(w, w, C)``) where ``mask`` into ``image[np.ix_(rows, cols)]`` and the source
    position (``(py + a, px + b)``, int32) into ``source`` (``(H, W, 2)``) there."""
    for a in range(rows.size):
        for b in range(cols.size):
            if mask[a, b]:
                y, x = rows[a], cols[b]
                for c in range(patch.shape[2]):
                    image[y, x, c] = patch[a, b, c]
                source[y, x, 0] = py + a
                source[y, x, 1] = px + b


@kernel(nogil=True)
def gather_many(image: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:  # pragma: no cover
    """:func:`gather` of ``k`` regions: ``rows``, ``cols`` ``(k, w)``; returns ``(k, w, w, C)``."""
    k, w = rows.shape
    out = np.empty((k, w, cols.shape[1], image.shape[2]), dtype=image.dtype)
    for b in range(k):
        out[b] = gather(image, rows[b], cols[b])
    return out


@kernel(nogil=True)
def template_terms_many(
    weights: np.ndarray, templates: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """:func:`template_terms` of ``k`` templates (``(k, w, w, C)`` each): ``M T`` ``(k, w, w, C)`` and
    the two sums ``(k,)``."""
    k = templates.shape[0]
    mt = np.empty(templates.shape, dtype=np.float64)
    sum_t = np.empty(k, dtype=np.float64)
    sum_tt = np.empty(k, dtype=np.float64)
    for b in range(k):
        m, s1, s2 = template_terms(weights[b], templates[b])
        mt[b] = m
        sum_t[b] = s1
        sum_tt[b] = s2
    return mt, sum_t, sum_tt


@kernel(nogil=True, parallel=True)
def stitch_many(
    canvas: tuple[np.ndarray, np.ndarray],
    places: tuple[np.ndarray, np.ndarray, np.ndarray],
    exemplar: np.ndarray,
    choices: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> np.ndarray:  # pragma: no cover - numba
    """Cut and paste ``k`` disjoint patches at once (numba's threads). ``canvas = (image, source)``, written
    in place; ``places = (rows, cols, regions)``: where each patch goes and the output it covers
    (``(k, w, w, C)``); ``choices = (pys, pxs, tops, lefts)``: patch ``b`` is the exemplar's at ``(pys[b],
    pxs[b])``, cut against ``regions[b]`` by :func:`raster_cut` with its ``tops[b]`` / ``lefts[b]``
    strips and pasted by :func:`paste` at ``rows[b]``, ``cols[b]``. Returns the new pixels' masks
    ``(k, w, w)``."""
    image, source = canvas
    rows, cols, regions = places
    pys, pxs, tops, lefts = choices
    k, w = rows.shape
    masks = np.empty((k, w, w), dtype=np.bool_)
    for b in prange(k):
        patch = exemplar[pys[b] : pys[b] + w, pxs[b] : pxs[b] + w]
        m = raster_cut(error_surface(regions[b], patch), tops[b], lefts[b])
        masks[b] = m
        paste(image, source, rows[b], cols[b], patch, m, pys[b], pxs[b])
    return masks


#: :func:`stitch_many` on the calling thread alone (see :data:`search_many_serial`).
stitch_many_serial = kernel(nogil=True)(getattr(stitch_many, "py_func", stitch_many))


@kernel(nogil=True)
def usage_factors(
    uses: np.ndarray, reach_box: np.ndarray, scale: float, weight: float, w: int
) -> np.ndarray:  # pragma: no cover - numba
    """``1 + weight * max(0, U / T - 1)`` at every ``w x w`` window of ``uses`` (``U``: the window's sum;
    ``T = reach_box * scale``), the usage penalty of :class:`texsynth.synth.patch.usage.UsagePenalty`.
    The window sums are NumPy's (cumulative sums down the columns, then along the rows, then the four
    corners), so fractional uses give the same bits too."""
    h, wd = uses.shape
    cs = np.zeros((h + 1, wd + 1), dtype=np.float64)
    for i in range(h):
        for j in range(wd):
            cs[i + 1, j + 1] = cs[i, j + 1] + uses[i, j]
    for i in range(h + 1):
        for j in range(1, wd + 1):
            cs[i, j] = cs[i, j - 1] + cs[i, j]
    rows, cols = h - w + 1, wd - w + 1
    out = np.empty((rows, cols), dtype=np.float64)
    for i in range(rows):
        for j in range(cols):
            box = cs[i + w, j + w] - cs[i, j + w] - cs[i + w, j] + cs[i, j]
            excess = box / (reach_box[i, j] * scale) - 1.0
            if not (excess >= 0.0 or np.isnan(excess)):
                excess = 0.0
            out[i, j] = 1.0 + weight * excess
    return out
