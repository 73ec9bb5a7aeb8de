"""Wei-Levoy solid synthesis: a volume whose orthogonal slices are matched in 2D exemplars.

For every voxel, in scan order, the ``n x n`` non-causal neighbourhoods of the three orthogonal slices
through it (``xy``, ``xz``, ``yz``; the study's "front and side views" plus the third) are each matched
in that plane's exemplar (SSD), and the voxel takes the **average of the matched centres**. Passes
repeat until the matches stop changing (the fraction of voxels whose match changed in any plane falls
below ``tolerance``, the study's "same neighbourhoods after 2 consecutive iterations") or
``iterations`` passes. Multi-resolution over Gaussian pyramids, coarse to fine
(:func:`texsynth.synth.pixel.solid.run_levels`).

References
----------
L.-Y. Wei, M. Levoy, "Fast texture synthesis using tree-structured vector quantization",
SIGGRAPH 2000; L.-Y. Wei, "Texture synthesis by fixed neighborhood searching", PhD thesis,
Stanford 2002, ch. 7 (solid textures from multiple 2D sources).
R. D. Urs, J.-P. Da Costa, J.-M. Leyssale, G. Vignoles, C. Germain, "Non-parametric synthesis of
laminar volumetric textures from a 2D sample", BMVC 2012, section 2.1: the 2D/3D variant and its
settings (5 levels, 7x7 non-causal neighbourhoods, Hilbert scan).

Departures (why: docs/solid.md, "Departures from the papers"):
- k-coherence search (Tong et al. 2002) seeded by the coarser level, not Wei's TSVQ (``search='exact'``);
- batches of at most 4096 voxels matched together (Jacobi inside a batch, Gauss-Seidel between);
- multi-resolution by initialisation only: the parent level is not part of the neighbourhood;
- neighbourhoods fully inside the exemplar; the volume wraps (``periodic``) or is mirrored;
- ``planes``: all three by default, or two (the study's front and side views) for laminae.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from texsynth.synth.api import MethodSpec, Progress, Result, register
from texsynth.synth.grid.scan import ScanOrder, scan_order
from texsynth.synth.kernels.solid_search import KCOHERENCE_BLOCKS
from texsynth.synth.methods.common import SolidParams, checked_progress
from texsynth.synth.params import ui
from texsynth.synth.pixel.solid import (
    PLANES,
    LevelStep,
    ProgressMeter,
    SolidPlan,
    SolidRun,
    gather_plane,
    initial_sources,
    initial_volume,
    plan_levels,
    run_levels,
    search_plane,
    slice_geometry,
    upsample_plane_sources,
    upsample_volume,
)

__all__ = ["SolidWeiLevoyParams", "run_solid_wei_levoy"]

#: Largest batch of voxels matched together.
MAX_BATCH = 4096
#: k-coherence search: random exemplar positions added to every voxel's candidates.
RANDOM_CANDIDATES = 2


class SolidWeiLevoyParams(SolidParams):
    """Parameters of Wei-Levoy solid synthesis; defaults are the study's settings."""

    levels: int = Field(
        5,
        ge=1,
        le=8,
        description="Number of pyramid levels, coarse to fine (fewer when the exemplar is small).",
        json_schema_extra=ui(basic=True, details=("Pyramid levels (fewer when the exemplar is small).")),
    )
    iterations: int = Field(
        10,
        ge=1,
        le=50,
        description="Largest number of passes over the volume at each level.",
        json_schema_extra=ui(basic=True, details=("Largest number of passes per level.")),
    )
    tolerance: float = Field(
        0.01,
        ge=0.0,
        le=1.0,
        description="Stop a level once fewer voxels than this share change their match.",
        json_schema_extra=ui(
            details=("Stop a level once fewer voxels than this fraction change their match.")
        ),
    )
    scan: ScanOrder = Field(
        "hilbert",
        description="Order in which voxels are visited.",
        json_schema_extra=ui(details=("Voxel visiting order.")),
    )
    search: Literal["kcoherence", "exact"] = Field(
        "kcoherence",
        description="How matches are found: 'kcoherence' tries a few likely exemplar places (fast), "
        "'exact' all (slow).",
        json_schema_extra=ui(
            details=("'kcoherence' (fast) or 'exact': every exemplar neighbourhood (slow).")
        ),
    )


class _WeiLevoyLoop:
    """Wei-Levoy passes at each level (:func:`texsynth.synth.pixel.solid.run_levels`)."""

    def __init__(self, params: SolidWeiLevoyParams, plan: SolidPlan, run: SolidRun) -> None:
        self.params, self.plan, self.run = params, plan, run
        self.meter = ProgressMeter(
            run.report, float(sum(params.iterations * np.prod(sh) for sh in plan.shapes))
        )
        self.distances: dict[str, float] = {}
        self.passes: dict[str, int] = {}
        self.vol = initial_volume(plan.shapes[-1], [plan.exemplars[p][-1] for p in run.active], run.rng)
        self.src = np.zeros((3, 0), dtype=np.int64)

    def start_level(self, step: LevelStep) -> None:
        """Upsample the volume and the coherent sources (or draw them)."""
        params, plan = self.params, self.plan
        self.nbhs = plan.neighbourhoods(step.level, centre=False)
        images = [plan.exemplars[p][step.level] for p in range(3)]
        if step.coarsest:
            self.src = initial_sources(self.nbhs, step.voxels, self.run.rng)
        else:
            self.vol = upsample_volume(self.vol, step.shape, params.periodic)
            self.src = upsample_plane_sources(self.src, plan, step.level)
        self.vol = np.ascontiguousarray(self.vol, dtype=np.float32)
        self.geometries = [slice_geometry(step.shape, plane, params.periodic) for plane in PLANES]
        stamps = np.zeros((KCOHERENCE_BLOCKS, max(im.size for im in images)), dtype=np.int64)
        self.scratch = (stamps, np.zeros(1, dtype=np.int64))

    def iterate(self, step: LevelStep, it: int) -> bool:
        """One pass in scan order, in batches; ``False`` once fewer than ``tolerance`` voxels changed."""
        params, rng, meter, src, active = self.params, self.run.rng, self.meter, self.src, self.run.active
        shape, n_vox, n = step.shape, step.voxels, step.size
        flat_vol = self.vol.reshape(-1)
        stage = f"solid-wei-levoy: level {step.level + 1} of {step.levels}, pass {it + 1}/{step.iterations}"
        order = scan_order(shape, params.scan, rng)
        keys = [int(rng.integers(0, 2**63)) for _ in PLANES]
        changed = 0
        sum_d2 = 0.0
        for a, b in meter.chunks(n_vox, 1.0, stage, step=min(MAX_BATCH, meter.chunk())):
            ids = order[a:b]
            centres = np.stack(np.unravel_index(ids, shape), axis=1).astype(np.int64)
            total = np.zeros(b - a, dtype=np.float64)
            moved = np.zeros(b - a, dtype=bool)
            for p in active:
                plane = PLANES[p]
                queries = gather_plane(self.vol, centres, plane, n, params.periodic, centre=False)
                pos, d2 = search_plane(
                    self.nbhs[p],
                    queries,
                    centres,
                    exact=params.search == "exact",
                    tree=step.coarsest and it == 0,
                    geometry=self.geometries[p],
                    src=src[p],
                    n_random=RANDOM_CANDIDATES,
                    seed_key=keys[p],
                    index0=a,
                    scratch=self.scratch,
                )
                moved |= src[p, ids] != pos
                src[p, ids] = pos
                total += self.nbhs[p].values(pos)
                sum_d2 += float(np.sum(d2)) / queries.shape[1]
            flat_vol[ids] = (total / len(active)).astype(np.float32)
            changed += int(np.count_nonzero(moved))
        self.distances[f"level {step.level + 1}"] = sum_d2 / (len(active) * n_vox)
        self.passes[f"level {step.level + 1}"] = it + 1
        if it > 0 and changed / n_vox < params.tolerance:
            meter.advance((step.iterations - it - 1) * n_vox, stage)  # the passes not needed
            return False
        return True

    def end_level(self, step: LevelStep) -> None:
        pass


def run_solid_wei_levoy(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int, int],
    params: SolidWeiLevoyParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
    exemplars: dict[str, np.ndarray] | None = None,
) -> Result:
    """Synthesize a ``size = (D, H, W)`` volume whose slices look like the per-plane exemplars."""
    run = SolidRun.start(exemplar, exemplars, params.planes, seed, checked_progress(progress))
    plan = plan_levels(run.views, size, params.levels, params.neighbourhood_size)
    loop = _WeiLevoyLoop(params, plan, run)
    run_levels(plan, [params.iterations] * plan.levels, loop)
    run.report("done", 1.0)
    return Result(
        method="solid-wei-levoy",
        image=np.clip(loop.vol, 0.0, 1.0).astype(np.float32),
        params=params.model_dump(),
        seed=seed,
        timings={"total": run.seconds()},
        stats={
            # Mean squared difference per neighbourhood entry, last pass of each level (level 1 = finest).
            "mean_best_distance": loop.distances,
            "passes": loop.passes,
            "levels": plan.levels,
            "neighbourhood_sizes": list(plan.sizes),
            "planes": list(params.planes),
        },
    )


SPEC = register(
    MethodSpec(
        name="solid-wei-levoy",
        summary="Solid texture: each voxel averages the matches of its 3 orthogonal slice neighbourhoods.",
        params_model=SolidWeiLevoyParams,
        run=run_solid_wei_levoy,
        output_ndim=3,
        plane_exemplars=True,
        paper="Wei & Levoy, SIGGRAPH 2000; Wei, PhD thesis 2002 (solid textures)",
        seconds_per_element=2.8e-4,  # 64^3 from 128^2 soot: 74 s (docs/solid.md)
    )
)
