"""The quantitative benchmark: how faithful an output (image or volume) is to its exemplar.

Grey-level, orientation and coherence histograms and their KL divergences, moments, HRTEM fringe
morphology, and the multi-2D measures of volumes (:mod:`texsynth.synth.evaluate.measures`); the two-point
correlation ``S2(r)`` of two-phase images and volumes (:mod:`texsynth.synth.evaluate.correlation`); broken
curvilinear features at patch boundaries (:mod:`texsynth.synth.evaluate.breaks`).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from texsynth.synth.evaluate.breaks import (
        SEAM_RADIUS,
        Seams,
        broken_features,
        broken_features_from_masks,
        feature_endpoints,
        seams_from_labels,
        seams_from_sources,
    )
    from texsynth.synth.evaluate.correlation import (
        compare_s2,
        correlation_length,
        image_s2,
        level_cut_s2,
        otsu_threshold,
        two_point_correlation,
        volume_s2,
    )
    from texsynth.synth.evaluate.measures import (
        COHERENCE_BINS,
        GREY_BINS,
        HIST_EPSILON,
        ORIENTATION_BINS,
        PLANE_AXES,
        PLANES,
        WINDOW,
        as_grey,
        evaluate_pair,
        evaluate_volume,
        grey_histogram,
        kl_divergence,
        moments,
        to_json_types,
        window_sigma,
    )
    from texsynth.synth.evaluate.patches import (
        COPY_PATCH,
        COPY_THRESHOLD,
        copy_map,
        copy_share,
        seam_contrast,
        seam_visibility,
        tile_seam,
    )

#: Where each public name lives. The submodules load on first use (PEP 562), so that importing one
#: of them (``texsynth.synth.evaluate.patches`` for a method's copy map, ``measures`` for the metrics of a
#: synthesis) does not import the others' scipy modules (``scipy.stats``, ``scipy.spatial``, ...).
_SOURCES: dict[str, str] = {
    **dict.fromkeys(
        (
            "compare_s2",
            "correlation_length",
            "image_s2",
            "level_cut_s2",
            "otsu_threshold",
            "two_point_correlation",
            "volume_s2",
        ),
        "correlation",
    ),
    **dict.fromkeys(
        (
            "COHERENCE_BINS",
            "GREY_BINS",
            "HIST_EPSILON",
            "ORIENTATION_BINS",
            "PLANE_AXES",
            "PLANES",
            "WINDOW",
            "as_grey",
            "evaluate_pair",
            "evaluate_volume",
            "grey_histogram",
            "kl_divergence",
            "moments",
            "to_json_types",
            "window_sigma",
        ),
        "measures",
    ),
    **dict.fromkeys(
        (
            "COPY_PATCH",
            "COPY_THRESHOLD",
            "copy_map",
            "copy_share",
            "seam_contrast",
            "seam_visibility",
            "tile_seam",
        ),
        "patches",
    ),
    **dict.fromkeys(
        (
            "SEAM_RADIUS",
            "Seams",
            "broken_features",
            "broken_features_from_masks",
            "feature_endpoints",
            "seams_from_labels",
            "seams_from_sources",
        ),
        "breaks",
    ),
}


def __getattr__(name: str) -> Any:
    if name not in _SOURCES:
        raise AttributeError(f"module 'texsynth.synth.evaluate' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"texsynth.synth.evaluate.{_SOURCES[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_SOURCES])


__all__ = [
    "COHERENCE_BINS",
    "COPY_PATCH",
    "COPY_THRESHOLD",
    "GREY_BINS",
    "HIST_EPSILON",
    "ORIENTATION_BINS",
    "PLANES",
    "PLANE_AXES",
    "SEAM_RADIUS",
    "WINDOW",
    "Seams",
    "as_grey",
    "broken_features",
    "broken_features_from_masks",
    "compare_s2",
    "copy_map",
    "copy_share",
    "correlation_length",
    "evaluate_pair",
    "evaluate_volume",
    "feature_endpoints",
    "grey_histogram",
    "image_s2",
    "kl_divergence",
    "level_cut_s2",
    "moments",
    "otsu_threshold",
    "seam_contrast",
    "seam_visibility",
    "seams_from_labels",
    "seams_from_sources",
    "tile_seam",
    "to_json_types",
    "two_point_correlation",
    "volume_s2",
    "window_sigma",
]
