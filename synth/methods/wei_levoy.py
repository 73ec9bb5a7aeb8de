"""Wei-Levoy pixel-based synthesis: the baseline every paper here compares with.

For every output pixel in scan order, its neighbourhood (causal L-shape or square, plus the parent
level's square neighbourhood) is compared by SSD with exemplar neighbourhoods and the best match's
centre is copied; multi-resolution over Gaussian pyramids, several passes per level, toroidal
output, exemplar neighbourhoods fully inside the exemplar (:mod:`texsynth.synth.pixel.synthesis`).

Departures, each measured in docs/pixel.md ("wei-levoy's defaults"), each undone by a parameter:
- unsynthesized pixels are ignored in the first pass rather than compared as noise;
- the search is k-coherence (Tong et al. 2002), not TSVQ; k-sets of 7 x 7 neighbourhoods on 8 components;
- position-histogram matching on (``histogram_weight=10``, Chen & Wang 2010): the plain search locks
  onto a few exemplar regions;
- a Gaussian falloff of the neighbourhood (``falloff=0.156``, Efros & Leung 1999);
- square refinement passes (``refinement='square'``);
- two pyramid levels (a coarse level loses the exemplar's border band);
- ``periodic=True``: tileable outputs, with 3 passes unless told.

References
----------
L.-Y. Wei, M. Levoy, "Fast texture synthesis using tree-structured vector quantization",
SIGGRAPH 2000.
"""

from __future__ import annotations

import time
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from texsynth.synth.api import MethodSpec, Progress, Result, register
from texsynth.synth.grid.pyramid import gaussian_pyramid, level_shapes
from texsynth.synth.methods.common import NeighbourhoodParams, as_features, checked_progress
from texsynth.synth.params import ui
from texsynth.synth.pixel.synthesis import check_neighbourhoods_fit, synthesize_source_map

__all__ = ["WeiLevoyParams", "run_wei_levoy"]


class WeiLevoyParams(NeighbourhoodParams):
    """Parameters of the Wei-Levoy baseline."""

    levels: int = Field(
        2,
        ge=1,
        le=6,
        description="Number of pyramid levels, coarse to fine (more levels: larger structures).",
        json_schema_extra=ui(basic=True, details=("Gaussian pyramid levels of exemplar and output.")),
    )
    iterations: int = Field(
        2,
        ge=1,
        le=10,
        description="Passes over the output at each pyramid level.",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Passes per pyramid level (default 2; 3 when periodic and not given: a second square pass "
                "closes the tile borders)."
            ),
        ),
    )
    # Pixel neighbourhoods need more k-coherent candidates than smooth tensor fields to match exact
    # search within 5% (docs/benchmarks.md, "Fast search against exact search").
    k: int = Field(
        10,
        ge=0,
        le=32,
        description="How many similar exemplar places each neighbour proposes (k of the k-coherence search).",
        json_schema_extra=ui(details=("k-coherence: similar exemplar positions per candidate.")),
    )
    kset_size: int = Field(
        7,
        ge=3,
        le=15,
        description="Side of the windows compared when listing similar exemplar places before the run.",
        json_schema_extra=ui(
            unit="px",
            odd=True,
            details=("k-coherence sets: side of the square neighbourhoods compared to build them (odd)."),
        ),
    )
    kset_dims: int = Field(
        8,
        ge=1,
        le=64,
        description="Number of principal components kept of those windows (fewer: faster, rougher).",
        json_schema_extra=ui(details=("k-coherence sets: principal components of those neighbourhoods.")),
    )
    falloff: float = Field(
        0.156,
        ge=0.0,
        le=2.0,
        description="How fast the window's pixels weigh less away from its centre; 0 weighs all equally "
        "(Gaussian σ = falloff × side).",
        json_schema_extra=ui(
            details=(
                "Gaussian weighting of the neighbourhood (Efros & Leung 1999): sigma = falloff x its side "
                "(Efros & Leung: 1 / 6.4 = 0.156); 0 = every entry weighs the same (Wei & Levoy)."
            )
        ),
    )
    refinement: Literal["same", "square"] = Field(
        "square",
        description="Window of the later passes: 'same' as the first pass, or 'square': all around each "
        "pixel.",
        json_schema_extra=ui(
            details=(
                "Neighbourhood of the refinement passes (2, 3, ...): 'same' as the first pass (Wei & "
                "Levoy), or 'square': the full square around each pixel in a random order, every "
                "neighbour proposing candidates."
            )
        ),
    )
    histogram_weight: float = Field(
        10.0,
        ge=0.0,
        le=100.0,
        description="How strongly over-used exemplar places are avoided; 0 is the paper's plain method "
        "(position histogram, Chen & Wang 2010).",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Position-histogram matching weight (Chen & Wang 2010): 0 = the paper's plain Wei-Levoy, "
                "which grows garbage (smears, streaks) on natural textures; larger values push toward "
                "every exemplar position being copied equally often."
            ),
        ),
    )

    @model_validator(mode="before")
    @classmethod
    def _periodic_passes(cls, data: Any) -> Any:
        """A tileable output gets three passes unless told otherwise: with the square refinement and
        falloff defaults, two passes leave the tile border a little above the interior (``tile_seam``
        of 96 x 96 smooth noise, seeds 1-8: ratio 1.21 +- 0.17, ranks 0.73), three close it (0.97 +-
        0.16, ranks 0.43)."""
        if isinstance(data, dict) and data.get("periodic") and "iterations" not in data:
            return {**data, "iterations": 3}
        return data


def run_wei_levoy(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int],
    params: WeiLevoyParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
) -> Result:
    start = time.perf_counter()
    report = checked_progress(progress)
    ex_levels = gaussian_pyramid(as_features(exemplar), params.levels)
    settings = params.search_settings(
        size=params.neighbourhood_size,
        levels=params.levels,
        iterations=params.iterations,
        kset_size=params.kset_size,
        kset_dims=params.kset_dims,
        histogram_weight=params.histogram_weight,
    )
    srcs, stats = synthesize_source_map(
        ex_levels, level_shapes(size, params.levels), settings, seed=seed, progress=report, stage="texture"
    )
    src = srcs[0]
    image = exemplar[src[..., 0], src[..., 1]].astype(np.float32)
    report("done", 1.0)
    return Result(
        method="wei-levoy",
        image=image,
        params=params.model_dump(),
        seed=seed,
        timings={"texture": time.perf_counter() - start},
        extras={"source_map": src.astype(np.int32)},
        stats={"mean_best_distance": stats.mean_best_distance},
    )


SPEC = register(
    MethodSpec(
        name="wei-levoy",
        summary="Pixel-based synthesis by neighbourhood matching (Wei & Levoy 2000), the baseline.",
        params_model=WeiLevoyParams,
        run=run_wei_levoy,
        precheck=lambda params, shapes: check_neighbourhoods_fit(
            shapes["exemplar"], params.levels, params.neighbourhood_size, params.parent_size
        ),
        paper="Wei & Levoy, SIGGRAPH 2000",
    )
)
