"""Multi-resolution, pixel-by-pixel synthesis of a *source map* (Wei & Levoy 2000, generalised).

Every pixel-based method here is this one loop with different features: the output is represented by
its source map (for each output position, the exemplar position it copies), so that grey, colour and
tensor-valued images, and images guided by a fixed field, share one engine. For each pyramid level,
coarsest first: initialise the source map (random exemplar positions at the top, the parent's sources
upsampled below), then run ``iterations`` passes over a scan order, each position taking the exemplar
position whose neighbourhood is closest (:mod:`texsynth.synth.kernels.pixel_search`: the distance and the
search). The output's borders wrap (toroidal); exemplar neighbourhoods lie fully inside the exemplar.

Weights (Akl 2014, eq 13): the pixel part (same and parent level) and the guidance part of a
neighbourhood are each divided by their *typical* size (the mean distance between random exemplar
positions under their metric, times the number of positions compared) before ``p`` and ``1 - p``
weigh them, so that ``p = 0.5`` counts both parts equally whatever the units.

Departures from Wei & Levoy, each with its figures in docs/pixel.md:
- the first pass leaves a level's not-yet-synthesized positions out of the comparison (not noise);
- passes run in parallel (Lefebvre & Hoppe 2005's independent sub-passes): a raster pass in tiles taken
  in waves, then the first columns searched again with the full square (the wrap the tiles cut); other
  orders by levels; histogram counts change between levels (:mod:`texsynth.synth.kernels.pixel_search`);
- the fast search is k-coherence (Tong et al. 2002), measured against the exact search;
- ``SearchSettings.falloff``: the same-level neighbourhood weighed by a Gaussian (Efros & Leung 1999);
- ``refine_square``: refinement passes compare the full square in a random order;
- ``SearchSettings.periodic``: tileable outputs (the first pass compares every synthesized neighbour,
  refinement passes the whole square, every neighbour proposes candidates).

References
----------
L.-Y. Wei, M. Levoy, "Fast texture synthesis using tree-structured vector quantization", SIGGRAPH 2000.
X. Tong et al., "Synthesis of bidirectional texture functions on arbitrary surfaces", SIGGRAPH 2002.
"""

from __future__ import annotations

import copy
import functools
import threading
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from texsynth.synth.analysis.tensor import Metric, coherence, log_tensors, orientation
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.grid.neighbourhood import Shape, neighbourhood_offsets, parent_offsets
from texsynth.synth.grid.scan import ScanOrder, scan_order
from texsynth.synth.kernels.pixel_search import (
    METRIC_NORM,
    METRIC_SO,
    METRIC_SSD,
    Candidates,
    ClassWindow,
    Histogram,
    Part,
    Pass,
    Schedule,
    SearchState,
    candidate_capacity,
    conflict_offsets,
    position_distance,
    schedule_levels,
    synthesize_levels,
    tile_schedule,
)
from texsynth.synth.threads import current_threads, thread_map, use_threads

__all__ = [
    "CandidateWindow",
    "Guidance",
    "SearchSettings",
    "SynthesisReport",
    "check_neighbourhoods_fit",
    "entry_weights",
    "k_coherence_sets",
    "kset_points",
    "level_neighbourhood_size",
    "sets_ahead",
    "source_map_pyramid",
    "synthesize_source_map",
    "tensor_features",
]

SearchKind = Literal["exact", "kcoherence"]

#: The same-level neighbours whose sources propose k-coherent candidates (radius in pixels).
_CANDIDATE_RADIUS = 1
#: Rows of the sample that estimates the principal axes (the axes, not the projection, are sampled).
_PCA_SAMPLE = 4096
#: Leaf size of the k-d tree that first searches the k-coherence sets (SciPy's default is 16): larger
#: leaves cut the query of 8-D neighbourhoods by a quarter (docs/benchmarks.md, "Threads: 1 -> 2, 2D
#: methods", session 14); rows whose answer a tie could change are searched again in the default tree.
_KSET_LEAF = 64
#: Below this ``k`` the default tree alone is as fast (its one query against two).
_KSET_FAST_MIN_K = 3
#: Relative gap under which two neighbours' distances count as tied (far above float64's rounding).
_KSET_TIE = 1e-9
#: Progress is reported about this many times per pass.
_CHUNKS_PER_PASS = 64
_COHERENCE_FLOOR = 1e-3
#: Rows of a band of :func:`tensor_features` on the job's threads.
_FEATURE_ROWS = 64
#: A coarse level's neighbourhood side is at most its shorter side divided by this.
_COARSE_DIVISOR = 4


@dataclass(frozen=True)
class SearchSettings:
    """How one synthesis (one stage) searches: neighbourhood, scan, pyramid and search backend."""

    size: int
    shape: Shape = "causal"
    scan: ScanOrder = "lexicographic"
    levels: int = 1
    parent_size: int = 5
    iterations: int = 2
    search: SearchKind = "kcoherence"
    k: int = 5
    random_candidates: int = 2
    alpha: float = 0.5
    #: k-coherence sets: neighbourhood side and principal components of the k-NN search that builds them.
    kset_size: int = 7
    kset_dims: int = 8
    #: Histogram-matching weight (see :func:`synthesize_source_map`'s ``histogram``): 0 = plain nearest
    #: neighbour; larger values push the output's label histogram toward its target.
    histogram_weight: float = 0.0
    #: Tileable output: the first pass compares every synthesized position of the square, the
    #: refinement passes the whole square in a random order (see the module docstring).
    periodic: bool = False
    #: Gaussian falloff of the same-level neighbourhood (Efros & Leung 1999): entry ``o`` weighs
    #: ``exp(-|o|^2 / (2 sigma^2))`` with ``sigma = falloff * side`` (normalised to mean 1); 0 = flat.
    falloff: float = 0.0
    #: Refinement passes (2, 3, ...) compare a full square of side ``refine_size`` (0: ``size``; at most
    #: the level's side) in a random order, every neighbour proposing candidates (always on when periodic).
    refine_square: bool = False
    refine_size: int = 0
    #: With guidance: eq 13's ``p`` in the refinement passes (2, 3, ...); None = the first pass's ``p``.
    #: 1 makes them match pixels only, the guidance having laid out the first pass.
    refine_p: float | None = None


@dataclass(frozen=True)
class Guidance:
    """A fixed field that guides the synthesis (the synthesized tensor field of Akl 2014, eq 13).

    ``out_levels``/``ex_levels`` are kernel features (see :func:`tensor_features`), finest first;
    ``weight`` is ``1 - p``; ``hint_levels`` optional source maps proposing candidates.
    """

    out_levels: Sequence[np.ndarray]
    ex_levels: Sequence[np.ndarray]
    metric: int
    weight: float
    size: int
    hint_levels: Sequence[np.ndarray] | None = None


@dataclass(frozen=True)
class CandidateWindow:
    """Per-position restriction of the candidates: classes of exemplar positions and wanted classes.

    A candidate is searched at an output position only when its class lies within ``span`` of the
    position's wanted class, cyclically modulo ``period`` (the arbitrary-shape method's rotated
    copies of the exemplar near the local constraint angle). ``ex_levels`` (h_l, w_l) and
    ``out_levels`` (H_l, W_l) int arrays, finest first; a negative class is never searched.

    ``transfer_levels`` (optional, finest first): per level, ``(to_common, from_common)``, each
    ``(n_classes, 2, 3)`` affine maps from a class's exemplar positions ``(row, col, 1)`` to a frame all
    classes share, and back. With them a proposal from another class is moved to the same point of the
    wanted class instead of being dropped (:mod:`texsynth.synth.kernels.pixel_search`), so coherent copying
    continues across class changes.
    """

    ex_levels: Sequence[np.ndarray]
    out_levels: Sequence[np.ndarray]
    period: int
    span: int
    transfer_levels: Sequence[tuple[np.ndarray, np.ndarray]] | None = None


@dataclass
class SynthesisReport:
    """Numbers measured during a run: mean best-match distance per level and pass."""

    mean_best_distance: dict[str, float]

    def final(self) -> float:
        return list(self.mean_best_distance.values())[-1]


ProgressFn = Callable[[str, float], None]


def tensor_features(tensors: np.ndarray, metric: Metric) -> tuple[np.ndarray, int]:
    """Per-position tensor features and the kernel metric code that realises ``metric``.

    ED: ``(S_xx, sqrt2 S_xy, S_yy)`` under SSD (eq 6); FN: the same under its norm (eq 10);
    LE: the log-tensors under the norm (eq 11); SO: ``(sin O, cos O, C, 1 / C)``, ``C >= 1e-3`` (eqs 7-9).
    Large fields are computed in bands of rows on the job's threads (element-wise NumPy, which releases
    the GIL; the same bytes as one call: arbitrary-shape's rotated dictionary holds millions of tensors).
    """
    threads = current_threads()
    if threads > 1 and tensors.ndim >= 2 and tensors.shape[0] >= 2 * _FEATURE_ROWS:
        # Written in place: each band's arrays are made and freed by the thread that computes it.
        out = np.empty((*tensors.shape[:-1], 4 if metric == "SO" else 3), dtype=np.float32)

        def band(r: int) -> int:
            out[r : r + _FEATURE_ROWS], code = _tensor_features(tensors[r : r + _FEATURE_ROWS], metric)
            return code

        codes = thread_map(band, range(0, tensors.shape[0], _FEATURE_ROWS), threads)
        return out, codes[0]
    return _tensor_features(tensors, metric)


def _tensor_features(tensors: np.ndarray, metric: Metric) -> tuple[np.ndarray, int]:
    t = tensors.astype(np.float32)
    if metric in ("ED", "FN"):
        feats = np.stack([t[..., 0], np.sqrt(2.0) * t[..., 1], t[..., 2]], axis=-1)
        code = METRIC_SSD if metric == "ED" else METRIC_NORM
    elif metric == "LE":
        lg = log_tensors(t.astype(np.float64))
        feats = np.stack([lg[..., 0], np.sqrt(2.0) * lg[..., 1], lg[..., 2]], axis=-1)
        code = METRIC_NORM
    elif metric == "SO":
        theta = orientation(t.astype(np.float64))
        coh = np.maximum(coherence(t), _COHERENCE_FLOOR)
        # 1 / C is stored so that the kernel's M_coh = max(C1 / C2, C2 / C1) needs no division.
        feats = np.stack([np.sin(theta), np.cos(theta), coh, 1.0 / coh], axis=-1)
        code = METRIC_SO
    else:
        raise InvalidParameter("metric", metric, "must be one of ED, SO, FN, LE")
    return np.ascontiguousarray(feats, dtype=np.float32), code


def _euclidean_embedding(feats: np.ndarray, code: int) -> np.ndarray:
    """Features in a space where Euclidean distance approximates the metric (for the k-NN sets)."""
    if code == METRIC_SO:  # doubled-angle vector scaled by coherence: orientations modulo pi
        s, c, k = feats[..., 0], feats[..., 1], feats[..., 2]
        return np.stack([k * (c * c - s * s), k * 2 * s * c], axis=-1)
    return feats


def _typical_distance(feats: np.ndarray, code: int, alpha: float, rng: np.random.Generator) -> float:
    """Mean position distance between random pairs of positions: the unit of a block's distance."""
    flat = feats.reshape(-1, feats.shape[-1])
    i = rng.integers(0, len(flat), 4096)
    j = rng.integers(0, len(flat), 4096)
    d = float(np.mean(position_distance(flat[i], flat[j], code, alpha)))
    return d if d > 1e-20 else 1.0


def source_map_pyramid(src: np.ndarray, levels: int) -> list[np.ndarray]:
    """A source map at every pyramid level, finest first: each level takes every other output
    position and halves its exemplar coordinates (the hints a coarser level's search is offered)."""
    maps = [np.ascontiguousarray(src)]
    for _ in range(levels - 1):
        maps.append(np.ascontiguousarray(maps[-1][::2, ::2] // 2))
    return maps


def level_neighbourhood_size(size: int, level_shape: tuple[int, int]) -> int:
    """The neighbourhood side used at a coarse pyramid level: ``size``, shrunk (odd, >= 3) to at
    most a quarter of the level's shorter side.

    Departure, and why: Akl 2014's Table 1 asks for 13x13 neighbourhoods on 4 levels of a 128x128
    exemplar; its coarsest level is 16x16, where a 13x13 neighbourhood fits at only 4x4 positions and
    the synthesis degenerates into copying one of 16 tensors. Worse, whatever lies within a
    neighbourhood radius of the exemplar's border can never be copied, and at level L that band is
    ``2^L`` times wider in the exemplar: laminae bent near the border disappeared from the output's
    orientation distribution. Coarse levels carry coarse structure, so a smaller neighbourhood there
    loses little, keeps the border band under about 12 exemplar pixels and keeps many candidates.
    """
    cap = max(3, int(min(level_shape) // _COARSE_DIVISOR))
    cap -= 1 - cap % 2
    return int(min(size, cap))


def check_neighbourhoods_fit(
    exemplar_shape: tuple[int, ...], levels: int, size: int, parent_size: int
) -> None:
    """Raise the driver's error now if a neighbourhood would not fit the exemplar at some pyramid level.

    Shapes only (:func:`texsynth.synth.grid.pyramid.level_shapes`, the driver's pyramid's shapes; no pixels),
    so the service can refuse such a job before queueing it instead of failing it in the worker.
    """
    from texsynth.synth.grid.pyramid import level_shapes

    shapes = level_shapes(tuple(int(n) for n in exemplar_shape[:2]), levels)  # type: ignore[arg-type]
    for level in range(levels - 1, -1, -1):  # coarse to fine, as the driver: the same first error
        ex_shape = shapes[level]
        side = size if level == 0 else level_neighbourhood_size(size, ex_shape)
        parent = None
        if level < levels - 1:
            parent = (shapes[level + 1], level_neighbourhood_size(parent_size, shapes[level + 1]) // 2)
        _valid_region(ex_shape, side // 2, parent, level)


def _valid_region(
    ex_shape: tuple[int, int], radius: int, parent: tuple[tuple[int, int], int] | None, level: int
) -> np.ndarray:
    h, w = ex_shape
    y0, y1, x0, x1 = radius, h - radius, radius, w - radius
    if parent is not None:
        (hp, wp), rp = parent
        y0, x0 = max(y0, 2 * rp), max(x0, 2 * rp)
        y1, x1 = min(y1, 2 * (hp - 1 - rp) + 2), min(x1, 2 * (wp - 1 - rp) + 2)
    if y1 <= y0 or x1 <= x0:
        raise InvalidParameter(
            "neighbourhood_size",
            2 * radius + 1,
            f"no neighbourhood fits inside the exemplar at pyramid level {level} ({h}x{w} pixels): "
            "use a smaller neighbourhood or fewer levels",
        )
    return np.array([y0, y1, x0, x1], dtype=np.int64)


def _square_vectors(feats: np.ndarray, size: int, valid: np.ndarray) -> np.ndarray:
    """Square neighbourhoods (flattened) of every valid position: ``(n_valid, size*size*C)``; the plain
    form of what :func:`kset_points` writes (tests compare them)."""
    r = size // 2
    y0, y1, x0, x1 = (int(v) for v in valid)
    parts = [
        feats[y0 + dy : y1 + dy, x0 + dx : x1 + dx].reshape(-1, feats.shape[-1])
        for dy in range(-r, r + 1)
        for dx in range(-r, r + 1)
    ]
    return np.concatenate(parts, axis=1)


def kset_points(
    embeds: Sequence[tuple[np.ndarray, float]],
    size: int,
    valid: np.ndarray,
    mask: np.ndarray,
    kset_size: int = 7,
    kset_dims: int = 8,
) -> np.ndarray:
    """The points whose nearest neighbours make the k-coherence sets (:func:`k_coherence_sets`): one row
    per valid, allowed exemplar position (raster order), its weighted square neighbourhood (side at most
    ``kset_size``) projected on the first ``kset_dims`` principal axes, float64."""
    ks = min(size, kset_size)
    y0, y1, x0, x1 = (int(v) for v in valid)
    inside = mask[y0:y1, x0:x1].ravel() != 0
    every = bool(inside.all())
    r = ks // 2
    # The weighted square neighbourhoods (:func:`_square_vectors`, times the square root of each weight,
    # in float64) written straight into one array: the same values as building, weighing, joining and
    # selecting them one after the other, without four whole copies.
    vectors = np.empty((int(inside.sum()), sum(ks * ks * e.shape[-1] for e, _ in embeds)), dtype=np.float64)
    col = 0
    for e, wt in embeds:
        scale = np.sqrt(wt)
        channels = e.shape[-1]
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                block = e[y0 + dy : y1 + dy, x0 + dx : x1 + dx].reshape(-1, channels)
                np.multiply(block if every else block[inside], scale, out=vectors[:, col : col + channels])
                col += channels
    vectors -= vectors.mean(axis=0)
    dims = min(kset_dims, vectors.shape[1], vectors.shape[0])
    # Principal axes from the covariance of a fixed, evenly spaced sample of rows (deterministic).
    sample = vectors[:: max(1, len(vectors) // _PCA_SAMPLE)]
    _, eigvec = np.linalg.eigh(sample.T @ sample)
    return vectors @ eigvec[:, ::-1][:, :dims]


def k_coherence_sets(
    embeds: Sequence[tuple[np.ndarray, float]],
    size: int,
    valid: np.ndarray,
    k: int,
    mask: np.ndarray,
    kset_size: int = 7,
    kset_dims: int = 8,
) -> np.ndarray:
    """For every valid exemplar position, its ``k`` most similar other valid positions.

    Neighbourhoods (square, at most ``kset_size``) of the weighted embeddings are projected on their
    first ``kset_dims`` principal components and queried in a k-d tree; ``-1`` marks positions
    without a set.
    """
    h, w = embeds[0][0].shape[:2]
    kset = np.full((h, w, k, 2), -1, dtype=np.int64)
    if k == 0:
        return kset
    y0, y1, x0, x1 = (int(v) for v in valid)
    inside = mask[y0:y1, x0:x1].ravel() != 0
    projected = kset_points(embeds, size, valid, mask, kset_size, kset_dims)
    kk = min(k + 1, len(projected))
    idx = _nearest_points(projected, kk, k >= _KSET_FAST_MIN_K)
    # Drop each position itself (wherever the tree put it among equal distances), keep k others.
    is_self = idx == np.arange(len(projected))[:, None]
    others_first = np.argsort(is_self, axis=1, kind="stable")
    idx = np.take_along_axis(idx, others_first, axis=1)[:, :k]
    idx = np.where(np.take_along_axis(is_self, others_first, axis=1)[:, :k], -1, idx)
    rows, cols = np.divmod(np.flatnonzero(inside), x1 - x0)
    ys = np.where(idx >= 0, y0 + rows[idx], -1)
    xs = np.where(idx >= 0, x0 + cols[idx], -1)
    kset[y0 + rows, x0 + cols, : idx.shape[1], 0] = ys
    kset[y0 + rows, x0 + cols, : idx.shape[1], 1] = xs
    return kset


def _nearest_points(points: np.ndarray, kk: int, fast: bool = True) -> np.ndarray:
    """Each point's ``kk`` nearest points (itself among them), nearest first: ``(n, kk)`` indices, exactly
    as SciPy's default k-d tree gives them (``cKDTree(points).query(points, kk)``), ties included.

    The tree's answer is unique wherever the ``kk + 1`` smallest distances of a row are all different:
    then any exact search finds those ``kk`` points in that order. With ``fast``, a tree of larger leaves
    (:data:`_KSET_LEAF`) finds ``kk + 1`` neighbours of every point; the rows with two of those distances
    within :data:`_KSET_TIE` of each other (duplicate or mirrored neighbourhoods: flat or binary exemplars)
    are searched again in the default tree, where its order among equal distances is the one the
    k-coherence sets always had. Queries are independent: the same answer on any number of workers.
    """
    n = len(points)
    workers = current_threads()
    if not fast or kk >= n:
        return cKDTree(points).query(points, k=kk, workers=workers)[1].reshape(n, kk)
    dist, idx = cKDTree(points, leafsize=_KSET_LEAF).query(points, k=kk + 1, workers=workers)
    tied = ~np.all(np.diff(dist, axis=1) > _KSET_TIE * dist[:, 1:], axis=1)
    idx = np.ascontiguousarray(idx[:, :kk])
    again = np.flatnonzero(tied)
    if len(again):
        idx[again] = cKDTree(points).query(points[again], k=kk, workers=workers)[1].reshape(-1, kk)
    return idx


def _level_mask(
    ex_masks: Sequence[np.ndarray] | None, level: int, shape: tuple[int, int], valid: np.ndarray
) -> np.ndarray:
    mask = (
        np.ones(shape, dtype=np.uint8)
        if ex_masks is None
        else np.ascontiguousarray(ex_masks[level], dtype=np.uint8)
    )
    y0, y1, x0, x1 = (int(v) for v in valid)
    if not mask[y0:y1, x0:x1].any():
        raise InvalidParameter(
            "neighbourhood_size", None, f"no valid exemplar position at pyramid level {level}"
        )
    return mask


class _Level(NamedTuple):
    """What a level's search needs before its sources: :func:`_level_setup`."""

    ex: np.ndarray
    par_ex: np.ndarray
    has_parent: bool
    size: int
    offs: np.ndarray
    cur_offs: np.ndarray
    par_offs: np.ndarray
    valid: np.ndarray
    unit: float
    gui_ex: np.ndarray
    gunit: float
    n_par: int
    w_pix: float
    gui_offs: np.ndarray
    w_gui: float
    mask: np.ndarray


def _level_setup(
    level: int,
    ex_levels: Sequence[np.ndarray],
    settings: SearchSettings,
    metric: int,
    p: float,
    guidance: Guidance | None,
    rng: np.random.Generator,
    ex_masks: Sequence[np.ndarray] | None,
) -> _Level:
    """A level's neighbourhoods, valid region, typical distances (the level's first draws of ``rng``),
    part weights and mask: everything :func:`synthesize_source_map` sets up before the level's sources.
    Reads the exemplar side only (``guidance.ex_levels``, not its output levels)."""
    levels = settings.levels
    ex = np.ascontiguousarray(ex_levels[level], dtype=np.float32)
    has_parent = level < levels - 1
    par_ex = (
        np.ascontiguousarray(ex_levels[level + 1], dtype=np.float32)
        if has_parent
        else _empty_features(ex.shape[2])
    )
    # The finest level keeps the requested size (too large is the user's error, said clearly).
    size = settings.size if level == 0 else level_neighbourhood_size(settings.size, ex.shape[:2])
    parent_size = level_neighbourhood_size(settings.parent_size, par_ex.shape[:2]) if has_parent else 1
    offs = neighbourhood_offsets(size, settings.shape)
    # Periodic: the kernel holds the whole square; the first pass compares its synthesized
    # positions (``offs``'s entries inside a lexicographic scan), the refinement passes all of it.
    cur_offs = neighbourhood_offsets(size, "square") if settings.periodic else offs
    cur_offs = _nearest_first(cur_offs, settings.falloff)
    par_offs = parent_offsets(parent_size) if has_parent else np.zeros((0, 2), np.int32)
    valid = _valid_region(
        ex.shape[:2], size // 2, (par_ex.shape[:2], parent_size // 2) if has_parent else None, level
    )
    unit = _typical_distance(ex, metric, settings.alpha, rng)
    if guidance is not None:
        gui_ex = np.ascontiguousarray(guidance.ex_levels[level], dtype=np.float32)
        gunit = _typical_distance(gui_ex, guidance.metric, settings.alpha, rng)
    else:
        gui_ex = _empty_features(3)
        gunit = 1.0
    n_par = len(par_offs) if has_parent else 0
    w_pix, gui_offs, w_gui = _part_weights(offs, n_par, unit, p, guidance, gunit)
    mask = _level_mask(ex_masks, level, ex.shape[:2], valid)
    return _Level(
        ex,
        par_ex,
        has_parent,
        size,
        offs,
        cur_offs,
        par_offs,
        valid,
        unit,
        gui_ex,
        gunit,
        n_par,
        w_pix,
        gui_offs,
        w_gui,
        mask,
    )


def _level_sets(lv: _Level, settings: SearchSettings, metric: int, guidance: Guidance | None) -> np.ndarray:
    """A level's k-coherence sets (:func:`k_coherence_sets`; an empty array for the exact search)."""
    if settings.search == "exact":
        return np.full((1, 1, 0, 2), -1, np.int64)
    embeds = [(_euclidean_embedding(lv.ex, metric), lv.w_pix)]
    if guidance is not None:
        embeds.append((_euclidean_embedding(lv.gui_ex, guidance.metric), lv.w_gui))
    return k_coherence_sets(
        embeds, lv.size, lv.valid, settings.k, lv.mask, settings.kset_size, settings.kset_dims
    )


def sets_ahead(
    ex_levels: Sequence[np.ndarray],
    settings: SearchSettings,
    *,
    metric: int = METRIC_SSD,
    p: float = 1.0,
    guidance: Guidance | None = None,
    seed: int = 0,
    ex_masks: Sequence[np.ndarray] | None = None,
) -> Callable[[], np.ndarray]:
    """Start the coarsest level's k-coherence sets of a later :func:`synthesize_source_map` (same
    arguments) on a thread of their own; return the call that waits for them (for its ``coarsest_sets``).

    They depend on the exemplar and the seed only (the level's typical distances are the run's first
    draws), so a caller with other work first (``tensor-constrained``'s structure stage) overlaps them
    with it: the sets' query and projections release Python's lock and fill the cores that work leaves
    idle. One thread (the k-d tree's ``workers``): the same sets as on any number. The output's guidance
    levels are not read (``guidance.out_levels`` may be empty).
    """
    box: list = []

    def work() -> None:
        try:
            with use_threads(1):
                rng = np.random.default_rng(seed)
                lv = _level_setup(
                    settings.levels - 1, ex_levels, settings, metric, p, guidance, rng, ex_masks
                )
                box.append(_level_sets(lv, settings, metric, guidance))
        except BaseException as err:  # raised again by the waiting call
            box.append(err)

    thread = threading.Thread(target=work, name="texsynth-sets", daemon=True)
    thread.start()

    def result() -> np.ndarray:
        thread.join()
        if isinstance(box[0], BaseException):
            raise box[0]
        return box[0]

    return result


def _initial_sources(
    shape: tuple[int, int],
    valid: np.ndarray,
    mask: np.ndarray,
    parent_src: np.ndarray | None,
    rng: np.random.Generator,
) -> np.ndarray:
    """Random valid exemplar positions at the top level; the parent's sources, upsampled, below.

    An upsampled source that is not a valid position is replaced by a random valid one.
    """
    y0, y1, x0, x1 = (int(v) for v in valid)
    allowed = np.zeros_like(mask, dtype=bool)
    allowed[y0:y1, x0:x1] = mask[y0:y1, x0:x1] != 0
    positions = np.argwhere(allowed)
    H, W = shape
    pick = positions[_source_draws(shape, len(positions), rng)].reshape(H, W, 2)
    if parent_src is None:
        return np.ascontiguousarray(pick, dtype=np.int64)
    yy, xx = np.mgrid[0:H, 0:W]
    up = parent_src[yy // 2, xx // 2]
    src = np.stack(
        [np.clip(2 * up[..., 0] + yy % 2, y0, y1 - 1), np.clip(2 * up[..., 1] + xx % 2, x0, x1 - 1)], axis=-1
    )
    bad = ~allowed[src[..., 0], src[..., 1]]
    src[bad] = pick[bad]
    return np.ascontiguousarray(src, dtype=np.int64)


def _source_draws(shape: tuple[int, int], allowed: int, rng: np.random.Generator) -> np.ndarray:
    """The draws of :func:`_initial_sources`: an index among the ``allowed`` positions per output position."""
    return rng.integers(0, allowed, size=int(shape[0]) * int(shape[1]))


def _pass_draws(
    settings: SearchSettings, shape: tuple[int, int], started: bool, rng: np.random.Generator
) -> None:
    """Draw from ``rng`` what :func:`synthesize_source_map`'s passes over one level draw, in their order
    (scan orders, pass keys, the seam's key and the next pass's order), and nothing else: the generator is
    then where the next level's set-up finds it. The ahead sets (:class:`_AheadSets`) replay a run with it;
    ``tests/synth/pixel/test_ahead_sets.py`` checks that every level's prediction holds."""
    square_refinement = settings.periodic or settings.refine_square
    ahead = False
    for it in range(settings.iterations):
        refine = square_refinement and (it > 0 or started)
        tiled = not refine and settings.scan == "lexicographic"
        if ahead:
            ahead = False
        elif not tiled:
            scan_order(shape, "random" if refine else settings.scan, rng)
        rng.integers(0, 2**63)
        if it == 0 and not started and tiled:
            rng.integers(0, 2**63)
            if square_refinement and it + 1 < settings.iterations:
                scan_order(shape, "random", rng)
                ahead = True


class _AheadSets:
    """The k-coherence sets of every level below the coarsest, made from the start of a run on a thread of
    their own while the coarser levels set up, load their kernels and run their passes (which leave a core
    idle at small sizes).

    A level's sets depend on its set-up (:func:`_level_setup`), whose typical distances are drawn from the
    run's generator after every draw of the coarser levels. A copy of the generator replays those draws
    (:func:`_level_setup`, :func:`_source_draws`, :func:`_pass_draws`) to set each level up ahead; the run
    takes a level's sets only when its own generator is then in exactly the state the copy was in (the
    same draws, the same set-up, the same sets), and makes them itself otherwise. One thread (the k-d
    tree's ``workers``): the same sets as on any number. Stopped between levels once the run no longer
    needs them (its finest level taken, or the run ended by an error: its object is then dropped).
    """

    def __init__(
        self,
        ex_levels: Sequence[np.ndarray],
        out_shapes: Sequence[tuple[int, int]],
        settings: SearchSettings,
        metric: int,
        p: float,
        guidance: Guidance | None,
        rng: np.random.Generator,
        ex_masks: Sequence[np.ndarray] | None,
        started: bool,
    ) -> None:
        levels = settings.levels
        self.states: dict[int, dict] = {}
        self.sets: dict[int, np.ndarray | BaseException] = {}
        self.ready = {level: threading.Event() for level in range(levels - 1)}
        stop = self.stop = threading.Event()
        twin = copy.deepcopy(rng)  # the run's generator as it is now, before any of its draws
        states, sets, ready = self.states, self.sets, self.ready

        def work() -> None:
            try:
                with use_threads(1):
                    made: list[tuple[int, _Level]] = []
                    lv = _level_setup(levels - 1, ex_levels, settings, metric, p, guidance, twin, ex_masks)
                    for level in range(levels - 1, 0, -1):  # the coarser levels' draws, replayed
                        shape = (int(out_shapes[level][0]), int(out_shapes[level][1]))
                        _source_draws(shape, _allowed_count(lv.valid, lv.mask), twin)
                        _pass_draws(settings, shape, started, twin)
                        states[level - 1] = twin.bit_generator.state
                        lv = _level_setup(level - 1, ex_levels, settings, metric, p, guidance, twin, ex_masks)
                        made.append((level - 1, lv))
                    for level, lv in made:
                        if stop.is_set():
                            break
                        sets[level] = _level_sets(lv, settings, metric, guidance)
                        ready[level].set()
            except BaseException as err:  # the run makes the sets itself (and meets the error there)
                for level in ready:
                    sets.setdefault(level, err)
            finally:
                for event in ready.values():
                    event.set()

        self.thread = threading.Thread(target=work, name="texsynth-sets-ahead", daemon=True)
        self.thread.start()
        weakref.finalize(self, stop.set)

    def take(self, level: int, state: dict) -> np.ndarray | None:
        """Level ``level``'s sets, if the run's generator was in ``state`` before its set-up, as predicted."""
        self.ready[level].wait()
        if level == 0:
            self.stop.set()
        sets = self.sets.get(level)
        if self.states.get(level) != state or not isinstance(sets, np.ndarray):
            return None
        return sets


def _allowed_count(valid: np.ndarray, mask: np.ndarray) -> int:
    """How many exemplar positions :func:`_initial_sources` draws from (valid and allowed by ``mask``)."""
    y0, y1, x0, x1 = (int(v) for v in valid)
    return int(np.count_nonzero(mask[y0:y1, x0:x1]))


def _histogram_state(
    histogram: tuple[np.ndarray, np.ndarray] | None,
    src: np.ndarray,
    valid: np.ndarray,
    mask: np.ndarray,
    weight: float,
) -> Histogram:
    """The kernel's histogram arrays: a label per exemplar position, the output's count per label
    (from the initial sources) and the wanted count per label.

    Without ``histogram`` the labels are the positions themselves and the target is a uniform use of
    every copyable position (Chen & Wang's position histogram); with ``(labels, fractions)`` the
    target is ``fractions`` of the output's pixels.
    """
    h, w = mask.shape
    n_out = src.shape[0] * src.shape[1]
    if histogram is None:
        y0, y1, x0, x1 = (int(v) for v in valid)
        labels = np.arange(h * w, dtype=np.int64)
        target = np.full(h * w, n_out / max(1, int(np.count_nonzero(mask[y0:y1, x0:x1]))))
    else:
        labels = np.ascontiguousarray(histogram[0], dtype=np.int64).ravel()
        # A label rarer than one output pixel still has room for one.
        target = np.maximum(np.asarray(histogram[1], dtype=np.float64) * n_out, 1.0)
    count = np.bincount(labels[(src[..., 0] * w + src[..., 1]).ravel()], minlength=len(target))
    return Histogram(labels, count.astype(np.int64), target, weight)


def _window_state(window: CandidateWindow | None, level: int) -> ClassWindow:
    """The kernel's class window at ``level`` (a span of -1 switches the window off)."""
    if window is None:
        return ClassWindow(np.zeros(1, np.int64), np.zeros((1, 1), np.int64), 1, -1)
    transfer = (
        window.transfer_levels[level]
        if window.transfer_levels is not None
        else (np.zeros((0, 2, 3)), np.zeros((0, 2, 3)))
    )
    return ClassWindow(
        np.ascontiguousarray(window.ex_levels[level], dtype=np.int64).ravel(),
        np.ascontiguousarray(window.out_levels[level], dtype=np.int64),
        int(window.period),
        int(window.span),
        *(np.ascontiguousarray(t, dtype=np.float64) for t in transfer),
    )


def _part_weights(
    compared: np.ndarray,
    n_par: int,
    unit: float,
    p: float,
    guidance: Guidance | None,
    gunit: float,
    gweight: float | None = None,
) -> tuple[float, np.ndarray, float]:
    """Per-entry weights of the pixel part (same and parent level) and of the guidance part, and the
    guidance offsets, when a pass compares the same-level offsets ``compared`` (eq 13, each part
    divided by its typical distance times the number of positions it compares; the guidance part
    weighs ``gweight``, by default ``guidance.weight``)."""
    w_pix = (p if guidance is not None else 1.0) / (unit * (len(compared) + n_par))
    if guidance is None:
        return w_pix, np.zeros((0, 2), np.int32), 0.0
    # The guidance (tensor) part has the pixel part's shape, centre included: the field is known there.
    gui = np.ascontiguousarray(np.vstack([[0, 0], compared]), dtype=np.int32)
    weight = guidance.weight if gweight is None else gweight
    return w_pix, gui, weight / (gunit * len(gui))


def entry_weights(offsets: np.ndarray, side: int, falloff: float) -> np.ndarray:
    """Per-entry weights of a neighbourhood's ``offsets``: a Gaussian of ``sigma = falloff * side``
    normalised to mean 1 (so the typical-distance normalisation of eq 13 keeps its meaning), or an
    empty array (all entries weigh 1) when ``falloff`` is 0."""
    if falloff <= 0.0:
        return np.ones(0, dtype=np.float64)
    sigma = falloff * side
    w = np.exp(-(offsets.astype(np.float64) ** 2).sum(axis=1) / (2.0 * sigma * sigma))
    return np.ascontiguousarray(w / w.mean())


def _nearest_first(offsets: np.ndarray, falloff: float) -> np.ndarray:
    """With a falloff, the offsets from the nearest to the farthest (stable), so that the kernel's
    partial distance, which stops once it exceeds the best so far, sums the heaviest entries first
    and stops sooner (the same sum in another order: the same argmin up to rounding). Flat: unchanged."""
    if falloff <= 0.0:
        return offsets
    order = np.argsort((offsets.astype(np.int64) ** 2).sum(axis=1), kind="stable")
    return np.ascontiguousarray(offsets[order])


def _empty_features(channels: int) -> np.ndarray:
    return np.zeros((1, 1, channels), dtype=np.float32)


class _Parts(NamedTuple):
    """The same-level offsets of a pass and the weights that go with them (:func:`_part_weights`)."""

    offsets: np.ndarray
    weight: float
    gui_offsets: np.ndarray
    gui_weight: float
    entry_weights: np.ndarray


def _seam_parts(
    size: int, falloff: float, n_par: int, unit: float, p: float, guidance: Guidance | None, gunit: float
) -> _Parts:
    """The full square of side ``size`` weighed as the first pass weighs its neighbourhood (eq 13's ``p``)."""
    offs = _nearest_first(neighbourhood_offsets(size, "square"), falloff)
    weight, gui_offs, gui_weight = _part_weights(offs, n_par, unit, p, guidance, gunit)
    return _Parts(offs, weight, gui_offs, gui_weight, entry_weights(offs, size, falloff))


def _search_seam(
    state: SearchState,
    shape: tuple[int, int],
    band: int,
    parts: _Parts,
    cand_offs: np.ndarray,
    seed_key: np.uint64,
    ahead: Callable[[], Schedule] | None = None,
) -> Schedule | None:
    """Search the first ``band`` columns again, row after row, with the full square ``parts``.

    A raster first pass run in tiles (:func:`texsynth.synth.kernels.pixel_search.tile_schedule`) leaves
    its first ``r`` columns without the end of the row above across the wrap, which a raster scan compares;
    once the pass is over every neighbour is there, on both sides. The driver passes ``band = 2 r``
    (measured best on the bent laminae, docs/pixel.md, "Parallel passes"). The band is a chain (each
    position touches the one before), searched on one thread; ``ahead`` (the next pass's schedule) runs
    meanwhile on another of the job's threads, and its result is returned (computed after the seam on
    one thread). Neither reads what the other writes: the bytes are the same either way.
    """
    H, W = shape
    band = min(band, W)
    if band <= 0:
        return ahead() if ahead is not None else None
    kept = (state.cur, state.par, state.gui, state.cands, state.run)
    state.cur = state.cur._replace(
        offsets=parts.offsets, weight=parts.weight, entry_weights=parts.entry_weights
    )
    state.par = state.par._replace(weight=parts.weight if state.par.weight > 0.0 else 0.0)
    state.gui = state.gui._replace(offsets=parts.gui_offsets, weight=float(parts.gui_weight))
    c = state.cands
    capacity = candidate_capacity(len(cand_offs), c.kset.shape[2], c.use_hint, c.n_random)
    state.cands = c._replace(cand_offs=cand_offs, capacity=max(c.capacity, capacity))
    counter = state.run.counter
    conflicts = conflict_offsets(parts.offsets, cand_offs)
    order, schedule = _seam_schedule(H, W, band, conflicts.tobytes())
    schedule = schedule._replace(tag0=int(counter[0]))
    counter[0] += len(order) + 1
    state.run = state.run._replace(order=order, first_pass=False, seed_key=seed_key)
    threads = current_threads()

    def seam() -> None:
        with use_threads(threads):  # whichever thread runs it: the job's count
            synthesize_levels(state, schedule, 0, len(schedule.starts) - 1)

    try:
        if ahead is None:
            seam()
            return None
        if threads < 2:
            seam()
            return ahead()
        return thread_map(lambda job: job(), [seam, ahead], 2)[1]
    finally:
        state.cur, state.par, state.gui, state.cands, state.run = kept


@functools.lru_cache(maxsize=8)
def _seam_schedule(H: int, W: int, band: int, conflicts: bytes) -> tuple[np.ndarray, Schedule]:
    """The seam's order (:func:`_search_seam`: the first ``band`` columns, row after row) and its schedule
    (:func:`texsynth.synth.kernels.pixel_search.schedule_levels`), once per shape, band and conflict
    offsets (every pass of every run shares them; nothing writes them)."""
    order = (np.arange(H)[:, None] * W + np.arange(band)[None, :]).ravel().astype(np.int64)
    return order, schedule_levels(order, (H, W), np.frombuffer(conflicts, dtype=np.int64).reshape(-1, 2))


def synthesize_source_map(
    ex_levels: Sequence[np.ndarray],
    out_shapes: Sequence[tuple[int, int]],
    settings: SearchSettings,
    *,
    metric: int = METRIC_SSD,
    p: float = 1.0,
    guidance: Guidance | None = None,
    seed: int = 0,
    progress: ProgressFn | None = None,
    stage: str = "synthesis",
    span: tuple[float, float] = (0.0, 1.0),
    ex_masks: Sequence[np.ndarray] | None = None,
    on_level_done: Callable[[int, dict], None] | None = None,
    histogram: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
    window: CandidateWindow | None = None,
    initial: Sequence[np.ndarray] | None = None,
    coarsest_sets: Callable[[], np.ndarray] | None = None,
) -> tuple[list[np.ndarray], SynthesisReport]:
    """Synthesize source maps for every pyramid level, coarsest first; return them finest first.

    Parameters
    ----------
    ex_levels : list of ndarray (h_l, w_l, C), finest first
        Exemplar features per level (pixels, or tensor features from :func:`tensor_features`).
    out_shapes : list of (H_l, W_l), finest first
    settings : SearchSettings
    metric : int
        Kernel metric code of the synthesized features (``METRIC_SSD`` for pixels).
    p : float
        Weight of the pixel part against the guidance part (eq 13); ignored without guidance.
    guidance : Guidance, optional
    seed : int
    progress : callable (stage, fraction), optional
        Called about 64 times per pass with the overall fraction inside ``span``; may raise to cancel.
    ex_masks : list of ndarray (h_l, w_l) bool, finest first, optional
        Exemplar positions that may be copied, per level (besides the neighbourhood-fits rectangle).
        Masked positions' neighbourhoods must lie inside the array; the caller guarantees they are
        meaningful (e.g. inside a rotated copy of the exemplar).
    on_level_done : callable (level, state), optional
        Receives each level's final kernel state (benchmarks use it to compare searches).
    histogram : list of (labels (h_l, w_l) int, fractions (n_labels,)), finest first, optional
        With ``settings.histogram_weight > 0``: the label of every exemplar position and the fraction
        of the output each label should cover (e.g. orientation bins and the exemplar's orientation
        histogram). Default: Chen & Wang's position histogram (every copyable position used equally).
    window : CandidateWindow, optional
        Restricts, per output position, the exemplar positions searched (exact and fast search).
    initial : list of ndarray (H_l, W_l, 2) int, finest first, optional
        Initial source maps (e.g. an exemplar laid out along a constraint): every level starts from
        its map instead of random sources (or its parent's), and with ``settings.refine_square`` every
        pass, the first included, is a square refinement pass (the whole square, random order), since
        every position already holds a source.
    coarsest_sets : callable, optional
        Returns the coarsest level's k-coherence sets, made ahead by :func:`sets_ahead` from the same
        exemplar levels, settings, metric, ``p``, guidance exemplar levels, seed and masks.
    """
    levels = settings.levels
    if len(ex_levels) != levels or len(out_shapes) != levels:
        raise InvalidParameter("levels", levels, "exemplar and output pyramids must have that many levels")
    rng = np.random.default_rng(seed)
    finer_sets = None  # the finer levels' k-coherence sets, made meanwhile on another thread
    if levels > 1 and settings.search != "exact" and settings.k > 0 and current_threads() > 1:
        finer_sets = _AheadSets(
            ex_levels, out_shapes, settings, metric, p, guidance, rng, ex_masks, initial is not None
        )
    cand_offs = neighbourhood_offsets(2 * _CANDIDATE_RADIUS + 1, "square")
    cand_offs = all_cand_offs = np.ascontiguousarray(np.vstack([[0, 0], cand_offs]), dtype=np.int32)
    square_refinement = settings.periodic or settings.refine_square
    # Only already-synthesized neighbours propose in a causal scan; a periodic run lets every one
    # propose (the first rows and columns across the bottom and right borders among them).
    if settings.shape == "causal" and not settings.periodic:
        cand_offs = np.ascontiguousarray(
            cand_offs[(cand_offs[:, 0] < 0) | ((cand_offs[:, 0] == 0) & (cand_offs[:, 1] <= 0))]
        )
    work = [settings.iterations * h * w for h, w in out_shapes]
    total_work = float(sum(work))
    done_work = 0.0
    report: dict[str, float] = {}
    srcs: list[np.ndarray | None] = [None] * levels
    stamp_size = max(int(np.prod(e.shape[:2])) for e in ex_levels)
    stamp = np.zeros((current_threads(), stamp_size), dtype=np.int64)  # one row per block of a level
    counter = np.zeros(1, dtype=np.int64)
    for level in range(levels - 1, -1, -1):
        drawn = rng.bit_generator.state if finer_sets is not None and level < levels - 1 else None
        lv = _level_setup(level, ex_levels, settings, metric, p, guidance, rng, ex_masks)
        ex, par_ex, has_parent, size, _, cur_offs, par_offs, valid = lv[:8]
        unit, gui_ex, gunit, n_par, w_pix, gui_offs, w_gui, mask = lv[8:]
        shape = tuple(out_shapes[level])
        if guidance is not None:
            gui_out = np.ascontiguousarray(guidance.out_levels[level], dtype=np.float32)
            hint = guidance.hint_levels[level] if guidance.hint_levels is not None else None
        else:
            gui_out = gui_ex
            hint = None
        # Refinement passes may weigh eq 13 otherwise (``refine_p``); None keeps the first pass's weights.
        p_ref, gw_ref = (p, None)
        if settings.refine_p is not None:
            p_ref, gw_ref = settings.refine_p, 1.0 - settings.refine_p
        src = _initial_sources(shape, valid, mask, srcs[level + 1] if has_parent else None, rng)
        if initial is not None:
            src = np.ascontiguousarray(initial[level], dtype=np.int64).copy()
        exact = settings.search == "exact"
        k = 0 if exact else settings.k
        if coarsest_sets is not None and level == levels - 1:
            kset = coarsest_sets()  # made ahead by :func:`sets_ahead`, from the same inputs
        else:
            kset = finer_sets.take(level, drawn) if finer_sets is not None and drawn is not None else None
            if kset is None:
                kset = _level_sets(lv, settings, metric, guidance)
        par_out = (
            np.ascontiguousarray(ex_levels[level + 1][srcs[level + 1][..., 0], srcs[level + 1][..., 1]])
            if has_parent
            else _empty_features(ex.shape[2])
        )
        gui_metric = guidance.metric if guidance is not None else METRIC_SSD
        best_out = np.zeros(shape, dtype=np.float32)
        state = SearchState(
            cur=Part(
                np.ascontiguousarray(ex[src[..., 0], src[..., 1]]),
                ex,
                cur_offs,
                metric,
                w_pix,
                entry_weights(cur_offs, size, settings.falloff),
            ),
            par=Part(par_out, par_ex, par_offs, metric, w_pix if has_parent else 0.0),
            gui=Part(gui_out, gui_ex, gui_offs, gui_metric, float(w_gui)),
            alpha=float(settings.alpha),
            cands=Candidates(
                src=src,
                hint=np.ascontiguousarray(hint, dtype=np.int64) if hint is not None else src,
                use_hint=hint is not None,
                valid=valid,
                mask=mask,
                kset=kset,
                cand_offs=cand_offs,
                exact=exact,
                n_random=0 if exact else settings.random_candidates,
                capacity=candidate_capacity(
                    len(all_cand_offs if square_refinement else cand_offs),
                    k,
                    hint is not None,
                    settings.random_candidates,
                ),
            ),
            hist=_histogram_state(
                histogram[level] if histogram is not None else None,
                src,
                valid,
                mask,
                float(settings.histogram_weight),
            ),
            win=_window_state(window, level),
            run=Pass(
                scan_order(shape, "lexicographic"),
                True,
                np.zeros(shape, np.uint8),
                np.uint64(0),
                stamp,
                counter,
                best_out,
            ),
        )
        n = shape[0] * shape[1]
        started = initial is not None  # every position holds a source: no first (causal) pass
        side = min(settings.refine_size or size, size)  # the square refinement passes' window
        ref_offs = _nearest_first(neighbourhood_offsets(side, "square"), settings.falloff)
        ahead: tuple[np.ndarray, Schedule] | None = None  # the next pass's order and schedule, if made
        for it in range(settings.iterations):
            refine = square_refinement and (it > 0 or started)
            if refine and it == (0 if started else 1):  # square refinement: the whole square, weighed as such
                w_ref, gui_ref, w_gui_ref = _part_weights(
                    ref_offs, n_par, unit, p_ref, guidance, gunit, gw_ref
                )
                state.cur = state.cur._replace(
                    offsets=ref_offs,
                    weight=w_ref,
                    entry_weights=entry_weights(ref_offs, side, settings.falloff),
                )
                state.par = state.par._replace(weight=w_ref if has_parent else 0.0)
                state.gui = state.gui._replace(offsets=gui_ref, weight=float(w_gui_ref))
                state.cands = state.cands._replace(cand_offs=all_cand_offs)
            first = it == 0 and not started
            tiled = not refine and settings.scan == "lexicographic"
            if ahead is not None:  # made while the seam pass ran (its order drawn then, in turn)
                order, schedule = ahead[0], ahead[1]._replace(tag0=int(counter[0]))
                ahead = None
            else:
                order = None if tiled else scan_order(shape, "random" if refine else settings.scan, rng)
                conflicts = conflict_offsets(state.cur.offsets, state.cands.cand_offs)
                if order is None:  # a raster scan: tiles in waves (a raster scan on a torus is one chain)
                    schedule = tile_schedule(shape, conflicts, tag0=int(counter[0]))
                else:
                    schedule = schedule_levels(order, shape, conflicts, int(counter[0]))
            counter[0] += n + 1
            state.run = Pass(
                order=schedule.sched if order is None else order,
                first_pass=first,
                done=state.run.done if it > 0 else np.full(shape, 1 if started else 0, np.uint8),
                seed_key=np.uint64(int(rng.integers(0, 2**63))),
                stamp=stamp,
                counter=counter,
                best_out=best_out,
            )
            label = f"{stage}: level {level + 1}/{levels}, pass {it + 1}/{settings.iterations}"
            ends = schedule.units[schedule.starts]  # positions done once each level has run
            n_levels = len(ends) - 1
            lo = 0
            while lo < n_levels:  # about _CHUNKS_PER_PASS chunks of whole levels, a progress report each
                hi = int(np.searchsorted(ends, ends[lo] + max(1, n // _CHUNKS_PER_PASS), side="left"))
                hi = min(n_levels, max(lo + 1, hi))
                synthesize_levels(state, schedule, lo, hi)
                lo = hi
                if progress is not None:
                    frac = (done_work + (it * n + int(ends[hi]))) / total_work
                    progress(label, span[0] + (span[1] - span[0]) * frac)
            if first and tiled:
                seam = _seam_parts(size, settings.falloff, n_par, unit, p, guidance, gunit)
                seam_key = np.uint64(int(rng.integers(0, 2**63)))
                make_next, next_order = None, None
                if square_refinement and it + 1 < settings.iterations:
                    # The next pass is a random square pass: its order is the generator's next draw (as
                    # when it is made at its turn), its schedule is made on another thread meanwhile.
                    next_order = scan_order(shape, "random", rng)
                    conflicts = conflict_offsets(ref_offs, all_cand_offs)
                    make_next = functools.partial(schedule_levels, next_order, shape, conflicts)
                made = _search_seam(state, shape, 2 * (size // 2), seam, all_cand_offs, seam_key, make_next)
                if made is not None and next_order is not None:
                    ahead = (next_order, made)
            report[f"level {level + 1} pass {it + 1}"] = float(np.mean(state.run.best_out))
        done_work += work[level]
        srcs[level] = src
        if on_level_done is not None:
            on_level_done(level, state)
    return [s for s in srcs if s is not None], SynthesisReport(report)
