"""Image quilting (Efros & Freeman 2001): patches in raster order, stitched by a minimum-error cut.

For every patch position of the layout (:class:`texsynth.synth.patch.layout.PatchLayout`: side ``w``, overlap
a sixth of it), the masked SSD of the output's overlap (L-shaped, top or left) against every exemplar patch
is computed by FFT correlation (:class:`texsynth.synth.patch.search.PatchSearcher`); one patch is chosen
uniformly at random among those whose error is within ``(1 + tolerance)`` of the best (sec. 2.1: "within 0.1
times the error of the best match"), and stitched along the minimum-error boundary cut of the overlap error
surface (sec. 2.1, dynamic programming; the vertical and horizontal cuts of an L meet at their cheapest
common point, :mod:`texsynth.synth.patch.cut`) or, with ``blending='graph-cut'``, along the Kwatra et al. 2003
graph-cut seam (:mod:`texsynth.synth.patch.graphcut`).

References
----------
A. A. Efros, W. T. Freeman, "Image quilting for texture synthesis and transfer", SIGGRAPH 2001,
pp. 341-346. V. Kwatra, A. Schödl, I. Essa, G. Turk, A. Bobick, "Graphcut textures: image and video
synthesis using graph cuts", ACM TOG 22(3), 2003, pp. 277-286 (eq. 1, for ``blending='graph-cut'``).

Departures (docs/patch.md has the measurements)
-----------------------------------------------
- The first patch is drawn uniformly among all exemplar patches; the output is grown to whole patches
  and cropped; the overlap error sums colour channels; only patches inside the exemplar are candidates.
- ``periodic=True`` (not the paper): a torus layout, the last patch of a row (column) searched and cut
  against both of its known strips (:func:`texsynth.synth.patch.cut.strips_cut_mask`).
- ``error='normalised'``, ``usage_weight=1`` (the paper: ``'ssd'``, 0): the SSD divided by the overlap's
  plus the candidate's variance (:meth:`texsynth.synth.patch.search.PatchSearcher.normalised_ssd`) times a
  penalty on over-used exemplar regions (:class:`texsynth.synth.patch.usage.UsagePenalty`), so the output does
  not settle in the exemplar's flattest region (docs/patch.md, section "Laminar HRTEM").
- ``stats['patch_sources']`` and ``stats['coverage']``
  (:func:`texsynth.synth.evaluate.coverage.exemplar_coverage`); extras ``copy_map``
  (:func:`texsynth.synth.evaluate.copy_map`) and ``source_map`` (row, column per pixel).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Literal

import numpy as np
from pydantic import Field

from texsynth.synth.api import MethodSpec, Progress, Result, register
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.evaluate.coverage import exemplar_coverage
from texsynth.synth.evaluate.patches import copy_map, copy_share
from texsynth.synth.kernels import patch_search as patch_kernels
from texsynth.synth.methods.common import PatchParams, checked_progress
from texsynth.synth.params import ui
from texsynth.synth.patch.cut import error_surface, strips_cut_mask
from texsynth.synth.patch.graphcut import graph_cut_mask
from texsynth.synth.patch.layout import PatchLayout, check_periodic_size, patch_rng
from texsynth.synth.patch.memory import settle_heap, wave_batch, wave_bytes
from texsynth.synth.patch.search import PatchSearcher
from texsynth.synth.patch.usage import UsagePenalty
from texsynth.synth.threads import current_threads, thread_map

__all__ = ["QuiltingParams", "check_patch_geometry", "precheck_patch_method", "run_quilting"]


class QuiltingParams(PatchParams):
    """Parameters of image quilting (Efros & Freeman 2001)."""

    OVERLAP_DIVISOR = 6
    MIN_OVERLAP = 1

    # Efros & Freeman choose the block "big enough to capture the relevant structures"; 32 px suits the
    # 128 -> 256 exemplars of their figures (and ours).
    patch_size: int = Field(
        32,
        ge=4,
        le=256,
        description="Side of the square patches copied from the exemplar (w).",
        json_schema_extra=ui(basic=True, unit="px", details=("Side w of the square patches, pixels.")),
    )
    overlap: int | None = Field(
        None,
        ge=1,
        le=255,
        description="How much neighbouring patches overlap; automatic: a sixth of the patch (the paper).",
        json_schema_extra=ui(
            basic=True,
            unit="px",
            details=(
                "Overlap between neighbouring patches, pixels; default a sixth of the patch (the paper)."
            ),
        ),
    )
    tolerance: float = Field(
        0.1,
        ge=0.0,
        le=10.0,
        description="A patch is drawn among those whose overlap error is within (1 + tolerance) of the best.",
        json_schema_extra=ui(),
    )
    error: Literal["normalised", "ssd"] = Field(
        "normalised",
        description="How overlaps are compared: 'normalised' does not favour flat patches; 'ssd' is the "
        "paper's plain squared difference.",
        json_schema_extra=ui(
            details=(
                "Overlap error: 'normalised' (default, not the paper) = SSD over the template's plus the "
                "candidate's own variance on the overlap, so flat candidates are not preferred for being "
                "flat; 'ssd' = the paper's sum of squared differences."
            )
        ),
    )
    usage_weight: float = Field(
        1.0,
        ge=0.0,
        le=100.0,
        description="How strongly over-used exemplar places are avoided; 0 is the paper (position "
        "histogram).",
        json_schema_extra=ui(
            details=(
                "Gain of the penalty on over-used exemplar regions (Chen & Wang's position histogram; not "
                "the paper): a candidate's error is multiplied by 1 + weight * excess use. 0 = the paper."
            )
        ),
    )
    blending: Literal["boundary-cut", "graph-cut"] = Field(
        "boundary-cut",
        description="How patches are stitched: a minimum-error 'boundary-cut' (the paper) or a "
        "'graph-cut' (Kwatra 2003).",
        json_schema_extra=ui(
            basic=True,
            details=(
                "'boundary-cut': minimum-error cut by dynamic programming (Efros & Freeman); 'graph-cut': "
                "minimum s-t cut over the overlap (Kwatra et al. 2003)."
            ),
        ),
    )


def check_patch_geometry(
    exemplar: np.ndarray | tuple[int, ...], patch_size: int, overlap: int, role: str = "exemplar"
) -> None:
    """Errors before any work: the patch must fit in the exemplar (an array or its shape) and the
    overlap in the patch."""
    h, w = (exemplar.shape if isinstance(exemplar, np.ndarray) else tuple(exemplar))[:2]
    if patch_size > min(h, w):
        raise InvalidParameter(
            "patch_size", patch_size, f"larger than the {role} ({h} x {w}); use at most {min(h, w)}"
        )
    if overlap >= patch_size:
        raise InvalidParameter("overlap", overlap, f"must be smaller than patch_size ({patch_size})")


def precheck_patch_method(params: PatchParams, shapes: Mapping[str, tuple[int, ...]]) -> None:
    """:attr:`MethodSpec.precheck` of a patch method: the patch fits the exemplar, and with ``periodic``
    the output (``shapes['output']``, when the caller knows it) holds at least two patch steps per side."""
    overlap = params.resolved_overlap()
    check_patch_geometry(shapes["exemplar"], params.patch_size, overlap)
    if params.periodic and "output" in shapes:
        check_periodic_size(shapes["output"], params.patch_size, overlap)


def run_quilting(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int],
    params: QuiltingParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
) -> Result:
    overlap = params.resolved_overlap()
    size = (int(size[0]), int(size[1]))
    precheck_patch_method(params, {"exemplar": exemplar.shape, "output": size})
    report = checked_progress(progress)
    start = time.perf_counter()
    w = params.patch_size
    layout = PatchLayout(size, w, overlap, periodic=params.periodic)
    searcher = PatchSearcher(exemplar, w)
    ex = searcher.exemplar
    gh, gw = layout.grown_shape
    out = np.zeros((gh, gw, ex.shape[2]), dtype=np.float64)
    source = np.zeros((gh, gw, 2), dtype=np.int32)
    n_pos = searcher.positions_shape[0] * searcher.positions_shape[1]
    usage = UsagePenalty(ex.shape, w, params.usage_weight)
    patches = layout.patches()
    placed: dict[int, tuple[int, int, np.ndarray, float | None]] = {}
    base = int(np.random.default_rng(seed).integers(2**63))

    def place_first(n: int) -> tuple[int, int, np.ndarray, None]:
        """Patch ``n`` with nothing known around it: drawn uniformly (its own random stream), pasted."""
        choice = int(patch_rng(base, n).integers(n_pos))
        py, px = (int(v) for v in np.unravel_index(choice, searcher.positions_shape))
        rows, cols = layout.rows_cols(patches[n][2], patches[n][3])
        new_mask = np.ones((w, w), dtype=bool)
        patch = np.ascontiguousarray(searcher.patch(py, px))
        patch_kernels.paste(out, source, rows, cols, patch, new_mask, py, px)
        return py, px, new_mask, None

    def stitch(n: int, py: int, px: int, region: np.ndarray) -> np.ndarray:
        """Cut patch ``n`` (a wrapped patch of a periodic layout, or a graph-cut seam) and paste it."""
        i, j, y, x, _ = patches[n]
        patch = searcher.patch(py, px)
        if params.blending == "graph-cut":
            new_mask = graph_cut_mask(region, patch, layout.strips(i, j).mask(w), layout.sealed(i, j))
        else:
            new_mask = strips_cut_mask(error_surface(region, patch), layout.strips(i, j))
        rows, cols = layout.rows_cols(y, x)
        patch_kernels.paste(out, source, rows, cols, np.ascontiguousarray(patch), new_mask, py, px)
        return new_mask

    # The patches of a wave do not overlap: the wave is split into one run of consecutive patches per
    # thread, and each run is searched (its FFTs in one SciPy call), drawn (each patch from its own random
    # stream, seed and patch), cut and pasted by one task, all its steps on that task's thread (the
    # kernels and the FFTs release the GIL): a wave costs one hand-over between threads, not one per step.
    # The usage counts are those of the wave's start; then the wave's patches are counted.
    threads = current_threads()
    normalised = params.error == "normalised"
    fast = params.blending == "boundary-cut"

    # a run is searched in batches of at most `batch` patches (memory.wave_batch): the same bytes, since the
    # patches of a wave neither overlap nor read each other
    batch = wave_batch(searcher.grid, searcher.channels, threads)

    def place_run(todo: list[int], factors: np.ndarray | None) -> list[tuple[int, int, np.ndarray, float]]:
        """Search, draw, cut and paste the patches ``todo`` of one wave (each has known strips), ``batch`` at
        a time, on the calling thread; their regions are disjoint from those of the wave's other runs."""
        return [got for a in range(0, len(todo), batch) for got in place_batch(todo[a : a + batch], factors)]

    def place_batch(todo: list[int], factors: np.ndarray | None) -> list[tuple[int, int, np.ndarray, float]]:
        """:func:`place_run` of one batch."""
        where = [layout.rows_cols(patches[n][2], patches[n][3]) for n in todo]
        rows = np.stack([r for r, _ in where])
        cols = np.stack([c for _, c in where])
        regions = patch_kernels.gather_many(out, rows, cols)
        strips = [layout.strips(patches[n][0], patches[n][1]) for n in todo]
        masks = [s.mask(w) for s in strips]
        _, ssd, pools, counts = searcher.search_many(regions, masks, normalised, factors, params.tolerance, 1)
        chosen = []
        for b, n in enumerate(todo):
            choice = int(pools[b, patch_rng(base, n).integers(counts[b])])
            py, px = (int(v) for v in np.unravel_index(choice, searcher.positions_shape))
            chosen.append((py, px, float(ssd[b].ravel()[choice]) / searcher.mask_weight(masks[b])))
        quick = [b for b in range(len(todo)) if fast and not strips[b].two_sided]
        new_masks: dict[int, np.ndarray] = {}
        if quick:
            picked = [(chosen[b][0], chosen[b][1], strips[b].top, strips[b].left) for b in quick]
            choices = tuple(np.array(column, dtype=np.int64) for column in zip(*picked, strict=True))
            places = (rows[quick], cols[quick], regions[quick])
            got = patch_kernels.stitch_many_serial((out, source), places, ex, choices)
            new_masks.update(zip(quick, got, strict=True))
        for b in range(len(todo)):
            if b not in new_masks:
                new_masks[b] = stitch(todo[b], chosen[b][0], chosen[b][1], regions[b])
        return [(chosen[b][0], chosen[b][1], new_masks[b], chosen[b][2]) for b in range(len(todo))]

    def place_wave(todo: list[int], factors: np.ndarray | None) -> None:
        """The patches ``todo`` of one wave, in one run per thread (:func:`place_run`)."""
        runs = [part.tolist() for part in np.array_split(np.array(todo), min(threads, len(todo)))]
        for run, got in zip(runs, thread_map(lambda r: place_run(r, factors), runs, threads), strict=True):
            placed.update(zip(run, got, strict=True))

    waves = layout.waves()
    settle_heap(wave_bytes(min(max(map(len, waves)), batch * threads), searcher.grid, searcher.channels))
    for wave in waves:
        factors = usage.factors() if params.usage_weight > 0 else None
        for n in wave:
            if patches[n][4] == "none":
                placed[n] = place_first(n)
        todo = [n for n in wave if patches[n][4] != "none"]
        if todo:
            place_wave(todo, factors)
        for n in wave:
            usage.add(placed[n][0], placed[n][1], placed[n][2])
        report("quilting", len(placed) / len(layout))
    used = [(placed[n][0], placed[n][1]) for n in range(len(patches))]
    errors = [placed[n][3] for n in range(len(patches)) if placed[n][3] is not None]
    h, wd = layout.size
    image = np.clip(out[:h, :wd], 0.0, 1.0).astype(np.float32)
    image = image[..., 0] if exemplar.ndim == 2 else image
    t_synth = time.perf_counter() - start
    cmap = copy_map(image, exemplar)
    report("done", 1.0)
    return Result(
        method="quilting",
        image=image,
        params=params.model_dump(),
        seed=seed,
        timings={"synthesis": t_synth, "copy_map": time.perf_counter() - start - t_synth},
        extras={"copy_map": cmap, "source_map": source[:h, :wd]},
        stats={
            "layout": layout.describe(),
            "mean_overlap_error": float(np.mean(errors)) if errors else 0.0,
            "copy_share": copy_share(cmap),
            "patch_sources": [list(p) for p in used],
            "coverage": exemplar_coverage(used, exemplar.shape, w),
        },
    )


SPEC = register(
    MethodSpec(
        name="quilting",
        summary="Image quilting: raster patches stitched along minimum-error cuts (Efros & Freeman 2001).",
        params_model=QuiltingParams,
        run=run_quilting,
        precheck=precheck_patch_method,
        paper="Efros & Freeman, SIGGRAPH 2001",
    )
)
