"""The hot loops of solid (3D from 2D) synthesis: slice neighbourhoods, nearest neighbours, IRLS update.

A voxel's neighbourhoods are the ``n x n`` squares around it in the three orthogonal slices through
it (planes ``xy``, ``xz``, ``yz``; see :mod:`texsynth.synth.pixel.solid`). Three loops do the work:

- :func:`gather_slices`: the neighbourhood vectors of a batch of voxels in one plane (toroidal wrap
  when the volume is periodic, mirror reflection at its faces otherwise);
- :func:`nearest_exact` and :func:`rerank`: the exemplar neighbourhood nearest to each query, by
  squared Euclidean distance, over every exemplar neighbourhood (the definition) or over a short
  list of candidates proposed by a tree search in PCA space (the fast search);
- :func:`kcoherence_search`: the best of the k-coherent candidates (Tong et al. 2002) on the slice;
- :func:`irls_update`: Kopf et al.'s optimisation step (eqs 2-4): every voxel becomes the weighted
  average of the exemplar values that the matched neighbourhoods covering it propose, weights
  ``||s - e||^(r - 2)`` (IRLS) divided by ``1 + gain * max(0, H_s(b) - H_e(b))`` (histogram
  matching, with the volume's histogram ``H_s`` brought up to date after every block of voxels in
  scan order).

Every kernel ``_x_kernel`` sits beside a plain NumPy ``x_reference`` that the tests compare it
with. Kernels assume what the wrappers prepare: C-contiguous float32 values, int64 indices. Sums
are accumulated in float64 in a fixed order, so results are the same bytes on every run.

Parallelism (numba ``prange``, ``parallel=True``): every parallel loop writes only its own slots
(a query's answer, a voxel's value) and reads nothing another iteration writes; sums stay inside one
iteration, in a fixed order; the k-coherence de-duplication stamps are per block of queries, a fixed
number of blocks (:data:`KCOHERENCE_BLOCKS`) whatever the threads; the histogram counts change only
between blocks of voxels, sequentially. So 1, 2 and 4 threads give the same bytes (tested in a
subprocess, ``tests/synth/test_threads.py``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import NamedTuple

import numba
import numpy as np
from numba import prange

from texsynth.synth.kernels.common import splitmix, splitmix_reference
from texsynth.synth.kernels.options import kernel

__all__ = [
    "KCOHERENCE_BLOCKS",
    "UPDATE_BLOCK",
    "CoherenceSets",
    "HistogramState",
    "MatchField",
    "PackedExemplars",
    "SliceGeometry",
    "best_vote",
    "best_vote_reference",
    "candidate_differences",
    "candidate_differences_reference",
    "gather_slices",
    "gather_slices_reference",
    "histogram_bin",
    "irls_update",
    "irls_update_reference",
    "kcoherence_candidates_reference",
    "kcoherence_search",
    "kcoherence_search_reference",
    "merge_remap",
    "merge_remap_reference",
    "nearest_exact",
    "nearest_exact_reference",
    "rerank",
    "rerank_reference",
]


#: Below this much work (items of about a microsecond each: voxels, plain queries) a kernel runs on the
#: calling thread only: waking the thread pool costs more than it saves (on a loaded machine, the tests
#: ran 3x slower with 2 threads at 16384). Kernels whose items cost more count them with a weight
#: (:data:`KCOHERENCE_WEIGHT`). At 4096, solid-kopf 64^3 runs every search and update on the pool.
PARALLEL_MIN_ITEMS = 4096

#: Work of one k-coherence query in :data:`PARALLEL_MIN_ITEMS` units (about 8 us against 1 us for a
#: gathered neighbourhood or an updated voxel: 3606 queries took 10 ms on one thread).
KCOHERENCE_WEIGHT = 8


@contextmanager
def _threads_for(items: int) -> Iterator[None]:
    """Run the enclosed kernel on one thread when ``items`` is small (same bytes either way)."""
    if items >= PARALLEL_MIN_ITEMS:
        yield
        return
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(before)


# ---------------------------------------------------------------------------------------------
# Slice neighbourhoods


@kernel(inline="always")
def _axis_index(i, n, periodic):
    """Index ``i`` brought inside ``[0, n)``: wrapped (periodic) or mirrored about the faces."""
    if periodic:
        return i % n
    if i < 0:
        i = -i
    if i >= n:
        i = 2 * n - 2 - i
    return min(max(i, 0), n - 1)


@kernel(parallel=True)
def _gather_slices_kernel(vol, centres, offsets, periodic, out):
    D, H, W = vol.shape
    for m in prange(centres.shape[0]):
        z = centres[m, 0]
        y = centres[m, 1]
        x = centres[m, 2]
        for k in range(offsets.shape[0]):
            zz = _axis_index(z + offsets[k, 0], D, periodic)
            yy = _axis_index(y + offsets[k, 1], H, periodic)
            xx = _axis_index(x + offsets[k, 2], W, periodic)
            out[m, k] = vol[zz, yy, xx]


def gather_slices(
    vol: np.ndarray, centres: np.ndarray, offsets: np.ndarray, periodic: bool, out: np.ndarray | None = None
) -> np.ndarray:
    """Neighbourhood vectors ``(M, K)`` float32 of the voxels ``centres`` in one plane.

    Parameters
    ----------
    vol : ndarray (D, H, W) float32
    centres : ndarray (M, 3) int64
        Voxel coordinates ``(z, y, x)``.
    offsets : ndarray (K, 3) int32
        The plane's offsets ``(dz, dy, dx)`` in the order of the exemplar vectors
        (:func:`texsynth.synth.pixel.solid.plane_offsets`).
    periodic : bool
        Wrap around the volume's faces (toroidal volume) or mirror about them.
    out : ndarray (M, K) float32, optional
        C-contiguous array to write into (e.g. a view of a buffer reused batch after batch), else a new one.
    """
    shape = (centres.shape[0], offsets.shape[0])
    if out is None:
        out = np.empty(shape, dtype=np.float32)
    elif out.shape != shape or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float32 array of shape {shape}")
    with _threads_for(centres.shape[0]):
        _gather_slices_kernel(
            np.ascontiguousarray(vol, dtype=np.float32),
            np.ascontiguousarray(centres, dtype=np.int64),
            np.ascontiguousarray(offsets, dtype=np.int32),
            bool(periodic),
            out,
        )
    return out


def _reference_index(i: np.ndarray, n: int, periodic: bool) -> np.ndarray:
    if periodic:
        return np.mod(i, n)
    i = np.abs(i)
    i = np.where(i >= n, 2 * n - 2 - i, i)
    return np.clip(i, 0, n - 1)


def gather_slices_reference(
    vol: np.ndarray, centres: np.ndarray, offsets: np.ndarray, periodic: bool
) -> np.ndarray:
    """Plain NumPy :func:`gather_slices`."""
    pos = centres[:, None, :].astype(np.int64) + offsets[None, :, :].astype(np.int64)
    idx = [_reference_index(pos[..., a], vol.shape[a], periodic) for a in range(3)]
    return vol[idx[0], idx[1], idx[2]].astype(np.float32)


# ---------------------------------------------------------------------------------------------
# Nearest exemplar neighbourhoods


@kernel(parallel=True)
def _nearest_exact_kernel(queries, vectors, best_idx, best_d2):
    K = queries.shape[1]
    for m in prange(queries.shape[0]):
        best = np.inf
        bi = -1
        for p in range(vectors.shape[0]):
            s = 0.0
            for k in range(K):
                d = np.float64(queries[m, k]) - np.float64(vectors[p, k])
                s += d * d
                if s >= best:  # partial sums only grow: this one cannot win (ties keep the first)
                    break
            if s < best:
                best = s
                bi = p
        best_idx[m] = bi
        best_d2[m] = best


def nearest_exact(queries: np.ndarray, vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index (int64) and squared distance (float64) of each query's nearest row of ``vectors``.

    Exhaustive: the definition every fast search is measured against. Ties go to the lowest index.
    """
    m = queries.shape[0]
    idx = np.empty(m, dtype=np.int64)
    d2 = np.empty(m, dtype=np.float64)
    with _threads_for(m):
        _nearest_exact_kernel(
            np.ascontiguousarray(queries, dtype=np.float32),
            np.ascontiguousarray(vectors, dtype=np.float32),
            idx,
            d2,
        )
    return idx, d2


def _squared_distances_reference(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(M, P)`` squared distances, summed over the vector entries in order (the kernels' order)."""
    d2 = np.zeros((q.shape[0], v.shape[0]), dtype=np.float64)
    for k in range(q.shape[1]):
        d2 += (q[:, None, k].astype(np.float64) - v[None, :, k].astype(np.float64)) ** 2
    return d2


def nearest_exact_reference(queries: np.ndarray, vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plain NumPy :func:`nearest_exact`."""
    d2 = _squared_distances_reference(queries, vectors)
    idx = np.argmin(d2, axis=1)
    return idx.astype(np.int64), d2[np.arange(len(idx)), idx]


@kernel(parallel=True)
def _rerank_kernel(queries, vectors, candidates, best_idx, best_d2):
    K = queries.shape[1]
    P = vectors.shape[0]
    for m in prange(queries.shape[0]):
        best = np.inf
        bi = -1
        for j in range(candidates.shape[1]):
            p = candidates[m, j]
            if p < 0 or p >= P:  # a short candidate list is padded (k-d trees pad with P)
                continue
            s = 0.0
            for k in range(K):
                d = np.float64(queries[m, k]) - np.float64(vectors[p, k])
                s += d * d
            if s < best or (s == best and p < bi):
                best = s
                bi = p
        best_idx[m] = bi
        best_d2[m] = best


def rerank(queries: np.ndarray, vectors: np.ndarray, candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The best of each query's ``candidates`` (rows of ``vectors``) under the full distance.

    The fast search proposes candidates in a reduced (PCA) space; this picks among them with the
    exact squared distance, so that the reported distance is the real one. Candidates outside
    ``[0, P)`` are padding; ties go to the lowest index.
    """
    m = queries.shape[0]
    idx = np.empty(m, dtype=np.int64)
    d2 = np.empty(m, dtype=np.float64)
    with _threads_for(m):
        _rerank_kernel(
            np.ascontiguousarray(queries, dtype=np.float32),
            np.ascontiguousarray(vectors, dtype=np.float32),
            np.ascontiguousarray(candidates, dtype=np.int64),
            idx,
            d2,
        )
    return idx, d2


def rerank_reference(
    queries: np.ndarray, vectors: np.ndarray, candidates: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Plain NumPy :func:`rerank`."""
    P = vectors.shape[0]
    idx = np.full(len(queries), -1, dtype=np.int64)
    d2 = np.full(len(queries), np.inf)
    for m in range(len(queries)):
        cands = np.unique(candidates[m][(candidates[m] >= 0) & (candidates[m] < P)])  # sorted: ties -> lowest
        if len(cands) == 0:
            continue
        d = _squared_distances_reference(queries[m : m + 1], vectors[cands])[0]
        j = int(np.argmin(d))
        idx[m], d2[m] = cands[j], d[j]
    return idx, d2


@kernel(parallel=True)
def _candidate_differences_kernel(vectors, candidates, out):
    last = vectors.shape[0] - 1
    for m in prange(candidates.shape[0]):
        for c in range(candidates.shape[1]):
            e = min(candidates[m, c], last)
            for j in range(vectors.shape[1]):
                out[m, c, j] = vectors[e, j] - vectors[m, j]


def candidate_differences(vectors: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """``vectors[min(candidates, P - 1)] - vectors[:, None, :]``, ``(M, C, K)`` float32, on the job's threads.

    ``vectors`` ``(P, K)`` float32 (``M <= P`` rows have candidates), ``candidates`` ``(M, C)`` int64
    (``P`` for "no neighbour", as SciPy's k-d tree answers). Each entry is one float32 subtraction, as
    NumPy's, so the bytes are :func:`candidate_differences_reference`'s; the array is NumPy's own.
    """
    vec = np.ascontiguousarray(vectors, dtype=np.float32)
    cand = np.ascontiguousarray(candidates, dtype=np.int64)
    out = np.empty((cand.shape[0], cand.shape[1], vec.shape[1]), dtype=np.float32)
    with _threads_for(out.size // 64):  # about 64 differences a microsecond
        _candidate_differences_kernel(vec, cand, out)
    return out


def candidate_differences_reference(vectors: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """Plain NumPy :func:`candidate_differences`."""
    return vectors[np.minimum(candidates, len(vectors) - 1)] - vectors[: len(candidates), None, :]


# ---------------------------------------------------------------------------------------------
# k-coherence search (Tong et al. 2002) on slice neighbourhoods


class CoherenceSets(NamedTuple):
    """One exemplar's k-coherence data, every array indexed by flat exemplar position ``row * width + col``.

    ``image``: the exemplar, flat float32; ``valid``: 1 where a neighbourhood fits (uint8);
    ``valid_pos``: those positions (int64); ``kset[s]``: the ``k`` positions whose neighbourhoods are
    most similar to ``s``'s (``-1`` pads); ``offsets``: the neighbourhood's flat offsets (int64, the
    query vectors' order); ``width``: the exemplar's width.
    """

    image: np.ndarray
    valid: np.ndarray
    valid_pos: np.ndarray
    kset: np.ndarray
    offsets: np.ndarray
    width: int


class SliceGeometry(NamedTuple):
    """Where the queries sit: volume ``shape`` (int64 (3,)), the plane's volume ``axes`` (row axis,
    column axis) and whether the volume wraps (``periodic``)."""

    shape: np.ndarray
    axes: np.ndarray
    periodic: bool


@kernel(inline="always")
def _candidate_distance(queries, m, image, pos, offsets, limit):
    s = 0.0
    for k in range(offsets.shape[0]):
        d = np.float64(queries[m, k]) - np.float64(image[pos + offsets[k]])
        s += d * d
        if s >= limit:
            return s
    return s


class RandomDraw(NamedTuple):
    """The random candidates of a k-coherence call: ``n_random`` per query, drawn from the hash of
    ``(seed_key, index0 + m)`` for query ``m``."""

    n_random: int
    seed_key: np.uint64
    index0: int


#: Queries of one k-coherence call are split into this many blocks, run in parallel, each with its own
#: de-duplication stamps: a fixed number, so the split (and the answer) does not depend on the threads.
KCOHERENCE_BLOCKS = 16


@kernel(inline="always")
def _kcoherence_one(queries, m, centres, geometry, src, sets, draw, stamp, tag):
    D = geometry.shape[0]
    H = geometry.shape[1]
    W = geometry.shape[2]
    a = geometry.axes[0]
    b = geometry.axes[1]
    periodic = geometry.periodic
    image = sets.image
    valid = sets.valid
    valid_pos = sets.valid_pos
    kset = sets.kset
    offsets = sets.offsets
    width = sets.width
    n_random = draw.n_random
    seed_key = draw.seed_key
    index0 = draw.index0
    h = image.shape[0] // width
    k = kset.shape[1]
    n_valid = valid_pos.shape[0]
    best = np.inf
    bp = -1
    for da in range(-1, 2):
        for db in range(-1, 2):
            qz = centres[m, 0]
            qy = centres[m, 1]
            qx = centres[m, 2]
            if a == 0:
                qz += da
            else:
                qy += da
            if b == 1:
                qy += db
            else:
                qx += db
            qz = _axis_index(qz, D, periodic)
            qy = _axis_index(qy, H, periodic)
            qx = _axis_index(qx, W, periodic)
            s = src[(qz * H + qy) * W + qx]
            for j in range(-1, k):
                e = s if j < 0 else kset[s, j]
                if e < 0:
                    continue
                er = e // width - da
                ec = e % width - db
                if er < 0 or er >= h or ec < 0 or ec >= width:
                    continue
                pos = er * width + ec
                if valid[pos] == 0 or stamp[pos] == tag:
                    continue
                stamp[pos] = tag
                d = _candidate_distance(queries, m, image, pos, offsets, best)
                if d < best:
                    best = d
                    bp = pos
    key = splitmix(seed_key ^ np.uint64(index0 + m))
    for j in range(n_random):
        r = splitmix(key + np.uint64(j))
        pos = valid_pos[np.int64(r % np.uint64(n_valid))]
        if stamp[pos] == tag:
            continue
        stamp[pos] = tag
        d = _candidate_distance(queries, m, image, pos, offsets, best)
        if d < best:
            best = d
            bp = pos
    if bp < 0:  # no proposal was valid (no random candidates): the first valid position
        bp = valid_pos[0]
        best = _candidate_distance(queries, m, image, bp, offsets, np.inf)
    return bp, best


@kernel(parallel=True)
def _kcoherence_kernel(queries, centres, geometry, src, sets, draw, stamp, tag0, best_pos, best_d2):
    M = queries.shape[0]
    blocks = stamp.shape[0]
    per = (M + blocks - 1) // blocks
    for blk in prange(blocks):
        for m in range(blk * per, min(M, (blk + 1) * per)):
            tag = tag0 + m + 1
            bp, best = _kcoherence_one(queries, m, centres, geometry, src, sets, draw, stamp[blk], tag)
            best_pos[m] = bp
            best_d2[m] = best


def kcoherence_search(
    queries: np.ndarray,
    centres: np.ndarray,
    geometry: SliceGeometry,
    src: np.ndarray,
    sets: CoherenceSets,
    n_random: int,
    seed_key: int,
    index0: int,
    stamp: np.ndarray,
    counter: np.ndarray,
    k: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Best k-coherent candidate of each query: flat exemplar position (int64) and squared distance.

    Candidates for the neighbourhood centred at voxel ``c`` (Tong et al. 2002, on the slice): for each
    in-plane neighbour ``q`` of ``c`` within one voxel (``c`` included), the exemplar position
    ``src[q]`` shifted back by ``q - c``, and the ``k`` positions of ``sets.kset[src[q]]`` shifted the
    same way, when they are valid; then ``n_random`` random valid positions drawn from the hash of
    ``(seed_key, index0 + m)`` (so chunking does not change them). The first candidate with the
    smallest full squared distance wins. ``src`` (N,) holds every voxel's current exemplar position
    in this plane. ``stamp`` (h * w,) and ``counter`` (1,) int64 are scratch that de-duplicates.
    """
    m = queries.shape[0]
    pos = np.empty(m, dtype=np.int64)
    d2 = np.empty(m, dtype=np.float64)
    stamps = stamp if stamp.ndim == 2 else stamp[None, :]
    tag0 = int(counter[0])
    counter[0] += m + 1  # tags only grow: stamps never need clearing
    kset = sets.kset if k is None or k >= sets.kset.shape[1] else np.ascontiguousarray(sets.kset[:, :k])
    with _threads_for(m * KCOHERENCE_WEIGHT):
        _kcoherence_kernel(
            np.ascontiguousarray(queries, dtype=np.float32),
            np.ascontiguousarray(centres, dtype=np.int64),
            geometry._replace(periodic=bool(geometry.periodic)),
            src,
            sets._replace(kset=kset, width=int(sets.width)),
            RandomDraw(int(n_random), np.uint64(seed_key), int(index0)),
            stamps,
            tag0,
            pos,
            d2,
        )
    return pos, d2


def kcoherence_candidates_reference(
    centre: np.ndarray,
    geometry: SliceGeometry,
    src: np.ndarray,
    sets: CoherenceSets,
    n_random: int,
    seed_key: int,
    index: int,
    k: int | None = None,
) -> list[int]:
    """The candidate positions of one query, in the kernel's order, without duplicates."""
    D, H, W = (int(v) for v in geometry.shape)
    a, b = (int(v) for v in geometry.axes)
    w = int(sets.width)
    h = len(sets.image) // w
    seen: list[int] = []
    for da in (-1, 0, 1):
        for db in (-1, 0, 1):
            q = np.array(centre, dtype=np.int64)
            q[a] += da
            q[b] += db
            qi = [
                int(_reference_index(np.array(q[i]), n, geometry.periodic)) for i, n in enumerate((D, H, W))
            ]
            s = int(src[(qi[0] * H + qi[1]) * W + qi[2]])
            for e in [s, *(int(v) for v in sets.kset[s][:k])]:
                if e < 0:
                    continue
                er, ec = e // w - da, e % w - db
                if 0 <= er < h and 0 <= ec < w and sets.valid[er * w + ec] and er * w + ec not in seen:
                    seen.append(er * w + ec)
    mask = (1 << 64) - 1
    key = splitmix_reference((int(seed_key) ^ index) & mask)
    for j in range(n_random):
        pos = int(sets.valid_pos[splitmix_reference((key + j) & mask) % len(sets.valid_pos)])
        if pos not in seen:
            seen.append(pos)
    return seen


def kcoherence_search_reference(
    queries: np.ndarray,
    centres: np.ndarray,
    geometry: SliceGeometry,
    src: np.ndarray,
    sets: CoherenceSets,
    n_random: int,
    seed_key: int,
    index0: int,
    k: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Plain NumPy :func:`kcoherence_search`."""
    pos = np.empty(len(queries), dtype=np.int64)
    d2 = np.empty(len(queries))
    for m in range(len(queries)):
        cands = kcoherence_candidates_reference(
            centres[m], geometry, src, sets, n_random, seed_key, index0 + m, k
        ) or [int(sets.valid_pos[0])]
        vectors = sets.image[np.array(cands)[:, None] + sets.offsets[None, :]]
        d = _squared_distances_reference(queries[m : m + 1], vectors)[0]
        j = int(np.argmin(d))
        pos[m], d2[m] = cands[j], d[j]
    return pos, d2


# ---------------------------------------------------------------------------------------------
# The final rank remap (histogram specification)


@kernel(inline="always")
def _sorts_before(a, b):
    """``a`` comes strictly before ``b`` in NumPy's sort order (NaN last)."""
    return a < b or (b != b and a == a)


@kernel
def _merge_remap_kernel(values, left, right, offset, ref, out):
    n = values.shape[0]
    size = ref.shape[0]
    i = 0
    j = 0
    for r in range(n):
        if j >= right.shape[0] or (
            i < left.shape[0] and not _sorts_before(values[offset + right[j]], values[left[i]])
        ):
            p = left[i]
            i += 1
        else:
            p = offset + right[j]
            j += 1
        out[p] = ref[(r * size) // n]


def merge_remap(
    values: np.ndarray, left: np.ndarray, right: np.ndarray, ref: np.ndarray, out: np.ndarray
) -> None:
    """``out[p_r] = ref[r * len(ref) // N]`` for the voxel ``p_r`` of rank ``r`` among ``values`` (N,).

    ``left`` and ``right`` are the stable argsorts of ``values[:len(left)]`` and of the rest (local
    indices); merging them, ties to ``left``, gives the stable argsort of the whole (one order only), so
    :func:`merge_remap_reference`'s bytes. ``ref`` is sorted; ``out`` is ``values``' float32 shape.
    """
    _merge_remap_kernel(values, left, right, len(left), ref, out)


def merge_remap_reference(values: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Plain NumPy :func:`merge_remap`: one stable argsort of the whole, then the remap."""
    out = np.empty_like(values)
    ranks = np.argsort(values, kind="stable")
    out[ranks] = ref[(np.arange(values.size, dtype=np.int64) * ref.size) // values.size]
    return out


# ---------------------------------------------------------------------------------------------
# Kopf's optimisation step


@dataclass
class MatchField:
    """The search step's answer, per plane, stored at the neighbourhood centres.

    ``match[p, v]``: flat index (``row * width + col`` in plane ``p``'s exemplar) of the centre of the
    exemplar neighbourhood matched to the plane-``p`` neighbourhood centred at voxel ``v`` (flat
    index into the volume), ``-1`` where no neighbourhood is centred (Kopf's sparse grid).
    ``weight[p, v]``: that neighbourhood's weight (IRLS: ``||s - e||^(r - 2)``).
    ``active[p]``: 0 for a plane left out (Kopf with two views); its matches are never read.
    ``offsets[p]``: the plane's volume offsets ``(K, 3)``; ``ex_offsets[p]``: the same offsets as flat
    exemplar offsets ``row * width + col``.
    """

    match: np.ndarray  # (3, N) int32 (or int64)
    weight: np.ndarray  # (3, N) float32
    offsets: np.ndarray  # (3, K, 3) int32
    ex_offsets: np.ndarray  # (3, K) int64
    axes: np.ndarray  # (3, 2) int64: each plane's volume axes (row, column)
    phase: np.ndarray  # (3, 2) int64: centres lie where those coordinates equal phase modulo stride
    stride: int = 1  # the kernel visits only the grid's centres
    active: np.ndarray = field(default_factory=lambda: np.ones(3, dtype=np.uint8))  # (3,) planes in use


class PackedExemplars(NamedTuple):
    """The three planes' exemplars, flattened one after another: plane ``p`` is
    ``values[start[p] : start[p] + h_p * w_p]`` (they may differ in size)."""

    values: np.ndarray  # (sum h_p w_p,) float32
    start: np.ndarray  # (3,) int64

    @classmethod
    def pack(cls, images: list[np.ndarray]) -> PackedExemplars:
        sizes = [int(im.size) for im in images]
        start = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        values = np.concatenate([np.ascontiguousarray(im, dtype=np.float32).ravel() for im in images])
        return cls(values=values, start=start)


class HistogramState(NamedTuple):
    """Kopf's histogram matching (eq 4): the volume's grey-level counts ``count`` (kept up to date by
    the update), the exemplar's expected counts at the volume's size ``target``, and ``gain``
    (0 switches the matching off). Bins are equal-width on [0, 1]."""

    count: np.ndarray  # (B,) float64
    target: np.ndarray  # (B,) float64
    gain: float

    @classmethod
    def start(cls, vol: np.ndarray, exemplar_values: np.ndarray, bins: int, gain: float) -> HistogramState:
        count = np.bincount(histogram_bin(vol.ravel(), bins), minlength=bins).astype(np.float64)
        ex = np.bincount(histogram_bin(exemplar_values.ravel(), bins), minlength=bins).astype(np.float64)
        return cls(count=count, target=ex / ex.sum() * vol.size, gain=float(gain))


def histogram_bin(values: np.ndarray, bins: int) -> np.ndarray:
    """Bin (int64) of grey values in [0, 1] among ``bins`` equal bins."""
    return np.clip((np.asarray(values, dtype=np.float64) * bins).astype(np.int64), 0, bins - 1)


@kernel(inline="always")
def _bin(value, bins):
    b = int(value * bins)
    return min(max(b, 0), bins - 1)


class _Proposals(NamedTuple):
    """The kernel's view of a :class:`MatchField`: the matches, their weights and where they lie."""

    match: np.ndarray  # (3, N) int32 (or int64)
    weight: np.ndarray  # (3, N) float32
    ex_offsets: np.ndarray  # (3, K) int64
    axes: np.ndarray  # (3, 2) int64
    on_grid: np.ndarray  # (3, 2, max side) uint8: :func:`_grid_tables`
    active: np.ndarray  # (3,) uint8
    size: int  # the neighbourhood side


#: The optimisation step updates voxels in blocks of this many (in scan order), in parallel within a block;
#: the volume's histogram is brought up to date between blocks.
UPDATE_BLOCK = 4096


@kernel(inline="always")
def _centre_coordinate(c, n, periodic):
    """A centre coordinate ``c`` (at most one side away) inside ``[0, n)``, wrapped when periodic, or -1
    when it lies outside a non-periodic volume."""
    if c < 0:
        return c + n if periodic else -1
    if c >= n:
        return c - n if periodic else -1
    return c


@kernel(inline="always")
def _irls_voxel(vol, v, proposals, exemplars, histogram, periodic):
    match = proposals.match
    weight = proposals.weight
    ex_offsets = proposals.ex_offsets
    axes = proposals.axes
    on_grid = proposals.on_grid
    active = proposals.active
    size = proposals.size
    ex_values = exemplars.values
    ex_start = exemplars.start
    count = histogram.count
    target = histogram.target
    gain = histogram.gain
    D, H, W = vol.shape
    HW = H * W
    n_total = D * HW
    bins = count.shape[0]
    r = size // 2
    z = v // HW
    y = (v % HW) // W
    x = v % W
    num = 0.0
    den = 0.0
    for p in range(3):
        if active[p] == 0:
            continue
        a = axes[p, 0]
        b = axes[p, 1]
        # (row, column, fixed) coordinates of the voxel in this plane's slices, and the slice sides
        if a == 1:  # xy: rows y, columns x, fixed z
            pa, na, pb, nb, c = y, H, x, W, z
        elif b == 2:  # xz: rows z, columns x, fixed y
            pa, na, pb, nb, c = z, D, x, W, y
        else:  # yz: rows z, columns y, fixed x
            pa, na, pb, nb, c = z, D, y, H, x
        for i in range(size):  # raster order of the offsets: voxel = centre + (i - r, j - r)
            ca = _centre_coordinate(pa - (i - r), na, periodic)
            if ca < 0 or on_grid[p, 0, ca] == 0:
                continue
            for j in range(size):
                cb = _centre_coordinate(pb - (j - r), nb, periodic)
                if cb < 0 or on_grid[p, 1, cb] == 0:
                    continue
                if a == 1:
                    u = (c * H + ca) * W + cb
                elif b == 2:
                    u = (ca * H + c) * W + cb
                else:
                    u = (ca * H + cb) * W + c
                e = match[p, u]
                if e < 0:
                    continue
                val = ex_values[ex_start[p] + e + ex_offsets[p, i * size + j]]
                w = np.float64(weight[p, u])
                if gain > 0.0:
                    bb = _bin(val, bins)
                    excess = (count[bb] - target[bb]) / n_total
                    if excess > 0.0:
                        w = w / (1.0 + gain * excess)
                num += w * val
                den += w
    return num, den


#: The optimisation step visits a block's voxels grouped into this many runs of the volume's memory
#: (a counting sort by ``v * UPDATE_BUCKETS // N``: one pass, where a full sort of a 256^3 volume's 16
#: blocks of a million voxels each took about a second per iteration on the calling thread alone).
UPDATE_BUCKETS = 4096


@kernel
def _memory_runs(order, lo, hi, n_total, counts, out):
    """``order[lo:hi]`` into ``out[: hi - lo]`` grouped by runs of the volume's memory (stable)."""
    buckets = counts.shape[0] - 1
    counts[:] = 0
    for i in range(lo, hi):
        counts[order[i] * buckets // n_total + 1] += 1
    for b in range(buckets):
        counts[b + 1] += counts[b]
    for i in range(lo, hi):
        b = order[i] * buckets // n_total
        out[counts[b]] = order[i]
        counts[b] += 1


@kernel(parallel=True)
def _irls_update_kernel(vol, order, start, stop, proposals, exemplars, histogram, periodic, block):
    flat = vol.reshape(-1)
    count = histogram.count
    gain = histogram.gain
    bins = count.shape[0]
    old = np.empty(block, dtype=np.float32)
    voxels = np.empty(block, dtype=np.int64)
    runs = np.empty(min(UPDATE_BUCKETS, flat.shape[0]) + 1, dtype=np.int64)
    lo = start
    while lo < stop:
        hi = min(stop, (lo // block + 1) * block)  # blocks aligned on multiples of ``block`` in ``order``
        # the block's voxels near memory order: fewer misses, the same answer (a voxel's new value reads
        # only the matches and the histogram at the block's start; the counts below change by whole units)
        _memory_runs(order, lo, hi, flat.shape[0], runs, voxels)
        for idx in prange(lo, hi):
            v = voxels[idx - lo]
            num, den = _irls_voxel(vol, v, proposals, exemplars, histogram, periodic)
            old[idx - lo] = flat[v]
            if den > 0.0:
                flat[v] = np.float32(num / den)
        if gain > 0.0:  # the histogram follows the block's changes, in scan order
            for idx in range(lo, hi):
                count[_bin(old[idx - lo], bins)] -= 1.0
                count[_bin(flat[voxels[idx - lo]], bins)] += 1.0
        lo = hi


@kernel(inline="always")
def _best_voxel(vol, v, proposals, exemplars, periodic):
    """The value proposed by the heaviest matched neighbourhood covering voxel ``v`` (first in the fixed
    order on ties), and that weight (0 when none covers it)."""
    match = proposals.match
    weight = proposals.weight
    ex_offsets = proposals.ex_offsets
    axes = proposals.axes
    on_grid = proposals.on_grid
    active = proposals.active
    size = proposals.size
    ex_values = exemplars.values
    ex_start = exemplars.start
    D, H, W = vol.shape
    HW = H * W
    r = size // 2
    z = v // HW
    y = (v % HW) // W
    x = v % W
    best = np.float32(0.0)
    best_w = 0.0
    for p in range(3):
        if active[p] == 0:
            continue
        a = axes[p, 0]
        b = axes[p, 1]
        if a == 1:
            pa, na, pb, nb, c = y, H, x, W, z
        elif b == 2:
            pa, na, pb, nb, c = z, D, x, W, y
        else:
            pa, na, pb, nb, c = z, D, y, H, x
        for i in range(size):
            ca = _centre_coordinate(pa - (i - r), na, periodic)
            if ca < 0 or on_grid[p, 0, ca] == 0:
                continue
            for j in range(size):
                cb = _centre_coordinate(pb - (j - r), nb, periodic)
                if cb < 0 or on_grid[p, 1, cb] == 0:
                    continue
                if a == 1:
                    u = (c * H + ca) * W + cb
                elif b == 2:
                    u = (ca * H + c) * W + cb
                else:
                    u = (ca * H + cb) * W + c
                e = match[p, u]
                if e < 0:
                    continue
                w = np.float64(weight[p, u])
                if w > best_w:
                    best_w = w
                    best = ex_values[ex_start[p] + e + ex_offsets[p, i * size + j]]
    return best, best_w


@kernel(parallel=True)
def _best_vote_kernel(vol, out, proposals, exemplars, periodic):
    flat = vol.reshape(-1)
    res = out.reshape(-1)
    for v in prange(flat.shape[0]):
        val, w = _best_voxel(vol, v, proposals, exemplars, periodic)
        res[v] = val if w > 0.0 else flat[v]


def best_vote(vol: np.ndarray, field: MatchField, exemplars: PackedExemplars, periodic: bool) -> np.ndarray:
    """Every voxel takes the value that the heaviest matched neighbourhood covering it proposes.

    The discrete counterpart of :func:`irls_update` (a new volume, ``vol`` unchanged): where the weighted
    average blends about ``3 (n / stride)^2`` proposals and smooths the exemplar's grain away, this copies
    one exemplar pixel, from the neighbourhood that matched best (largest ``field.weight``: IRLS and usage
    factors). Neighbouring voxels mostly share that neighbourhood, so the copies are coherent pieces of
    the exemplar. Ties go to the first in (plane, offset row, offset column) order; a voxel no
    neighbourhood covers keeps its value. Voxels are independent: the same bytes on any thread count.
    """
    size = math.isqrt(field.ex_offsets.shape[1])
    out = np.empty_like(vol)
    with _threads_for(vol.size):
        proposals = _Proposals(
            field.match,
            field.weight,
            field.ex_offsets,
            field.axes,
            _grid_tables(vol.shape, field),
            field.active,
            size,
        )
        _best_vote_kernel(vol, out, proposals, exemplars, bool(periodic))
    return out


def best_vote_reference(
    vol: np.ndarray, field: MatchField, exemplars: PackedExemplars, periodic: bool
) -> np.ndarray:
    """Plain NumPy :func:`best_vote` (one voxel at a time, the same order)."""
    out = vol.copy()
    for v in range(vol.size):
        best_w = 0.0
        for value, w in _proposals_reference(v, vol.shape, field, exemplars, periodic):
            if w > best_w:
                best_w = w
                out[np.unravel_index(v, vol.shape)] = value
    return out


def _proposals_reference(
    v: int, shape: tuple[int, ...], field: MatchField, exemplars: PackedExemplars, periodic: bool
) -> list[tuple[np.float32, float]]:
    """For the plain references: the (exemplar value, weight) that each matched neighbourhood covering
    voxel ``v`` proposes, planes then window entries, the kernels' order."""
    D, H, W = shape
    z, y, x = np.unravel_index(int(v), shape)
    found = []
    for p in range(3):
        if not field.active[p]:
            continue
        a, b = (int(t) for t in field.axes[p])
        c = np.array([z, y, x])[None, :] - field.offsets[p].astype(np.int64)
        if periodic:
            c = np.mod(c, [D, H, W])
            inside = np.ones(len(c), dtype=bool)
        else:
            inside = np.all((c >= 0) & (c < [D, H, W]), axis=1)
        on_grid = ((c[:, a] - field.phase[p, 0]) % field.stride == 0) & (
            (c[:, b] - field.phase[p, 1]) % field.stride == 0
        )
        for k in np.flatnonzero(inside & on_grid):
            u = (c[k, 0] * H + c[k, 1]) * W + c[k, 2]
            e = field.match[p, u]
            if e < 0:
                continue
            value = exemplars.values[exemplars.start[p] + e + field.ex_offsets[p, k]]
            found.append((value, float(field.weight[p, u])))
    return found


def _grid_tables(shape: tuple[int, ...], field: MatchField) -> np.ndarray:
    """``(3, 2, max side)`` uint8: 1 where a coordinate along plane ``p``'s row (0) or column (1) axis
    is a neighbourhood centre of the sparse grid (``phase`` modulo ``stride``)."""
    out = np.zeros((3, 2, max(shape)), dtype=np.uint8)
    for p in range(3):
        for t in range(2):
            side = shape[int(field.axes[p, t])]
            out[p, t, :side] = (np.arange(side) - field.phase[p, t]) % field.stride == 0
    return out


def irls_update(
    vol: np.ndarray,
    order: np.ndarray,
    start: int,
    stop: int,
    field: MatchField,
    exemplars: PackedExemplars,
    histogram: HistogramState,
    periodic: bool,
    *,
    block: int = UPDATE_BLOCK,
) -> None:
    """Kopf's optimisation step on the voxels ``order[start:stop]``, in place.

    Each voxel ``v`` becomes ``sum w e / sum w`` over the matched neighbourhoods of the active planes
    whose window covers it, ``e`` the value the matched exemplar neighbourhood puts at ``v`` and ``w``
    its weight, divided by ``1 + gain * max(0, H_s(b) - H_e(b))`` (normalised histograms, ``b`` the
    bin of ``e``) when histogram matching is on. A voxel no neighbourhood covers keeps its value.
    Without ``periodic``, only centres inside the volume count.

    The voxels are taken in blocks of ``block`` consecutive entries of ``order`` (aligned on multiples
    of ``block``, so splitting a run at such a multiple changes nothing): a voxel's new value depends
    only on the matches and on the histogram, never on other voxels, so a block is computed in
    parallel from the histogram as it was at the block's start; then ``histogram.count`` takes the
    block's changes. Sums run in a fixed order (plane, offset row, offset column): the same bytes
    whatever the number of threads. Only the centres on each plane's grid (``field.stride``,
    ``field.phase``) are visited. ``vol`` must be C-contiguous float32.
    """
    size = math.isqrt(field.ex_offsets.shape[1])
    with _threads_for(int(stop) - int(start)):
        proposals = _Proposals(
            field.match,
            field.weight,
            field.ex_offsets,
            field.axes,
            _grid_tables(vol.shape, field),
            field.active,
            size,
        )
        histogram = histogram._replace(gain=float(histogram.gain))
        _irls_update_kernel(
            vol, order, int(start), int(stop), proposals, exemplars, histogram, bool(periodic), int(block)
        )


def irls_update_reference(
    vol: np.ndarray,
    order: np.ndarray,
    start: int,
    stop: int,
    field: MatchField,
    exemplars: PackedExemplars,
    histogram: HistogramState,
    periodic: bool,
    *,
    block: int = UPDATE_BLOCK,
) -> None:
    """Plain NumPy :func:`irls_update` (one voxel at a time, the same order of operations)."""
    bins = len(histogram.count)
    n_total = vol.size
    gain = histogram.gain
    count = histogram.count
    lo = start
    while lo < stop:
        hi = min(stop, (lo // block + 1) * block)
        frozen = count.copy()
        changes = []
        for v in order[lo:hi]:
            z, y, x = np.unravel_index(int(v), vol.shape)
            num = 0.0
            den = 0.0
            for val, w in _proposals_reference(int(v), vol.shape, field, exemplars, periodic):
                if gain > 0:
                    bb = histogram_bin(val, bins)
                    excess = (frozen[bb] - histogram.target[bb]) / n_total
                    if excess > 0:
                        w = w / (1.0 + gain * excess)
                num += w * float(val)
                den += w
            old = vol[z, y, x]
            if den > 0:
                vol[z, y, x] = np.float32(num / den)
            changes.append((old, vol[z, y, x]))
        if gain > 0:
            for old, new in changes:
                count[histogram_bin(old, bins)] -= 1.0
                count[histogram_bin(new, bins)] += 1.0
        lo = hi
