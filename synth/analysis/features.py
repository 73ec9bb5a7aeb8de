"""Curvilinear feature maps (edges or ridges) with a tangent per feature pixel (Wu & Yu 2004, section 2.3).

A feature map is the binary image of a texture's thin curvilinear features, one pixel wide, that
feature-guided patch synthesis matches and aligns (:mod:`texsynth.synth.analysis.feature_matching`,
:mod:`texsynth.synth.analysis.warp`). :func:`feature_map` follows the paper's section 2.3 step by step:

1. **bilateral filter** (Tomasi & Manduchi 1998), ``sigma_d = 2`` px, ``sigma_r = 10/256``;
2. **response**: the gradient magnitude of central differences (``features='edges'``), or the 5-point
   Laplacian made positive on the chosen ``polarity`` (``'ridges'``: bright or dark lines, e.g. HRTEM
   fringes);
3. **two-pass classification**: strong pixels at or above the ``high_percentile``-th percentile ``T``;
   a weak pixel kept when ``response >= alpha R(q)`` for a strong ``q`` within ``radius`` (the paper's
   local low threshold, not Canny's global one), then only components that hold a strong pixel;
4. **thinning** to one pixel (:func:`skimage.morphology.thin`, Lam, Lee & Suen 1992);
5. **tangent**: the structure direction of the filtered image (the paper's "smoothed tangent"),
   radians counter-clockwise from +x, ``y`` up, wrapped to ``(-pi/2, pi/2]``.

Departures, each explained in docs/design.md ("feature maps"):
- ``high_percentile=90``, ``radius=3`` (no values in the paper), chosen on HRTEM soot and bent laminae;
- ``suppress=True``: non-maximum suppression across the feature before thinning (the paper's thinning
  removes weak pixels first; skimage's does not); ``suppress=False`` is the paper literally;
- ``presmooth`` (default 0, the paper): a Gaussian before the bilateral filter for noisy images;
- a response below 1% of the largest never counts.

References
----------
Q. Wu, Y. Yu, "Feature matching and deformation for texture synthesis", ACM TOG 23(3), 2004, section 2.3.
C. Tomasi, R. Manduchi, "Bilateral filtering for gray and color images", Proc. ICCV 1998, pp. 839-846.
L. Lam, S.-W. Lee, C. Y. Suen, "Thinning methodologies - a comprehensive survey", IEEE TPAMI 14(9), 1992.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy import ndimage as ndi
from skimage.color import hsv2rgb
from skimage.morphology import disk, thin
from skimage.restoration import denoise_bilateral

from texsynth.synth.analysis.tensor import orientation, structure_direction, structure_tensor
from texsynth.synth.colour import to_grey
from texsynth.synth.errors import InvalidInput, InvalidParameter

__all__ = [
    "FEATURE_KINDS",
    "FeatureKind",
    "FeatureMap",
    "Polarity",
    "feature_map",
    "feature_overlay",
    "feature_response",
]

FeatureKind = Literal["edges", "ridges"]
FEATURE_KINDS: tuple[FeatureKind, ...] = ("edges", "ridges")
Polarity = Literal["bright", "dark"]

#: Responses below this fraction of the image's largest response never count as features.
_RESPONSE_FLOOR = 0.01


@dataclass(frozen=True)
class FeatureMap:
    """The curvilinear features of an image: a one-pixel-wide mask and a tangent per feature pixel.

    Attributes
    ----------
    mask : ndarray of bool, shape (H, W)
        Feature pixels, one pixel wide (thinned).
    tangent : ndarray of float64, shape (H, W)
        Feature direction at feature pixels, radians counter-clockwise from +x with ``y`` up,
        in ``(-pi/2, pi/2]``; NaN off the features.
    response : ndarray of float64, shape (H, W)
        The filter response that was thresholded (gradient magnitude or signed Laplacian, >= 0).
    filtered : ndarray of float64, shape (H, W)
        The bilateral-filtered grey image.
    high_threshold : float
        The global high threshold ``T`` of pass 1.
    features : {'edges', 'ridges'}
        Which features were detected.
    """

    mask: np.ndarray
    tangent: np.ndarray
    response: np.ndarray = field(repr=False)
    filtered: np.ndarray = field(repr=False)
    high_threshold: float = 0.0
    features: FeatureKind = "edges"

    @property
    def count(self) -> int:
        """Number of feature pixels."""
        return int(np.count_nonzero(self.mask))

    def points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(rows, cols, tangents)`` of the feature pixels, in raster order."""
        rows, cols = np.nonzero(self.mask)
        return rows, cols, self.tangent[rows, cols]


def _positive(name: str, value: float) -> float:
    if not (isinstance(value, int | float | np.floating | np.integer) and np.isfinite(value) and value > 0):
        raise InvalidParameter(name, value, "must be a positive, finite number")
    return float(value)


def _grey(image: np.ndarray) -> np.ndarray:
    arr = np.asarray(image)
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[-1] == 3)):
        raise InvalidInput(
            "image", f"feature detection needs an (H, W) or (H, W, 3) image, got shape {arr.shape}"
        )
    if arr.size == 0 or min(arr.shape[:2]) < 3:
        raise InvalidInput(
            "image", f"is too small for feature detection ({arr.shape[:2]}, needs at least 3x3)"
        )
    if not np.issubdtype(arr.dtype, np.number) or not np.isfinite(arr).all():
        raise InvalidInput("image", "holds NaN/inf or non-numeric values")
    return to_grey(arr, np.float64)


def feature_response(
    image: np.ndarray,
    *,
    features: FeatureKind = "edges",
    sigma_d: float = 2.0,
    sigma_r: float = 10 / 256,
    polarity: Polarity = "bright",
    presmooth: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Bilateral filter, then the edge or ridge response (Wu & Yu 2004, section 2.3, steps 1-2).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        Image in [0, 1]; RGB becomes grey by :func:`texsynth.synth.colour.to_grey`.
    features : {'edges', 'ridges'}
        ``'edges'``: gradient magnitude of central finite differences; ``'ridges'``: the Laplacian.
    sigma_d : float
        Closeness (spatial) scale of the bilateral filter, pixels (paper: 2.0).
    sigma_r : float
        Similarity (grey-level) scale of the bilateral filter, on [0, 1] images (paper: 10/256).
    polarity : {'bright', 'dark'}
        Ridges only: detect bright lines (response ``-L``) or dark lines (``+L``).
    presmooth : float
        Scale, pixels, of a Gaussian applied before the bilateral filter; 0 (the paper) for none.
        Noisy micrographs need about 1: the bilateral filter keeps noise larger than ``sigma_r``.

    Returns
    -------
    response : ndarray of float64, shape (H, W)
        Non-negative, high on features.
    filtered : ndarray of float64, shape (H, W)
        The bilateral-filtered grey image.
    """
    grey = _grey(image)
    sigma_d = _positive("sigma_d", sigma_d)
    sigma_r = _positive("sigma_r", sigma_r)
    if features not in FEATURE_KINDS:
        raise InvalidParameter("features", features, "must be 'edges' or 'ridges'")
    if polarity not in ("bright", "dark"):
        raise InvalidParameter("polarity", polarity, "must be 'bright' or 'dark'")
    if not (isinstance(presmooth, int | float) and np.isfinite(presmooth) and presmooth >= 0):
        raise InvalidParameter("presmooth", presmooth, "must be a finite number of pixels >= 0")
    if presmooth > 0:
        grey = ndi.gaussian_filter(grey, float(presmooth), mode="reflect")
    filtered = denoise_bilateral(grey, sigma_color=sigma_r, sigma_spatial=sigma_d, mode="reflect")
    if features == "edges":
        d_row, d_col = np.gradient(filtered)
        response = np.hypot(d_row, d_col)
    else:
        lap = ndi.laplace(filtered, mode="reflect")
        response = np.maximum(-lap if polarity == "bright" else lap, 0.0)
    return response, filtered


def _crests(response: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Pixels whose response is not below either neighbour across the feature (non-maximum suppression).

    ``normal`` is the gradient orientation (y up) from the structure tensor; the step across the
    feature, ``(drow, dcol) = (-sin, cos)``, is rounded to one of the 8 neighbours (Canny's scheme).
    """
    h, w = response.shape
    padded = np.pad(response, 1, mode="constant", constant_values=-np.inf)
    drow = np.rint(-np.sin(normal)).astype(np.intp)
    dcol = np.rint(np.cos(normal)).astype(np.intp)
    rows, cols = np.mgrid[1 : h + 1, 1 : w + 1]
    ahead = padded[rows + drow, cols + dcol]
    behind = padded[rows - drow, cols - dcol]
    return (response >= ahead) & (response >= behind)


def _classify(
    response: np.ndarray, candidates: np.ndarray, high: float, alpha: float, radius: float
) -> np.ndarray:
    """Two-pass classification (module docstring, step 3): strong pixels, then weak pixels near them."""
    floor = _RESPONSE_FLOOR * float(response.max())
    candidates = candidates & (response > floor) & (response > 0)
    strong = candidates & (response >= high)
    if not strong.any():
        return strong
    strong_r = np.where(strong, response, np.inf)
    local_min = ndi.minimum_filter(
        strong_r, footprint=disk(max(1, round(radius))), mode="constant", cval=np.inf
    )
    kept = strong | (candidates & (response >= alpha * local_min))
    labels, n = ndi.label(kept, structure=np.ones((3, 3), dtype=bool))
    has_strong = np.zeros(n + 1, dtype=bool)
    has_strong[labels[strong]] = True
    has_strong[0] = False
    return has_strong[labels]


def feature_map(
    image: np.ndarray,
    *,
    features: FeatureKind = "edges",
    sigma_d: float = 2.0,
    sigma_r: float = 10 / 256,
    high_percentile: float = 90.0,
    high_threshold: float | None = None,
    alpha: float = 0.3,
    radius: float = 3.0,
    polarity: Polarity = "bright",
    tangent_sigma: tuple[float, float] = (1.0, 2.0),
    suppress: bool = True,
    presmooth: float = 0.0,
) -> FeatureMap:
    """Detect one-pixel-wide curvilinear features (edges or ridges) and their tangents.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        Image in [0, 1]; RGB becomes grey by :func:`texsynth.synth.colour.to_grey`.
    features : {'edges', 'ridges'}
        Edges (gradient magnitude) or ridges (Laplacian, see ``polarity``).
    sigma_d : float
        Bilateral closeness scale, pixels (paper: 2.0).
    sigma_r : float
        Bilateral similarity scale on [0, 1] grey levels (paper: 10 of 256 levels, ``10/256``).
    high_percentile : float
        Percentile in (0, 100) of the response that sets the global high threshold of pass 1.
    high_threshold : float, optional
        The high threshold itself (overrides ``high_percentile``; the paper's interactive adjustment).
    alpha : float
        Ratio of the local low threshold to the response ``R`` of a nearby strong pixel, in (0, 1]
        (paper: 0.3).
    radius : float
        Radius, pixels, of the neighbourhood around each strong pixel where its low threshold
        ``alpha R`` applies (the paper gives no size).
    polarity : {'bright', 'dark'}
        Ridges only: bright lines (default) or dark lines (HRTEM lattice fringes).
    tangent_sigma : (float, float)
        Derivative and window scales of the structure tensor that gives the tangents, pixels.
    suppress : bool
        Keep only pixels whose response is a maximum across the feature (non-maximum suppression
        along the structure tensor's gradient orientation) before the classification; stands in for
        the paper's thinning that removes weak pixels first (module docstring). ``False``: the
        paper's steps literally, which merge the broad responses of smooth laminae into blobs.
    presmooth : float
        Gaussian scale, pixels, applied before the bilateral filter; 0 (the paper) for none.

    Returns
    -------
    FeatureMap
        The thinned mask, tangents (NaN off features), response, filtered image and threshold.

    Raises
    ------
    InvalidInput
        The image is not (H, W) or (H, W, 3), smaller than 3x3, or holds NaN/inf.
    InvalidParameter
        A parameter is out of range (the message names it).

    Notes
    -----
    The steps, and where they depart from the paper, are in the module docstring. Tangents are
    feature directions (along the edge or ridge), not gradient directions.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.zeros((32, 32))
    >>> img[15:18, :] = 1.0                      # a bright horizontal line, 3 px wide
    >>> fmap = feature_map(img, features="ridges")
    >>> sorted(set(np.nonzero(fmap.mask)[0].tolist()))
    [16]
    >>> round(float(np.degrees(np.nanmedian(fmap.tangent))), 3)
    0.0
    """
    if high_threshold is None:
        if not (isinstance(high_percentile, int | float) and 0 < high_percentile < 100):
            raise InvalidParameter("high_percentile", high_percentile, "must be a number in (0, 100)")
    else:
        _positive("high_threshold", high_threshold)
    if not (isinstance(alpha, int | float) and 0 < alpha <= 1):
        raise InvalidParameter("alpha", alpha, "must be in (0, 1]: the low threshold is a fraction of R")
    _positive("radius", radius)
    if (
        not isinstance(tangent_sigma, tuple | list)
        or len(tangent_sigma) != 2
        or not all(isinstance(s, int | float) and np.isfinite(s) and s > 0 for s in tangent_sigma)
    ):
        raise InvalidParameter(
            "tangent_sigma", tangent_sigma, "must be two positive scales (derivative, window)"
        )
    response, filtered = feature_response(
        image, features=features, sigma_d=sigma_d, sigma_r=sigma_r, polarity=polarity, presmooth=presmooth
    )
    high = (
        float(np.percentile(response, high_percentile)) if high_threshold is None else float(high_threshold)
    )
    tensors = structure_tensor(filtered, float(tangent_sigma[0]), float(tangent_sigma[1]))
    candidates = _crests(response, orientation(tensors)) if suppress else np.ones(response.shape, dtype=bool)
    mask = thin(_classify(response, candidates, high, float(alpha), float(radius)))
    tangent = np.where(mask, structure_direction(tensors).astype(np.float64), np.nan)
    return FeatureMap(
        mask=mask,
        tangent=tangent,
        response=response,
        filtered=filtered,
        high_threshold=high,
        features=features,
    )


def feature_overlay(image: np.ndarray, fmap: FeatureMap, *, dim: float = 0.6) -> np.ndarray:
    """RGB picture of the feature pixels coloured by tangent over the image in grey.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        The image the features were detected on, in [0, 1].
    fmap : FeatureMap
        Its feature map.
    dim : float
        The grey background is scaled by this factor in (0, 1] so that coloured pixels stand out.

    Returns
    -------
    ndarray of uint8, shape (H, W, 3)
        Feature pixels take the project's cyclic orientation hue ``hue = (theta + pi/2) / pi``
        (ALGORITHMS.md, "Rendering"; the palette of :func:`texsynth.synth.output.render.orientation_hue`:
        0 degrees cyan, +45 violet, -45 yellow-green, +-90 red), at full saturation and value.
    """
    grey = _grey(image)
    if fmap.mask.shape != grey.shape:
        raise InvalidInput("fmap", f"feature map {fmap.mask.shape} does not match image {grey.shape}")
    if not (isinstance(dim, int | float) and 0 < dim <= 1):
        raise InvalidParameter("dim", dim, "must be in (0, 1]")
    background = np.clip(grey, 0.0, 1.0) * dim
    rgb = np.repeat(background[..., None], 3, axis=2)
    on = fmap.mask
    if on.any():
        hue = np.mod((fmap.tangent[on] + np.pi / 2) / np.pi, 1.0)
        hsv = np.stack([hue, np.ones_like(hue), np.ones_like(hue)], axis=-1)
        rgb[on] = hsv2rgb(hsv[None])[0]
    return np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
