"""Wei-Levoy pixel-based synthesis: the baseline every paper here compares with.

For every output pixel in scan order, its neighbourhood (causal L-shape or square, plus the parent
level's square neighbourhood) is compared by SSD with exemplar neighbourhoods and the best match's
centre is copied; multi-resolution over Gaussian pyramids, several passes per level, toroidal
output, exemplar neighbourhoods fully inside the exemplar.

References
----------
L.-Y. Wei, M. Levoy, "Fast texture synthesis using tree-structured vector quantization",
SIGGRAPH 2000. Departures (see :mod:`synth.pixel.synthesis`): unsynthesized pixels are ignored in
the first pass rather than compared as noise; the default search is k-coherence, not TSVQ.

Default departure: **position-histogram matching on** (``histogram_weight=10``; Chen & Wang 2010, the
same re-weighting the structure stage of tensor-constrained synthesis uses). The paper's plain search
(``histogram_weight=0``) locks onto a few exemplar regions and grows garbage: 128 -> 256, seed 1,
grey / orientation KL against the exemplar, plain -> matched: grass 0.36 / 0.11 -> 0.001 / 0.008
(smeared blades and streaks -> grass), gravel 0.13 / 0.07 -> 0.004 / 0.008 (diagonal streaks ->
stones), hrtem-soot-128 0.07 / 0.10 -> 0.002 / 0.007 (issue 13).

Default departures of issue 13 (docs/quality.md, 128 -> 256, seeds 1-3, mean (worst)), each reachable
back by a parameter (``levels=3, falloff=0, refinement='same', kset_size=9, kset_dims=16`` give the
earlier bytes):

- **Gaussian falloff** of the neighbourhood (``falloff=0.156``: Efros & Leung 1999's sigma = side / 6.4).
  Flat weights let the 84 entries of a 13 x 13 L-shape outvote the 4 that touch the pixel: its value
  is left nearly free, so two thirds of soot's 4-neighbour pairs came from unrelated sources (median
  coherent piece: 1 pixel) with twice the texture's gradient energy across them (``seam_contrast``
  1.92). With the falloff the nearest entries decide; they are summed first, which the partial
  distance's early stop rewards.
- **Square refinement passes** (``refinement='square'``): pass 2 compares the full 13 x 13 square in a
  random order, every neighbour proposing candidates, so a pixel meets the pixels after it too.
- **Two pyramid levels** (3 before): at a coarse level no neighbourhood fits within about 12 px of the
  exemplar's border, and on bent laminae that band holds one slope (22 % of the exemplar's orientations,
  5 % of the copyable positions): the output lost it (orientation KL 0.104 (0.143)).
- **k-sets of 7 x 7 neighbourhoods on 8 components** (9 x 9 on 16 before, measured with flat weights):
  as good on the table with the falloff, and their k-d tree query, a third of the run before, is cheaper.

Seams before -> after: gravel 1.54 -> 0.71, soot 1.92 -> 0.98; laminae orientation KL 0.104 (0.143) ->
0.066 (0.088); wood strand ratio 0.75 (0.70) -> 0.92 (0.88); every cell of the table meets issue 13's
targets but brick's strand ratio, which measures 3 strands of the exemplar (docs/quality.md). CPU
per run, soot and wood 128 -> 256, the earlier settings then the defaults: 2.07 -> 1.70 s. Not helping
(measured, seed 1): a coherence bias (Hertzmann et al. 2001's kappa; fewer, harder seams: soot 1.92 ->
2.26 at kappa 0.5), position-histogram targets that restore the border band's orientations (laminae
worst 0.130 -> 0.116 only).

Tileable outputs: ``periodic=True`` (see :mod:`synth.pixel.synthesis`). The toroidal output of the
paper wraps every neighbourhood, yet its causal scan ends at the bottom and right borders, which a
2 x 2 tiling shows (soot 128 -> 128, seed 1, :func:`synth.evaluate.tile_seam` ratio 1.42, ranks
0.99 / 0.97); with ``periodic`` the first pass also compares the synthesized first rows and columns
across those borders and the refinement passes compare the full square in random order (seed 1:
ratio 0.91, ranks 0.31 / 0.35; seeds 1-3: mean ratio 1.56 -> 0.93); a causal neighbourhood then
needs ``iterations >= 2``; with the defaults above a periodic run gets 3 passes unless told (96 x 96
smooth noise, seeds 1-8: ``tile_seam`` ratio 1.21 -> 0.97, ranks 0.73 -> 0.43). Those figures are
for the paper's passes (``refinement='same', falloff=0``); the default square refinement already looks
across the borders (non-periodic, the same noise: ratio 1.18, ranks 0.72).
"""

from __future__ import annotations

import time
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from synth.api import MethodSpec, Progress, Result, register
from synth.grid.pyramid import gaussian_pyramid, level_shapes
from synth.methods.common import NeighbourhoodParams, as_features, checked_progress
from synth.pixel.synthesis import check_neighbourhoods_fit, synthesize_source_map

__all__ = ["WeiLevoyParams", "run_wei_levoy"]


class WeiLevoyParams(NeighbourhoodParams):
    """Parameters of the Wei-Levoy baseline."""

    levels: int = Field(2, ge=1, le=6, description="Gaussian pyramid levels of exemplar and output.")
    iterations: int = Field(
        2,
        ge=1,
        le=10,
        description="Passes per pyramid level (default 2; 3 when periodic and not given: a second square "
        "pass closes the tile borders).",
    )
    # Pixel neighbourhoods need more k-coherent candidates than smooth tensor fields to match exact
    # search within 5% (docs/benchmarks.md, "Fast search against exact search").
    k: int = Field(10, ge=0, le=32, description="k-coherence: similar exemplar positions per candidate.")
    kset_size: int = Field(
        7,
        ge=3,
        le=15,
        description="k-coherence sets: side of the square neighbourhoods compared to build them (odd).",
    )
    kset_dims: int = Field(
        8, ge=1, le=64, description="k-coherence sets: principal components of those neighbourhoods."
    )
    falloff: float = Field(
        0.156,
        ge=0.0,
        le=2.0,
        description="Gaussian weighting of the neighbourhood (Efros & Leung 1999): sigma = falloff x its "
        "side (Efros & Leung: 1 / 6.4 = 0.156); 0 = every entry weighs the same (Wei & Levoy).",
    )
    refinement: Literal["same", "square"] = Field(
        "square",
        description="Neighbourhood of the refinement passes (2, 3, ...): 'same' as the first pass (Wei & "
        "Levoy), or 'square': the full square around each pixel in a random order, every neighbour "
        "proposing candidates.",
    )
    histogram_weight: float = Field(
        10.0,
        ge=0.0,
        le=100.0,
        description="Position-histogram matching weight (Chen & Wang 2010): 0 = the paper's plain Wei-Levoy, "
        "which grows garbage (smears, streaks) on natural textures; larger values push toward every "
        "exemplar position being copied equally often.",
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
