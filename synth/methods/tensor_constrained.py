"""Structure-tensor-constrained synthesis (Akl et al., ICIP 2014): tensor field first, then texture.

Stage 1 (structure layer): the exemplar's structure tensor field ``S_in`` (eqs 1-3) is synthesized
into an output field ``S_out`` by the Wei-Levoy scheme adapted to tensors: neighbourhoods of tensors
compared by the sum of tensor dissimilarities (STD, eq 12) under ED, SO, FN or LE (eqs 6-11), over
Gaussian pyramids of the tensor fields, the best match's tensor being copied. Stage 2 (texture layer):
Wei-Levoy on pixels where every neighbourhood has a pixel part (SSD) and a tensor part (``S_out``
around the output position against ``S_in`` around the candidate, STD): ``D = p SSD + (1 - p) STD``
(eq 13). The paper leaves eq 13's normalisation open: each part is divided by its typical value
(:mod:`texsynth.synth.pixel.synthesis`), so ``p = 0.5`` weighs both equally. ``periodic=True`` closes the tile
borders in both stages (``S_out``'s pyramid always wraps).

Departures, each measured in docs/tensor-constrained.md ("Departures from the paper, measured"):
- the structure stage matches the orientation histogram (``structure_histogram``; 'none' is the paper);
- the stage-1 source map proposes candidates to the stage-2 search (fast search finds what ``S_out`` asks);
- the LE metric by default: SO is blind to coherence where orientations agree (brick's vertical joints);
- a Gaussian falloff of the neighbourhood weights, flat (the paper) for strongly oriented exemplars with
  structures in two directions (:func:`falloff_for`);
- a square refinement pass in both stages (:func:`refinement_size_for`), matching pixels only in the
  texture stage (``refinement_p=1``);
- the texture stage: Chen & Wang's position histogram (weight 3), ``p = 0.8``, ``k = 2``.

References
----------
A. Akl, C. Yaacoub, M. Donias, J.-P. Da Costa, C. Germain, "Structure tensor based synthesis of
directional textures for virtual material design", IEEE ICIP 2014.
"""

from __future__ import annotations

import time
from typing import Literal

import numpy as np
from pydantic import Field

from texsynth.synth.analysis.tensor import (
    ORIENTED_COHERENCE,
    Metric,
    coherence,
    cross_orientation_fraction,
    orientation,
    structure_tensor,
)
from texsynth.synth.api import MethodSpec, Progress, Result, register
from texsynth.synth.grid.neighbourhood import Shape
from texsynth.synth.grid.pyramid import gaussian_pyramid, level_shapes
from texsynth.synth.methods.common import NeighbourhoodParams, as_features, checked_progress
from texsynth.synth.params import ui
from texsynth.synth.pixel.synthesis import (
    Guidance,
    check_neighbourhoods_fit,
    sets_ahead,
    source_map_pyramid,
    synthesize_source_map,
    tensor_features,
)
from texsynth.synth.threads import current_threads

__all__ = [
    "TensorConstrainedParams",
    "falloff_for",
    "orientation_labels",
    "run_tensor_constrained",
    "synthesize_tensor_field",
]

#: Orientation bins of the structure stage's histogram matching (5 degrees each).
ORIENTATION_LABELS = 36


class TensorConstrainedParams(NeighbourhoodParams):
    """Parameters of tensor-constrained synthesis; neighbourhood, levels, metric and passes = Akl 2014,
    Table 1, figure 3 column; the search and weighting defaults are issue 13's (see the module docstring)."""

    structure_levels: int = Field(
        4,
        ge=1,
        le=6,
        description="Pyramid levels of the first stage, which makes the orientation field.",
        json_schema_extra=ui(basic=True, details=("Pyramid levels of the tensor-field synthesis.")),
    )
    texture_levels: int = Field(
        1,
        ge=1,
        le=6,
        description="Pyramid levels of the second stage, which makes the texture under that field.",
        json_schema_extra=ui(basic=True, details=("Pyramid levels of the texture synthesis.")),
    )
    structure_iterations: int = Field(
        2,
        ge=1,
        le=10,
        description="Passes per level in the orientation-field stage.",
        json_schema_extra=ui(details=("Passes per level, structure stage.")),
    )
    texture_iterations: int = Field(
        2,
        ge=1,
        le=10,
        description="Passes per level in the texture stage.",
        json_schema_extra=ui(details=("Passes per level, texture stage.")),
    )
    structure_neighbourhood_size: int | None = Field(
        None,
        ge=3,
        le=41,
        description="Window side of the orientation-field stage; automatic: the neighbourhood size.",
        json_schema_extra=ui(
            unit="px",
            odd=True,
            details=("Neighbourhood side of the structure stage (default: neighbourhood_size)."),
        ),
    )
    structure_neighbourhood: Shape | None = Field(
        None,
        description="Window shape of the orientation-field stage; automatic: as the neighbourhood.",
        json_schema_extra=ui(
            details=("Neighbourhood shape of the structure stage (default: neighbourhood).")
        ),
    )
    metric: Metric = Field(
        "LE",
        description="How two orientation tensors are compared: log-Euclidean (LE), Euclidean (ED), "
        "shape-orientation (SO) or Frobenius (FN).",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Tensor dissimilarity: ED, SO (shape-orientation, the paper's figure 3), FN or LE "
                "(log-Euclidean, the default: SO is blind to coherence where orientations agree)."
            ),
        ),
    )
    alpha: float = Field(
        0.5,
        ge=0.0,
        le=1.0,
        description="With shape-orientation only: weight of orientation against coherence (α).",
        json_schema_extra=ui(details=("SO metric: weight of orientation against coherence.")),
    )
    p: float = Field(
        0.8,
        ge=0.0,
        le=1.0,
        description="How strongly the grey levels weigh against the orientation field when matching (p, "
        "Eq. 13).",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Eq 13: weight of the pixel part against the tensor part (the paper leaves it open; 0.5 "
                "weighs both equally)."
            ),
        ),
    )
    refinement_p: float | None = Field(
        1.0,
        ge=0.0,
        le=1.0,
        description="The same weight in the texture stage's later square passes; 1 compares grey levels "
        "only (p, Eq. 13).",
        json_schema_extra=ui(
            details=(
                "Eq 13's p in the texture stage's square refinement passes (refinement='square' or "
                "periodic): 1 = pixels only, the first pass having laid the texture out under the tensor "
                "field; None = p (the paper: every pass weighs alike)."
            )
        ),
    )
    sigma_d: float = Field(
        1.0,
        gt=0.0,
        le=16.0,
        description="Blur before the image gradients of the orientation field (σ_d).",
        json_schema_extra=ui(unit="px", details=("Structure tensor: derivative scale (pixels).")),
    )
    sigma_w: float = Field(
        3.0,
        gt=0.0,
        le=32.0,
        description="Size of the window over which the orientation field is averaged (σ_w).",
        json_schema_extra=ui(unit="px", details=("Structure tensor: window scale (pixels).")),
    )
    # Measured within 5% of exact search on both stages at k = 3 (docs/benchmarks.md); 2 with the
    # falloff and square refinement below (docs/quality.md, issue 13).
    k: int = Field(
        2,
        ge=0,
        le=32,
        description="How many similar exemplar places each neighbour proposes in the texture stage (k).",
        json_schema_extra=ui(details=("k-coherence: similar exemplar positions per candidate.")),
    )
    falloff: float | None = Field(
        None,
        ge=0.0,
        le=2.0,
        description="How fast the window's pixels weigh less away from its centre; 0 weighs all equally; "
        "automatic per stage.",
        json_schema_extra=ui(
            details=(
                "Gaussian weighting of both stages' same-level neighbourhood (Efros & Leung 1999): sigma "
                "= falloff x its side (Efros & Leung: 1 / 6.4 = 0.156); 0 = flat (the paper). None: "
                "chosen from the exemplar, 0 for strongly oriented exemplars with structures in two "
                "directions (brick's joints: the whole neighbourhood must see whether a joint meets "
                "another), 0.156 otherwise."
            )
        ),
    )
    refinement: Literal["same", "square"] = Field(
        "square",
        description="Window of the later passes of both stages: 'same' as the first pass (the paper), or "
        "'square'.",
        json_schema_extra=ui(
            details=(
                "Neighbourhood of both stages' refinement passes: 'same' as the first pass (the paper), "
                "or 'square': the full square of refinement_size in a random order, every neighbour "
                "proposing candidates."
            )
        ),
    )
    refinement_size: int | None = Field(
        None,
        ge=3,
        le=41,
        description="Side of the square window of the later passes; automatic: chosen from the exemplar.",
        json_schema_extra=ui(
            unit="px",
            odd=True,
            details=(
                "Side of the square refinement neighbourhood (odd; capped at each level's neighbourhood "
                "side). None: chosen from the exemplar, neighbourhood_size for strongly oriented "
                "exemplars (mean coherence >= 0.7: laminae, fibres, joints), 7 for weakly oriented ones."
            ),
        ),
    )
    # The structure stage copies smooth tensor fields: k-coherent candidates there copy large coherent
    # patches and skew the field's orientation distribution (soot 128: field orientation KL 0.22 at
    # k = 3, 0.05 with 16 random candidates and no k-set; 8 measure the same and run 1.6x faster).
    structure_k: int = Field(
        0,
        ge=0,
        le=32,
        description="How many similar places each neighbour proposes in the orientation-field stage (k).",
        json_schema_extra=ui(details=("Structure stage: k-coherent candidates per neighbour.")),
    )
    structure_random_candidates: int = Field(
        8,
        ge=0,
        le=64,
        description="Random exemplar places tried per pixel in the orientation-field stage.",
        json_schema_extra=ui(details=("Structure stage: random exemplar positions tried per pixel.")),
    )
    # Departure measured in docs/tensor-constrained.md: with 'none' (the paper) a causal structure
    # stage lays out the field once at the coarse levels and some seeds over-represent one slope of
    # bent laminae (field orientation KL above 1); matching the orientation histogram removes that.
    structure_histogram: Literal["none", "position", "orientation"] = Field(
        "orientation",
        description="What the orientation-field stage keeps balanced: 'orientation' spread, exemplar "
        "'position' use, or 'none' (the paper).",
        json_schema_extra=ui(
            details=(
                "Structure stage histogram matching: 'none' (the paper), 'position' (Chen & Wang 2010: "
                "every exemplar position used equally) or 'orientation' (the field's orientation "
                "histogram pulled toward the exemplar's)."
            )
        ),
    )
    structure_histogram_weight: float = Field(
        10.0,
        ge=0.0,
        le=100.0,
        description="How strongly that balance is enforced (ignored with 'none').",
        json_schema_extra=ui(
            details=("Weight of the structure stage's histogram matching (ignored with 'none').")
        ),
    )

    texture_histogram_weight: float = Field(
        3.0,
        ge=0.0,
        le=100.0,
        description="How strongly over-used exemplar places are avoided in the texture stage; 0 is the "
        "paper's plain search.",
        json_schema_extra=ui(
            details=(
                "Texture stage: position-histogram matching weight (Chen & Wang 2010, as wei-levoy's "
                "histogram_weight); 0 = the paper's plain search."
            )
        ),
    )

    def periodic_stages(self) -> list[tuple[str, Shape]]:
        return [
            ("structure_iterations", self.structure_neighbourhood or self.neighbourhood),
            ("texture_iterations", self.neighbourhood),
        ]

    def resolved(self, s_in: np.ndarray) -> TensorConstrainedParams:
        """These parameters with the automatic choices made from the exemplar's tensors ``s_in``:
        ``falloff=None`` (:func:`falloff_for`) and, for square refinement passes (the only ones that use
        it), ``refinement_size=None`` (:func:`refinement_size_for`). Fields already set are kept, so
        resolving twice changes nothing; the run records the resolved values."""
        update: dict[str, object] = {}
        if self.falloff is None:
            update["falloff"] = falloff_for(s_in)
        if self.refinement == "square" and self.refinement_size is None:
            update["refinement_size"] = refinement_size_for(s_in, self)
        return self.model_copy(update=update) if update else self


#: Square refinement side for weakly oriented exemplars (``refinement_size=None``).
WEAK_REFINEMENT_SIZE = 7


def refinement_size_for(s_in: np.ndarray, params: TensorConstrainedParams) -> int:
    """The square refinement side ``refinement_size=None`` stands for, from the exemplar's tensors.

    Measured (docs/quality.md, 128 -> 256, seeds 1-3, mean (worst)): a 7 x 7 refinement keeps weakly
    oriented textures' seams low (soot ``seam_contrast`` 1.01 against 1.21 with 13 x 13; grass 0.67
    against 0.78), while strongly oriented ones need the whole neighbourhood to continue their long
    structures (bent laminae strand ratio 0.874 (0.774) -> 0.913 (0.843); brick seam 1.77 (1.99) ->
    1.35 (1.52); wood grain within its targets either way). :data:`ORIENTED_COHERENCE` splits them.
    """
    oriented = float(coherence(s_in).mean()) >= ORIENTED_COHERENCE
    return params.neighbourhood_size if oriented else min(WEAK_REFINEMENT_SIZE, params.neighbourhood_size)


#: Falloff of every exemplar but the crossed oriented ones (``falloff=None``; issue 13's value).
DEFAULT_FALLOFF = 0.156
#: An oriented exemplar whose cross fraction
# (:func:`texsynth.synth.analysis.tensor.cross_orientation_fraction`)
#: reaches this has structures in two directions (brick 0.14; bent laminae 0.001, wood grain 0.000).
CROSSED_FRACTION = 0.05


def falloff_for(s_in: np.ndarray) -> float:
    """The falloff ``falloff=None`` stands for, from the exemplar's tensors.

    Why flat for crossed oriented exemplars (Akl 2014 compares flat neighbourhoods; the falloff is issue
    13's departure): a falloff of 0.156 x 13 leaves a 13 x 13 neighbourhood about 5 x 5 effective pixels,
    too few to see whether a brick's horizontal joint meets a vertical one 10 pixels away, so both stages
    laid down joint pieces ending mid-brick (stubs). Measured on brick (128 -> 256, seeds 1-3, mean
    (worst)), flat in both stages: stubs mostly gone by eye, seam 0.83 (0.90) -> 0.91 (0.95), periodic
    ``tile_seam`` 1.65 (2.06) -> 0.72 (1.02); flat in one stage only leaves the stubs. Flat on bent
    laminae and wood grain (oriented in one direction) raises their seams (0.95 -> 1.00, 0.93 -> 1.07),
    hence the split by :data:`CROSSED_FRACTION` within the oriented exemplars (:data:`ORIENTED_COHERENCE`).
    """
    oriented = float(coherence(s_in).mean()) >= ORIENTED_COHERENCE
    crossed = oriented and cross_orientation_fraction(s_in) >= CROSSED_FRACTION
    return 0.0 if crossed else DEFAULT_FALLOFF


def orientation_labels(tensors: np.ndarray, bins: int = ORIENTATION_LABELS) -> tuple[np.ndarray, np.ndarray]:
    """Each position's orientation bin over ``(-pi/2, pi/2]`` and the fraction of positions per bin:
    the labels and target of orientation-histogram matching in the structure stage."""
    theta = orientation(tensors)
    labels = np.clip(((theta + np.pi / 2) / np.pi * bins).astype(np.int64), 0, bins - 1)
    return labels, np.bincount(labels.ravel(), minlength=bins) / labels.size


def synthesize_tensor_field(
    s_in: np.ndarray, size: tuple[int, int], params: TensorConstrainedParams, *, seed: int, progress, span
) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """Stage 1: synthesize ``S_out`` from ``S_in``; returns ``(S_out, source map, stats)``."""
    params = params.resolved(s_in)
    levels = params.structure_levels
    code = tensor_features(s_in[:1, :1], params.metric)[1]
    tensor_levels = gaussian_pyramid(s_in, levels)
    feat_levels = [tensor_features(t, params.metric)[0] for t in tensor_levels]
    matching = params.structure_histogram
    weight = params.structure_histogram_weight if matching != "none" else 0.0
    n = params.structure_neighbourhood_size or params.neighbourhood_size
    structure = params.model_copy(
        update={
            "k": params.structure_k,
            "random_candidates": params.structure_random_candidates,
            "neighbourhood": params.structure_neighbourhood or params.neighbourhood,
            "scan": params.scan if params.structure_neighbourhood is None else None,
        }
    )
    settings = structure.search_settings(
        size=n,
        levels=levels,
        iterations=params.structure_iterations,
        alpha=params.alpha,
        histogram_weight=weight,
    )
    srcs, stats = synthesize_source_map(
        feat_levels,
        level_shapes(size, levels),
        settings,
        metric=code,
        seed=seed,
        progress=progress,
        stage="structure",
        span=span,
        histogram=[orientation_labels(t) for t in tensor_levels] if matching == "orientation" else None,
    )
    src = srcs[0]
    return s_in[src[..., 0], src[..., 1]].astype(np.float32), src, stats.mean_best_distance


def run_tensor_constrained(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int],
    params: TensorConstrainedParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
) -> Result:
    report = checked_progress(progress)
    t0 = time.perf_counter()
    s_in = structure_tensor(exemplar, params.sigma_d, params.sigma_w)
    params = params.resolved(s_in)
    # The texture stage's exemplar side first: its coarsest k-coherence sets depend on nothing else
    # (nor on the structure stage), so with 2 threads or more they are made during the structure stage.
    levels = params.texture_levels
    gui_code = tensor_features(s_in, params.metric)[1]
    gui_ex = [tensor_features(t, params.metric)[0] for t in gaussian_pyramid(s_in, levels)]
    ex_levels = gaussian_pyramid(as_features(exemplar), levels)
    settings = params.search_settings(
        size=params.neighbourhood_size,
        levels=levels,
        iterations=params.texture_iterations,
        alpha=params.alpha,
        histogram_weight=params.texture_histogram_weight,
        refine_p=params.refinement_p,
    )
    guide = {
        "ex_levels": gui_ex,
        "metric": gui_code,
        "weight": 1.0 - params.p,
        "size": params.neighbourhood_size,
    }
    sets = None
    if current_threads() > 1:
        sets = sets_ahead(
            ex_levels, settings, p=params.p, guidance=Guidance(out_levels=(), **guide), seed=seed + 1
        )
    # Half the work estimate each: the structure stage runs on more levels, the texture on richer data.
    try:
        s_out, src_structure, stats_structure = synthesize_tensor_field(
            s_in, size, params, seed=seed, progress=report, span=(0.0, 0.5)
        )
    except BaseException:
        if sets is not None:  # not left running behind an error (or a cancelled job)
            sets()
        raise
    t1 = time.perf_counter()
    gui_out = [tensor_features(t, params.metric)[0] for t in gaussian_pyramid(s_out, levels, mode="wrap")]
    guidance = Guidance(out_levels=gui_out, hint_levels=source_map_pyramid(src_structure, levels), **guide)
    srcs, stats_texture = synthesize_source_map(
        ex_levels,
        level_shapes(size, levels),
        settings,
        p=params.p,
        guidance=guidance,
        seed=seed + 1,
        progress=report,
        stage="texture",
        span=(0.5, 1.0),
        coarsest_sets=sets,
    )
    src = srcs[0]
    image = exemplar[src[..., 0], src[..., 1]].astype(np.float32)
    t2 = time.perf_counter()
    report("done", 1.0)
    return Result(
        method="tensor-constrained",
        image=image,
        params=params.model_dump(),
        seed=seed,
        timings={"structure": t1 - t0, "texture": t2 - t1},
        tensor_field=s_out,
        extras={
            "coherence": coherence(s_out),
            "orientation": orientation(s_out),
            "source_map": src.astype(np.int32),
        },
        stats={
            "mean_best_distance": {"structure": stats_structure, "texture": stats_texture.mean_best_distance}
        },
    )


def _precheck(params: TensorConstrainedParams, shape: tuple[int, ...]) -> None:
    """Both stages' neighbourhoods fit the exemplar at every level (before any work)."""
    n = params.structure_neighbourhood_size or params.neighbourhood_size
    check_neighbourhoods_fit(shape, params.structure_levels, n, params.parent_size)
    check_neighbourhoods_fit(shape, params.texture_levels, params.neighbourhood_size, params.parent_size)


SPEC = register(
    MethodSpec(
        name="tensor-constrained",
        summary="Two-stage synthesis: structure tensor field first, then the texture under it (Akl 2014).",
        params_model=TensorConstrainedParams,
        run=run_tensor_constrained,
        precheck=lambda params, shapes: _precheck(params, shapes["exemplar"]),
        paper="Akl, Yaacoub, Donias, Da Costa, Germain, ICIP 2014",
    )
)
