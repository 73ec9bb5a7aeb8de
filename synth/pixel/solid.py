"""Solid textures from 2D exemplars: the machinery and the driver the slice-based solid methods share.

A voxel of a volume ``(D, H, W) = (z, y, x)`` lies in three orthogonal slices: ``xy`` (rows ``y``,
columns ``x``), ``xz`` (rows ``z``, columns ``x``) and ``yz`` (rows ``z``, columns ``y``)
(:data:`texsynth.synth.api.PLANES`). Its *slice neighbourhoods* are the ``n x n`` squares around it in those
slices, each compared with the neighbourhoods of that plane's own exemplar. This module holds:

- :func:`plane_offsets` / :func:`exemplar_offsets`: one plane's square as volume offsets and as flat
  exemplar offsets, in the same (raster) order, so that slice and exemplar neighbourhoods compare;
- :class:`ExemplarNeighbourhoods`: every neighbourhood fully inside an exemplar, its principal axes
  and a k-d tree: exact, fast (PCA + tree, re-ranked) or k-coherent search (:func:`search_plane`);
- :class:`SolidPlan` (:func:`plan_levels`): exemplar pyramids per plane, the volume's level shapes
  and each level's neighbourhood side, validated once (:class:`~texsynth.synth.errors.InvalidInput`);
- :func:`checked_planes`: the views a method matches (all three, or two for laminar materials);
- volumes and coherent sources between levels (:func:`initial_volume`, :func:`upsample_volume`,
  :func:`initial_sources`, :func:`upsample_plane_sources`), Kopf's sparse centres (:func:`plane_centres`);
- the driver: :class:`SolidRun` (views, constrained planes, the one random generator, progress),
  :func:`run_levels` (coarse to fine, per-level iteration counts, a method's :class:`LevelLoop` at
  each level) and :class:`ProgressMeter` (``progress(stage, fraction)`` at least every 2%; a report
  may cancel). A method is a :class:`LevelLoop`; another stage (e.g. a structure field before the
  texture levels) is another loop run over its own plan.

References
----------
J. Kopf, C.-W. Fu, D. Cohen-Or, O. Deussen, D. Lischinski, T.-T. Wong, "Solid texture synthesis
from 2D exemplars", ACM Trans. Graph. 26(3) (SIGGRAPH 2007), article 2.
L.-Y. Wei, "Texture synthesis from multiple sources", SIGGRAPH 2003 Sketches (and Wei's thesis,
Stanford 2002, ch. 7): the per-slice neighbourhoods of Wei-Levoy solid synthesis.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.spatial import cKDTree

from texsynth.synth.analysis.tensor import mean_coherence
from texsynth.synth.errors import InvalidInput
from texsynth.synth.grid.pyramid import gaussian_pyramid, level_shapes
from texsynth.synth.kernels.solid_search import (
    CoherenceSets,
    SliceGeometry,
    candidate_differences,
    gather_slices,
    kcoherence_search,
    merge_remap,
    nearest_exact,
    rerank,
)
from texsynth.synth.kernels.solid_sources import dense_sources, upsample_sources
from texsynth.synth.pixel.synthesis import level_neighbourhood_size
from texsynth.synth.threads import current_threads, thread_map, use_threads

__all__ = [
    "PLANES",
    "PLANE_AXES",
    "SOURCE_DTYPE",
    "ExemplarNeighbourhoods",
    "LevelLoop",
    "LevelStep",
    "ProgressMeter",
    "SolidPlan",
    "SolidRun",
    "checked_planes",
    "dense_sources",
    "exemplar_neighbourhoods",
    "exemplar_offsets",
    "gather_plane",
    "initial_sources",
    "initial_volume",
    "is_laminar",
    "match_histogram",
    "plan_levels",
    "plane_centres",
    "plane_offsets",
    "run_levels",
    "search_plane",
    "slice_geometry",
    "structure_schedule",
    "upsample_plane_sources",
    "upsample_sources",
    "upsample_volume",
    "volume_pyramid",
]

#: The planes in the order every per-plane array uses (index 0, 1, 2), as :data:`texsynth.synth.api.PLANES`.
PLANES: tuple[str, ...] = ("xy", "xz", "yz")
#: The volume axes ``(row axis, column axis)`` of each plane's slices.
PLANE_AXES: dict[str, tuple[int, int]] = {"xy": (1, 2), "xz": (0, 2), "yz": (0, 1)}


def checked_planes(planes: Sequence[str]) -> tuple[str, ...]:
    """The views a solid method matches, in :data:`PLANES` order: two or three distinct plane names.

    Raises ``ValueError`` (a parameter error once pydantic wraps it) naming the allowed values.

    >>> checked_planes(("yz", "xz"))
    ('xz', 'yz')
    """
    given = [planes] if isinstance(planes, str) else list(planes)
    unknown = [p for p in given if p not in PLANES]
    if unknown:
        raise ValueError(f"planes must be names among 'xy', 'xz', 'yz'; got {unknown}")
    if len(set(given)) != len(given) or len(given) < 2:
        raise ValueError(f"planes must be two or three distinct planes among 'xy', 'xz', 'yz'; got {given}")
    return tuple(p for p in PLANES if p in given)


#: The coarsest pyramid level keeps exemplars at least this many pixels on a side ...
MIN_EXEMPLAR_SIDE = 8
#: ... and the volume at least this many voxels on a side.
MIN_VOLUME_SIDE = 4
#: An exemplar whose mean structure-tensor coherence reaches this is laminar (oriented) ...
ORIENTED_COHERENCE = 0.75
#: ... otherwise a micro-structure, synthesized over at most this many levels ...
MICROSTRUCTURE_LEVELS = 2
#: ... while laminae get at least this many iterations per level (Kopf's 10) (:func:`structure_schedule`).
LAMINAR_ITERATIONS = 10


def is_laminar(exemplars: Sequence[np.ndarray]) -> bool:
    """Whether some exemplar is strongly oriented: mean coherence >= :data:`ORIENTED_COHERENCE`.

    Measured mean coherences: bent laminae 0.84-0.91, laminae slices across the sheets 0.73; HRTEM soot
    0.39, level-cut Gaussian fields (grains, pores) 0.37-0.61.
    """
    return max(mean_coherence(e) for e in exemplars) >= ORIENTED_COHERENCE


def structure_schedule(exemplars: Sequence[np.ndarray], levels: int, iterations: int) -> tuple[int, int]:
    """Pyramid levels and iterations per level that the exemplars' structure needs.

    - A **micro-structure** (no exemplar laminar, :func:`is_laminar`: grains, pores, soot) gets at most
      :data:`MICROSTRUCTURE_LEVELS` levels: a 7x7 neighbourhood at the second level already spans 14
      pixels, and the coarser levels of a structure a few pixels across hold only residual noise that the
      optimisation's averaging and histogram pull amplify into blobs several times too large (issue 10's
      known answer, a level-cut Gaussian field of correlation lengths 2/3.5/6: S2 relative error along
      z/y/x 0.13-0.17/0.08-0.09/0.08-0.10 with 4 levels, 0.03-0.04 on every axis with 2; soot kept its
      orientation KL, 0.04 per axis, and its S2 error fell from 0.06-0.08 to 0.03-0.04). More iterations
      coarsen it further (10 iterations at 2 levels: 0.11 along z), so ``iterations`` is kept.
    - **Laminae** keep ``levels`` (fewer leave more defects: per-plane laminae, 64^3 from 128^2,
      orientation KL 0.05/0.25/0.21 with 2 levels against 0.02/0.10/0.12 with 5) and get at least
      :data:`LAMINAR_ITERATIONS` iterations, which anneal the dislocations between laminae domains
      (seeds 1-3, mean orientation KL per axis 0.045/0.164/0.133 with 4 -> 0.044/0.077/0.069 with 10).
    """
    if is_laminar(exemplars):
        return levels, max(iterations, LAMINAR_ITERATIONS)
    return min(levels, MICROSTRUCTURE_LEVELS), iterations


#: Principal components of the k-d tree that builds the k-coherence sets and seeds the coarsest level.
PCA_DIMS = 8
#: The tree search re-ranks this many tree neighbours with the full distance ...
TREE_CANDIDATES = 8
#: ... found within this relative error (``cKDTree.query``'s ``eps``: an approximate, faster tree search).
TREE_EPS = 1.0
#: k-coherence: similar exemplar positions precomputed for every exemplar position.
COHERENCE_K = 8
#: Each progress step covers at most this fraction of the run (the contract: every 2%).
PROGRESS_STEP = 0.01


# ---------------------------------------------------------------------------------------------
# Offsets


def _square(size: int, centre: bool) -> np.ndarray:
    r = size // 2
    rows, cols = np.mgrid[-r : r + 1, -r : r + 1]
    rc = np.stack([rows.ravel(), cols.ravel()], axis=1)
    if not centre:
        rc = rc[(rc[:, 0] != 0) | (rc[:, 1] != 0)]
    return rc


def plane_offsets(plane: str, size: int, *, centre: bool = True) -> np.ndarray:
    """Volume offsets ``(K, 3)`` int32 ``(dz, dy, dx)`` of the ``size x size`` square in ``plane``.

    Entries follow the raster order of the plane's (row, column) offsets, as
    :func:`exemplar_offsets`; ``centre=False`` leaves the centre out (Wei-Levoy's non-causal square).

    >>> plane_offsets("xz", 3)[:2].tolist()
    [[-1, 0, -1], [-1, 0, 0]]
    """
    rc = _square(size, centre)
    out = np.zeros((len(rc), 3), dtype=np.int32)
    a, b = PLANE_AXES[plane]
    out[:, a] = rc[:, 0]
    out[:, b] = rc[:, 1]
    return out


def exemplar_offsets(size: int, width: int, *, centre: bool = True) -> np.ndarray:
    """Flat offsets ``(K,)`` int64 ``d_row * width + d_col`` of the square, in :func:`plane_offsets` order."""
    rc = _square(size, centre)
    return (rc[:, 0] * width + rc[:, 1]).astype(np.int64)


# ---------------------------------------------------------------------------------------------
# Exemplar neighbourhoods and their search


@dataclass(frozen=True)
class ExemplarNeighbourhoods:
    """Every neighbourhood fully inside one exemplar (one pyramid level), ready to be searched.

    ``centres[i]`` is the flat position (``row * width + col``) of neighbourhood ``i``'s centre,
    ``vectors[i]`` its values in :func:`exemplar_offsets` order. ``mean`` and ``basis`` (``(K, d)``,
    the leading principal axes) project a vector for the k-d ``tree``; ``sets`` holds the
    k-coherence data (each position's :data:`COHERENCE_K` most similar positions).
    Every search answers flat exemplar positions and squared distances over the full vectors.
    """

    image: np.ndarray
    size: int
    centre_included: bool
    centres: np.ndarray
    vectors: np.ndarray
    mean: np.ndarray
    basis: np.ndarray
    tree: cKDTree
    sets: CoherenceSets

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    def values(self, positions: np.ndarray) -> np.ndarray:
        """The exemplar's values at flat ``positions``."""
        return self.image.ravel()[positions]

    def search(self, queries: np.ndarray, *, exact: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Nearest exemplar neighbourhood of each query ``(M, K)``: flat positions, squared distances.

        ``exact``: every neighbourhood is compared (the definition). Otherwise the
        :data:`TREE_CANDIDATES` nearest in PCA space (approximate k-d tree, :data:`TREE_EPS`) are
        re-ranked with the full distance.
        """
        if exact or len(self.centres) <= TREE_CANDIDATES:
            idx, d2 = nearest_exact(queries, self.vectors)
        else:
            proj = (queries - self.mean) @ self.basis
            # Independent queries: the answer does not depend on how the tree splits the work.
            _, cand = self.tree.query(
                proj.astype(np.float64), k=TREE_CANDIDATES, eps=TREE_EPS, workers=current_threads()
            )
            idx, d2 = rerank(
                queries, self.vectors, np.asarray(cand, dtype=np.int64).reshape(len(queries), -1)
            )
        return self.centres[idx], d2

    def search_coherent(
        self,
        queries: np.ndarray,
        centres: np.ndarray,
        geometry: SliceGeometry,
        src: np.ndarray,
        *,
        n_random: int,
        seed_key: int,
        index0: int,
        scratch: tuple[np.ndarray, np.ndarray],
        k: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """k-coherence search (:func:`texsynth.synth.kernels.solid_search.kcoherence_search`) of the queries
        centred at voxels ``centres``, from the plane's current per-voxel positions ``src``; ``k``: how
        many of each k-coherence set to use (all by default)."""
        stamp, counter = scratch
        return kcoherence_search(
            queries, centres, geometry, src, self.sets, n_random, seed_key, index0, stamp, counter, k
        )


def exemplar_neighbourhoods(
    image: np.ndarray, size: int, *, centre: bool = True, role: str = "exemplar"
) -> ExemplarNeighbourhoods:
    """The neighbourhoods of ``image`` (``(h, w)`` float32) fully inside it, with PCA, k-d tree and k-sets.

    Principal axes: eigenvectors of the covariance of all neighbourhood vectors (deterministic), the
    :data:`PCA_DIMS` leading ones. The k-coherence sets come from the tree (approximate, then
    re-ranked). Raises :class:`~texsynth.synth.errors.InvalidInput` (``role``) when no neighbourhood fits.
    The tables of the last :data:`NEIGHBOURHOOD_CACHE` (image content, size, centre) are kept and handed
    out again (the same object: callers only read it).
    """
    img = np.ascontiguousarray(image, dtype=np.float32)
    h, w = img.shape
    if h < size or w < size:
        raise InvalidInput(
            role,
            f"{h}x{w} pixels is smaller than the {size}x{size} neighbourhood: use a smaller neighbourhood",
        )
    key = (img.shape, hashlib.blake2b(img.tobytes(), digest_size=16).digest(), int(size), bool(centre))
    while True:
        with _BUILT_LOCK:
            if key in _BUILT:
                _BUILT.move_to_end(key)
                return _BUILT[key]
            building = _BUILDING.get(key)
            if building is None:  # this thread builds it; another asking meanwhile waits for it
                building = _BUILDING[key] = threading.Event()
                break
        building.wait()  # another thread built it (a prefetch): from the cache, or built here if that failed
    try:
        built = _build_neighbourhoods(img, int(size), bool(centre))
        with _BUILT_LOCK:
            _BUILT[key] = built
            while len(_BUILT) > NEIGHBOURHOOD_CACHE:
                _BUILT.popitem(last=False)
    finally:
        with _BUILT_LOCK:
            del _BUILDING[key]
        building.set()
    return built


#: Exemplar tables kept in the process (most recently used): a pilot, then the run, and the pyramid levels
#: of a method's stages build the same tables from the same images; building them is serial NumPy work.
NEIGHBOURHOOD_CACHE = 8
_BUILT: OrderedDict[tuple, ExemplarNeighbourhoods] = OrderedDict()
_BUILDING: dict[tuple, threading.Event] = {}  # tables being built now, by key
_BUILT_LOCK = threading.Lock()
#: The thread that builds a finer level's tables while the coarser level runs (:meth:`SolidPlan.prefetch`).
_PREFETCH: list[ThreadPoolExecutor] = []


def _prefetcher() -> ThreadPoolExecutor:
    """This process's one table-building thread, started at first use and kept (its CPU stays counted)."""
    with _BUILT_LOCK:
        if not _PREFETCH:
            _PREFETCH.append(ThreadPoolExecutor(1, thread_name_prefix="texsynth-tables"))
        return _PREFETCH[0]


def _forget_prefetcher() -> None:
    """In a forked child the parent's threads do not exist: its pool, locks and builds in flight go."""
    global _BUILT_LOCK
    _PREFETCH.clear()
    _BUILDING.clear()
    _BUILT_LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_prefetcher)


def _build_neighbourhoods(img: np.ndarray, size: int, centre: bool) -> ExemplarNeighbourhoods:
    """:func:`exemplar_neighbourhoods` of a validated float32 image, on a copy of it (the key's content)."""
    img = img.copy()
    h, w = img.shape
    r = size // 2
    rows, cols = np.mgrid[r : h - r, r : w - r]
    centres = (rows * w + cols).ravel().astype(np.int64)
    offs = exemplar_offsets(size, w, centre=centre)
    vectors = np.ascontiguousarray(img.ravel()[centres[:, None] + offs[None, :]], dtype=np.float32)
    mean = vectors.mean(axis=0, dtype=np.float64)
    centred = vectors.astype(np.float64) - mean
    _, evecs = np.linalg.eigh(centred.T @ centred)
    dims = min(PCA_DIMS, vectors.shape[1])
    basis = np.ascontiguousarray(evecs[:, ::-1][:, :dims], dtype=np.float32)
    proj = ((vectors - mean.astype(np.float32)) @ basis).astype(np.float64)
    tree = cKDTree(proj)
    # k-coherence sets: each position's nearest others (tree candidates, re-ranked on full vectors).
    k = min(COHERENCE_K, len(centres) - 1)
    kset = np.full((h * w, max(k, 1)), -1, dtype=np.int64)
    if k > 0:
        kk = min(len(centres), 2 * k + 1)
        _, cand = tree.query(proj, k=kk, eps=TREE_EPS, workers=current_threads())
        cand = np.asarray(cand, dtype=np.int64).reshape(len(centres), kk)
        diff = candidate_differences(vectors, cand)  # on the job's threads: 0.1 s of NumPy at 128^2
        d2 = np.einsum("mkj,mkj->mk", diff, diff, dtype=np.float64)
        d2[(cand == np.arange(len(centres))[:, None]) | (cand >= len(centres))] = np.inf  # not itself
        best = np.argsort(d2, axis=1, kind="stable")[:, :k]
        chosen = np.take_along_axis(cand, best, axis=1)
        chosen = np.where(
            np.take_along_axis(d2, best, axis=1) < np.inf, centres[np.minimum(chosen, len(centres) - 1)], -1
        )
        kset[centres] = chosen
    valid = np.zeros(h * w, dtype=np.uint8)
    valid[centres] = 1
    sets = CoherenceSets(image=img.ravel(), valid=valid, valid_pos=centres, kset=kset, offsets=offs, width=w)
    return ExemplarNeighbourhoods(
        image=img,
        size=int(size),
        centre_included=centre,
        centres=centres,
        vectors=vectors,
        mean=mean.astype(np.float32),
        basis=basis,
        tree=tree,
        sets=sets,
    )


def slice_geometry(shape: tuple[int, int, int], plane: str, periodic: bool) -> SliceGeometry:
    """The kernels' description of ``plane``'s slices in a volume of ``shape``."""
    return SliceGeometry(
        shape=np.asarray(shape, dtype=np.int64),
        axes=np.asarray(PLANE_AXES[plane], dtype=np.int64),
        periodic=periodic,
    )


# ---------------------------------------------------------------------------------------------
# Levels


@dataclass(frozen=True)
class SolidPlan:
    """The pyramid of one solid synthesis, finest level first.

    ``exemplars[p][l]``: plane ``p``'s exemplar at level ``l`` (:data:`PLANES` order);
    ``shapes[l]``: the volume's shape; ``sizes[l]``: the neighbourhood side; ``roles[p]``: the name
    to blame in messages (``'exemplar'`` when one image serves the three planes).
    """

    levels: int
    shapes: list[tuple[int, int, int]]
    sizes: list[int]
    exemplars: list[list[np.ndarray]]
    roles: list[str]

    def prefetch(self, level: int, *, centre: bool = True) -> Future | None:
        """Start building ``level``'s tables (:meth:`neighbourhoods`) on a helper thread when the job has
        two threads or more, so that a finer level's tables are built while the coarser level runs (their
        serial NumPy and k-d tree work on the core the coarser level's Python leaves idle); ``None`` with
        one thread or no such level. The tables depend only on the images: the same bytes either way. A
        later :meth:`neighbourhoods` waits for a build in flight; a failed one is built (and raises) again
        in the caller."""
        threads = current_threads()
        if threads < 2 or not 0 <= level < self.levels:
            return None

        def build() -> None:
            with use_threads(threads), contextlib.suppress(InvalidInput):  # raised again where it is run
                self.neighbourhoods(level, centre=centre)

        return _prefetcher().submit(build)

    def neighbourhoods(self, level: int, *, centre: bool = True) -> list[ExemplarNeighbourhoods]:
        """The three planes' :class:`ExemplarNeighbourhoods` at ``level`` (built once per distinct image)."""
        built: dict[int, ExemplarNeighbourhoods] = {}
        out = []
        for p in range(3):
            img = self.exemplars[p][level]
            key = id(img)
            if key not in built:
                built[key] = exemplar_neighbourhoods(
                    img, self.sizes[level], centre=centre, role=self.roles[p]
                )
            out.append(built[key])
        return out


def plan_levels(
    exemplars: Mapping[str, np.ndarray], size: tuple[int, int, int], levels: int, neighbourhood_size: int
) -> SolidPlan:
    """Validate the exemplars against the neighbourhood and build the pyramids.

    The number of levels is ``levels`` or fewer: the coarsest level keeps every exemplar at least
    :data:`MIN_EXEMPLAR_SIDE` pixels and the volume at least :data:`MIN_VOLUME_SIDE` voxels on a side
    (Kopf: "fewer levels if the exemplar is small"). The finest level uses ``neighbourhood_size``;
    coarser levels shrink it to at most a quarter of the exemplar's shorter side
    (:func:`texsynth.synth.pixel.synthesis.level_neighbourhood_size`) and to the volume's shorter side.
    """
    images = [np.ascontiguousarray(exemplars[p], dtype=np.float32) for p in PLANES]
    same = all(images[p] is images[0] or exemplars[PLANES[p]] is exemplars["xy"] for p in range(3))
    roles = ["exemplar" if same else f"exemplar_{p}" for p in PLANES]
    n = int(neighbourhood_size)
    for img, role in zip(images, roles, strict=True):
        if img.ndim != 2:
            raise InvalidInput(role, f"solid methods take grey exemplars; this one has shape {img.shape}")
        if min(img.shape) < n:
            h, w = img.shape
            raise InvalidInput(
                role, f"{h}x{w} pixels is smaller than the {n}x{n} neighbourhood: use a smaller neighbourhood"
            )
        if img.size > MAX_EXEMPLAR_PIXELS:
            raise InvalidInput(
                role, f"{img.size} pixels is too many for a solid method: at most {MAX_EXEMPLAR_PIXELS}"
            )
    min_ex = min(min(img.shape) for img in images)
    min_vol = min(size)
    used = 1
    while used < levels and min_ex / 2**used >= MIN_EXEMPLAR_SIDE and min_vol / 2**used >= MIN_VOLUME_SIDE:
        used += 1
    pyramids: dict[int, list[np.ndarray]] = {}
    ex_levels = []
    for img in images:
        if id(img) not in pyramids:  # one pyramid per distinct image: planes sharing it share arrays
            pyramids[id(img)] = gaussian_pyramid(img, used, mode="reflect")
        ex_levels.append(pyramids[id(img)])
    shapes = [tuple(int(s) for s in sh) for sh in level_shapes(size, used)]  # type: ignore[arg-type]
    sizes = []
    for level in range(used):
        if level == 0:
            sizes.append(n)
            continue
        side = min(level_neighbourhood_size(n, ex[level].shape) for ex in ex_levels)
        side = min(side, min(shapes[level]) - (1 - min(shapes[level]) % 2))
        sizes.append(max(3, side))
    return SolidPlan(levels=used, shapes=shapes, sizes=sizes, exemplars=ex_levels, roles=roles)  # type: ignore[arg-type]


def initial_volume(
    shape: tuple[int, int, int], images: Sequence[np.ndarray], rng: np.random.Generator
) -> np.ndarray:
    """A volume of grey levels drawn at random (``rng``) from the pixels of ``images`` pooled."""
    pool = np.concatenate([np.asarray(im, dtype=np.float32).ravel() for im in images])
    return np.ascontiguousarray(pool[rng.integers(0, len(pool), size=shape)], dtype=np.float32)


def match_histogram(vol: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``vol`` with its grey levels replaced, rank for rank, by the quantiles of ``values``.

    Exact histogram specification: the voxel of rank ``i`` (ties by position, a stable sort, so the
    result is deterministic) takes the value of rank ``i * n / N`` among the ``n`` sorted ``values``.
    The volume's histogram becomes the exemplar's while its order (its structure) is kept. With two
    threads or more, a volume of :data:`SPLIT_SORT` voxels and more is sorted in two halves at once
    (NumPy's sort lets the GIL go), whose merge writes the output (the same ranks as one sort:
    :func:`~texsynth.synth.kernels.solid_search.merge_remap`). No whole-volume array but the halves' ranks
    and the output (a rank array and its quantile indices were two more int64 arrays of the volume's
    size: 2 GiB at 512^3).
    """
    flat = np.ascontiguousarray(vol).ravel()
    ref = np.sort(np.asarray(values, dtype=np.float32).ravel())
    split = current_threads() > 1 and flat.size >= SPLIT_SORT
    half = flat.size // 2 if split else flat.size
    bounds = [(0, half), (half, flat.size)]
    left, right = thread_map(lambda ab: np.argsort(flat[ab[0] : ab[1]], kind="stable"), bounds, 1 + split)
    out = np.empty_like(flat)
    merge_remap(flat, left, right, ref, out)
    return out.reshape(vol.shape)


#: Volumes from this many voxels are sorted in two halves on two threads (smaller ones: one sort).
SPLIT_SORT = 1 << 16


def _upsample_axis(arr: np.ndarray, axis: int, n_out: int, periodic: bool) -> np.ndarray:
    """Linear 2:1 upsampling along ``axis``: fine sample ``i`` sits at coarse ``(i + 0.5) / 2 - 0.5``."""
    n = arr.shape[axis]
    i = np.arange(n_out)
    pos = (i + 0.5) / 2.0 - 0.5
    lo = np.floor(pos).astype(np.int64)
    t = (pos - lo).astype(np.float32)
    hi = lo + 1
    if periodic:
        lo, hi = lo % n, hi % n
    else:
        lo, hi = np.clip(lo, 0, n - 1), np.clip(hi, 0, n - 1)
    shape = [1] * arr.ndim
    shape[axis] = n_out
    t = t.reshape(shape)
    return np.take(arr, lo, axis=axis) * (1 - t) + np.take(arr, hi, axis=axis) * t


def upsample_volume(vol: np.ndarray, shape: tuple[int, int, int], periodic: bool) -> np.ndarray:
    """The coarse volume ``vol`` at the finer level's ``shape`` (trilinear, 2:1; wrapped if ``periodic``)."""
    out = vol.astype(np.float32)
    for axis in range(3):
        out = _upsample_axis(out, axis, shape[axis], periodic)
    return np.ascontiguousarray(out, dtype=np.float32)


def volume_pyramid(vol: np.ndarray, levels: int, periodic: bool) -> list[np.ndarray]:
    """Gaussian pyramid of a volume, finest first (:func:`texsynth.synth.grid.pyramid.gaussian_pyramid`)."""
    return gaussian_pyramid(vol, levels, volume=True, mode="wrap" if periodic else "reflect")


def plane_centres(
    shape: tuple[int, int, int], plane: str, stride: int = 1, phase: tuple[int, int] = (0, 0)
) -> np.ndarray:
    """Voxels ``(M, 3)`` int64 ``(z, y, x)`` whose ``plane`` neighbourhoods are searched.

    ``stride`` 1: every voxel. ``stride`` s: Kopf's sparse grid, every s-th voxel along the plane's two
    axes (from ``phase``), every voxel along the third: each voxel is still covered by about
    ``(n / s)^2`` neighbourhoods of each plane. Raster order.
    """
    a, b = PLANE_AXES[plane]
    ranges = [np.arange(s, dtype=np.int64) for s in shape]
    ranges[a] = ranges[a][phase[0] % stride :: stride]
    ranges[b] = ranges[b][phase[1] % stride :: stride]
    lengths = [len(r) for r in ranges]
    out = np.empty((*lengths, 3), dtype=np.int64)  # each coordinate broadcast in place: no meshgrid copies
    for axis, r in enumerate(ranges):
        out[..., axis] = r.reshape([-1 if i == axis else 1 for i in range(3)])
    return out.reshape(-1, 3)


def gather_plane(
    vol: np.ndarray,
    centres: np.ndarray,
    plane: str,
    size: int,
    periodic: bool,
    *,
    centre: bool = True,
    out: np.ndarray | None = None,
):
    """Slice neighbourhood vectors ``(M, K)`` float32 of ``centres`` in ``plane`` (kernel-gathered; into
    ``out`` when given)."""
    return gather_slices(vol, centres, plane_offsets(plane, size, centre=centre), periodic, out)


# ---------------------------------------------------------------------------------------------
# Progress


class ProgressMeter:
    """Turns units of work into ``progress(stage, fraction)`` calls.

    The caller declares the run's ``total`` units, asks :meth:`chunk` how many items of a given
    unit cost to do between two reports (at most :data:`PROGRESS_STEP` of the run), and calls
    :meth:`advance` after each chunk. ``progress`` may raise (e.g. :class:`~texsynth.synth.errors.Cancelled`).
    """

    def __init__(self, progress: Callable[[str, float], None], total: float) -> None:
        self.progress = progress
        self.total = max(float(total), 1.0)
        self.done = 0.0

    def chunk(self, unit_cost: float = 1.0) -> int:
        """Items of cost ``unit_cost`` that fit in one progress step (at least 1)."""
        return max(1, int(PROGRESS_STEP * self.total / max(unit_cost, 1e-12)))

    def advance(self, units: float, stage: str) -> None:
        self.done += units
        self.progress(stage, min(1.0, self.done / self.total))

    def chunks(
        self, n: int, unit_cost: float, stage: str, step: int | None = None
    ) -> Iterator[tuple[int, int]]:
        """Items ``[a, b)`` of ``n`` in chunks of :meth:`chunk` (or ``step``) items, advancing the meter
        by ``(b - a) * unit_cost`` after the caller has done each chunk (whose report may cancel)."""
        step = self.chunk(unit_cost) if step is None else step
        for a in range(0, n, step):
            b = min(n, a + step)
            yield a, b
            self.advance((b - a) * unit_cost, stage)


# ---------------------------------------------------------------------------------------------
# The driver: a run's setup and its per-level loop


@dataclass
class SolidRun:
    """What every solid run starts from (:meth:`start`): the exemplar of each plane, the constrained
    planes, the random generator (the only source of randomness), the progress callback and the clock."""

    views: dict[str, np.ndarray]
    active: list[int]
    rng: np.random.Generator
    report: Callable[[str, float], None]
    started: float = field(default_factory=time.perf_counter)

    @classmethod
    def start(
        cls,
        exemplar: np.ndarray | None,
        exemplars: Mapping[str, np.ndarray] | None,
        planes: Sequence[str],
        seed: int,
        report: Callable[[str, float], None],
    ) -> SolidRun:
        """``exemplars`` per plane, or ``exemplar`` on all three; ``planes``: the constrained ones."""
        started = time.perf_counter()
        views = dict(exemplars) if exemplars is not None else dict.fromkeys(PLANES, exemplar)
        active = [PLANES.index(plane) for plane in planes]
        return cls(views, active, np.random.default_rng(seed), report, started)  # type: ignore[arg-type]

    def constrained(self) -> list[np.ndarray]:
        """The constrained planes' exemplars."""
        return [self.views[PLANES[p]] for p in self.active]

    def seconds(self) -> float:
        return time.perf_counter() - self.started


@dataclass(frozen=True)
class LevelStep:
    """One pyramid level of a run as the driver hands it to a :class:`LevelLoop`.

    ``level``: pyramid index (0 the finest, ``levels - 1`` the coarsest, run first); ``shape``: the
    volume's; ``size``: the neighbourhood side; ``iterations``: this level's count.
    """

    level: int
    levels: int
    shape: tuple[int, int, int]
    size: int
    iterations: int

    @property
    def coarsest(self) -> bool:
        return self.level == self.levels - 1

    @property
    def voxels(self) -> int:
        return int(np.prod(self.shape))


class LevelLoop(Protocol):
    """A method's work at each level: set the level up (initialise at the coarsest, else upsample the
    coarser level's state), iterate (return ``False`` to end the level early), close it."""

    def start_level(self, step: LevelStep) -> None: ...

    def iterate(self, step: LevelStep, it: int) -> bool: ...

    def end_level(self, step: LevelStep) -> None: ...


def run_levels(plan: SolidPlan, iterations: Sequence[int], loop: LevelLoop) -> None:
    """Coarse to fine over ``plan``'s levels: ``loop.start_level``, up to ``iterations[level]`` calls of
    ``loop.iterate``, ``loop.end_level``. Stages run one after the other as loops of their own (e.g. a
    structure stage before the texture levels); per-level neighbourhood sides come from ``plan.sizes``."""
    for level in range(plan.levels - 1, -1, -1):
        step = LevelStep(level, plan.levels, plan.shapes[level], plan.sizes[level], int(iterations[level]))
        loop.start_level(step)
        for it in range(step.iterations):
            if not loop.iterate(step, it):
                break
        loop.end_level(step)


def initial_sources(
    nbhs: Sequence[ExemplarNeighbourhoods], n_voxels: int, rng: np.random.Generator
) -> np.ndarray:
    """Every voxel's exemplar position ``(3, N)`` (:data:`SOURCE_DTYPE`) per plane, drawn at random
    (``rng``) among the plane's neighbourhood centres: the coarsest level's k-coherence seeds."""
    out = np.empty((3, n_voxels), dtype=SOURCE_DTYPE)
    for p in range(3):
        out[p] = nbhs[p].centres[rng.integers(0, len(nbhs[p].centres), n_voxels)]
    return out


#: Type of the per-voxel exemplar positions (sources, matches) the driver keeps for every voxel and plane:
#: a flat exemplar position is below 2^31 (an exemplar is at most 4096^2 pixels), and int32 halves the
#: two ``(3, N)`` arrays a solid run holds at its finest level (48 of its bytes per voxel with int64).
SOURCE_DTYPE = np.int32
#: The largest exemplar (pixels) whose flat positions :data:`SOURCE_DTYPE` holds.
MAX_EXEMPLAR_PIXELS = int(np.iinfo(SOURCE_DTYPE).max)


def upsample_plane_sources(src: np.ndarray, plan: SolidPlan, level: int) -> np.ndarray:
    """The three planes' per-voxel exemplar positions ``(3, N)`` (:data:`SOURCE_DTYPE`) of level
    ``level + 1`` at ``level`` (:func:`upsample_sources`, written plane by plane into one array)."""
    out = np.empty((3, int(np.prod(plan.shapes[level]))), dtype=SOURCE_DTYPE)
    for p, plane in enumerate(PLANES):
        upsample_sources(
            src[p],
            plan.shapes[level + 1],
            plan.shapes[level],
            plane,
            plan.exemplars[p][level].shape,
            plan.exemplars[p][level + 1].shape,
            out=out[p],
        )
    return out


def search_plane(
    nbh: ExemplarNeighbourhoods,
    queries: np.ndarray,
    centres: np.ndarray,
    *,
    exact: bool,
    tree: bool,
    **coherent: object,
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest exemplar neighbourhoods of ``queries``: every neighbourhood (``exact``), the PCA + k-d
    tree search (``tree``: a level's very first search has no coherent sources yet), else k-coherence
    (:meth:`ExemplarNeighbourhoods.search_coherent` with the keyword arguments ``coherent``)."""
    if exact or tree:
        return nbh.search(queries, exact=exact)
    return nbh.search_coherent(queries, centres, **coherent)  # type: ignore[arg-type]
