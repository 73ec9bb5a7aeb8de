"""k-coherence search and discrete solver over the three slice neighbourhoods of a volume (Chen & Wang 2010).

The volume ``(D, H, W) = (z, y, x)`` is synthesized as in Kopf et al. (2007) by alternating two passes:

- **search** (:func:`search_pass`): for every voxel ``v`` and constrained plane ``p``, the ``n x n`` slice
  through ``v`` is compared (SSD) with plane ``p``'s exemplar neighbourhoods; the best centre goes to
  ``match[p, v]``. Candidates are k-coherent (Tong et al. 2002): for each voxel ``u = v + d`` of a small
  slice window, ``match[p, u] - d`` and the ``k`` positions most similar to ``match[p, u]``, shifted by
  ``-d``. A distance is multiplied by the **index histogram** factor ``1 + index_weight * max(0, count /
  target - 1)`` (``count``: (voxel, plane) pairs matching that neighbourhood). The IRLS weight
  ``(msd + eps) ** ((r - 2) / 2)`` (Kopf's ``||s - e||^(r - 2)`` per entry) goes to ``weight[p, v]``.
- **solve** (:func:`solve_pass`, Chen & Wang's discrete solver): voxel ``v``'s candidates are the exemplar
  pixels the matches centred within ``solve_radius`` lay on it. Candidate ``g`` costs
  ``(mean_q D_q(g) + consensus * (ex[g] - mu)^2) * h_pos(g) * h_grey(g)``: ``D_q`` the entry-weighted mean
  squared difference of ``g``'s neighbourhood and ``v``'s slice in every plane sharing the exemplar;
  ``mu`` the IRLS-weighted mean of the values the covering matches propose (Kopf's least-squares voxel);
  ``h_pos``, ``h_grey`` the **position** and grey-level histogram factors. With ``rerank > 0`` candidates
  are ranked in the principal subspace first. ``v`` copies the winner: every voxel is an exemplar pixel.

Storage: the planes' exemplars are concatenated into one flat ``values`` buffer (planes with the same
exemplar share it, and so their histograms); a position is its *global index* ``offset_p + row * w_p +
col``. Exemplar neighbourhoods never wrap; the volume wraps when ``periodic``.

The kernels take their inputs in named groups (:class:`ExemplarBank`, :class:`SliceGeometry`,
:class:`SolidState`, :class:`SearchKnobs`, :class:`SearchWork`, :class:`SolveWork`), numba named tuples;
:func:`search_reference` and :func:`solve_reference` are plain NumPy versions of the passes with the same
arguments and results, which the tests compare with.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import prange

from texsynth.synth.kernels.common import histogram_factor, splitmix
from texsynth.synth.kernels.options import kernel

__all__ = [
    "PARALLEL_BLOCKS",
    "SOLVE_BLOCK",
    "ExemplarBank",
    "SliceGeometry",
    "SolidState",
    "SolverWeights",
    "new_scratch",
    "search_pass",
    "search_reference",
    "solve_pass",
    "solve_reference",
]

#: Added to a match's mean squared difference before the IRLS power (a perfect match keeps a finite weight).
_WEIGHT_EPS = 1e-4


class ExemplarBank(NamedTuple):
    """The three planes' exemplars at one pyramid level, in one flat buffer.

    Attributes
    ----------
    values : ndarray (N,) float32
        Every plane's exemplar, raveled and concatenated (shared storage when two planes' are equal).
    layout : ndarray (3, 3) int64
        Per plane ``[offset, height, width]`` of its exemplar in ``values``.
    valid : ndarray (3, 4) int64
        Per plane ``[y0, y1, x0, x1]``: the neighbourhood centres that fit inside its exemplar.
    kset : ndarray (N, k) int32
        Global indices of the ``k`` exemplar positions most similar to each position; ``-1`` for none.
    features : ndarray (N, d) float32
        Each valid position's neighbourhood projected on its plane's principal axes (zeros elsewhere).
    mean : ndarray (3, K) float32
        Per plane, the mean exemplar neighbourhood (entries in :class:`SliceGeometry` order).
    basis : ndarray (3, K, d) float32
        Per plane, the principal axes (columns; zero columns pad a plane that keeps fewer).
    grey_bin : ndarray (N,) int64
        The grey-level bin of each exemplar pixel.
    """

    values: np.ndarray
    layout: np.ndarray
    valid: np.ndarray
    kset: np.ndarray
    features: np.ndarray
    mean: np.ndarray
    basis: np.ndarray
    grey_bin: np.ndarray


class SliceGeometry(NamedTuple):
    """The slice neighbourhoods and candidate windows of the three planes, as volume and exemplar offsets.

    Attributes
    ----------
    offsets : ndarray (3, K, 3) int64
        Volume offsets ``(dz, dy, dx)`` of plane ``p``'s ``n x n`` neighbourhood entries (centre included).
    lin : ndarray (3, K) int64
        The same entries as linear offsets in plane ``p``'s exemplar (``d_row * w_p + d_col``).
    cand_offsets : ndarray (3, C, 3) int64
        Volume offsets of the voxels whose matches propose candidates (the centre first).
    cand_rc : ndarray (3, C, 2) int64
        The same as ``(d_row, d_col)`` in plane ``p``'s slices (the shift applied to their matches).
    periodic : bool
        Whether the volume wraps (a tileable volume).
    active : ndarray (3,) bool
        The constrained planes (the others' slices are left free: neither searched nor proposing).
    entry_weight : ndarray (3, K) float64
        Weight of each neighbourhood entry in the solver's distances (a Gaussian of the offset).
    """

    offsets: np.ndarray
    lin: np.ndarray
    cand_offsets: np.ndarray
    cand_rc: np.ndarray
    periodic: bool
    active: np.ndarray
    entry_weight: np.ndarray


class SolidState(NamedTuple):
    """The synthesis state at one level (arrays updated in place by the passes).

    Attributes
    ----------
    volume : ndarray (D, H, W) float32
        Voxel values: each is the exemplar pixel ``origin`` names.
    match : ndarray (3, D, H, W) int32
        Per plane, the global index of the exemplar neighbourhood centre matched to the slice through each
        voxel (the per-voxel source map of each plane: what k-coherence propagates).
    weight : ndarray (3, D, H, W) float32
        IRLS weight of each match.
    origin : ndarray (D, H, W) int32
        Global index of the exemplar pixel each voxel copies; ``-1`` before the first solve.
    index_count, position_count : ndarray (N,) int64
        How many (voxel, constrained plane) matches use each exemplar neighbourhood; how many voxels copy
        each pixel.
    index_target, position_target : ndarray (N,) float64
        Their counts under uniform use (positive).
    grey_count, grey_target : ndarray (B,) int64, (B,) float64
        Voxels per grey-level bin (``ExemplarBank.grey_bin``), and their number under the exemplars'
        histogram.
    orientation_factor : ndarray (3, N) float64
        Per plane, the factor multiplying the search distance of each exemplar neighbourhood: eq 4's
        re-weighting on the plane's orientation histogram
        (:func:`texsynth.synth.analysis.orientation_histogram.usage_factors`), frozen during a search pass;
        ones switch it off.
    """

    volume: np.ndarray
    match: np.ndarray
    weight: np.ndarray
    origin: np.ndarray
    index_count: np.ndarray
    index_target: np.ndarray
    position_count: np.ndarray
    position_target: np.ndarray
    grey_count: np.ndarray
    grey_target: np.ndarray
    orientation_factor: np.ndarray


@dataclass(frozen=True)
class SolverWeights:
    """Histogram weights, IRLS exponent, solver and candidate settings of one run.

    ``index_weight``, ``position_weight`` and ``grey_weight`` are the histogram-matching strengths (0 switches
    one off); ``exponent`` is Kopf's ``r``; ``consensus`` weighs the solver's pull toward the proposals'
    weighted mean; ``solve_radius``: the solver's candidates come from the matches centred within it;
    ``kset_window``: the first ``kset_window`` voxels of the search's candidate window (the voxel first)
    add their matches' k-coherence sets; ``n_random`` random valid candidates per voxel and plane are added to
    the k-coherent ones, drawn from ``seed_key`` (a fresh 63-bit key per pass). ``rerank`` > 0: the
    candidates are ranked by their distance in the principal subspace (times the index factor) and the
    ``rerank`` best are compared in full; 0: every candidate is compared in full.
    """

    index_weight: float = 1.0
    position_weight: float = 1.0
    exponent: float = 0.8
    n_random: int = 0
    seed_key: int = 0
    rerank: int = 4
    solve_radius: int = 1
    kset_window: int = 5
    consensus: float = 0.5
    grey_weight: float = 5.0


class SearchKnobs(NamedTuple):
    """The search kernel's scalar settings (from :class:`SolverWeights`, typed for numba)."""

    index_weight: float
    exponent: float
    n_random: int
    seed_key: np.uint64
    rerank: int
    kset_window: int


class SearchWork(NamedTuple):
    """What one search call reads besides the state, and writes besides it."""

    prev: np.ndarray  # (3, D, H, W) int32: the matches as the pass found them (candidates come from them)
    index_factor: np.ndarray  # (N,) float64: the index-histogram factor, frozen during the call
    stamp: np.ndarray  # (PARALLEL_BLOCKS, N) int64: de-duplication stamps, one row per block
    tags: np.ndarray  # (PARALLEL_BLOCKS,) int64: each block's current stamp
    msd_out: np.ndarray  # (stop - start, 3) float64: each match's mean squared difference
    n_cand_out: np.ndarray  # (stop - start, 3) int64: each search's number of candidates


class SolveWork(NamedTuple):
    """One solve block's candidates and their costs before the histogram factors."""

    cand: np.ndarray  # (M, n_max) int64
    cost: np.ndarray  # (M, n_max) float64
    n_cand: np.ndarray  # (M,) int64


# ---------------------------------------------------------------------------------------------- kernels


@kernel(inline="always")
def _wrap(i, n):
    """``i`` wrapped into ``[0, n)`` for ``|i| < 2 n`` without a division (the hot loops' common case)."""
    if i < 0:
        i += n
        if i < 0:
            i %= n
    elif i >= n:
        i -= n
        if i >= n:
            i %= n
    return i


@kernel(inline="always")
def _neighbour(z, y, x, dz, dy, dx, D, H, W, periodic):
    """Flat index of ``(z + dz, y + dy, x + dx)`` in a ``(D, H, W)`` volume (wrapped), or -1 outside it."""
    zz = z + dz
    yy = y + dy
    xx = x + dx
    if periodic:
        zz = _wrap(zz, D)
        yy = _wrap(yy, H)
        xx = _wrap(xx, W)
    elif zz < 0 or zz >= D or yy < 0 or yy >= H or xx < 0 or xx >= W:
        return -1
    return (zz * H + yy) * W + xx


@kernel(inline="always")
def _near(v, inner, delta, z, y, x, dz, dy, dx, D, H, W, periodic):
    """:func:`_neighbour`, with the interior's shortcut: far enough from every face (``inner``), the
    neighbour is ``v + delta`` (``delta`` the offset's flat step), the same index without the bounds work."""
    if inner:
        return v + delta
    return _neighbour(z, y, x, dz, dy, dx, D, H, W, periodic)


@kernel
def _flat_steps(offsets, H, W, sign):
    """Flat index steps ``sign * ((dz H) + dy) W + dx`` of an offset table ``(P, K, 3)``, and the largest
    offset component (voxels at least that far from every face are interior)."""
    P = offsets.shape[0]
    K = offsets.shape[1]
    steps = np.empty((P, K), dtype=np.int64)
    reach = 0
    for p in range(P):
        for i in range(K):
            dz = offsets[p, i, 0]
            dy = offsets[p, i, 1]
            dx = offsets[p, i, 2]
            steps[p, i] = sign * ((dz * H + dy) * W + dx)
            reach = max(reach, abs(dz), abs(dy), abs(dx))
    return steps, reach


@kernel(inline="always")
def _interior(z, y, x, reach, D, H, W):
    return reach <= z < D - reach and reach <= y < H - reach and reach <= x < W - reach


@kernel(inline="always")
def _add_shifted(cand, n, g, off, w, dr, dc, y0, y1, x0, x1, stamp, tag):
    """Append exemplar position ``g`` shifted by ``(-dr, -dc)`` if that lies in ``[y0, y1) x [x0, x1)``
    and is new (``stamp[key] != tag``)."""
    local = g - off
    cy = local // w - dr
    cx = local % w - dc
    if cy < y0 or cy >= y1 or cx < x0 or cx >= x1:
        return n
    key = off + cy * w + cx
    if stamp[key] == tag:
        return n
    stamp[key] = tag
    cand[n] = key
    return n + 1


@kernel(inline="always")
def _index_factor(index_factor, index_count, index_target, index_weight, g, old):
    """The index-histogram factor of candidate ``g`` for a voxel whose old match is ``old``: the call's
    precomputed factor, except for ``old`` itself, whose own use does not count against it."""
    if g == old:
        return histogram_factor(index_count[g] - 1, index_target[g], index_weight)
    return index_factor[g]


@kernel(inline="always")
def _ssd(q, ql, n, ex, base, limit):
    """Sum of squared differences of the query ``q[:n]`` and the exemplar block at ``base``.

    Entries are summed four at a time, ``((t0 + t1) + (t2 + t3))``, then one by one; the sum stops
    early once it exceeds ``limit`` (checked after every group: the argmin is unchanged).
    """
    s = 0.0
    i = 0
    while i + 4 <= n:
        d0 = np.float64(q[i]) - np.float64(ex[base + ql[i]])
        d1 = np.float64(q[i + 1]) - np.float64(ex[base + ql[i + 1]])
        d2 = np.float64(q[i + 2]) - np.float64(ex[base + ql[i + 2]])
        d3 = np.float64(q[i + 3]) - np.float64(ex[base + ql[i + 3]])
        s += (d0 * d0 + d1 * d1) + (d2 * d2 + d3 * d3)
        if s > limit:
            return s
        i += 4
    while i < n:
        d = np.float64(q[i]) - np.float64(ex[base + ql[i]])
        s += d * d
        i += 1
    return s


#: Voxels of one parallel call are split into this many blocks, run in parallel, each with its own
#: working arrays (the search's de-duplication stamps): a fixed number, so the split (and the answer)
#: does not depend on the threads.
PARALLEL_BLOCKS = 16


@kernel(parallel=True)
def _search_kernel(order, start, stop, bank, geometry, state, knobs, work):
    """Search phase on ``order[start:stop]`` (see :func:`search_pass`), in :data:`PARALLEL_BLOCKS` blocks."""
    vol = state.volume
    match = state.match
    weight = state.weight
    index_count = state.index_count
    index_target = state.index_target
    orient_factor = state.orientation_factor
    ex = bank.values
    layout = bank.layout
    valid = bank.valid
    kset = bank.kset
    features = bank.features
    mean = bank.mean
    basis = bank.basis
    offsets = geometry.offsets
    lin = geometry.lin
    cand_offsets = geometry.cand_offsets
    cand_rc = geometry.cand_rc
    periodic = geometry.periodic
    active = geometry.active
    index_weight = knobs.index_weight
    exponent = knobs.exponent
    n_random = knobs.n_random
    seed_key = knobs.seed_key
    rerank = knobs.rerank
    kset_window = knobs.kset_window
    prev = work.prev
    index_factor = work.index_factor
    stamp = work.stamp
    tags = work.tags
    msd_out = work.msd_out
    n_cand_out = work.n_cand_out
    D, H, W = vol.shape
    n_dims = basis.shape[2]
    K = offsets.shape[1]
    C = cand_offsets.shape[1]
    k = kset.shape[1]
    volf = vol.ravel()
    prevf = prev.ravel()
    power = 0.5 * (exponent - 2.0)
    steps, reach = _flat_steps(offsets, H, W, 1)
    csteps, creach = _flat_steps(cand_offsets, H, W, 1)
    reach = max(reach, creach)
    blocks = stamp.shape[0]
    count = stop - start
    per = (count + blocks - 1) // blocks
    for blk in prange(blocks):
        proj = np.empty(n_dims, dtype=np.float64)
        top_d = np.empty(max(rerank, 1), dtype=np.float64)
        top_g = np.empty(max(rerank, 1), dtype=np.int64)
        q = np.empty(K, dtype=np.float32)
        ql = np.empty(K, dtype=np.int64)
        cand = np.empty(C * (k + 1) + n_random, dtype=np.int64)
        for idx in range(start + blk * per, min(stop, start + (blk + 1) * per)):
            v = order[idx]
            z = v // (H * W)
            y = (v // W) % H
            x = v % W
            inner = _interior(z, y, x, reach, D, H, W)
            for p in range(3):
                if not active[p]:
                    continue
                off = layout[p, 0]
                w = layout[p, 2]
                y0 = valid[p, 0]
                y1 = valid[p, 1]
                x0 = valid[p, 2]
                x1 = valid[p, 3]
                n = 0
                for i in range(K):
                    u = _near(
                        v,
                        inner,
                        steps[p, i],
                        z,
                        y,
                        x,
                        offsets[p, i, 0],
                        offsets[p, i, 1],
                        offsets[p, i, 2],
                        D,
                        H,
                        W,
                        periodic,
                    )
                    if u < 0:
                        continue
                    q[n] = volf[u]
                    ql[n] = lin[p, i]
                    n += 1
                tags[blk] += 1
                tag = tags[blk]
                nc = 0
                for c in range(C):
                    u = _near(
                        v,
                        inner,
                        csteps[p, c],
                        z,
                        y,
                        x,
                        cand_offsets[p, c, 0],
                        cand_offsets[p, c, 1],
                        cand_offsets[p, c, 2],
                        D,
                        H,
                        W,
                        periodic,
                    )
                    if u < 0:
                        continue
                    g = np.int64(prevf[p * D * H * W + u])
                    dr = cand_rc[p, c, 0]
                    dc = cand_rc[p, c, 1]
                    nc = _add_shifted(cand, nc, g, off, w, dr, dc, y0, y1, x0, x1, stamp[blk], tag)
                    for j in range(k if c < kset_window else 0):  # Tong: positions similar to u's match
                        gk = np.int64(kset[g, j])
                        if gk >= 0:
                            nc = _add_shifted(cand, nc, gk, off, w, dr, dc, y0, y1, x0, x1, stamp[blk], tag)
                if n_random > 0:
                    span_y = np.uint64(y1 - y0)
                    span_x = np.uint64(x1 - x0)
                    key = splitmix(np.uint64(seed_key) ^ np.uint64(v * 3 + p))
                    for j in range(n_random):
                        r = splitmix(key + np.uint64(j))
                        gy = y0 + np.int64(r % span_y)
                        gx = x0 + np.int64((r >> np.uint64(32)) % span_x)
                        nc = _add_shifted(
                            cand, nc, off + gy * w + gx, off, w, 0, 0, y0, y1, x0, x1, stamp[blk], tag
                        )
                old = np.int64(prev[p, z, y, x])
                pool = cand
                n_pool = nc
                if rerank > 0 and n == K and nc > rerank:
                    # Rank in the principal subspace; keep the ``rerank`` best (stable), compare them in full.
                    for dd in range(n_dims):
                        proj[dd] = 0.0
                    for i in range(K):
                        c0 = np.float64(q[i]) - np.float64(mean[p, i])
                        for dd in range(n_dims):
                            proj[dd] += c0 * np.float64(basis[p, i, dd])
                    n_top = 0
                    for j in range(nc):
                        g = cand[j]
                        s = 0.0
                        for dd in range(n_dims):
                            t = proj[dd] - np.float64(features[g, dd])
                            s += t * t
                        if index_weight > 0.0:
                            s *= _index_factor(index_factor, index_count, index_target, index_weight, g, old)
                        s *= orient_factor[p, g]
                        if n_top < rerank:
                            pos = n_top
                            n_top += 1
                        elif s < top_d[rerank - 1]:
                            pos = rerank - 1
                        else:
                            continue
                        while pos > 0 and top_d[pos - 1] > s:
                            top_d[pos] = top_d[pos - 1]
                            top_g[pos] = top_g[pos - 1]
                            pos -= 1
                        top_d[pos] = s
                        top_g[pos] = g
                    pool = top_g
                    n_pool = n_top
                best = np.inf
                best_raw = np.inf
                bg = old
                for j in range(n_pool):
                    g = pool[j]
                    f = 1.0
                    if index_weight > 0.0:
                        f = _index_factor(index_factor, index_count, index_target, index_weight, g, old)
                    f *= orient_factor[p, g]
                    d = f * _ssd(q, ql, n, ex, g, best / f)
                    if d < best:
                        best = d
                        best_raw = d / f
                        bg = g
                match[p, z, y, x] = bg
                msd = best_raw / n
                weight[p, z, y, x] = (msd + _WEIGHT_EPS) ** power
                msd_out[idx - start, p] = msd
                n_cand_out[idx - start, p] = nc


@kernel
def _search_tally(order, start, stop, prev, match, active, index_count, msd_out, n_cand_out, acc):
    """After a search block: the index histogram moves each voxel's count from its old match to its new
    one, and the statistics are summed, in scan order (one thread: the same sums on every run)."""
    H = match.shape[2]
    W = match.shape[3]
    for idx in range(start, stop):
        v = order[idx]
        z = v // (H * W)
        y = (v // W) % H
        x = v % W
        for p in range(3):
            if not active[p]:
                continue
            index_count[prev[p, z, y, x]] -= 1
            index_count[match[p, z, y, x]] += 1
            acc[0] += msd_out[idx - start, p]
            acc[1] += 1.0
            acc[2] += n_cand_out[idx - start, p]


#: A solve call is taken in blocks of this many voxels (in scan order): each block's candidate costs are
#: computed in parallel from the volume as the block found it, then its voxels choose one after the other.
SOLVE_BLOCK = 2048


@kernel(parallel=True)
def _consensus_kernel(match, weight, ex, offsets, lin, periodic, active, mu):
    """``mu[v]``: the IRLS-weighted mean of the values that the matched neighbourhoods covering voxel ``v``
    propose (Kopf's least-squares voxel), for the whole volume at once: the matches and weights do not
    change during a solve pass. Offset by offset over whole rows, so the arrays are read in order; every
    voxel's sums still run over the planes, then the offsets, in a fixed order."""
    D = match.shape[1]
    H = match.shape[2]
    W = match.shape[3]
    K = offsets.shape[1]
    for z in prange(D):
        sw = np.zeros((H, W), dtype=np.float64)
        swe = np.zeros((H, W), dtype=np.float64)
        for p in range(3):
            if not active[p]:
                continue
            for i in range(K):
                zz = z - offsets[p, i, 0]
                if periodic:
                    zz = _wrap(zz, D)
                elif zz < 0 or zz >= D:
                    continue
                dy = offsets[p, i, 1]
                dx = offsets[p, i, 2]
                li = lin[p, i]
                for y in range(H):
                    yy = y - dy
                    if periodic:
                        yy = _wrap(yy, H)
                    elif yy < 0 or yy >= H:
                        continue
                    for x in range(W):
                        xx = x - dx
                        if periodic:
                            xx = _wrap(xx, W)
                        elif xx < 0 or xx >= W:
                            continue
                        wt = np.float64(weight[p, zz, yy, xx])
                        sw[y, x] += wt
                        swe[y, x] += wt * np.float64(ex[np.int64(match[p, zz, yy, xx]) + li])
        for y in range(H):
            for x in range(W):
                mu[z, y, x] = swe[y, x] / sw[y, x]


@kernel(parallel=True)
def _solve_fit_kernel(order, start, stop, bank, geometry, state, consensus_mean, consensus, radius, out):
    """Each voxel's candidates and their costs before the histogram factors (see :func:`solve_pass`)."""
    vol = state.volume
    match = state.match
    ex = bank.values
    layout = bank.layout
    valid = bank.valid
    offsets = geometry.offsets
    lin = geometry.lin
    periodic = geometry.periodic
    active = geometry.active
    entry_weight = geometry.entry_weight
    cand_out = out.cand
    cost_out = out.cost
    n_out = out.n_cand
    D, H, W = vol.shape
    K = offsets.shape[1]
    n_vox = D * H * W
    matchf = match.ravel()
    volf = vol.ravel()
    steps, reach = _flat_steps(offsets, H, W, 1)
    blocks = PARALLEL_BLOCKS
    per = (stop - start + blocks - 1) // blocks
    for blk in prange(blocks):
        q = np.empty((3, K), dtype=np.float32)
        ql = np.empty((3, K), dtype=np.int64)
        qw = np.empty((3, K), dtype=np.float64)
        qsum = np.zeros(3, dtype=np.float64)
        nq = np.zeros(3, dtype=np.int64)
        cplane = np.empty(cand_out.shape[1], dtype=np.int64)
        for idx in range(start + blk * per, min(stop, start + (blk + 1) * per)):
            v = order[idx]
            z = v // (H * W)
            y = (v // W) % H
            x = v % W
            inner = _interior(z, y, x, reach, D, H, W)
            # The voxel's slices in the constrained planes.
            for p in range(3):
                if not active[p]:
                    continue
                n = 0
                sq = 0.0
                for i in range(K):
                    u = _near(
                        v,
                        inner,
                        steps[p, i],
                        z,
                        y,
                        x,
                        offsets[p, i, 0],
                        offsets[p, i, 1],
                        offsets[p, i, 2],
                        D,
                        H,
                        W,
                        periodic,
                    )
                    if u < 0:
                        continue
                    q[p, n] = volf[u]
                    ql[p, n] = lin[p, i]
                    qw[p, n] = entry_weight[p, i]
                    sq += entry_weight[p, i]
                    n += 1
                qsum[p] = sq
                nq[p] = n
            # The proposals of every matched neighbourhood covering v: their IRLS-weighted mean (Kopf's
            # least-squares voxel), and the candidates, those centred within ``radius`` (Chen & Wang).
            nc = 0
            row = idx - start
            for p in range(3):
                if not active[p]:
                    continue
                off = layout[p, 0]
                w = layout[p, 2]
                for i in range(K):
                    if max(abs(offsets[p, i, 0]), abs(offsets[p, i, 1]), abs(offsets[p, i, 2])) > radius:
                        continue
                    u = _near(
                        v,
                        inner,
                        -steps[p, i],
                        z,
                        y,
                        x,
                        -offsets[p, i, 0],
                        -offsets[p, i, 1],
                        -offsets[p, i, 2],
                        D,
                        H,
                        W,
                        periodic,
                    )
                    if u < 0:
                        continue
                    g = np.int64(matchf[p * n_vox + u]) + lin[p, i]
                    local = g - off
                    cy = local // w
                    cx = local % w
                    if cy < valid[p, 0] or cy >= valid[p, 1] or cx < valid[p, 2] or cx >= valid[p, 3]:
                        continue
                    seen = False
                    for j in range(nc):
                        if cand_out[row, j] == g:
                            seen = True
                            break
                    if seen:
                        continue
                    cand_out[row, nc] = g
                    cplane[nc] = p
                    nc += 1
            mu = consensus_mean[v]
            for j in range(nc):
                g = cand_out[row, j]
                pg = cplane[j]
                s = 0.0
                m = 0
                for p in range(3):
                    if not active[p] or layout[p, 0] != layout[pg, 0]:
                        continue
                    d = 0.0
                    for i in range(nq[p]):
                        t = np.float64(q[p, i]) - np.float64(ex[g + ql[p, i]])
                        d += qw[p, i] * t * t
                    s += d / qsum[p]
                    m += 1
                t = np.float64(ex[g]) - mu
                cost_out[row, j] = s / m + consensus * t * t
            n_out[row] = nc


@kernel
def _solve_pick_kernel(order, start, stop, bank, state, position_weight, grey_weight, fit, acc):
    """The voxels of a block, in scan order: each takes its candidate of lowest cost times the position
    and grey-level histogram factors (the first lowest wins), and the histograms follow at once."""
    vol = state.volume
    origin = state.origin
    position_count = state.position_count
    position_target = state.position_target
    grey_count = state.grey_count
    grey_target = state.grey_target
    grey_bin = bank.grey_bin
    ex = bank.values
    cand = fit.cand
    cost = fit.cost
    n_cand = fit.n_cand
    volf = vol.ravel()
    originf = origin.ravel()
    for idx in range(start, stop):
        v = order[idx]
        row = idx - start
        if position_weight > 0.0 and originf[v] >= 0:
            position_count[originf[v]] -= 1
        if grey_weight > 0.0 and originf[v] >= 0:
            grey_count[grey_bin[originf[v]]] -= 1
        best = np.inf
        bg = cand[row, 0]
        for j in range(n_cand[row]):
            g = cand[row, j]
            s = cost[row, j]
            if position_weight > 0.0:
                s *= histogram_factor(position_count[g], position_target[g], position_weight)
            if grey_weight > 0.0:
                s *= histogram_factor(grey_count[grey_bin[g]], grey_target[grey_bin[g]], grey_weight)
            if s < best:
                best = s
                bg = g
        volf[v] = ex[bg]
        originf[v] = bg
        if position_weight > 0.0:
            position_count[bg] += 1
        if grey_weight > 0.0:
            grey_count[grey_bin[bg]] += 1
        acc[0] += best
        acc[1] += 1.0


# ---------------------------------------------------------------------------------------------- wrappers


def new_scratch(bank: ExemplarBank, state: SolidState) -> dict[str, np.ndarray]:
    """The working arrays of the passes over one level, kept across calls: de-duplication ``stamp`` and
    ``counter`` (the solve's), ``search_stamp`` / ``search_tags`` (one row per search block), ``previous``
    (the matches as the current search pass found them) and ``acc`` ((3,) float64: the sums of the
    matches' mean squared differences, of searches and of candidates)."""
    n = len(bank.values)
    return {
        "stamp": np.zeros(n, dtype=np.int64),
        "counter": np.zeros(1, dtype=np.int64),
        "search_stamp": np.zeros((PARALLEL_BLOCKS, n), dtype=np.int64),
        "search_tags": np.zeros(PARALLEL_BLOCKS, dtype=np.int64),
        "previous": np.empty_like(state.match),
        "acc": np.zeros(3, dtype=np.float64),
    }


def search_pass(
    bank: ExemplarBank,
    geometry: SliceGeometry,
    state: SolidState,
    weights: SolverWeights,
    order: np.ndarray,
    start: int,
    stop: int,
    scratch: dict[str, np.ndarray],
) -> None:
    """Search phase on the voxels ``order[start:stop]``: update ``state.match``, ``weight``, ``index_count``.

    A pass is Jacobi, as Kopf's search: every voxel's candidates come from the matches as they were
    when the pass began (``start == 0`` takes that snapshot into ``scratch['previous']``), so the voxels
    of a call are searched in parallel; the index histogram is the one at the start of the call (minus
    the voxel's own old match) and is brought up to date after it, in scan order. ``scratch``: see
    :func:`new_scratch`.
    """
    start, stop = int(start), int(stop)
    if start == 0:
        np.copyto(scratch["previous"], state.match)
    msd = np.zeros((stop - start, 3), dtype=np.float64)
    n_cand = np.zeros((stop - start, 3), dtype=np.int64)
    # The index histogram is frozen during the call: every position's factor, once.
    excess = state.index_count / state.index_target - 1.0
    factor = np.where(excess > 0.0, 1.0 + float(weights.index_weight) * excess, 1.0)
    knobs = SearchKnobs(
        float(weights.index_weight),
        float(weights.exponent),
        int(weights.n_random),
        np.uint64(weights.seed_key),
        int(weights.rerank),
        int(weights.kset_window),
    )
    stamps, tags = scratch["search_stamp"], scratch["search_tags"]
    work = SearchWork(scratch["previous"], factor, stamps, tags, msd, n_cand)
    _search_kernel(order, start, stop, bank, geometry, state, knobs, work)
    _search_tally(
        order,
        start,
        stop,
        scratch["previous"],
        state.match,
        geometry.active,
        state.index_count,
        msd,
        n_cand,
        scratch["acc"],
    )


def solve_pass(
    bank: ExemplarBank,
    geometry: SliceGeometry,
    state: SolidState,
    weights: SolverWeights,
    order: np.ndarray,
    start: int,
    stop: int,
    scratch: dict[str, np.ndarray],
) -> None:
    """Discrete-solver phase on ``order[start:stop]``: update ``volume``, ``origin``, ``position_count``.

    Taken in blocks of :data:`SOLVE_BLOCK` voxels: a block's candidate costs are computed in parallel
    from the volume as the block found it; then its voxels choose in scan order with the histograms
    kept up to date voxel by voxel. ``scratch['acc']`` ((3,) float64) receives the sum of the chosen
    costs and their number.
    """
    start, stop = int(start), int(stop)
    if start == 0:
        scratch["consensus"] = np.empty(state.volume.shape, dtype=np.float64)
        _consensus_kernel(
            state.match,
            state.weight,
            bank.values,
            geometry.offsets,
            geometry.lin,
            geometry.periodic,
            geometry.active,
            scratch["consensus"],
        )
    radius = int(weights.solve_radius)
    n_max = 3 * min(geometry.offsets.shape[1], (2 * radius + 1) ** 2)
    for lo in range(start, stop, SOLVE_BLOCK):
        hi = min(stop, lo + SOLVE_BLOCK)
        cand = np.full((hi - lo, n_max), -1, dtype=np.int64)
        cost = np.zeros((hi - lo, n_max), dtype=np.float64)
        n_cand = np.zeros(hi - lo, dtype=np.int64)
        fit = SolveWork(cand, cost, n_cand)
        consensus = scratch["consensus"].ravel()
        lam = float(weights.consensus)
        _solve_fit_kernel(order, lo, hi, bank, geometry, state, consensus, lam, radius, fit)
        position_weight = float(weights.position_weight)
        grey_weight = float(weights.grey_weight)
        _solve_pick_kernel(order, lo, hi, bank, state, position_weight, grey_weight, fit, scratch["acc"])


# ---------------------------------------------------------------------------------------------- references
# The same algorithms, one voxel at a time, in plain NumPy and without early stopping.


def _hist_factor_reference(count: np.ndarray, target: np.ndarray, weight: float) -> np.ndarray:
    excess = count / target - 1.0
    return np.where(excess > 0.0, 1.0 + weight * excess, 1.0)


def _neighbours_reference(
    zyx: tuple[int, int, int], offs: np.ndarray, shape: tuple[int, ...], periodic: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices of ``zyx + offs`` and which of the offsets lie inside the volume (or all, wrapped)."""
    pts = np.asarray(zyx)[None, :] + offs
    if periodic:
        pts = pts % np.asarray(shape)
        inside = np.ones(len(pts), dtype=bool)
    else:
        inside = np.all((pts >= 0) & (pts < np.asarray(shape)), axis=1)
    flat = np.ravel_multi_index(tuple(np.clip(pts, 0, np.asarray(shape) - 1).T), shape)
    return flat, inside


def search_reference(
    bank: ExemplarBank,
    geometry: SliceGeometry,
    state: SolidState,
    weights: SolverWeights,
    order: np.ndarray,
    start: int,
    stop: int,
    scratch: dict[str, np.ndarray],
) -> None:
    """Slow, obvious NumPy version of :func:`search_pass` (same arguments, same results)."""
    s, b, g = state, bank, geometry
    shape = s.volume.shape
    n_vox = s.volume.size
    volf = s.volume.ravel()
    if int(start) == 0:
        scratch["previous"] = s.match.copy()
    prev = scratch["previous"]
    prevf = prev.reshape(3, n_vox)
    counts = s.index_count.copy()  # the histogram as the call found it
    for v in order[start:stop]:
        zyx = np.unravel_index(int(v), shape)
        for p in np.flatnonzero(g.active):
            off, _, w = (int(t) for t in b.layout[p])
            y0, y1, x0, x1 = (int(t) for t in b.valid[p])
            flat, inside = _neighbours_reference(zyx, g.offsets[p], shape, g.periodic)
            q = volf[flat[inside]].astype(np.float64)
            ql = g.lin[p][inside]
            cands: list[int] = []
            cflat, cin = _neighbours_reference(zyx, g.cand_offsets[p], shape, g.periodic)
            proposals: list[tuple[int, int, int]] = []
            for c in np.flatnonzero(cin):
                m = int(prevf[p, cflat[c]])
                dr, dc = (int(t) for t in g.cand_rc[p, c])
                proposals.append((m, dr, dc))
                if c < weights.kset_window:
                    proposals.extend((int(kk), dr, dc) for kk in b.kset[m] if kk >= 0)
            if weights.n_random > 0:
                key = splitmix(np.uint64(weights.seed_key) ^ np.uint64(int(v) * 3 + p))
                for j in range(weights.n_random):
                    r = int(splitmix(np.uint64((int(key) + j) & ((1 << 64) - 1))))
                    gy = y0 + r % (y1 - y0)
                    gx = x0 + (r >> 32) % (x1 - x0)
                    proposals.append((off + gy * w + gx, 0, 0))
            for m, dr, dc in proposals:
                cy, cx = divmod(m - off, w)
                cy, cx = cy - dr, cx - dc
                key_pos = off + cy * w + cx
                if y0 <= cy < y1 and x0 <= cx < x1 and key_pos not in cands:
                    cands.append(key_pos)
            ca = np.asarray(cands, dtype=np.int64)
            old = int(prev[p][zyx])
            own = counts[ca] - (ca == old)  # the voxel's own old match does not count against it
            n_all = len(ca)
            if weights.rerank > 0 and len(q) == g.offsets.shape[1] and len(ca) > weights.rerank:
                proj = np.zeros(b.basis.shape[2])
                for i in range(len(q)):  # entry by entry: the kernel's order of summation
                    proj += (q[i] - np.float64(b.mean[p, i])) * b.basis[p, i].astype(np.float64)
                pd = np.zeros(len(ca))
                for dd in range(len(proj)):
                    pd += (proj[dd] - b.features[ca, dd].astype(np.float64)) ** 2
                if weights.index_weight > 0:
                    pd *= _hist_factor_reference(own, s.index_target[ca], weights.index_weight)
                pd *= s.orientation_factor[p, ca]
                keep = np.lexsort((np.arange(len(ca)), pd))[: weights.rerank]
                ca, own = ca[keep], own[keep]
            t = (q[None, :] - b.values[ca[:, None] + ql[None, :]].astype(np.float64)) ** 2
            d = np.zeros(len(ca))
            n4 = len(q) - len(q) % 4
            for i in range(0, n4, 4):  # the kernel's order of summation
                d += (t[:, i] + t[:, i + 1]) + (t[:, i + 2] + t[:, i + 3])
            for i in range(n4, len(q)):
                d += t[:, i]
            f = np.ones(len(ca))
            if weights.index_weight > 0:
                f = _hist_factor_reference(own, s.index_target[ca], weights.index_weight)
            f = f * s.orientation_factor[p, ca]
            best = int(np.argmin(f * d))
            s.match[p][zyx] = ca[best]
            s.index_count[old] -= 1
            s.index_count[ca[best]] += 1
            msd = d[best] / len(q)
            s.weight[p][zyx] = (msd + _WEIGHT_EPS) ** (0.5 * (weights.exponent - 2.0))
            scratch["acc"][0] += msd
            scratch["acc"][1] += 1.0
            scratch["acc"][2] += n_all


def solve_reference(
    bank: ExemplarBank,
    geometry: SliceGeometry,
    state: SolidState,
    weights: SolverWeights,
    order: np.ndarray,
    start: int,
    stop: int,
    scratch: dict[str, np.ndarray],
) -> None:
    """Slow, obvious NumPy version of :func:`solve_pass` (same arguments, same results)."""
    s, b, g = state, bank, geometry
    shape = s.volume.shape
    n_vox = s.volume.size
    originf = s.origin.ravel()
    matchf = s.match.reshape(3, n_vox)
    weightf = s.weight.reshape(3, n_vox)
    pw, gw, lam = weights.position_weight, weights.grey_weight, weights.consensus
    planes = [int(p) for p in np.flatnonzero(g.active)]
    if int(start) == 0:
        scratch["consensus"] = np.empty(shape, dtype=np.float64)
    for lo in range(int(start), int(stop), SOLVE_BLOCK):
        block = order[lo : min(int(stop), lo + SOLVE_BLOCK)]
        volf = s.volume.ravel().copy()  # the volume as the block found it
        costs: list[tuple[np.ndarray, np.ndarray]] = []
        for v in block:
            zyx = np.unravel_index(int(v), shape)
            qs, qls, qws = {}, {}, {}
            for p in planes:
                flat, inside = _neighbours_reference(zyx, g.offsets[p], shape, g.periodic)
                qs[p] = volf[flat[inside]].astype(np.float64)
                qls[p] = g.lin[p][inside]
                qws[p] = g.entry_weight[p][inside]
            cands: list[tuple[int, int]] = []
            sw, swe = 0.0, 0.0
            for p in planes:
                off, _, w = (int(t) for t in b.layout[p])
                y0, y1, x0, x1 = (int(t) for t in b.valid[p])
                flat, inside = _neighbours_reference(zyx, -g.offsets[p], shape, g.periodic)
                for i in np.flatnonzero(inside):
                    gg = int(matchf[p, flat[i]]) + int(g.lin[p, i])
                    sw += float(weightf[p, flat[i]])
                    swe += float(weightf[p, flat[i]]) * float(b.values[gg])
                    if np.abs(g.offsets[p, i]).max() > weights.solve_radius:
                        continue
                    cy, cx = divmod(gg - off, w)
                    if y0 <= cy < y1 and x0 <= cx < x1 and gg not in [c for c, _ in cands]:
                        cands.append((gg, p))
            mu = swe / sw
            scratch["consensus"].ravel()[int(v)] = mu
            cost = np.zeros(len(cands))
            for j, (gg, pg) in enumerate(cands):
                sharing = [p for p in planes if b.layout[p, 0] == b.layout[pg, 0]]
                for p in sharing:
                    t = (qs[p] - b.values[gg + qls[p]].astype(np.float64)) ** 2
                    dd, sq = 0.0, 0.0
                    for wi, ti in zip(qws[p], t, strict=True):  # the kernel's order of summation
                        dd += wi * ti
                        sq += wi
                    cost[j] += dd / sq
                cost[j] = cost[j] / len(sharing) + lam * (float(b.values[gg]) - mu) ** 2
            costs.append((np.asarray([c for c, _ in cands], dtype=np.int64), cost))
        for v, (ca, cost) in zip(block, costs, strict=True):
            if pw > 0 and originf[v] >= 0:
                s.position_count[originf[v]] -= 1
            if gw > 0 and originf[v] >= 0:
                s.grey_count[b.grey_bin[originf[v]]] -= 1
            total = cost.copy()  # factors applied one after the other: the kernel's order
            if pw > 0:
                total *= _hist_factor_reference(s.position_count[ca], s.position_target[ca], pw)
            if gw > 0:
                gb = b.grey_bin[ca]
                total *= _hist_factor_reference(s.grey_count[gb], s.grey_target[gb], gw)
            best = int(np.argmin(total))
            s.volume.ravel()[v] = b.values[ca[best]]
            originf[v] = ca[best]
            if pw > 0:
                s.position_count[ca[best]] += 1
            if gw > 0:
                s.grey_count[b.grey_bin[ca[best]]] += 1
            scratch["acc"][0] += float(total[best])
            scratch["acc"][1] += 1.0
