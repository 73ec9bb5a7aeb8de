"""Feature-guided patch synthesis (Wu & Yu 2004): match curvilinear features as well as colour, bend, cut.

Patches in raster order with overlap, as in image quilting; each new patch is chosen on a mix of the
colour SSD over the overlap and the chamfer matching cost of the features (eq 2 with eq 1's ``gdist``),
then, with ``deform``, warped by a thin-plate spline so that its features meet the context's, and
merged along a graph-cut seam (Kwatra et al. 2003). The steps: :mod:`texsynth.synth.patch.feature_guided`; the
feature maps: :mod:`texsynth.synth.analysis.features`; the matching:
:mod:`texsynth.synth.analysis.feature_matching`; the warp: :mod:`texsynth.synth.analysis.warp`.
``Result.extras``: ``features_exemplar``, ``features_output``,
``seams`` and ``copy_map``; ``stats['broken_features']`` (:func:`texsynth.synth.evaluate.broken_features`).

Departures, each measured in docs/feature-guided.md (full text: docs/design.md, "feature-guided"):
- patch size 32 (the paper: 32-64), overlap a quarter of the patch;
- detector defaults where the paper gives none (``high_percentile = 90``, ``radius = 3``);
- ``deform`` on (the paper) with a changed warp (tangent gate, normal displacements, spaced controls,
  a 4 px band, cubic resampling): the paper's warp broke and doubled features;
- ``reverse_weight`` (not the paper): the reverse chamfer term, 2 on weakly oriented exemplars;
- ``periodic=True``: a torus layout matched, warped and cut on every known strip;
- ``error``, ``usage_weight`` (not the paper; None: variance-normalised colour error and a usage penalty on
  weakly oriented exemplars, the paper's SSD on strongly oriented ones): docs/patch.md, "Laminar HRTEM".

References
----------
Q. Wu, Y. Yu, "Feature matching and deformation for texture synthesis", ACM Transactions on Graphics
23(3) (Proc. SIGGRAPH 2004), pp. 364-367.
"""

from __future__ import annotations

import time
from typing import Literal

import numpy as np
from pydantic import Field

from texsynth.synth.analysis.feature_matching import BETA, MATCH_TAU, WARP_TAU
from texsynth.synth.analysis.features import feature_map, feature_overlay
from texsynth.synth.analysis.tensor import ORIENTED_COHERENCE, mean_coherence
from texsynth.synth.api import MethodSpec, Progress, Result, register
from texsynth.synth.evaluate.breaks import broken_features_from_masks, seams_from_sources
from texsynth.synth.evaluate.coverage import exemplar_coverage
from texsynth.synth.evaluate.patches import copy_map, copy_share
from texsynth.synth.methods.common import PatchParams, checked_progress
from texsynth.synth.methods.quilting import precheck_patch_method
from texsynth.synth.params import ui
from texsynth.synth.patch.feature_guided import FeatureGuidedSettings, seam_overlay, synthesize_feature_guided

__all__ = ["WEAK_REVERSE_WEIGHT", "FeatureGuidedParams", "run_feature_guided"]

#: ``reverse_weight=None`` on weakly oriented exemplars (:func:`reverse_weight_for`; the term's own
#: measurements use :data:`texsynth.synth.analysis.feature_matching.REVERSE_WEIGHT`, 4).
WEAK_REVERSE_WEIGHT = 2.0


class FeatureGuidedParams(PatchParams):
    """Parameters of feature-guided patch synthesis (Wu & Yu 2004)."""

    OVERLAP_DIVISOR = 4
    MIN_OVERLAP = 2

    patch_size: int = Field(
        32,
        ge=8,
        le=256,
        description="Side of the square patches copied from the exemplar.",
        json_schema_extra=ui(
            basic=True,
            unit="px",
            details=("Side of the square patches, pixels (the paper: 32 to 64 for 128 -> 256)."),
        ),
    )
    overlap: int | None = Field(
        None,
        ge=2,
        le=255,
        description="How much neighbouring patches overlap; automatic: a quarter of the patch.",
        json_schema_extra=ui(
            basic=True,
            unit="px",
            details=("Overlap between neighbouring patches, pixels; default a quarter of the patch."),
        ),
    )
    feature_weight: float = Field(
        0.5,
        ge=0.0,
        le=1.0,
        description="How strongly matching lines and edges weigh against matching grey levels; 0: grey "
        "levels only.",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Weight of the feature cost against the colour SSD, each scaled by its mean over the "
                "candidates (the paper: 0.5). 0 = colour only."
            ),
        ),
    )
    candidates: int = Field(
        20,
        ge=1,
        le=1000,
        description="How many best patches on grey levels are then compared on their features.",
        json_schema_extra=ui(
            details=("Patches of least colour SSD on the overlap whose feature cost is computed.")
        ),
    )
    tolerance: float = Field(
        0.1,
        ge=0.0,
        le=10.0,
        description="A patch is drawn among those whose cost is within (1 + tolerance) of the best.",
        json_schema_extra=ui(
            details=(
                "A patch is drawn among the candidates whose total cost is within (1 + tolerance) of the "
                "least."
            )
        ),
    )
    features: Literal["edges", "ridges"] = Field(
        "edges",
        description="Which features to follow: 'edges' (grey-level steps) or 'ridges' (thin lines).",
        json_schema_extra=ui(
            basic=True,
            details=("'edges': gradient magnitude; 'ridges': the Laplacian (thin lines, see polarity)."),
        ),
    )
    polarity: Literal["bright", "dark"] = Field(
        "bright",
        description="With ridges: follow bright lines, or dark lines (HRTEM lattice fringes).",
        json_schema_extra=ui(
            basic=True, details=("Ridges only: bright lines, or dark lines (HRTEM lattice fringes).")
        ),
    )
    high_percentile: float = Field(
        90.0,
        gt=0.0,
        lt=100.0,
        description="Share of the feature response below the threshold for a strong feature.",
        json_schema_extra=ui(
            unit="%", details=("Percentile of the response that sets the global high threshold.")
        ),
    )
    alpha: float = Field(
        0.3,
        gt=0.0,
        le=1.0,
        description="Weaker features next to a strong one are kept above this fraction of its strength (α).",
        json_schema_extra=ui(
            details=("Local low threshold alpha R around a strong feature of response R (paper: 0.3).")
        ),
    )
    presmooth: float = Field(
        0.0,
        ge=0.0,
        le=5.0,
        description="Blur before the features are found; about 1 for noisy micrographs.",
        json_schema_extra=ui(
            unit="px",
            details=("Gaussian scale (px) before the bilateral filter; about 1 for noisy micrographs."),
        ),
    )
    tau: float = Field(
        MATCH_TAU,
        ge=0.0,
        le=100.0,
        description="Weight of direction differences between features when patches are compared (τ, Eq. 1).",
        json_schema_extra=ui(
            details=("Weight of tangent differences in the matching cost (eq 1; paper: 0.1).")
        ),
    )
    beta: float = Field(
        BETA,
        ge=0.0,
        le=100.0,
        description="Weight of features that do not pair one-to-one when patches are compared (β, Eq. 2).",
        json_schema_extra=ui(details=("Weight of non-bijectivity in the matching cost (eq 2; paper: 0.3).")),
    )
    reverse_weight: float | None = Field(
        None,
        ge=0.0,
        le=100.0,
        description="Weight of the check from the candidate's features back to the output's, against "
        "cluttered patches.",
        json_schema_extra=ui(
            details=(
                "Weight of the reverse chamfer term: mean gdist from the candidate's features in the "
                "overlap to the context's, so that cluttered candidates stop winning (0 = the paper's eq "
                "2). None: 2 for weakly oriented exemplars (mean coherence < 0.7: HRTEM fringes), 0 for "
                "strongly oriented ones (laminae, fibres, brick joints)."
            )
        ),
    )
    warp_tau: float = Field(
        WARP_TAU,
        ge=0.0,
        le=1000.0,
        description="Weight of direction differences when pairing features for the warp (τ, Eq. 1).",
        json_schema_extra=ui(details=("tau of eq 1 for the deformation's correspondences (paper: 10).")),
    )
    deform: bool = Field(
        True,
        description="Warp each patch near its overlap so that its features meet the ones already there.",
        json_schema_extra=ui(
            details=(
                "Warp each patch near its overlap so its features meet the context's (thin-plate spline; "
                "the paper's method): fewer or as many broken features as without it on every exemplar "
                "measured (docs/feature-guided.md)."
            )
        ),
    )
    max_shift: float = Field(
        4.0,
        gt=0.0,
        le=64.0,
        description="Features farther apart than this are not pulled together.",
        json_schema_extra=ui(
            unit="px", details=("Correspondences farther apart than this (px) are not pulled together.")
        ),
    )
    warp_angle: float = Field(
        30.0,
        ge=0.0,
        le=90.0,
        description="Features whose directions differ by more than this are not pulled together.",
        json_schema_extra=ui(
            unit="degrees",
            details=("Features whose tangents differ by more than this (degrees) are not pulled together."),
        ),
    )
    warp_band: float = Field(
        4.0,
        ge=0.0,
        le=64.0,
        description="Distance beyond the overlap over which the warp fades out.",
        json_schema_extra=ui(
            unit="px",
            details=(
                "The warp's displacement decays to 0 over this many px beyond the overlap; the rest of "
                "the patch is not moved."
            ),
        ),
    )
    rotations: bool = Field(
        False,
        description="Also take patches from the exemplar turned and mirrored (7 more copies).",
        json_schema_extra=ui(
            details=("Also take patches from the 7 rotated/reflected copies of the exemplar.")
        ),
    )
    error: Literal["normalised", "ssd"] | None = Field(
        None,
        description="How overlaps are compared: 'normalised' does not favour flat patches; 'ssd' is the "
        "paper's.",
        json_schema_extra=ui(
            details=(
                "Colour error of the candidates on the overlap: 'ssd' = the paper; 'normalised' = SSD "
                "over the overlap's plus the candidate's own variance (flat ones not preferred for being "
                "flat). None: 'normalised' for weakly oriented exemplars (mean coherence < 0.7: HRTEM "
                "fringes, grass, gravel), 'ssd' for strongly oriented ones (laminae, fibres, brick "
                "joints)."
            )
        ),
    )
    usage_weight: float | None = Field(
        None,
        ge=0.0,
        le=100.0,
        description="How strongly over-used exemplar places are avoided; 0 is the paper (position "
        "histogram).",
        json_schema_extra=ui(
            details=(
                "Gain of the penalty on over-used exemplar regions in the candidate search (Chen & Wang's "
                "position histogram; not the paper); 0 = the paper. None: 1 for weakly oriented "
                "exemplars, 0 for strongly oriented ones (as error)."
            )
        ),
    )

    def feature_options(self) -> dict[str, object]:
        """Keyword arguments of :func:`texsynth.synth.analysis.features.feature_map`."""
        return {
            "features": self.features,
            "polarity": self.polarity,
            "high_percentile": self.high_percentile,
            "alpha": self.alpha,
            "presmooth": self.presmooth,
        }


def reverse_weight_for(exemplar: np.ndarray) -> float:
    """The reverse chamfer term's weight ``reverse_weight=None`` stands for, from the exemplar.

    The term penalises candidate features in the overlap that continue no context feature. On weakly
    oriented exemplars (HRTEM soot, mean coherence 0.39) that is what cluttered, broken fringes do, and
    the term brings the fringes back to the exemplar's length (docs/feature-guided.md: soot, seeds 0-29,
    mean length 19.14 px with eq 2, 19.69 at weight 2, 19.94 at 4, the exemplar's 19.99). A candidate
    with few features in the overlap pays little of it, so it also favours the bland patches: with the
    variance-normalised search of those exemplars, weight 4 pulled the onion-core crop's coherence ratio
    under 0.85 on 2 seeds of 8 (worst 0.823); :data:`WEAK_REVERSE_WEIGHT` (2) keeps every seed above
    (worst 0.855, docs/patch.md, "Laminar HRTEM"). On strongly oriented exemplars a feature that starts
    inside the overlap is often real (a brick's horizontal joint meeting a vertical one): with weight 4
    brick's orientation KL went 0.018 -> 0.098 (docs/quality.md, seeds 1-3). So
    :data:`WEAK_REVERSE_WEIGHT` below :data:`~texsynth.synth.analysis.tensor.ORIENTED_COHERENCE`, 0 (the
    paper's eq 2) at or above it.
    """
    return WEAK_REVERSE_WEIGHT if mean_coherence(exemplar) < ORIENTED_COHERENCE else 0.0


def search_for(exemplar: np.ndarray) -> tuple[str, float]:
    """The candidate search ``error=None`` / ``usage_weight=None`` stand for, from the exemplar.

    On weakly oriented exemplars (below :data:`~texsynth.synth.analysis.tensor.ORIENTED_COHERENCE`) the
    paper's colour SSD picks the flattest candidates where the overlap cannot be matched exactly, and on
    laminar HRTEM crops that mix ordered shells and a disordered core the output converges to one region (the
    core, or the straightest fringes: onion crop orientation KL 1.22, share of the exemplar used 0.54);
    the variance-normalised error with the usage penalty (1) uses the whole exemplar (0.03, 0.92) and keeps
    or improves grey KL, orientation KL and coherence on grass, gravel and soot (docs/patch.md). On brick
    (strongly oriented) it raised the seam ratio (1.13 -> 1.24, seeds 1-3) for no gain the pictures show:
    ``('ssd', 0)``, the paper, there.
    """
    return ("normalised", 1.0) if mean_coherence(exemplar) < ORIENTED_COHERENCE else ("ssd", 0.0)


def run_feature_guided(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int],
    params: FeatureGuidedParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
) -> Result:
    overlap = params.resolved_overlap()
    size = (int(size[0]), int(size[1]))
    precheck_patch_method(params, {"exemplar": exemplar.shape, "output": size})
    report = checked_progress(progress)
    start = time.perf_counter()
    if params.reverse_weight is None:
        params = params.model_copy(update={"reverse_weight": reverse_weight_for(exemplar)})
    if params.error is None or params.usage_weight is None:
        error, usage_weight = search_for(exemplar)
        params = params.model_copy(
            update={
                "error": error if params.error is None else params.error,
                "usage_weight": usage_weight if params.usage_weight is None else params.usage_weight,
            }
        )
    options = params.feature_options()
    report("features", 0.0)
    fmap = feature_map(exemplar, **options)  # type: ignore[arg-type]
    settings = FeatureGuidedSettings(
        patch_size=params.patch_size,
        overlap=overlap,
        candidates=params.candidates,
        tolerance=params.tolerance,
        feature_weight=params.feature_weight,
        tau=params.tau,
        beta=params.beta,
        reverse_weight=params.reverse_weight,
        warp_tau=params.warp_tau,
        deform=params.deform,
        max_shift=params.max_shift,
        max_angle=float(np.radians(params.warp_angle)),
        warp_band=params.warp_band,
        rotations=params.rotations,
        periodic=params.periodic,
        error=str(params.error),
        usage_weight=float(params.usage_weight or 0.0),
    )
    made = synthesize_feature_guided(exemplar, fmap, size, settings, np.random.default_rng(seed), report)
    image = np.clip(made.image, 0.0, 1.0).astype(np.float32)
    image = image[..., 0] if exemplar.ndim == 2 else image
    t_synth = time.perf_counter() - start
    report("measures", 1.0)
    out_map = feature_map(image, **options)  # type: ignore[arg-type]
    seams = seams_from_sources(made.sources, made.labels)
    broken = broken_features_from_masks(out_map.mask, fmap.mask, seams)
    cmap = copy_map(image, exemplar)
    report("done", 1.0)
    return Result(
        method="feature-guided",
        image=image,
        params=params.model_dump(),
        seed=seed,
        timings={"synthesis": t_synth, "measures": time.perf_counter() - start - t_synth},
        extras={
            "features_exemplar": feature_overlay(exemplar, fmap).astype(np.float32) / 255.0,
            "features_output": feature_overlay(image, out_map).astype(np.float32) / 255.0,
            "seams": seam_overlay(image, seams),
            "copy_map": cmap,
        },
        stats={
            "layout": made.layout.describe(),
            "broken_features": broken,
            "output_features": int(out_map.count),
            "synthesized_features": int(made.mask.sum()),
            "copy_share": copy_share(cmap),
            **made.stats,
            "coverage": exemplar_coverage(
                [p[:2] for p in made.stats["patch_sources"] if p[2] == 0], exemplar.shape, params.patch_size
            ),
        },
    )


SPEC = register(
    MethodSpec(
        name="feature-guided",
        summary="Feature-guided patches: matched on curvilinear features and colour, warped to meet, "
        "graph-cut (Wu & Yu 2004).",
        params_model=FeatureGuidedParams,
        run=run_feature_guided,
        precheck=precheck_patch_method,
        paper="Wu & Yu, SIGGRAPH 2004",
    )
)
