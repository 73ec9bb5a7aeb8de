"""Solid texture synthesis by global optimisation (Kopf et al. 2007): a volume from 2D exemplars.

The volume ``s`` minimises ``E(s, {e}) = sum_v sum_{i in planes} ||s_{v,i} - e_{v,i}||^r`` (eq 1), ``s_{v,i}``
the ``n x n`` neighbourhood of voxel ``v`` in the slice orthogonal to axis ``i``, ``e_{v,i}`` the most similar
neighbourhood of that plane's exemplar. Each iteration alternates the **search step** (every ``e_{v,i}``)
and the **optimisation step**: every voxel becomes the weighted average of the values the matched
neighbourhoods covering it propose (eq 2), IRLS weights ``||s_{v,i} - e_{v,i}||^(r-2)``, ``r = 0.8`` (eq 3),
divided by ``1 + gain * max(0, H_s(b) - H_e(b))`` (eq 4: histogram matching). Coarse to fine over Gaussian
pyramids (:func:`texsynth.synth.pixel.solid.run_levels`); ``planes``: all three views, or two for laminae.

References: J. Kopf, C.-W. Fu, D. Cohen-Or, O. Deussen, D. Lischinski, T.-T. Wong, "Solid texture
synthesis from 2D exemplars", SIGGRAPH 2007, eqs 1-4. V. Kwatra et al., SIGGRAPH 2005 (IRLS). X. Tong et
al., SIGGRAPH 2002 (k-coherence). R. D. Urs et al., BMVC 2012 (the settings and the scan orders).

Departures (why and the measurements: docs/solid.md, "Departures from the papers"):
- histogram gain 64, not eq 4's 1 (:data:`HISTOGRAM_GAIN`): gain 1 let the volume collapse to flat grey;
- exemplar-usage re-weighting (:data:`POSITION_GAIN`, after Chen & Wang): against laminar attractors;
  on a crop that mixes order and disorder its target follows the local order (``order_usage``);
- one rank remap of the finished volume (``histogram_matching``); ``stats['contrast_before_remap']``;
- k-coherence search seeded by the coarser level (the k-d tree only at the very first iteration); 4
  iterations per level (the study: 10); a sparse grid of centres whose phase is drawn every iteration;
- the histogram follows the update in blocks of ``max(4096, N / 16)`` voxels (parallel), not voxel by voxel;
- the schedule follows the structure (``adapt_to_structure``): micro-structures 2 levels, laminae 10 its;
- orientation-usage re-weighting (``orientation_gain`` 32; 0 = the paper): eq 4 on orientation histograms;
- grey histogram, 16 bins; 7x7 neighbourhoods (smaller at coarse levels) inside the exemplar; wrap or mirror;
- structured starts (``structure``, :mod:`texsynth.synth.pixel.laminar`; Akl 2014's structure first, in 3D):
  curved sheets (a centred field; length fitted: ``structure_length``) for isotropic fringes, a crumpled
  stack for anisotropic ones; bent laminae (straight over 2 periods and more) keep the random start;
- after a structured start the last step copies the best match's pixel (``final_step``), blended with the
  average where that is grainier than the exemplar (:mod:`texsynth.synth.analysis.grain`).
"""

from __future__ import annotations

import time
from functools import partial
from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from texsynth.synth.analysis.grain import match_grain
from texsynth.synth.analysis.orientation_histogram import (
    OrientationLabels,
    orientation_excess,
    orientation_labels,
    usage_factors,
)
from texsynth.synth.analysis.stationarity import stationarity
from texsynth.synth.analysis.tensor import (
    coherence,
    mean_coherence,
    structure_tensor,
    structure_tensor_stack,
)
from texsynth.synth.api import MethodSpec, Progress, Result, register
from texsynth.synth.grid.scan import ScanOrder, scan_order
from texsynth.synth.kernels.solid_search import (
    KCOHERENCE_BLOCKS,
    UPDATE_BLOCK,
    HistogramState,
    MatchField,
    PackedExemplars,
    best_vote,
    irls_update,
)
from texsynth.synth.methods.common import (
    ShellKind,
    ShellParams,
    checked_progress,
    precheck_structured_start,
    shells_field,
    structure_fields,
)
from texsynth.synth.params import ui
from texsynth.synth.pixel.laminar import (
    ORIENTED_MAX_BEND,
    Shells,
    centre_phase,
    choose_shells,
    domain_phase,
    dominant_period,
    fitted_oriented_length,
    fitted_structure_length,
    laminar_phase,
    level_phase,
    oriented_phase,
    plane_orientation,
    resolved_length,
    sheet_normal,
    sheets,
    stack_period,
    start_kind,
    structure_levels,
)
from texsynth.synth.pixel.solid import (
    PLANE_AXES,
    PLANES,
    SOURCE_DTYPE,
    LevelStep,
    ProgressMeter,
    SolidPlan,
    SolidRun,
    dense_sources,
    exemplar_offsets,
    gather_plane,
    initial_sources,
    initial_volume,
    match_histogram,
    plan_levels,
    plane_centres,
    plane_offsets,
    run_levels,
    search_plane,
    slice_geometry,
    structure_schedule,
    upsample_plane_sources,
    upsample_volume,
)
from texsynth.synth.threads import current_threads, thread_map

__all__ = ["SolidKopfParams", "run_solid_kopf"]

#: Histogram bins of the matching (Kopf uses 16 per channel).
HISTOGRAM_BINS = 16
#: RMS neighbourhood difference below which IRLS weights stop growing (about 1/4 grey level in 8 bits).
DISTANCE_FLOOR = 1e-3
#: Relative cost of one neighbourhood search and one voxel update (for progress reporting).
SEARCH_COST = 1.0
UPDATE_COST = 0.3
#: Histogram-matching gain: eq 4 with normalised histograms is gain 1, which let the volume collapse to a
#: flat grey; 64 measured best (docs/solid.md, Departures).
HISTOGRAM_GAIN = 64.0
#: k-coherence search: how many of each exemplar position's similar positions are proposed.
COHERENCE_USED = 8
#: The optimisation step updates at least 1/16 of the volume between two histogram updates (cache).
UPDATE_BLOCKS_PER_SWEEP = 16
#: Exemplar-usage re-weighting: gain, and cells per exemplar side (docs/solid.md, Departures).
POSITION_GAIN = 1.0
POSITION_CELLS = 16
#: ``order_usage``: each cell's usage target is proportional to its mean coherence to this power
#: (docs/solid.md: the onion crop's tortuosity KS 0.29 -> 0.26 at 2, 0.25 at 6, 0.22 at 12, 0.20 at 24
#: with a worse orientation KL).
ORDER_POWER = 12.0
#: Default gain of the orientation-usage re-weighting (docs/solid.md, Departures; 0 = the paper).
ORIENTATION_GAIN = 32.0
#: Correlation length of the oriented start's crumples, in periods (docs/solid.md: the turbostratic stack's
#: tortuosity KS worst 0.12 at 2, 0.24 at its fitted 2.5, 0.28 at 4; also ``solid-chen-wang``'s default).
ORIENTED_LENGTH = 2.0
#: k-coherence search: random exemplar positions added to every voxel's candidates.
RANDOM_CANDIDATES = 2
#: Queries gathered and searched at once, through one buffer reused all run (a progress chunk at 256^3
#: held about 2 million neighbourhoods, 0.4 GB allocated anew each time).
SEARCH_BATCH = 65536


class SolidKopfParams(ShellParams):
    """Parameters of Kopf et al.'s solid optimisation; defaults are the study's settings."""

    levels: int = Field(
        5,
        ge=1,
        le=8,
        description="Number of pyramid levels, coarse to fine (fewer when the exemplar is small).",
        json_schema_extra=ui(basic=True, details=("Pyramid levels (fewer when the exemplar is small).")),
    )
    adapt_to_structure: bool = Field(
        True,
        description="Adapt the schedule to the exemplar: fewer levels for grainy ones, more passes for "
        "layered ones.",
        json_schema_extra=ui(
            details=(
                "Micro-structures (weakly oriented exemplars) use at most 2 levels; laminae at least 10 "
                "iterations per level (off: levels and iterations literally)."
            )
        ),
    )
    orientation_gain: float = Field(
        ORIENTATION_GAIN,
        ge=0.0,
        le=64.0,
        description="How strongly slices are pulled toward the exemplar's spread of orientations; 0 is "
        "off (the paper).",
        json_schema_extra=ui(
            details=(
                "Pull each plane's slices toward its exemplar's orientation histogram (eq 4 on "
                "orientations; 0 = off, the paper)."
            )
        ),
    )
    structure: Literal["auto", "none", "laminar", "oriented"]
    structure_length: float | None
    structure, structure_length = structure_fields(
        (
            "'laminar': start from a volume of curved sheets at the exemplar's period, on the "
            "levels that keep the period (the structure first, Akl 2014 in 3D); 'oriented': from a "
            "crumpled stack whose mean normal and spread fit the exemplars' fringe orientations; "
            "'none': the paper's random start; 'auto' (with adapt_to_structure): 'laminar' for one "
            "isotropic exemplar on the three planes that is fringed (mean coherence >= 0.6) or chosen "
            "by a small pilot (0.45-0.6), or for fringed isotropic per-plane exemplars; 'oriented' "
            "for fringed exemplars of which one is anisotropic; else 'none'."
        ),
        (
            "Curvature length of the laminar start, in periods (0-64]; empty or 'auto': the shortest "
            "length whose sheets' slices are at least as coherent at the period's scale and at most as "
            "curved as the exemplars (small onions get short sheets, large shells long ones)."
        ),
    )
    shells: ShellKind = shells_field(
        "sheets",
        "Default 'sheets': domains measured better on the real crops of short straight fringes and the "
        "surfaces on the onion crop's long arcs; 'auto' drew rings closer to the onion truth's but its "
        "fringe lengths measured worse (sessions 17 and 19; docs/solid.md).",
    )
    oriented_length: float | None = Field(
        ORIENTED_LENGTH,
        gt=0.0,
        le=64.0,
        description="How far the oriented start's crumples stay straight, in fringe periods; empty (or "
        "'auto'): fitted to the exemplars.",
        json_schema_extra=ui(
            unit="periods",
            details=(
                "Correlation length of the oriented start's crumples, in periods (0-64]; empty or 'auto': "
                "the length whose slices keep their orientation as far as the exemplars' fringes do "
                "(measured worse than 2 on the stacks and bent laminae tried: docs/solid.md)."
            ),
        ),
    )
    iterations: int = Field(
        4,
        ge=1,
        le=50,
        description="Search-and-update passes over the volume at each level.",
        json_schema_extra=ui(basic=True, details=("Search + optimisation iterations per level.")),
    )
    scan: ScanOrder = Field(
        "random",
        description="Order of the voxel updates.",
        json_schema_extra=ui(details=("Order of the voxel updates in the optimisation step.")),
    )
    r: float = Field(
        0.8,
        gt=0.0,
        le=2.0,
        description="Robustness of the matching energy: below 2, bad matches weigh less (r, Kopf's "
        "exponent).",
        json_schema_extra=ui(details=("Robust norm exponent (IRLS weights ||s-e||^(r-2)).")),
    )
    histogram_matching: bool = Field(
        True,
        description="Keep the volume's grey-level histogram close to the exemplar's.",
        json_schema_extra=ui(details=("Re-weight toward the exemplar's grey-level histogram.")),
    )
    stride: int = Field(
        2,
        ge=1,
        le=4,
        description="Compare windows centred on every n-th voxel of each slice (1: all, faster with more).",
        json_schema_extra=ui(
            details=("Neighbourhoods centred on every stride-th voxel of each slice (sparse grid).")
        ),
    )
    final_step: Literal["auto", "average", "best"] = Field(
        "auto",
        description="How each voxel gets its final value: the average of its matches (the paper) or the "
        "best match's pixel; 'auto' picks by the slices.",
        json_schema_extra=ui(
            details=(
                "The last step of the finest level: 'average' (the paper: the weighted average of the "
                "proposals), 'best' (each voxel copies the best-matching neighbourhood's pixel, which keeps "
                "the exemplar's grain), 'auto': after a laminar or oriented start, the one whose slices "
                "keep the exemplars' mean coherence better (the best copies blended with the average until "
                "no grainier than the exemplar), else 'average'."
            )
        ),
    )
    order_usage: Literal["auto", "on", "off"] = Field(
        "auto",
        description="Let ordered parts of the exemplar be used more than disordered ones; 'auto': only "
        "when an exemplar mixes order and disorder.",
        json_schema_extra=ui(
            details=(
                "The exemplar-usage re-weighting's target per cell grows with the cell's fringe order "
                "(structure-tensor coherence to the power 12) instead of being even: the optimisation "
                "copies less from a crop's disordered core. 'auto' (with adapt_to_structure): on when an "
                "exemplar is reported not stationary (the stationarity diagnostics), else off (even usage)."
            )
        ),
    )
    search: Literal["tree", "exact"] = Field(
        "tree",
        description="How matches are found: 'tree' tries a few likely places (fast), 'exact' every one "
        "(slow).",
        json_schema_extra=ui(
            details=(
                "'tree': k-coherence (k-d tree at the start; fast); 'exact': every exemplar neighbourhood "
                "(slow)."
            )
        ),
    )

    @field_validator("structure_length", "oriented_length", mode="before")
    @classmethod
    def _auto_length(cls, value: object) -> object:
        """``'auto'`` is the empty value: the length fitted to the exemplars."""
        return None if value == "auto" else value


def _position_cell(ex_shape: tuple[int, int]) -> tuple[int, int, int]:
    """Side of the usage cells of an exemplar of ``ex_shape``, and the cells per column and row."""
    h, w = ex_shape
    cell = max(2, min(h, w) // POSITION_CELLS)
    return cell, (h + cell - 1) // cell, (w + cell - 1) // cell


def _position_factors(
    match: np.ndarray, ex_shape: tuple[int, int], target: np.ndarray | None = None
) -> np.ndarray:
    """Weight factors ``1 / (1 + gain * max(0, u(c) / mean(u) - 1))`` of a plane's matched neighbourhoods.

    ``match`` holds the flat exemplar positions of the plane's matches; the exemplar is cut into about
    :data:`POSITION_CELLS` x :data:`POSITION_CELLS` square cells, ``u(c)`` counts the matches centred in
    cell ``c`` and ``mean(u)`` is over the cells used. A match in an over-used cell loses weight in
    proportion to the excess (:data:`POSITION_GAIN`), as eq 4 does for grey levels. With ``target``
    (per cell, mean 1: :func:`_order_target`) the excess is ``u(c) / (mean(u) t(c)) - 1``, ``mean(u)``
    over every cell: ordered cells may be used more than disordered ones (``order_usage``).
    """
    w = ex_shape[1]
    cell, nr, nc = _position_cell(ex_shape)
    rows, cols = np.divmod(match, w)
    cells = (rows // cell) * nc + cols // cell
    usage = np.bincount(cells, minlength=nr * nc).astype(np.float64)
    if target is not None:
        excess = np.maximum(0.0, usage[cells] / (max(float(usage.mean()), 1e-12) * target[cells]) - 1.0)
        return (1.0 / (1.0 + POSITION_GAIN * excess)).astype(np.float32)
    mean = usage[usage > 0].mean() if np.any(usage > 0) else 1.0
    excess = np.maximum(0.0, usage[cells] / mean - 1.0)
    return (1.0 / (1.0 + POSITION_GAIN * excess)).astype(np.float32)


#: Below this side (px) an exemplar is not judged for stationarity (three windows of 8 px).
STATIONARITY_MIN_SIDE = 24


def _mixed(images: list[np.ndarray]) -> bool:
    """Whether one of ``images`` mixes order and disorder: reported not stationary by
    :func:`texsynth.synth.analysis.stationarity.stationarity` (exemplars under 24 px are not judged)."""
    return any(
        min(im.shape[:2]) >= STATIONARITY_MIN_SIDE and not stationarity(im).stationary for im in images
    )


def _order_target(image: np.ndarray) -> np.ndarray:
    """Per usage cell of ``image`` (:func:`_position_cell`, row-major), the usage target ``t(c)``
    proportional to the cell's mean structure-tensor coherence (sigma_d 1, sigma_w 3) to the power
    :data:`ORDER_POWER`, normalised to mean 1 over the cells (``order_usage``)."""
    h, w = image.shape
    cell, nr, nc = _position_cell((h, w))
    coh = coherence(structure_tensor(np.ascontiguousarray(image, dtype=np.float32), 1.0, 3.0))
    sums = np.zeros((nr * cell, nc * cell))
    counts = np.zeros_like(sums)
    sums[:h, :w], counts[:h, :w] = coh, 1.0
    cells = sums.reshape(nr, cell, nc, cell).sum(axis=(1, 3))
    cells /= np.maximum(counts.reshape(nr, cell, nc, cell).sum(axis=(1, 3)), 1.0)
    target = np.maximum(cells.ravel(), 1e-3) ** ORDER_POWER
    return target / target.mean()


def _orientation_factors(
    match: np.ndarray, labels: OrientationLabels, weight: np.ndarray, gain: float
) -> np.ndarray:
    """Weight factors ``1 / (1 + gain * excess)`` of a plane's matched neighbourhoods.

    The excess of each bin is the (current, IRLS-weighted) over-use of the orientations of the exemplar
    pixels the plane's matches are centred on
    (:func:`texsynth.synth.analysis.orientation_histogram.orientation_excess`), interpolated between a match's
    two bins: eq 4's histogram matching applied to orientations instead of grey levels, so the slices
    of each plane are pulled toward their exemplar's orientation distribution (a departure; docs/solid.md).
    """
    excess = orientation_excess(labels, match, weight)
    return (1.0 / usage_factors(labels, excess, match, gain)).astype(np.float32)


class _KopfLoop:
    """Kopf's search and optimisation steps at each level (:func:`texsynth.synth.pixel.solid.run_levels`)."""

    def __init__(
        self,
        params: SolidKopfParams,
        plan: SolidPlan,
        run: SolidRun,
        iterations: int,
        period: float = 0.0,
        start_phase: np.ndarray | None = None,
    ) -> None:
        self.params, self.plan, self.run, self.iterations = params, plan, run, iterations
        self.period = period  # > 0: the laminar start at this period (px of the finest level)
        s = params.stride
        total = sum(
            iterations * np.prod(shape) * (len(run.active) * SEARCH_COST / s**2 + UPDATE_COST)
            for shape in plan.shapes
        )
        self.meter = ProgressMeter(run.report, float(total))
        self.timings = {"search": 0.0, "optimisation": 0.0}
        self.energies: dict[str, list[float]] = {}
        if period > 0 and start_phase is not None:  # the structured start's phase at the coarsest level
            coarsest = plan.levels - 1
            values = np.concatenate([plan.exemplars[p][-1].ravel() for p in run.active])
            self.vol = sheets(start_phase, period / 2.0**coarsest, values)
        else:
            self.vol = initial_volume(plan.shapes[-1], [plan.exemplars[p][-1] for p in run.active], run.rng)
        self.src = np.zeros((3, 0), dtype=np.int64)
        self.pooled = np.zeros(0, dtype=np.float32)
        self.final = "average"  # the last step taken (``final_step``)
        self.final_blend: float | None = None  # the average's share in 'auto''s best step (grain capped)
        self.grain_ratio: dict[str, float] | None = None
        self.start_length: float | None = None  # periods; set by the caller after a structured start
        self.shells: Shells | None = None  # the laminar start's sheets; set by the caller
        self.order_usage = False  # the usage target follows the exemplar's order (``order_usage``)

    def start_level(self, step: LevelStep) -> None:
        """Upsample the volume and the coherent sources (or draw them), and build the level's tables."""
        params, plan, active = self.params, self.plan, self.run.active
        n = step.size
        self.nbhs = plan.neighbourhoods(step.level)
        plan.prefetch(step.level - 1)  # the next finer level's tables, built while this level runs
        images = [plan.exemplars[p][step.level] for p in range(3)]
        self.images = images
        if step.coarsest:
            self.src = initial_sources(self.nbhs, step.voxels, self.run.rng)
        else:
            self.vol = upsample_volume(self.vol, step.shape, params.periodic)
            self.src = upsample_plane_sources(self.src, plan, step.level)
        self.vol = np.ascontiguousarray(self.vol, dtype=np.float32)
        self.field = MatchField(
            match=np.full((3, self.vol.size), -1, dtype=SOURCE_DTYPE),
            weight=np.zeros((3, self.vol.size), dtype=np.float32),
            offsets=np.ascontiguousarray(np.stack([plane_offsets(p, n) for p in PLANES]), dtype=np.int32),
            ex_offsets=np.ascontiguousarray(np.stack([exemplar_offsets(n, im.shape[1]) for im in images])),
            axes=np.array([PLANE_AXES[p] for p in PLANES], dtype=np.int64),
            phase=np.zeros((3, 2), dtype=np.int64),
            stride=params.stride,
            active=np.array([p in active for p in range(3)], dtype=np.uint8),
        )
        self.packed = PackedExemplars.pack(images)
        self.orient: dict[int, OrientationLabels] = {}
        if params.orientation_gain > 0:
            known: dict[int, OrientationLabels] = {}
            for p in active:
                if id(images[p]) not in known:
                    known[id(images[p])] = orientation_labels(images[p])
                self.orient[p] = known[id(images[p])]
        self.targets: dict[int, np.ndarray] = {}
        if self.order_usage:
            by_image: dict[int, np.ndarray] = {}
            for p in active:
                if id(images[p]) not in by_image:
                    by_image[id(images[p])] = _order_target(images[p])
                self.targets[p] = by_image[id(images[p])]
        self.pooled = np.concatenate([images[p].ravel() for p in active])
        self.hist = HistogramState.start(
            self.vol, self.pooled, HISTOGRAM_BINS, HISTOGRAM_GAIN if params.histogram_matching else 0.0
        )
        self.queries = np.empty(SEARCH_BATCH * n * n, dtype=np.float32)  # one search batch's neighbourhoods
        stamps = np.zeros((KCOHERENCE_BLOCKS, max(im.size for im in images)), dtype=np.int64)
        self.scratch = (stamps, np.zeros(1, dtype=np.int64))

    def iterate(self, step: LevelStep, it: int) -> bool:
        """The search step on every active plane, then the optimisation step (eqs 2-4)."""
        params, rng, meter = self.params, self.run.rng, self.meter
        stage = f"solid-kopf: level {step.level + 1} of {step.levels}, iteration {it + 1}/{step.iterations}"
        t0 = time.perf_counter()
        self.field.match.fill(-1)
        sum_d2, count = 0.0, 0
        for p in self.run.active:
            sum_d2, count = self._search_plane(step, it, p, stage, sum_d2, count)
        t1 = time.perf_counter()
        order = scan_order(step.shape, params.scan, rng)
        block = max(UPDATE_BLOCK, self.vol.size // UPDATE_BLOCKS_PER_SWEEP)
        # the chunks are fixed by the sizes: the same blocks on every run
        for a, b in meter.chunks(len(order), UPDATE_COST, stage):
            irls_update(
                self.vol, order, a, b, self.field, self.packed, self.hist, params.periodic, block=block
            )
        self.timings["search"] += t1 - t0
        self.timings["optimisation"] += time.perf_counter() - t1
        self.energies.setdefault(f"level {step.level + 1}", []).append(sum_d2 / max(count, 1))
        return True

    def _search_plane(
        self, step: LevelStep, it: int, p: int, stage: str, sum_d2: float, count: int
    ) -> tuple[float, int]:
        """Plane ``p``'s search step on a sparse grid of a fresh phase, and its weights (IRLS, usage);
        adds its squared distances and searches to the running ``sum_d2`` and ``count``."""
        params, rng, field, s = self.params, self.run.rng, self.field, self.params.stride
        plane, shape, n = PLANES[p], step.shape, step.size
        phase = (int(rng.integers(0, s)), int(rng.integers(0, s)))
        field.phase[p] = phase
        centres = plane_centres(shape, plane, s, phase)
        flat = np.ravel_multi_index(tuple(centres.T), shape)
        geometry = slice_geometry(shape, plane, params.periodic)
        seed_key = int(rng.integers(0, 2**63))
        tree = step.coarsest and it == 0
        k2 = n * n
        for a, b in self.meter.chunks(len(centres), SEARCH_COST, stage):
            # k-coherence and exact answers are per query: batches through one reused buffer give the same
            # answers as the whole chunk at once (the tree's PCA projection keeps the chunk: BLAS)
            batch = b - a if tree else SEARCH_BATCH
            pos = np.empty(b - a, dtype=np.int64)
            d2 = np.empty(b - a, dtype=np.float64)
            for c in range(a, b, batch):
                e = min(b, c + batch)
                out = None if tree else self.queries[: (e - c) * k2].reshape(e - c, k2)
                queries = gather_plane(self.vol, centres[c:e], plane, n, params.periodic, out=out)
                pos[c - a : e - a], d2[c - a : e - a] = search_plane(
                    self.nbhs[p],
                    queries,
                    centres[c:e],
                    exact=params.search == "exact",
                    tree=tree,
                    geometry=geometry,
                    src=self.src[p],
                    n_random=RANDOM_CANDIDATES,
                    seed_key=seed_key,
                    index0=c,
                    scratch=self.scratch,
                    k=COHERENCE_USED,
                )
            rms = np.maximum(np.sqrt(d2 / k2), DISTANCE_FLOOR)
            field.match[p, flat[a:b]] = pos
            field.weight[p, flat[a:b]] = (rms ** (params.r - 2.0)).astype(np.float32)
            sum_d2 += float(np.sum(d2 / k2))
            count += b - a
        dense_sources(field.match[p], shape, plane, s, phase, self.images[p].shape, out=self.src[p])
        if POSITION_GAIN > 0:
            field.weight[p, flat] *= _position_factors(
                field.match[p, flat], self.images[p].shape, self.targets.get(p)
            )
        if params.orientation_gain > 0:
            field.weight[p, flat] *= _orientation_factors(
                field.match[p, flat], self.orient[p], field.weight[p, flat], params.orientation_gain
            )
        return sum_d2, count

    def end_level(self, step: LevelStep) -> None:
        """At the finest level, the discrete last step on the last matches: always (``final_step='best'``),
        or (``'auto'``, after a structured start) when its slices keep the exemplars' mean coherence
        better than the average's (the average smooths a grainy exemplar's fringes into too-ordered ones;
        on a smooth exemplar the copies' seams show)."""
        final = self.params.final_step
        if step.level != 0 or final == "average" or (final == "auto" and self.period <= 0):
            return
        best = best_vote(self.vol, self.field, self.packed, self.params.periodic)
        if final == "auto":
            # a flat exemplar has no coherence to keep (0): the pilot's floor, so neither step divides by it
            target = max(float(np.mean([mean_coherence(self.images[p]) for p in self.run.active])), 1e-6)
            gaps = [
                abs(np.log(max(slice_coherence(v, _slice_step(v)) / target, 1e-6))) for v in (self.vol, best)
            ]
            self.final = "best" if gaps[1] < gaps[0] else "average"
            if self.final == "average":
                return
            best = self._grain_capped(best)
        self.final = "best"
        self.vol = best

    def _grain_capped(self, best: np.ndarray) -> np.ndarray:
        """The best copies blended with the average (``self.vol``) by the least weight whose slices are no
        grainier than the exemplars (:mod:`texsynth.synth.analysis.grain`): unchanged where they are not."""
        images = [self.images[p] for p in self.run.active]
        best, self.final_blend, self.grain_ratio = match_grain(
            best, self.vol, images, self.run.active, self.params.periodic
        )
        return best

    def result(self, seed: int) -> Result:
        """The finished volume (its grey levels remapped onto the exemplars' when histogram matching)."""
        params, vol = self.params, self.vol
        # The optimisation's own contrast (std against the exemplars'), before the final remap: near 0 means
        # the volume collapsed toward a flat grey, as it did with eq 4's gain 1.
        contrast = float(vol.std() / max(float(self.pooled.std()), 1e-12))
        if params.histogram_matching:  # final rank remap onto the exemplars' grey levels (see Departures)
            vol = match_histogram(vol, self.pooled)
        image = np.clip(vol, 0.0, 1.0).astype(np.float32)
        self.run.report("done", 1.0)
        self.timings["total"] = self.run.seconds()
        energies = self.energies
        return Result(
            method="solid-kopf",
            image=image,
            params=params.model_dump(),
            seed=seed,
            timings=self.timings,
            stats={
                # Mean squared difference per neighbourhood entry of the search step, every iteration
                # (the energy the iterations lower), per level (coarse first); and its last value per level.
                "energy": energies,
                "mean_best_distance": {k: v[-1] for k, v in energies.items()},
                "levels": self.plan.levels,
                "iterations": self.iterations,
                "neighbourhood_sizes": list(self.plan.sizes),
                "planes": list(params.planes),
                "contrast_before_remap": contrast,
                "laminar_start": self.period > 0,
                "final_step": self.final,
                # 'auto''s best step: the average's weight that caps its grain, and the grain before and after
                "final_blend": self.final_blend,
                "grain_ratio": self.grain_ratio,
                "period": self.period if self.period > 0 else None,
                # The structured start's sheet or crumple length (periods), fitted ('auto') or given.
                "start_length": self.start_length,
                # The laminar start's sheets ('surfaces', 'centres' or 'domains'), the exemplars' centres of
                # curvature (share gathered), the centres' or domains' spacing (periods), how much one
                # centre explains and how far the fringes keep their orientation (periods).
                "shells": self.shells.kind if self.shells else None,
                "centre_concentration": self.shells.concentration if self.shells else None,
                "centre_spacing": self.shells.spacing if self.shells else None,
                "concentric_explained": self.shells.concentric if self.shells else None,
                "fringe_bend": self.shells.bend if self.shells else None,
                "order_usage": self.order_usage,
            },
        )


#: The laminar start's random field is centred (:func:`laminar_phase`): its mean, which outweighs the few
#: waves a long sheet length leaves in a small volume, no longer puts the zero level outside most of it.
CENTRED_START = True


def run_solid_kopf(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int, int],
    params: SolidKopfParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
    exemplars: dict[str, np.ndarray] | None = None,
) -> Result:
    """Synthesize a ``size = (D, H, W)`` volume whose slices in ``params.planes`` match their exemplars."""
    return _run_solid_kopf(
        exemplar,
        size=size,
        params=params,
        seed=seed,
        progress=progress,
        constraint=constraint,
        exemplars=exemplars,
        centred=CENTRED_START,
    )


def _run_solid_kopf(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int, int],
    params: SolidKopfParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None,
    exemplars: dict[str, np.ndarray] | None,
    centred: bool,
) -> Result:
    """:func:`run_solid_kopf`, the laminar start's field ``centred`` or not (:func:`laminar_phase`)."""
    run = SolidRun.start(exemplar, exemplars, params.planes, seed, checked_progress(progress))
    levels, iterations = params.levels, params.iterations
    if params.adapt_to_structure:
        levels, iterations = structure_schedule(run.constrained(), levels, iterations)
    # names bad exemplars before choosing a start; its one level is the finest level of every plan below
    # (the same images and neighbourhood side), whose tables are built meanwhile on a helper thread when
    # one exemplar serves every plane (per-plane exemplars' three tables a level would crowd the cache of
    # tables before their level comes: each level prefetches the next finer one instead)
    checked = plan_levels(run.views, size, 1, params.neighbourhood_size)
    if set(checked.roles) == {"exemplar"}:
        checked.prefetch(0)
    period, phi, length = 0.0, None, None
    pilot = partial(
        laminar_pilot, settings={"structure_length": params.structure_length}, centred=CENTRED_START
    )
    kind = start_kind(
        params.structure, run.views, params.planes, params.adapt_to_structure, pilot, ORIENTED_MAX_BEND
    )
    if kind == "oriented":
        views = {PLANES[p]: run.views[PLANES[p]] for p in run.active}
        levels = structure_levels(float(np.mean([dominant_period(im) for im in views.values()])), levels)
        normal = sheet_normal({p: plane_orientation(im) for p, im in views.items()})
        period = stack_period(views, normal)
        plan = plan_levels(run.views, size, levels, params.neighbourhood_size)
        length = resolved_length(params.oriented_length, partial(fitted_oriented_length, views))
        phi = oriented_phase(
            plan.shapes[0], views, period, length * period, run.rng, periodic=params.periodic
        )
    elif kind == "laminar":
        period = float(np.mean([dominant_period(image) for image in run.constrained()]))
        levels = structure_levels(period, levels)
    plan = plan_levels(run.views, size, levels, params.neighbourhood_size)
    coarsest, shells, start_phase = plan.levels - 1, None, None
    if period > 0 and phi is None:
        length = resolved_length(params.structure_length, partial(fitted_structure_length, run.constrained()))
        shells = choose_shells(params.shells, params.centre_spacing, run.constrained())
        if shells.kind in ("centres", "domains"):  # drawn at the coarsest level, the only one the start reads
            spacing = shells.spacing * period / 2.0**coarsest
            drawn = centre_phase if shells.kind == "centres" else domain_phase
            start_phase = drawn(plan.shapes[-1], spacing, run.rng, periodic=params.periodic)
        else:
            phi = laminar_phase(
                plan.shapes[0], length * period, run.rng, periodic=params.periodic, centred=centred
            )
    if phi is not None:
        start_phase = level_phase(phi, coarsest)
    loop = _KopfLoop(params, plan, run, iterations, period, start_phase)
    loop.start_length = length
    loop.shells = shells
    loop.order_usage = params.order_usage == "on" or (
        params.order_usage == "auto" and params.adapt_to_structure and _mixed(run.constrained())
    )
    del phi  # the start read its coarsest level; the full-size float64 phase is not kept through the levels
    run_levels(plan, [iterations] * plan.levels, loop)
    return loop.result(seed)


#: The pilot's settings when its caller gives none (solid-chen-wang): those it was measured with before
#: Kopf's structured starts changed (docs/solid.md), so that its choices do not move with Kopf's defaults.
PILOT_SETTINGS: dict[str, object] = {"structure_length": 4.0, "final_step": "average", "order_usage": "off"}
#: Side of the pilot volumes of :func:`laminar_pilot` (two Kopf runs of about 0.5-1 s of CPU each).
PILOT_SIDE = 32


def laminar_pilot(
    exemplar: np.ndarray, settings: dict[str, object] | None = None, *, centred: bool = False
) -> bool:
    """Whether the laminar start keeps ``exemplar``'s coherence better than the random start.

    Two ``PILOT_SIDE^3`` volumes (defaults but ``settings``, else :data:`PILOT_SETTINGS`; seed 0; one
    from each start) are synthesized, and the start whose slices' mean coherence over the exemplar's
    (``log`` ratio) is nearer 1 wins: on short-fringed
    exemplars the random start gives blobs (real onion crops 0.64-0.74x) and the sheets can be too
    ordered (soot-128 1.54x); docs/solid.md, "The laminar start, chosen by a pilot". ``centred``: the
    laminar volume's field centred (:func:`laminar_phase`; solid-kopf's own pilot): uncentred, the
    pilot's 29 px sheets leave a 32^3 field wholly inside its zero level, and the "laminar" volume is
    one diagonal stack (docs/solid.md, "The pilot's laminar volume mended").
    """
    ratios = pilot_ratios(exemplar, settings, centred=centred)
    gaps = {structure: abs(np.log(max(ratio, 1e-6))) for structure, ratio in ratios.items()}
    return gaps["laminar"] < gaps["none"]


def pilot_ratios(
    exemplar: np.ndarray,
    settings: dict[str, object] | None = None,
    *,
    side: int = PILOT_SIDE,
    centred: bool = False,
) -> dict[str, float]:
    """The pilot's measure (:func:`laminar_pilot`): for each start (``'none'``, ``'laminar'``), the mean
    slice coherence of a ``side^3`` volume (seed 0) over the exemplar's."""
    target = mean_coherence(exemplar)
    pinned = settings if settings is not None else PILOT_SETTINGS
    ratios = {}
    for structure in ("none", "laminar"):
        # the surfaces, as the pilot was measured: its choice does not move with the shells' rule
        params = SolidKopfParams(structure=structure, **{"shells": "surfaces", **pinned})  # type: ignore[arg-type]
        volume = _run_solid_kopf(
            exemplar,
            size=(side,) * 3,
            params=params,
            seed=0,
            progress=lambda *_, **__: None,
            constraint=None,
            exemplars=None,
            centred=centred,
        ).image
        ratios[structure] = slice_coherence(volume) / max(target, 1e-6)
    return ratios


def _slice_step(volume: np.ndarray) -> int:
    """Every 4th slice, or fewer on large volumes: at most 16 slices along an axis."""
    return max(4, max(volume.shape) // 16)


def slice_coherence(volume: np.ndarray, step: int = 4) -> float:
    """Mean structure-tensor coherence of every ``step``-th slice along each of the three axes.

    Each axis's slices are two stacks filtered in one call per step (:func:`structure_tensor_stack`, bit for
    bit the per-slice filter), the six on the job's threads; each slice's value is
    ``mean_coherence`` of it, the mean over the slices in axis order (:func:`slice_coherence_reference`).
    """
    runs = []
    for axis in range(3):
        stack = np.moveaxis(volume, axis, 0)[::step]
        half = (len(stack) + 1) // 2  # two runs an axis: six even items for two threads
        runs += [stack[:half], stack[half:]]
    per_run = thread_map(_stack_coherences, runs, current_threads())
    return float(np.mean([value for values in per_run for value in values]))


def _stack_coherences(stack: np.ndarray) -> list[float]:
    """:func:`mean_coherence` of each image of a stack ``(N, H, W)``."""
    if len(stack) == 0:
        return []
    coh = coherence(structure_tensor_stack(np.ascontiguousarray(stack, dtype=np.float32), 1.0, 3.0))
    return [float(c.mean()) for c in coh]


def slice_coherence_reference(volume: np.ndarray, step: int = 4) -> float:
    """Plain :func:`slice_coherence`: one :func:`mean_coherence` call per slice."""
    values = [
        mean_coherence(np.ascontiguousarray(np.take(volume, i, axis=axis)))
        for axis in range(3)
        for i in range(0, volume.shape[axis], step)
    ]
    return float(np.mean(values))


SPEC = register(
    MethodSpec(
        name="solid-kopf",
        summary="Solid texture by optimising 3 orthogonal slice neighbourhoods per voxel (Kopf et al. 2007).",
        params_model=SolidKopfParams,
        run=run_solid_kopf,
        precheck=precheck_structured_start,
        output_ndim=3,
        plane_exemplars=True,
        paper="Kopf, Fu, Cohen-Or, Deussen, Lischinski, Wong, SIGGRAPH 2007",
        seconds_per_element=1.6e-5,  # 128^3 from 128^2 soot: 33 s (docs/benchmarks.md)
    )
)
