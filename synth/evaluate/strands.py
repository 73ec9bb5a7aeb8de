"""Grey levels along strands: does each strand keep its grey level along its length?

A fibrous texture (wood grain: fibres each with its own grey level between dark boundaries) changes
grey level across its fibres and hardly along them. An output that switches from a light to a dark
fibre every few tens of pixels along one strand (a patchwork of grey) still has continuous dark
boundaries (the strand ratio of :mod:`texsynth.synth.analysis.fringes` does not see it) and the exemplar's
grey-level histogram (the KL does not either); this measure does.

:func:`strand_grey` follows, from points every ``stride`` pixels, the strand direction field for
``length`` pixels each way (:func:`texsynth.synth.analysis.streamlines.trace`: the curve turns with the field)
and takes the grey-level variance of the ``2 length + 1`` samples (bilinear), and does the same along
the perpendicular field (across the strands). ``ratio = along / across`` is 0 for strands of constant
grey and about 1 for a texture with no preferred direction. For an output of arbitrary-shape synthesis
the field is the constraint's strand direction (what the output should follow); the reference is the
exemplar along its own fibres (its structure direction), so an output that keeps its strands' grey
as the exemplar does scores the exemplar's ratio. Samples outside the image are left out (a curve
needs at least ``length + 1`` samples inside to count).

Reference: the measure is this project's (issue 13's wood grain; docs/arbitrary-shape.md).
"""

from __future__ import annotations

import numpy as np

from texsynth.synth.analysis.streamlines import sample_along
from texsynth.synth.analysis.tensor import structure_direction, structure_tensor
from texsynth.synth.colour import to_grey

__all__ = ["STRAND_LENGTH", "exemplar_strand_grey", "strand_grey"]

#: Half-length (pixels) of the curves followed: a blotch of "a few tens of pixels" along a strand
#: falls inside one curve (2 x 24 + 1 = 49 samples).
STRAND_LENGTH = 24


def _variance_along(img: np.ndarray, angle: np.ndarray, starts: np.ndarray, length: int) -> np.ndarray:
    vals, inside = sample_along(img, angle, starts, length)
    n = inside.sum(axis=0)
    mean = np.where(inside, vals, 0.0).sum(axis=0) / np.maximum(n, 1)
    var = np.where(inside, (vals - mean) ** 2, 0.0).sum(axis=0) / np.maximum(n, 1)
    return np.where(n >= length + 1, var, np.nan)


def strand_grey(
    image: np.ndarray, strand_angle: np.ndarray, *, length: int = STRAND_LENGTH, stride: int = 2
) -> dict[str, float]:
    """Mean grey-level variance along the strands of ``strand_angle`` (the strand direction, radians,
    y up, modulo pi; (H, W) like ``image``), across them, and their ratio (lower: strands keep their
    grey level). RGB images count by their luma."""
    img = to_grey(image).astype(np.float64)
    rows, cols = np.mgrid[0 : img.shape[0] : stride, 0 : img.shape[1] : stride]
    starts = np.stack([rows.ravel(), cols.ravel()], axis=-1).astype(np.float64)
    along = _variance_along(img, strand_angle, starts, length)
    across = _variance_along(img, np.asarray(strand_angle) + np.pi / 2, starts, length)
    ok = np.isfinite(along) & np.isfinite(across)
    a, c = float(along[ok].mean()), float(across[ok].mean())
    ratio = a / c if c > 0 else (0.0 if a == 0 else float("inf"))
    return {"along": a, "across": c, "ratio": ratio}


def exemplar_strand_grey(
    exemplar: np.ndarray, *, sigma_w: float = 3.0, length: int = STRAND_LENGTH
) -> dict[str, float]:
    """:func:`strand_grey` of an exemplar along its own fibres (its structure direction at scale
    ``sigma_w``): the reference an output's ratio is read against."""
    grey = to_grey(exemplar)
    return strand_grey(grey, structure_direction(structure_tensor(grey, 1.0, sigma_w)), length=length)
