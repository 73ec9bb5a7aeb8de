"""The orientation histogram of an exemplar, and how far a synthesis' matches over-use its bins.

Kopf et al.'s histogram matching (eq 4) re-weights the proposals whose grey level is over-represented
in the volume; the solid methods apply the same rule to orientations (a departure, measured in
:mod:`texsynth.synth.methods.solid_kopf` and :mod:`texsynth.synth.methods.solid_chen_wang`): each exemplar
pixel carries the gradient orientation of its structure tensor, the exemplar's coherence-weighted histogram is
the target, and a plane's matches are counted by the orientation of the exemplar pixels they are centred
on. Orientations are binned linearly between the two nearest bin centres, so an orientation on a bin
edge is not split arbitrarily between the exemplar and the slices.

J. Kopf, C.-W. Fu, D. Cohen-Or, O. Deussen, D. Lischinski, T.-T. Wong, "Solid texture synthesis from
2D exemplars", ACM Trans. Graph. 26(3), SIGGRAPH 2007, eq 4.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from texsynth.synth.analysis.tensor import coherence, orientation, structure_tensor

__all__ = [
    "ORIENTATION_BINS",
    "OrientationLabels",
    "orientation_excess",
    "orientation_labels",
    "usage_factors",
]

#: Circular bins over [-pi/2, pi/2) (15 degrees each).
ORIENTATION_BINS = 12


class OrientationLabels(NamedTuple):
    """Each exemplar pixel's two bins and the exemplar's histogram.

    ``lower`` (int64) and ``fraction`` (float64), one per pixel in raster order: the pixel counts
    ``1 - fraction`` in bin ``lower`` and ``fraction`` in ``(lower + 1) % bins``; ``shares`` (float64,
    ``bins``): the exemplar's coherence-weighted share of each bin, floored at ``0.1 / bins``.
    """

    lower: np.ndarray
    fraction: np.ndarray
    shares: np.ndarray


def orientation_labels(image: np.ndarray, bins: int = ORIENTATION_BINS) -> OrientationLabels:
    """Each exemplar pixel's orientation between two bins, and the exemplar's share of each bin.

    The gradient orientation of the structure tensor (:func:`texsynth.synth.analysis.tensor.orientation`, the
    evaluation's 7x7-window tensor), over ``bins`` circular bins of ``[-pi/2, pi/2)`` whose centres are
    ``-pi/2 + (i + 1/2) pi / bins``. A pixel counts ``1 - t`` in its ``lower`` bin and ``t`` in the next
    one (linear binning): with hard bins an orientation on a bin edge (a 45-degree grating with 12 bins)
    fell in one bin for the exemplar and, jittered, in the next for the slices, whose matches were then
    penalised as a foreign orientation. The shares are coherence-weighted (weakly oriented pixels say
    little about orientation), floored so that no bin has a zero target.
    """
    tensors = structure_tensor(np.asarray(image, dtype=np.float32))
    theta = orientation(tensors).ravel().astype(np.float64)
    u = (theta + np.pi / 2) / np.pi * bins - 0.5
    base = np.floor(u)
    fraction = u - base
    lower = base.astype(np.int64) % bins
    weight = coherence(tensors).ravel().astype(np.float64)
    shares = np.bincount(lower, weights=weight * (1.0 - fraction), minlength=bins)
    shares += np.bincount((lower + 1) % bins, weights=weight * fraction, minlength=bins)
    shares = shares / max(shares.sum(), 1e-12)
    return OrientationLabels(lower, fraction, np.maximum(shares, 0.1 / bins))


def orientation_excess(
    labels: OrientationLabels, positions: np.ndarray, weight: np.ndarray | None = None
) -> np.ndarray:
    """Per bin, ``max(0, u(b) / H_e(b) - 1)``: how much the matches centred on ``positions`` over-use it.

    ``u(b)`` is the share of the matches (each counted with ``weight``, e.g. its IRLS weight; 1 when
    ``None``) whose exemplar pixel lies in bin ``b``, split between two bins as the pixel is; ``H_e`` is
    ``labels.shares``.
    """
    bins = len(labels.shares)
    b0 = labels.lower[positions]
    t = labels.fraction[positions]
    w = np.ones(len(b0)) if weight is None else np.asarray(weight, dtype=np.float64)
    usage = np.bincount(b0, weights=w * (1.0 - t), minlength=bins)
    usage += np.bincount((b0 + 1) % bins, weights=w * t, minlength=bins)
    usage = usage / max(usage.sum(), 1e-12)
    return np.maximum(0.0, usage / labels.shares - 1.0)


def usage_factors(
    labels: OrientationLabels, excess: np.ndarray, positions: np.ndarray, gain: float
) -> np.ndarray:
    """``1 + gain * excess`` of each of ``positions``, the excess interpolated between its two bins.

    A distance multiplied by this factor (or a weight divided by it) is eq 4's re-weighting on
    orientations.
    """
    b0 = labels.lower[positions]
    t = labels.fraction[positions]
    return 1.0 + gain * ((1.0 - t) * excess[b0] + t * excess[(b0 + 1) % len(excess)])
