"""Bucketed chamfer matching of curvilinear features (Wu & Yu 2004, section 2.1, eqs 1-2).

Feature-guided patch synthesis compares the feature pixels of the output's L-shaped context region
(``f_out``, ``m`` of them) with those of the input feature map under the same region translated to a
candidate position (``f_in``, ``n`` of them), and later aligns them by deformation
(:mod:`texsynth.synth.analysis.warp`). This module holds the matching cost and the correspondences:

- **eq 1**: ``gdist(f_out, f_in) = |f_out - f_in|_2 + tau |v_out - v_in|_2`` with unit tangents taken
  as orientations (:func:`tangent_difference`: ``2 sin(d / 2)``); ``tau = 0.1`` for matching, ``10``
  for the deformation's correspondences;
- **buckets** ``C_l``, ``l = 0..3``: tangents quantised into four 45-degree intervals centred on 0,
  45, 90 and -45 degrees (:func:`orientation_bucket`); ``W_f(f_out)`` is the nearest input feature of
  least ``gdist`` in the buckets ``l``, ``l - 1``, ``l + 1``, from one distance transform per bucket;
- **eq 2**: ``(1/m) sum_i gdist(f_i, W_f(f_i)) + beta (1/n) sum_j |B_f(f_j) - 1|``, ``beta = 0.3``,
  ``B_f(f_j)`` the number of context features mapped onto ``f_j``.

Departure: ``reverse_weight`` (``lambda``) adds the reverse chamfer term
``lambda (1/n) sum_j gdist(f_j, W_b(f_j))`` (the symmetric chamfer distance; ``lambda = 0`` is eq 2,
the same bytes; :func:`reverse_cost_reference` spells it out). Choices where the paper is silent (the
whole input map is searched, :func:`unmatched_penalty`, empty sums, ties) and why: docs/design.md
("chamfer matching").

References
----------
Q. Wu, Y. Yu, "Feature matching and deformation for texture synthesis", ACM TOG 23(3), 2004, pp. 364-367,
sections 2.1 (eqs 1-2) and 2.2. G. Borgefors, "Hierarchical chamfer matching: a parametric edge
matching algorithm", IEEE TPAMI 10(6), 1988, pp. 849-865.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sfft
from scipy import ndimage as ndi

from texsynth.synth.analysis.tensor import wrap_angle
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.kernels.options import kernel

__all__ = [
    "BETA",
    "MATCH_TAU",
    "N_BUCKETS",
    "REVERSE_WEIGHT",
    "WARP_TAU",
    "ContextFeatures",
    "Correspondences",
    "FeatureIndex",
    "build_feature_index",
    "context_features",
    "feature_correspondences",
    "match_features",
    "match_features_reference",
    "matching_cost",
    "matching_cost_reference",
    "matching_costs",
    "orientation_bucket",
    "reverse_cost_reference",
    "reverse_costs",
    "tangent_difference",
    "thin_correspondences",
    "unmatched_penalty",
]

N_BUCKETS = 4
#: tau of eq 1 for the matching cost (paper, section 2.1).
MATCH_TAU = 0.1
#: tau of eq 1 for the correspondences of the deformation step (paper, section 2.2).
WARP_TAU = 10.0
#: beta of eq 2 (paper, section 2.1, distances in pixels).
BETA = 0.3
#: Weight of the reverse chamfer term (not the paper; 0 = eq 2): the default of the feature-guided
#: method, measured on soot fringes (docs/feature-guided.md; module docstring, "the reverse term").
REVERSE_WEIGHT = 4.0
#: Order in which the three candidate buckets are tried (own bucket first): bucket offsets.
_BUCKET_STEPS = (0, -1, 1)


def orientation_bucket(theta: np.ndarray | float) -> np.ndarray:
    """Bucket ``l`` in ``0..3`` of tangent orientations: 45-degree intervals centred on 0, 45, 90, -45 deg.

    Examples
    --------
    >>> import numpy as np
    >>> orientation_bucket(np.radians([0.0, 30.0, 45.0, 90.0, -89.0, -45.0])).tolist()
    [0, 1, 1, 2, 2, 3]
    """
    t = wrap_angle(np.asarray(theta, dtype=np.float64))
    return (np.floor((t + np.pi / 8) / (np.pi / 4)).astype(np.int64) % N_BUCKETS).astype(np.int8)


def tangent_difference(t1: np.ndarray | float, t2: np.ndarray | float) -> np.ndarray:
    """``|v1 - v2|`` of the unit tangents of two orientations, modulo pi: ``2 sin(d / 2)``, ``d <= pi/2``.

    Examples
    --------
    >>> import numpy as np
    >>> tangent_difference(np.radians([0.0, 0.0, 89.0]), np.radians([180.0, 90.0, -89.0])).round(6).tolist()
    [0.0, 1.414214, 0.034905]
    """
    d = np.abs(wrap_angle(np.asarray(t1, dtype=np.float64) - np.asarray(t2, dtype=np.float64)))
    return 2.0 * np.sin(d / 2.0)


def unmatched_penalty(shape: tuple[int, int], tau: float) -> float:
    """``gdist`` given to a context feature that has no candidate in its three buckets."""
    return float(np.hypot(*shape) + tau * np.sqrt(2.0))


def _check_tau_beta(tau: float, beta: float | None = None) -> None:
    if not (isinstance(tau, int | float) and np.isfinite(tau) and tau >= 0):
        raise InvalidParameter(
            "tau", tau, "must be a finite number >= 0 (weight of tangent differences, eq 1)"
        )
    if beta is not None and not (isinstance(beta, int | float) and np.isfinite(beta) and beta >= 0):
        raise InvalidParameter("beta", beta, "must be a finite number >= 0 (weight of bijectivity, eq 2)")


def _check_reverse_weight(reverse_weight: float) -> None:
    if not (
        isinstance(reverse_weight, int | float)
        and not isinstance(reverse_weight, bool)
        and np.isfinite(reverse_weight)
        and reverse_weight >= 0
    ):
        raise InvalidParameter(
            "reverse_weight",
            reverse_weight,
            "must be a finite number >= 0 (weight of the candidate-to-context chamfer term; 0 = eq 2)",
        )


def _mask_and_tangent(role: str, mask: np.ndarray, tangent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    m = np.asarray(mask)
    t = np.asarray(tangent, dtype=np.float64)
    if m.ndim != 2 or m.size == 0:
        raise InvalidInput(role, f"feature mask must be a non-empty (H, W) array, got shape {m.shape}")
    if m.dtype != bool:
        raise InvalidInput(role, f"feature mask must be boolean, got {m.dtype}")
    if t.shape != m.shape:
        raise InvalidInput(role, f"tangent shape {t.shape} does not match mask shape {m.shape}")
    if not np.isfinite(t[m]).all():
        raise InvalidInput(role, "has feature pixels without a finite tangent")
    return m, t


@dataclass(frozen=True)
class FeatureIndex:
    """The input feature map prepared for constant-time nearest-feature queries per bucket.

    Attributes
    ----------
    shape : (int, int)
        ``(H, W)`` of the feature map.
    rows, cols : ndarray of int64, shape (n_total,)
        Feature pixels, raster order; a feature is referred to by its position in these arrays.
    tangent : ndarray of float64, shape (n_total,)
        Their tangent orientations.
    bucket : ndarray of int8, shape (n_total,)
        Their buckets (:func:`orientation_bucket`).
    nearest : ndarray of int32, shape (4, H, W)
        ``nearest[l, r, c]``: the feature of bucket ``l`` nearest to pixel ``(r, c)``, or -1 when the
        bucket is empty (the distance transforms' pointers).
    mask : ndarray of bool, shape (H, W)
        The feature mask.
    unit : ndarray of float64, shape (n_total, 2)
        Unit tangent vectors ``(cos, sin)`` (for the kernel).
    label : ndarray of int32, shape (H, W)
        ``label[r, c]``: the feature at pixel ``(r, c)`` (its position in ``rows``), -1 off the features
        (for the reverse term of :func:`matching_costs`).
    """

    shape: tuple[int, int]
    rows: np.ndarray
    cols: np.ndarray
    tangent: np.ndarray
    bucket: np.ndarray
    nearest: np.ndarray = field(repr=False)
    mask: np.ndarray = field(repr=False)
    unit: np.ndarray = field(repr=False)
    label: np.ndarray = field(repr=False)

    @property
    def count(self) -> int:
        """Number of feature pixels."""
        return len(self.rows)


def build_feature_index(mask: np.ndarray, tangent: np.ndarray) -> FeatureIndex:
    """One Euclidean distance transform per orientation bucket, with pointers to the nearest feature.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
        Feature pixels (e.g. :attr:`texsynth.synth.analysis.features.FeatureMap.mask`).
    tangent : ndarray of float, shape (H, W)
        Tangent orientations, finite at feature pixels.

    Returns
    -------
    FeatureIndex
    """
    m, t = _mask_and_tangent("feature map", mask, tangent)
    rows, cols = np.nonzero(m)
    tangents = t[rows, cols]
    buckets = orientation_bucket(tangents)
    label = np.full(m.shape, -1, dtype=np.int32)
    label[rows, cols] = np.arange(len(rows), dtype=np.int32)
    nearest = np.full((N_BUCKETS, *m.shape), -1, dtype=np.int32)
    for b in range(N_BUCKETS):
        sel = buckets == b
        if not sel.any():
            continue
        background = np.ones(m.shape, dtype=bool)
        background[rows[sel], cols[sel]] = False
        _, (ir, ic) = ndi.distance_transform_edt(background, return_distances=True, return_indices=True)
        nearest[b] = label[ir, ic]
    return FeatureIndex(
        shape=(int(m.shape[0]), int(m.shape[1])),
        rows=rows.astype(np.int64),
        cols=cols.astype(np.int64),
        tangent=tangents,
        bucket=buckets,
        nearest=nearest,
        mask=m,
        unit=np.stack([np.cos(tangents), np.sin(tangents)], axis=1),
        label=label,
    )


@dataclass(frozen=True)
class ContextFeatures:
    """The context region's feature pixels, in window coordinates, ready to be matched.

    Attributes
    ----------
    shape : (int, int)
        ``(h, w)`` of the window (the patch).
    region : ndarray of bool, shape (h, w)
        The overlap (context) region within the window.
    rows, cols : ndarray of int64, shape (m,)
        Context feature pixels inside ``region``.
    tangent : ndarray of float64, shape (m,)
    bucket : ndarray of int8, shape (m,)
    unit : ndarray of float64, shape (m, 2)
        Unit tangent vectors ``(cos, sin)``.
    """

    shape: tuple[int, int]
    region: np.ndarray = field(repr=False)
    rows: np.ndarray = field(repr=False)
    cols: np.ndarray = field(repr=False)
    tangent: np.ndarray = field(repr=False)
    bucket: np.ndarray = field(repr=False)
    unit: np.ndarray = field(repr=False)

    @property
    def count(self) -> int:
        """``m``, the number of context features."""
        return len(self.rows)


def context_features(
    mask: np.ndarray, tangent: np.ndarray, region: np.ndarray | None = None
) -> ContextFeatures:
    """Collect the feature pixels of a window's overlap region (the output side of eq 2).

    Parameters
    ----------
    mask : ndarray of bool, shape (h, w)
        Feature pixels of the output window (already synthesised part).
    tangent : ndarray of float, shape (h, w)
        Their tangents.
    region : ndarray of bool, shape (h, w), optional
        The overlap region (L-shaped for raster-order patches); default the whole window.
    """
    m, t = _mask_and_tangent("context", mask, tangent)
    reg = np.ones(m.shape, dtype=bool) if region is None else np.asarray(region)
    if reg.shape != m.shape or reg.dtype != bool:
        raise InvalidInput(
            "region", f"must be a boolean array of shape {m.shape}, got {reg.dtype} {reg.shape}"
        )
    rows, cols = np.nonzero(m & reg)
    tangents = t[rows, cols]
    return ContextFeatures(
        shape=(int(m.shape[0]), int(m.shape[1])),
        region=reg,
        rows=rows.astype(np.int64),
        cols=cols.astype(np.int64),
        tangent=tangents,
        bucket=orientation_bucket(tangents),
        unit=np.stack([np.cos(tangents), np.sin(tangents)], axis=1),
    )


def _offsets(context: ContextFeatures, index: FeatureIndex, offsets: np.ndarray) -> np.ndarray:
    off = np.asarray(offsets)
    if off.ndim == 1:
        off = off[None, :]
    if off.ndim != 2 or off.shape[1] != 2 or not np.issubdtype(off.dtype, np.integer):
        raise InvalidParameter(
            "offsets", f"array of shape {off.shape}", "must be integer (row, col) pairs, (k, 2)"
        )
    h, w = context.shape
    H, W = index.shape
    bad = (off[:, 0] < 0) | (off[:, 1] < 0) | (off[:, 0] + h > H) | (off[:, 1] + w > W)
    if bad.any():
        first = tuple(int(v) for v in off[np.argmax(bad)])
        raise InvalidParameter(
            "offsets", first, f"the {h}x{w} window must lie inside the {H}x{W} input feature map"
        )
    return off.astype(np.int64)


def _match(
    context: ContextFeatures, index: FeatureIndex, off: np.ndarray, tau: float
) -> tuple[np.ndarray, np.ndarray]:
    """Matches ``(k, m)`` (indices into the index's features, -1 for none) and their gdist ``(k, m)``."""
    qr = off[:, 0:1] + context.rows[None, :]
    qc = off[:, 1:2] + context.cols[None, :]
    best = np.full(qr.shape, -1, dtype=np.int64)
    best_g = np.full(qr.shape, unmatched_penalty(index.shape, tau))
    for step in _BUCKET_STEPS:
        b = (context.bucket.astype(np.int64) + step) % N_BUCKETS
        cand = index.nearest[b[None, :], qr, qc].astype(np.int64)
        ok = cand >= 0
        c = np.where(ok, cand, 0)
        if index.count == 0:
            continue
        g = np.hypot(index.rows[c] - qr, index.cols[c] - qc) + tau * tangent_difference(
            index.tangent[c], context.tangent[None, :]
        )
        better = ok & (g < best_g)
        best = np.where(better, cand, best)
        best_g = np.where(better, g, best_g)
    return best, best_g


def match_features(
    context: ContextFeatures,
    index: FeatureIndex,
    offset: tuple[int, int] | np.ndarray = (0, 0),
    *,
    tau: float = MATCH_TAU,
) -> tuple[np.ndarray, np.ndarray]:
    """The mapping ``W_f`` for one candidate position (paper, section 2.1).

    Parameters
    ----------
    context : ContextFeatures
        The output's context features, window coordinates.
    index : FeatureIndex
        The input feature map.
    offset : (int, int)
        Row and column of the window's top-left corner in the input map (the translation ``T``).
    tau : float
        Weight of the tangent difference in eq 1.

    Returns
    -------
    match : ndarray of int64, shape (m,)
        ``W_f(f_i^out)`` as an index into ``index.rows`` / ``index.cols``; -1 when no candidate.
    gdist : ndarray of float64, shape (m,)
        ``gdist(f_i^out, W_f(f_i^out))`` (eq 1), pixels.
    """
    _check_tau_beta(tau)
    off = _offsets(context, index, np.asarray(offset))
    best, g = _match(context, index, off, float(tau))
    return best[0], g[0]


def _region_counts(context: ContextFeatures, index: FeatureIndex, off: np.ndarray) -> np.ndarray:
    """``n`` per candidate: input features inside the region at each offset."""
    h, w = context.shape
    if len(off) <= 16:
        return np.array(
            [np.count_nonzero(index.mask[r : r + h, c : c + w] & context.region) for r, c in off],
            dtype=np.int64,
        )
    counts = _window_sums(index.mask.astype(np.float64), context.region.astype(np.float64))
    return np.rint(counts[off[:, 0], off[:, 1]]).astype(np.int64)


def _window_sums(image: np.ndarray, window: np.ndarray) -> np.ndarray:
    """``out[r, c] = sum(image[r : r + h, c : c + w] * window)`` at every offset where the ``(h, w)``
    window lies inside ``image``: ``scipy.signal.correlate(image, window, mode='valid')``.

    By FFT on ``image``'s grid (padded to fast lengths): a circular correlation, whose offsets inside
    the image never wrap. On 0/1 images the sums are counts, exact to far less than 0.5 either way, so
    they round to the same integers as SciPy's (tested); ``scipy.signal`` itself is not imported (it
    loads ``scipy.stats``: 0.1-0.2 s of every feature-guided command's start, docs/benchmarks.md).
    """
    (big_h, big_w), (h, w) = image.shape, window.shape
    shape = (sfft.next_fast_len(big_h, real=True), sfft.next_fast_len(big_w, real=True))
    spectrum = sfft.rfft2(image, s=shape) * np.conj(sfft.rfft2(window, s=shape))
    return sfft.irfft2(spectrum, s=shape)[: big_h - h + 1, : big_w - w + 1]


@kernel
def _matching_costs_kernel(
    ctx_rows: np.ndarray,
    ctx_cols: np.ndarray,
    ctx_cos: np.ndarray,
    ctx_sin: np.ndarray,
    ctx_bucket: np.ndarray,
    region: np.ndarray,
    nearest: np.ndarray,
    f_rows: np.ndarray,
    f_cols: np.ndarray,
    f_cos: np.ndarray,
    f_sin: np.ndarray,
    offsets: np.ndarray,
    n_region: np.ndarray,
    tau: float,
    beta: float,
    penalty: float,
) -> np.ndarray:  # pragma: no cover - compiled; compared with matching_cost_reference in the tests
    """Eq 2 at every offset: O(m) per candidate with one hit counter per input feature."""
    k = offsets.shape[0]
    m = ctx_rows.shape[0]
    h, w = region.shape
    out = np.empty(k, dtype=np.float64)
    hits = np.zeros(f_rows.shape[0], dtype=np.int64)
    counted = np.empty(m, dtype=np.int64)
    for q in range(k):
        r0 = offsets[q, 0]
        c0 = offsets[q, 1]
        total = 0.0
        m_in = 0
        d_in = 0
        for i in range(m):
            qr = r0 + ctx_rows[i]
            qc = c0 + ctx_cols[i]
            best = -1
            best_g = penalty
            for s in range(3):
                step = 0 if s == 0 else (-1 if s == 1 else 1)
                b = (ctx_bucket[i] + step + N_BUCKETS) % N_BUCKETS
                j = nearest[b, qr, qc]
                if j < 0:
                    continue
                # |v_out - v_in| with v_in flipped into v_out's half-plane (tangents modulo pi)
                sign = 1.0 if ctx_cos[i] * f_cos[j] + ctx_sin[i] * f_sin[j] >= 0.0 else -1.0
                dv = math.hypot(ctx_cos[i] - sign * f_cos[j], ctx_sin[i] - sign * f_sin[j])
                g = math.hypot(f_rows[j] - qr, f_cols[j] - qc) + tau * dv
                if g < best_g:
                    best = j
                    best_g = g
            total += best_g
            counted[i] = -1
            if best >= 0:
                lr = f_rows[best] - r0
                lc = f_cols[best] - c0
                if 0 <= lr < h and 0 <= lc < w and region[lr, lc]:
                    m_in += 1
                    if hits[best] == 0:
                        d_in += 1
                    hits[best] += 1
                    counted[i] = best
        for i in range(m):
            if counted[i] >= 0:
                hits[counted[i]] = 0
        first = total / m if m > 0 else 0.0
        n = n_region[q]
        second = (n - 2 * d_in + m_in) / n if n > 0 else 0.0
        out[q] = first + beta * second
    return out


@kernel
def _reverse_costs_kernel(
    region: np.ndarray,
    label: np.ndarray,
    f_cos: np.ndarray,
    f_sin: np.ndarray,
    f_bucket: np.ndarray,
    ctx_nearest: np.ndarray,
    ctx_rows: np.ndarray,
    ctx_cols: np.ndarray,
    ctx_cos: np.ndarray,
    ctx_sin: np.ndarray,
    offsets: np.ndarray,
    tau: float,
    penalty: float,
) -> np.ndarray:  # pragma: no cover - compiled; compared with reverse_cost_reference in the tests
    """The reverse term at every offset: mean gdist from each region feature to its context partner."""
    k = offsets.shape[0]
    h, w = region.shape
    out = np.empty(k, dtype=np.float64)
    for q in range(k):
        r0 = offsets[q, 0]
        c0 = offsets[q, 1]
        total = 0.0
        n = 0
        for lr in range(h):
            for lc in range(w):
                if not region[lr, lc]:
                    continue
                j = label[r0 + lr, c0 + lc]
                if j < 0:
                    continue
                n += 1
                best_g = penalty
                for s in range(3):
                    step = 0 if s == 0 else (-1 if s == 1 else 1)
                    b = (f_bucket[j] + step + N_BUCKETS) % N_BUCKETS
                    i = ctx_nearest[b, lr, lc]
                    if i < 0:
                        continue
                    sign = 1.0 if ctx_cos[i] * f_cos[j] + ctx_sin[i] * f_sin[j] >= 0.0 else -1.0
                    dv = math.hypot(f_cos[j] - sign * ctx_cos[i], f_sin[j] - sign * ctx_sin[i])
                    g = math.hypot(ctx_rows[i] - lr, ctx_cols[i] - lc) + tau * dv
                    if g < best_g:
                        best_g = g
                total += best_g
        out[q] = total / n if n > 0 else 0.0
    return out


def _context_index(context: ContextFeatures) -> FeatureIndex:
    """The context's features as a :class:`FeatureIndex` of the window (distance transforms per bucket)."""
    mask = np.zeros(context.shape, dtype=bool)
    mask[context.rows, context.cols] = True
    tangent = np.full(context.shape, np.nan)
    tangent[context.rows, context.cols] = context.tangent
    return build_feature_index(mask, tangent)


def reverse_costs(
    context: ContextFeatures,
    index: FeatureIndex,
    offsets: np.ndarray,
    *,
    tau: float = MATCH_TAU,
) -> np.ndarray:
    """The reverse chamfer term ``(1/n) sum_j gdist(f_j^in, W_b(f_j^in))`` at many candidate positions.

    The other direction of eq 2's first term (module docstring, "the reverse term"): every input
    feature inside the overlapping region at the offset is matched to the nearest context feature
    of its own and the two adjacent buckets (eq 1's ``gdist``; no partner: :func:`unmatched_penalty`
    of the window), through four distance transforms of the context's features. A numba kernel,
    O(region area) per candidate; :func:`reverse_cost_reference` is the brute-force spelling.

    Parameters
    ----------
    context : ContextFeatures
    index : FeatureIndex
    offsets : ndarray of int, shape (k, 2)
        Top-left ``(row, col)`` of each candidate window in the input map.
    tau : float
        Weight of tangent differences in eq 1.

    Returns
    -------
    ndarray of float64, shape (k,)
        0 where the region holds no input feature.
    """
    _check_tau_beta(tau)
    off = _offsets(context, index, offsets)
    ctx = _context_index(context)
    return _reverse_costs_kernel(
        np.ascontiguousarray(context.region),
        index.label,
        index.unit[:, 0].copy(),
        index.unit[:, 1].copy(),
        index.bucket,
        ctx.nearest,
        ctx.rows,
        ctx.cols,
        ctx.unit[:, 0].copy(),
        ctx.unit[:, 1].copy(),
        off,
        float(tau),
        unmatched_penalty(context.shape, float(tau)),
    )


def matching_costs(
    context: ContextFeatures,
    index: FeatureIndex,
    offsets: np.ndarray,
    *,
    tau: float = MATCH_TAU,
    beta: float = BETA,
    reverse_weight: float = 0.0,
) -> np.ndarray:
    """Matching cost of eq 2 at many candidate positions (a numba kernel, O(m) per candidate).

    Parameters
    ----------
    context : ContextFeatures
        ``f^out``: the context features and the overlap region, window coordinates.
    index : FeatureIndex
        The input feature map with its per-bucket distance transforms.
    offsets : ndarray of int, shape (k, 2)
        Top-left ``(row, col)`` of each candidate window in the input map (the translations ``T``);
        every window must lie inside the map.
    tau, beta : float
        Weights of eqs 1 and 2 (paper: 0.1 and 0.3).
    reverse_weight : float
        ``lambda``, weight of the reverse chamfer term (:func:`reverse_costs`); 0 (default) is the
        paper's eq 2 and computes nothing more.

    Returns
    -------
    ndarray of float64, shape (k,)
        ``(1/m) sum_i gdist(f_i^out, W_f(f_i^out)) + beta (1/n) sum_j |B_f(f_j^in) - 1|``
        ``+ lambda (1/n) sum_j gdist(f_j^in, W_b(f_j^in))``; the sums over ``j`` run over the input
        features inside the region at that offset.

    Notes
    -----
    With ``M`` the context features mapped into the region and ``D`` the distinct region features
    they hit, ``sum_j |B_f - 1| = (n - D) + (M - D)``: unmatched region features count 1 each, a
    feature hit ``B`` times counts ``B - 1``. The kernel keeps one counter per input feature (the
    paper's "counter indicating the number of features to which it corresponds") and resets only
    the ones it touched, so a candidate costs O(m). :func:`matching_cost_reference` is the
    brute-force spelling the tests compare it with.
    """
    _check_tau_beta(tau, beta)
    _check_reverse_weight(reverse_weight)
    off = _offsets(context, index, offsets)
    n = _region_counts(context, index, off)
    costs = _matching_costs_kernel(
        context.rows,
        context.cols,
        context.unit[:, 0],
        context.unit[:, 1],
        context.bucket,
        context.region,
        index.nearest,
        index.rows,
        index.cols,
        index.unit[:, 0],
        index.unit[:, 1],
        off,
        n,
        float(tau),
        float(beta),
        unmatched_penalty(index.shape, float(tau)),
    )
    if reverse_weight > 0:
        costs = costs + float(reverse_weight) * reverse_costs(context, index, off, tau=tau)
    return costs


def matching_cost(
    context: ContextFeatures,
    index: FeatureIndex,
    offset: tuple[int, int] | np.ndarray,
    *,
    tau: float = MATCH_TAU,
    beta: float = BETA,
    reverse_weight: float = 0.0,
) -> float:
    """Matching cost for one candidate ``offset = (row, col)``: see :func:`matching_costs`."""
    costs = matching_costs(
        context, index, np.asarray(offset)[None, :], tau=tau, beta=beta, reverse_weight=reverse_weight
    )
    return float(costs[0])


# --- brute-force references -------------------------------------------------------------------


def match_features_reference(
    context_points: np.ndarray,
    context_tangents: np.ndarray,
    feature_points: np.ndarray,
    feature_tangents: np.ndarray,
    *,
    tau: float = MATCH_TAU,
    penalty: float = np.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """``W_f`` by brute force, O(mn): the slow, obvious spelling of :func:`match_features`.

    For each context feature and each of its three buckets (order ``l, l - 1, l + 1``), scan every
    input feature for the nearest one of that bucket (first of least distance in the given order);
    keep the candidate of least ``gdist`` (eq 1). Points are ``(row, col)`` pairs in one frame.

    Returns ``(match, gdist)``: indices into ``feature_points`` (-1 for none, with ``gdist =
    penalty``) and the distances.
    """
    cp = np.asarray(context_points, dtype=np.float64).reshape(-1, 2)
    fp = np.asarray(feature_points, dtype=np.float64).reshape(-1, 2)
    cb = orientation_bucket(np.asarray(context_tangents, dtype=np.float64)).reshape(-1)
    fb = orientation_bucket(np.asarray(feature_tangents, dtype=np.float64)).reshape(-1)
    ct = np.asarray(context_tangents, dtype=np.float64).reshape(-1)
    ft = np.asarray(feature_tangents, dtype=np.float64).reshape(-1)
    match = np.full(len(cp), -1, dtype=np.int64)
    gdist = np.full(len(cp), penalty, dtype=np.float64)
    for i in range(len(cp)):
        for step in _BUCKET_STEPS:
            bucket = (int(cb[i]) + step) % N_BUCKETS
            nearest, nearest_d = -1, np.inf
            for j in range(len(fp)):
                if fb[j] != bucket:
                    continue
                d = float(np.hypot(fp[j, 0] - cp[i, 0], fp[j, 1] - cp[i, 1]))
                if d < nearest_d:
                    nearest, nearest_d = j, d
            if nearest < 0:
                continue
            g = nearest_d + tau * float(tangent_difference(ft[nearest], ct[i]))
            if g < gdist[i]:
                match[i], gdist[i] = nearest, g
    return match, gdist


def matching_cost_reference(
    context_points: np.ndarray,
    context_tangents: np.ndarray,
    feature_points: np.ndarray,
    feature_tangents: np.ndarray,
    in_region: np.ndarray,
    *,
    tau: float = MATCH_TAU,
    beta: float = BETA,
    penalty: float = np.inf,
    reverse_weight: float = 0.0,
    reverse_penalty: float = np.inf,
) -> float:
    """Eq 2 by brute force: :func:`match_features_reference`, then ``B_f`` counted feature by feature.

    ``feature_points`` are all the input features that may be matched (the whole input map, in the
    context's frame); ``in_region[j]`` says whether feature ``j`` lies in the overlapping region (the
    ``n`` features that the second term sums over). With ``reverse_weight`` the reverse term
    (:func:`reverse_cost_reference`, unmatched features at ``reverse_penalty``) is added.
    """
    match, gdist = match_features_reference(
        context_points, context_tangents, feature_points, feature_tangents, tau=tau, penalty=penalty
    )
    region = np.asarray(in_region, dtype=bool).reshape(-1)
    first = float(np.mean(gdist)) if len(gdist) else 0.0
    hits: dict[int, int] = {}
    for j in match:
        if j >= 0:
            hits[int(j)] = hits.get(int(j), 0) + 1
    n = int(region.sum())
    second = sum(abs(hits.get(j, 0) - 1) for j in np.flatnonzero(region)) / n if n else 0.0
    cost = first + beta * second
    if reverse_weight > 0:
        cost += reverse_weight * reverse_cost_reference(
            context_points,
            context_tangents,
            feature_points,
            feature_tangents,
            region,
            tau=tau,
            penalty=reverse_penalty,
        )
    return cost


def reverse_cost_reference(
    context_points: np.ndarray,
    context_tangents: np.ndarray,
    feature_points: np.ndarray,
    feature_tangents: np.ndarray,
    in_region: np.ndarray,
    *,
    tau: float = MATCH_TAU,
    penalty: float = np.inf,
) -> float:
    """The reverse term by brute force: :func:`match_features_reference` with the roles swapped.

    Each input feature with ``in_region[j]`` is matched against all the context features (O(mn));
    the mean of their ``gdist`` (0 when there is none) is the slow, obvious spelling of
    :func:`reverse_costs`.
    """
    region = np.asarray(in_region, dtype=bool).reshape(-1)
    fp = np.asarray(feature_points, dtype=np.float64).reshape(-1, 2)[region]
    ft = np.asarray(feature_tangents, dtype=np.float64).reshape(-1)[region]
    if len(fp) == 0:
        return 0.0
    _, gdist = match_features_reference(fp, ft, context_points, context_tangents, tau=tau, penalty=penalty)
    return float(np.mean(gdist))


# --- correspondences for the deformation ------------------------------------------------------


@dataclass(frozen=True)
class Correspondences:
    """One-to-one feature correspondences ``(x_i, x'_i)`` between the context and a patch (section 2.2).

    Attributes
    ----------
    targets : ndarray of float64, shape (k, 2)
        ``x_i``: context feature pixels, ``(row, col)`` in window coordinates.
    sources : ndarray of float64, shape (k, 2)
        ``x'_i``: the corresponding patch feature pixels, same frame.
    gdist : ndarray of float64, shape (k,)
        Their ``gdist`` (eq 1, with the ``tau`` used).
    """

    targets: np.ndarray
    sources: np.ndarray
    gdist: np.ndarray

    @property
    def count(self) -> int:
        """Number of pairs."""
        return len(self.gdist)


def feature_correspondences(
    context_mask: np.ndarray,
    context_tangent: np.ndarray,
    patch_mask: np.ndarray,
    patch_tangent: np.ndarray,
    region: np.ndarray | None = None,
    *,
    tau: float = WARP_TAU,
    max_distance: float | None = None,
    max_angle: float | None = None,
    normal_only: bool = False,
) -> Correspondences:
    """The mapping ``W'_f`` of section 2.2, made one-to-one: context feature -> patch feature.

    Parameters
    ----------
    context_mask, context_tangent : ndarray, shape (h, w)
        Feature pixels and tangents of the output window (the context).
    patch_mask, patch_tangent : ndarray, shape (h, w)
        Feature pixels and tangents of the chosen input patch, same window frame.
    region : ndarray of bool, shape (h, w), optional
        The overlap region; both sides' features are taken inside it (default: the whole window).
    tau : float
        Weight of tangents in eq 1; the paper uses 10 here "to emphasize tangents".
    max_distance : float, optional
        Drop pairs farther apart than this many pixels (the paper keeps all).
    max_angle : float, optional
        Drop pairs whose tangent orientations differ by more than this (radians, modulo pi). Eq 1
        with ``tau = 10`` only *penalises* a tangent difference, and the adjacent buckets admit up
        to 67.5 degrees: where nothing parallel lies near, a crossing feature is paired, and the
        warp then bends one feature onto another that does not continue it.
    normal_only : bool
        Keep only the component of each displacement along the context feature's normal: the
        source becomes ``x_i + ((x'_i - x_i) . n_i) n_i``. Two pieces of one curve meet when they lie
        on the same curve; where along it the nearest pixel happens to be is noise of the pixel grid
        (up to half a pixel) that would otherwise shear the patch along its features.

    Returns
    -------
    Correspondences
        Pairs with distinct patch features: when ``W'_f`` maps several context features onto one
        patch feature, the one of least ``gdist`` is kept ("we enforce a one-to-one mapping by
        removing extraneous corresponding features from the context region"); ties go to the
        first context feature in raster order. The filters (distance, angle) act before that
        choice, so a rejected pair does not displace an acceptable one.

    Notes
    -----
    ``W'_f`` is the bucketed approximation of :func:`match_features`, with the distance transforms
    of the patch's own features inside the region, so every source lies on a patch feature.
    """
    _check_tau_beta(tau)
    if max_distance is not None and not (
        isinstance(max_distance, int | float) and np.isfinite(max_distance) and max_distance >= 0
    ):
        raise InvalidParameter("max_distance", max_distance, "must be a finite number of pixels >= 0")
    if max_angle is not None and not (
        isinstance(max_angle, int | float) and np.isfinite(max_angle) and 0 <= max_angle <= np.pi / 2
    ):
        raise InvalidParameter("max_angle", max_angle, "must be an angle in [0, pi/2] radians")
    context = context_features(context_mask, context_tangent, region)
    pm, pt = _mask_and_tangent("patch", patch_mask, patch_tangent)
    if pm.shape != context.shape:
        raise InvalidInput("patch", f"shape {pm.shape} does not match the context window {context.shape}")
    index = build_feature_index(pm & context.region, np.where(pm & context.region, pt, np.nan))
    match, g = match_features(context, index, (0, 0), tau=tau)
    keep = match >= 0
    if max_distance is not None and keep.any():  # (no pair: nothing to filter, and no feature to index)
        c = np.where(keep, match, 0)
        dist = np.hypot(index.rows[c] - context.rows, index.cols[c] - context.cols)
        keep &= dist <= max_distance
    if max_angle is not None and keep.any():
        c = np.where(keep, match, 0)
        turn = np.abs(wrap_angle(index.tangent[c] - context.tangent))
        keep &= turn <= max_angle + 1e-12
    order = np.lexsort((np.arange(len(g)), g))  # by gdist, then raster order
    order = order[keep[order]]
    _, first = np.unique(match[order], return_index=True)
    chosen = np.sort(order[first])
    targets = np.stack([context.rows[chosen], context.cols[chosen]], axis=1).astype(np.float64)
    sources = np.stack([index.rows[match[chosen]], index.cols[match[chosen]]], axis=1).astype(np.float64)
    targets, sources = targets.reshape(-1, 2), sources.reshape(-1, 2)
    if normal_only and len(chosen):
        # the normal of a tangent theta (y up) in (row, col): (cos theta, sin theta)
        theta = context.tangent[chosen]
        normal = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        along = ((sources - targets) * normal).sum(axis=1, keepdims=True)
        sources = targets + along * normal
    return Correspondences(targets=targets, sources=sources, gdist=g[chosen])


def thin_correspondences(pairs: Correspondences, spacing: float) -> Correspondences:
    """Control points at least ``spacing`` px apart, each carrying the median displacement around it.

    A warp fitted exactly through every pixel of a context feature follows the one-pixel jitter of
    two independently thinned feature maps (neighbouring pairs displaced by 0 and 1 px): the spline
    then ripples, and straight features come out wavy. Here the targets are taken greedily in order
    of ``gdist`` (then as given), skipping any closer than ``spacing`` to one already taken; each
    kept target gets the component-wise median of the displacements ``x'_i - x_i`` of all pairs
    within ``spacing`` of it (itself included), a robust local average.

    Parameters
    ----------
    pairs : Correspondences
    spacing : float
        Minimum distance between kept targets, pixels; ``0`` returns the pairs unchanged.

    Returns
    -------
    Correspondences
        The kept targets (in their original order), with ``sources = targets + median displacement``
        and their own ``gdist``.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.array([[5.0, c] for c in range(8)])
    >>> d = np.zeros((8, 2)); d[3] = [1.0, 0.0]             # one pixel of jitter on a straight line
    >>> thin = thin_correspondences(Correspondences(t, t + d, np.zeros(8)), 3.0)
    >>> thin.targets[:, 1].tolist(), float(np.abs(thin.sources - thin.targets).max())
    ([0.0, 3.0, 6.0], 0.0)
    """
    if not (isinstance(spacing, int | float) and np.isfinite(spacing) and spacing >= 0):
        raise InvalidParameter("spacing", spacing, "must be a finite number of pixels >= 0")
    if spacing == 0 or pairs.count < 2:
        return pairs
    t, s = pairs.targets, pairs.sources
    disp = s - t
    near = np.hypot(*(t[:, None, :] - t[None, :, :]).transpose(2, 0, 1)) < spacing
    taken = np.zeros(pairs.count, dtype=bool)
    blocked = np.zeros(pairs.count, dtype=bool)
    for i in np.lexsort((np.arange(pairs.count), pairs.gdist)):
        if blocked[i]:
            continue
        taken[i] = True
        blocked |= near[i]
    keep = np.flatnonzero(taken)
    moved = np.stack([np.median(disp[near[i]], axis=0) for i in keep]).reshape(-1, 2)
    return Correspondences(targets=t[keep], sources=t[keep] + moved, gdist=pairs.gdist[keep])
