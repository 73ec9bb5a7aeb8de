"""Do an exemplar's fibres carry their own grey levels? The fibre grey spread.

Why: arbitrary-shape synthesis's strand hints (:mod:`texsynth.synth.methods.strand_hints`) lay the exemplar's
fibres along the constraint's strands so that each output strand keeps one fibre's grey level. That is
what a wood grain needs (fibres each with its own grey level between dark boundaries: without the
hints a strand's grey switches from fibre to fibre along its length), and what uniform periodic
stripes (HRTEM fringes, laminae: every light band the same grey) do not: there the hints close the
rings into loops and gain nothing (docs/arbitrary-shape.md, "Continuous strands"). The automatic
choice (:meth:`texsynth.synth.methods.arbitrary_shape.ArbitraryShapeParams.resolved`) reads this measure.

How (:func:`fibre_grey_spread`):

1. The exemplar's grey levels are averaged along its fibres: at every pixel, the mean of the
   ``2 length + 1`` samples (bilinear) of the streamline of its structure direction through it
   (:func:`texsynth.synth.analysis.streamlines.trace`, which turns with bent fibres), ``length`` pixels each
   way. Noise and grey changes along a fibre average out; a fibre's own grey level stays.
2. The fibres' *crests*: pixels at least as bright as the averaged image one pixel to either side
   across the fibres (along the normal of the structure direction), away from a ``margin`` at the
   border. In stripes these are the light bands' middles; in a wood grain, every fibre's fill.
3. ``spread`` = the variance of the averaged image over the crests / the exemplar's grey variance.
   Uniform stripes: every crest at the same level, spread near 0 (straight fringes 0.007, bent
   laminae 0.012); fibres with their own grey levels: the crests spread like the fibres' levels
   (wood grain 0.68). The measure needs no fibre spacing (no scale to estimate: the crests are found
   wherever they are). It is not bounded by 1: the crests of an image whose averaged grey is bimodal
   across (brick rows and mortar) can spread more than its pixels.
The values on the project's exemplars are in docs/arbitrary-shape.md. Reference: this project's
measure (issue 13's wood grain).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from texsynth.synth.analysis.streamlines import sample_along
from texsynth.synth.analysis.tensor import structure_direction, structure_tensor
from texsynth.synth.colour import to_grey

__all__ = ["FIBRE_GREY_LENGTH", "OWN_GREY_FIBRES", "fibre_grey_spread", "fibre_means"]

#: Half-length (pixels) of the streamlines the grey levels are averaged along: long enough to average
#: the noise and a fibre's slow grey changes out (33 samples), short enough for a 48 px exemplar.
FIBRE_GREY_LENGTH = 16
#: Threshold of the automatic choice: at least this spread counts as fibres with their own grey levels.
#: In the gap between the measured exemplars (docs/arbitrary-shape.md): below, fringes 0.007, bent
#: laminae 0.012, soot 0.159, grass 0.273, gravel 0.279; above, wood grain 0.683 (0.60-0.70 over seeds
#: 1-8 at 128 px, 0.68-0.77 for fibres 3-12 px wide; 0.42-0.75 on 48-64 px crops, whose few fibres
#: make the variance noisier) and brick 1.709.
OWN_GREY_FIBRES = 0.35
#: Pixels whose streamlines :func:`fibre_means` follows at once.
CHUNK = 16_384


def fibre_means(image: np.ndarray, direction: np.ndarray, length: int = FIBRE_GREY_LENGTH) -> np.ndarray:
    """The grey image averaged along the streamlines of ``direction`` (radians, y up, modulo pi; (H, W)),
    ``length`` pixels each way of every pixel; samples outside the image are left out. Pixels are taken
    :data:`CHUNK` at a time, so the streamlines' memory stays bounded (about 40 MB at length 16) on large
    exemplars; every pixel's mean is its own, so the chunking does not change the result."""
    img = np.asarray(image, dtype=np.float64)
    h, w = img.shape
    starts = np.stack(np.mgrid[0:h, 0:w], axis=-1).reshape(-1, 2).astype(np.float64)
    out = np.empty(h * w, np.float64)
    for lo in range(0, h * w, CHUNK):
        chunk = starts[lo : lo + CHUNK]
        vals, inside = sample_along(img, direction, chunk, length)
        out[lo : lo + len(chunk)] = np.where(inside, vals, 0.0).sum(axis=0) / inside.sum(axis=0)
    return out.reshape(h, w)


def fibre_grey_spread(
    image: np.ndarray,
    sigma_d: float = 1.0,
    sigma_w: float = 3.0,
    *,
    length: int = FIBRE_GREY_LENGTH,
    margin: int = 3,
) -> float:
    """The variance of the fibres' own grey levels over the exemplar's grey variance (see the module's
    docstring): about 0 for uniform stripes, large for fibres with their own grey levels. Grey or RGB
    (luma); the structure direction at scales ``sigma_d``, ``sigma_w``. A flat image gives 0."""
    grey = to_grey(image).astype(np.float64)
    total = float(grey.var())
    if total <= 0 or min(grey.shape) <= 2 * margin:
        return 0.0
    direction = structure_direction(structure_tensor(grey, sigma_d, sigma_w)).astype(np.float64)
    means = fibre_means(grey, direction, length)
    h, w = grey.shape
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64)
    # the normal of the direction (-sin a, cos a) in (row, col): (cos a, sin a)
    nr, nc = np.cos(direction), np.sin(direction)
    ahead = ndi.map_coordinates(means, [rows + nr, cols + nc], order=1, mode="nearest")
    behind = ndi.map_coordinates(means, [rows - nr, cols - nc], order=1, mode="nearest")
    inner = np.zeros(grey.shape, bool)
    inner[margin : h - margin, margin : w - margin] = True
    crests = inner & (means >= ahead) & (means >= behind)
    if crests.sum() < 2:
        return 0.0
    return float(means[crests].var() / total)
