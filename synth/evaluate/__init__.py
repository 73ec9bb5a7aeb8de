"""The quantitative benchmark: how faithful an output (image or volume) is to its exemplar.

Grey-level, orientation and coherence histograms and their KL divergences, moments, HRTEM fringe
morphology, and the multi-2D measures of volumes (:mod:`synth.evaluate.measures`).
"""

from synth.evaluate.measures import (
    COHERENCE_BINS,
    GREY_BINS,
    HIST_EPSILON,
    ORIENTATION_BINS,
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

__all__ = [
    "COHERENCE_BINS",
    "GREY_BINS",
    "HIST_EPSILON",
    "ORIENTATION_BINS",
    "WINDOW",
    "as_grey",
    "evaluate_pair",
    "evaluate_volume",
    "grey_histogram",
    "kl_divergence",
    "moments",
    "to_json_types",
    "window_sigma",
]
