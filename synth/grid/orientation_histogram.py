"""Moved to :mod:`synth.analysis.orientation_histogram` (it computes structure tensors: grid is below
analysis). This re-export keeps the solid methods' imports working until they import it from there;
then delete it (it is the one import from grid up to analysis left)."""

from synth.analysis.orientation_histogram import (
    ORIENTATION_BINS,
    OrientationLabels,
    orientation_excess,
    orientation_labels,
    usage_factors,
)

__all__ = [
    "ORIENTATION_BINS",
    "OrientationLabels",
    "orientation_excess",
    "orientation_labels",
    "usage_factors",
]
