"""The quantitative benchmark: how faithful an output (image or volume) is to its exemplar.

Grey-level, orientation and coherence histograms and their KL divergences, moments, HRTEM fringe
morphology, and the multi-2D measures of volumes (:mod:`synth.evaluate.measures`); the two-point
correlation ``S2(r)`` of two-phase images and volumes (:mod:`synth.evaluate.correlation`).
"""

from synth.evaluate.correlation import (
    compare_s2,
    correlation_length,
    image_s2,
    level_cut_s2,
    otsu_threshold,
    two_point_correlation,
    volume_s2,
)
from synth.evaluate.measures import (
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
from synth.evaluate.patches import (
    COPY_PATCH,
    COPY_THRESHOLD,
    copy_map,
    copy_share,
    seam_visibility,
)

__all__ = [
    "COHERENCE_BINS",
    "COPY_PATCH",
    "COPY_THRESHOLD",
    "GREY_BINS",
    "HIST_EPSILON",
    "ORIENTATION_BINS",
    "PLANES",
    "PLANE_AXES",
    "WINDOW",
    "as_grey",
    "compare_s2",
    "copy_map",
    "copy_share",
    "correlation_length",
    "evaluate_pair",
    "evaluate_volume",
    "grey_histogram",
    "image_s2",
    "kl_divergence",
    "level_cut_s2",
    "moments",
    "otsu_threshold",
    "seam_visibility",
    "to_json_types",
    "two_point_correlation",
    "volume_s2",
    "window_sigma",
]
