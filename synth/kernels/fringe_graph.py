"""The fringe skeleton's graph work in one nogil kernel: prune short branches, break junctions, measure.

Steps 4-6 of :mod:`texsynth.synth.analysis.fringes` on one skeleton image: the skeleton is read as a
graph (pixels in raster order; axial links, and diagonal links only where no pixel bridges them), branches
from a free end to a junction shorter than ``min_length`` are removed (up to :data:`PRUNE_ROUNDS` rounds),
junction pixels are dropped, and each remaining simple path is measured by the shortest path between its
two ends on the full 8-neighbour graph of the piece (axial step 1, diagonal ``sqrt(2)``; Dijkstra).

The plain reference is the NumPy/SciPy code beside it in fringes.py (``_prune_branches`` and ``_measure``,
sparse graphs and ``scipy.sparse.csgraph``); a test compares the two on random and drawn skeletons. The
kernel sums branch lengths in the reference's order (the same bits); path lengths may differ from SciPy's
Dijkstra by an ulp where two shortest paths tie, which the caller's rounding to 1e-9 px removes. Why a
kernel: at 64^2 a slice cost about 4400 Python calls of graph bookkeeping that held the GIL, so the
threads of a volume's evaluation waited on each other (docs/benchmarks.md, "Outside the synthesis").
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from texsynth.synth.kernels.options import kernel

__all__ = ["PRUNE_ROUNDS", "skeleton_paths"]

#: Branch pruning stops after this many rounds (fringes.py's ``_PRUNE_ROUNDS``).
PRUNE_ROUNDS = 4
_SQRT2 = math.sqrt(2.0)


@kernel(nogil=True)
def _index(skel):
    """Raster-order numbers of the skeleton pixels: ``(rows, cols, index)`` (-1 off the skeleton)."""
    h, w = skel.shape
    n = 0
    for r in range(h):
        for c in range(w):
            if skel[r, c]:
                n += 1
    rows = np.empty(n, np.int64)
    cols = np.empty(n, np.int64)
    index = np.full((h, w), -1, np.int64)
    k = 0
    for r in range(h):
        for c in range(w):
            if skel[r, c]:
                rows[k] = r
                cols[k] = c
                index[r, c] = k
                k += 1
    return rows, cols, index


@kernel(nogil=True)
def _thin_edges(skel, index):
    """Edges ``(src, dst, weight)``, each pair once, in the reference's order: offsets (0, 1), (1, 0),
    (1, 1), (1, -1), each in raster order; a diagonal only where neither bridging pixel is set."""
    h, w = skel.shape
    n_max = 4 * (index.max() + 1)
    src = np.empty(n_max, np.int64)
    dst = np.empty(n_max, np.int64)
    wts = np.empty(n_max, np.float64)
    e = 0
    for k in range(4):
        dy = 0 if k == 0 else 1
        dx = 1 if k == 0 else (0 if k == 1 else (1 if k == 2 else -1))
        for r in range(h - dy):
            for c in range(w):
                c2 = c + dx
                if c2 < 0 or c2 >= w or not skel[r, c] or not skel[r + dy, c2]:
                    continue
                if dy and dx and (skel[r, c2] or skel[r + 1, c]):
                    continue
                src[e] = index[r, c]
                dst[e] = index[r + dy, c2]
                wts[e] = _SQRT2 if dy and dx else 1.0
                e += 1
    return src[:e], dst[:e], wts[:e]


@kernel(nogil=True)
def _find(parent, i):
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:
        up = parent[i]
        parent[i] = root
        i = up
    return root


@kernel(nogil=True)
def _components(n, src, dst, use):
    """Connected components over the edges with ``use``: labels numbered in order of each component's
    lowest node (as ``scipy.sparse.csgraph.connected_components``); every node has one."""
    parent = np.arange(n)
    for e in range(len(src)):
        if use[e]:
            a, b = _find(parent, src[e]), _find(parent, dst[e])
            if a != b:
                if a < b:
                    parent[b] = a
                else:
                    parent[a] = b
    label = np.full(n, -1, np.int64)
    count = 0
    out = np.empty(n, np.int64)
    for i in range(n):
        root = _find(parent, i)
        if label[root] < 0:
            label[root] = count
            count += 1
        out[i] = label[root]
    return out, count


@kernel(nogil=True)
def _degrees(n, src, dst, use):
    degree = np.zeros(n, np.int64)
    for e in range(len(src)):
        if use[e]:
            degree[src[e]] += 1
            degree[dst[e]] += 1
    return degree


@kernel(nogil=True)
def _prune(skel, min_length):
    """``fringes._prune_branches``: a new skeleton without branches shorter than ``min_length``."""
    skel = skel.copy()
    for _ in range(PRUNE_ROUNDS):
        rows, cols, index = _index(skel)
        n = len(rows)
        src, dst, wts = _thin_edges(skel, index)
        m = len(src)
        every = np.ones(m, np.bool_)
        degree = _degrees(n, src, dst, every)
        junction = degree > 2
        if not junction.any():
            break
        inner = np.empty(m, np.bool_)
        for e in range(m):
            inner[e] = not junction[src[e]] and not junction[dst[e]]
        seg, n_seg = _components(n, src, dst, inner)
        # as the reference: the inner steps summed in edge order, the steps onto junctions apart, then added
        inner_len = np.zeros(n_seg)
        cross_len = np.zeros(n_seg)
        touches = np.zeros(n_seg, np.bool_)
        for e in range(m):
            a, b = src[e], dst[e]
            if inner[e]:
                inner_len[seg[a]] += wts[e]
            elif junction[a] != junction[b]:
                outer = b if junction[a] else a
                cross_len[seg[outer]] += wts[e]
                touches[seg[outer]] = True
        free = np.zeros(n_seg, np.bool_)
        for i in range(n):
            if degree[i] <= 1 and not junction[i]:
                free[seg[i]] = True
        any_doomed = False
        for i in range(n):
            s = seg[i]
            if not junction[i] and touches[s] and free[s] and inner_len[s] + cross_len[s] < min_length:
                skel[rows[i], cols[i]] = False
                any_doomed = True
        if not any_doomed:
            break
    return skel


@kernel(nogil=True)
def _path_length(skel, index, comp, rows, cols, start, stop, dist, done):
    """Shortest-path length from node ``start`` to ``stop`` over the full 8-neighbourhood of their piece."""
    h, w = skel.shape
    piece = comp[start]
    dist[start] = 0.0
    heap = [(0.0, start)]
    while len(heap):
        d, u = heapq.heappop(heap)
        if done[u]:
            continue
        done[u] = True
        if u == stop:
            return d
        r, c = rows[u], cols[u]
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                rr, cc = r + dy, c + dx
                if (dy == 0 and dx == 0) or rr < 0 or rr >= h or cc < 0 or cc >= w or not skel[rr, cc]:
                    continue
                v = index[rr, cc]
                if comp[v] != piece or done[v]:
                    continue
                nd = d + (_SQRT2 if dy != 0 and dx != 0 else 1.0)
                if nd < dist[v]:
                    dist[v] = nd
                    heapq.heappush(heap, (nd, v))
    return np.inf


@kernel(nogil=True)
def _measure(skel):
    """``fringes._measure``: ``(pixel_path, rows, cols, lengths, pairs, n_loops)``."""
    rows, cols, index = _index(skel)
    n = len(rows)
    src, dst, _ = _thin_edges(skel, index)
    m = len(src)
    degree = _degrees(n, src, dst, np.ones(m, np.bool_))
    junction = degree > 2
    keep = np.empty(m, np.bool_)
    for e in range(m):
        keep[e] = not junction[src[e]] and not junction[dst[e]]
    comp, n_comp = _components(n, src, dst, keep)
    for i in range(n):
        if junction[i]:
            comp[i] = -1
    degree = _degrees(n, src, dst, keep)
    # per piece: its two ends (lowest and highest raster index), or none for a loop
    first = np.full(n_comp, -1, np.int64)
    last = np.full(n_comp, -1, np.int64)
    used = np.zeros(n_comp, np.bool_)
    for i in range(n):
        if comp[i] < 0:
            continue
        used[comp[i]] = True
        if degree[i] <= 1:
            if first[comp[i]] < 0:
                first[comp[i]] = i
            last[comp[i]] = i
    path_of = np.full(n_comp, -1, np.int64)
    n_paths = 0
    n_pieces = 0
    for k in range(n_comp):
        if used[k]:
            n_pieces += 1
            if first[k] >= 0:
                path_of[k] = n_paths
                n_paths += 1
    pairs = np.empty((n_paths, 2), np.int64)
    for k in range(n_comp):
        if path_of[k] >= 0:
            pairs[path_of[k], 0] = first[k]
            pairs[path_of[k], 1] = last[k]
    dist = np.full(n, np.inf)
    done = np.zeros(n, np.bool_)
    lengths = np.empty(n_paths)
    for p in range(n_paths):
        lengths[p] = _path_length(skel, index, comp, rows, cols, pairs[p, 0], pairs[p, 1], dist, done)
    pixel_path = np.full(n, -1, np.int64)
    for i in range(n):
        if comp[i] >= 0:
            pixel_path[i] = path_of[comp[i]]
    return pixel_path, rows, cols, lengths, pairs, n_pieces - n_paths


@kernel(nogil=True)
def skeleton_paths(skel, min_length, prune):
    """Prune (when ``prune``) and measure one boolean skeleton image.

    Returns ``(skeleton, pixel_path, rows, cols, lengths, pairs, n_loops)``: the pruned skeleton, and as
    ``fringes._measure``: each skeleton pixel's path id (-1 for junction and loop pixels; paths numbered
    in raster order of their first pixel), the pixels' rows and columns (raster order), each path's
    length and end pixels (lower raster index first), and the number of closed loops.
    """
    if prune:
        skel = _prune(skel, min_length)
    pixel_path, rows, cols, lengths, pairs, n_loops = _measure(skel)
    return skel, pixel_path, rows, cols, lengths, pairs, n_loops
