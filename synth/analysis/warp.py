"""Feature alignment by deformation: warp a patch so its features meet the context's (Wu & Yu 2004, 2.2).

Given one-to-one feature correspondences ``(x_i, x'_i)`` (context feature ``x_i``, patch feature
``x'_i``; :func:`texsynth.synth.analysis.feature_matching.feature_correspondences`), the chosen patch is
deformed by a smooth warp that moves each ``x'_i`` onto ``x_i`` while the pixels of its bottom and
right borders stay where they are ("to prevent the accumulation of deformations").

How: the warp is fitted backwards, as resampling needs it: ``g`` maps a pixel of the warped patch to
the patch position it takes its value from, ``g(x_i) = x'_i`` and ``g(p) = p`` on the fixed borders;
the displacement ``g(y) - y`` is interpolated by a thin-plate spline (Meinguet 1979; scipy's
``RBFInterpolator``, least bending energy), and by Shepard's method (inverse-distance weighting,
power 2) when the spline fails: an unsolvable system, a constraint missed by more than 1e-6 px, or a
fold (a Jacobian determinant ``<= 0``, a check the paper does not name). The patch is resampled with
:func:`scipy.ndimage.map_coordinates` (``order=1``, or ``3`` clipped to the four pixels around each
source). Coordinates are ``(row, col)`` in the patch's pixel frame.

Departures (why: docs/design.md, "the warp"; measured in docs/feature-guided.md):
- ``smoothing > 0``: the spline regularised at the feature constraints (the borders stay exact);
- ``falloff``: a weight map confining the displacement to a band along the overlap (:func:`band_falloff`).

References
----------
Q. Wu, Y. Yu, "Feature matching and deformation for texture synthesis", ACM TOG 23(3), 2004, section 2.2.
J. Meinguet, "Multivariate interpolation at arbitrary points made simple", ZAMP 30, 1979, pp. 292-304.
D. Shepard, "A two-dimensional interpolation function for irregularly-spaced data", Proc. ACM National
Conference, 1968, pp. 517-524.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy import ndimage as ndi
from scipy.interpolate import RBFInterpolator

from texsynth.synth.errors import InvalidInput, InvalidParameter

__all__ = [
    "SIDES",
    "Side",
    "WarpMethod",
    "WarpResult",
    "band_falloff",
    "fixed_points",
    "resample",
    "shepard_displacement",
    "warp_coordinates",
    "warp_patch",
]

Side = Literal["top", "bottom", "left", "right"]
SIDES: tuple[Side, ...] = ("top", "bottom", "left", "right")
WarpMethod = Literal["identity", "tps", "shepard"]

#: A thin-plate spline that misses a constraint by more than this (pixels) counts as failed.
CONSTRAINT_TOLERANCE = 1e-6
#: Shepard weights ``|y - y_i|^-POWER``.
SHEPARD_POWER = 2.0


@dataclass(frozen=True)
class WarpResult:
    """A warped patch and how it was warped.

    Attributes
    ----------
    image : ndarray, shape (h, w) or (h, w, C)
        The warped patch, same dtype as the input patch.
    method : {'identity', 'tps', 'shepard'}
        ``'identity'`` when there was nothing to move (no pairs, or every source on its target).
    reason : str or None
        Why the thin-plate spline was rejected, when ``method == 'shepard'`` after a failure.
    coordinates : ndarray of float64, shape (2, h, w)
        The backward map ``g``: ``(row, col)`` in the patch that each output pixel samples.
    folds : bool
        Whether the returned map has a non-positive Jacobian determinant somewhere (Shepard's
        method can fold too, under large displacements; the caller may then reject the warp).
    """

    image: np.ndarray
    method: WarpMethod
    reason: str | None
    coordinates: np.ndarray = field(repr=False)
    folds: bool = False


def fixed_points(shape: tuple[int, int], sides: Iterable[Side]) -> np.ndarray:
    """Pixel centres ``(row, col)`` of the given borders of an ``(h, w)`` patch, each once."""
    h, w = shape
    pts: set[tuple[int, int]] = set()
    for side in sides:
        if side == "top":
            pts.update((0, c) for c in range(w))
        elif side == "bottom":
            pts.update((h - 1, c) for c in range(w))
        elif side == "left":
            pts.update((r, 0) for r in range(h))
        elif side == "right":
            pts.update((r, w - 1) for r in range(h))
        else:
            raise InvalidParameter("fixed", side, f"sides must be among {', '.join(SIDES)}")
    return np.array(sorted(pts), dtype=np.float64).reshape(-1, 2)


def band_falloff(region: np.ndarray, width: float) -> np.ndarray:
    """Weight 1 on ``region``, falling as a raised cosine to 0 at ``width`` px from it, 0 beyond.

    ``w(d) = (1 + cos(pi d / width)) / 2`` for the Euclidean distance ``d`` of a pixel centre to the
    nearest region pixel, ``0 < d < width``: continuous with a continuous first derivative, so a
    displacement multiplied by it stays smooth.

    Parameters
    ----------
    region : ndarray of bool, shape (h, w)
        Where the warp acts in full (the overlap).
    width : float
        Length of the decay, pixels (``0``: the region only).

    Examples
    --------
    >>> import numpy as np
    >>> region = np.zeros((1, 7), dtype=bool); region[0, :2] = True
    >>> band_falloff(region, 4.0).round(3).tolist()
    [[1.0, 1.0, 0.854, 0.5, 0.146, 0.0, 0.0]]
    """
    reg = np.asarray(region)
    if reg.ndim != 2 or reg.dtype != bool:
        raise InvalidInput("region", f"must be a boolean (h, w) mask, got {reg.dtype} {reg.shape}")
    if not (isinstance(width, int | float) and np.isfinite(width) and width >= 0):
        raise InvalidParameter("width", width, "must be a finite number of pixels >= 0")
    if not reg.any():
        return np.zeros(reg.shape)
    d = ndi.distance_transform_edt(~reg)
    if width == 0:
        return (d == 0).astype(np.float64)
    return np.where(d < width, 0.5 * (1.0 + np.cos(np.pi * np.minimum(d, width) / width)), 0.0)


def shepard_displacement(points: np.ndarray, values: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """Shepard (inverse-distance-weighted, power 2) interpolation of ``values`` at ``queries``.

    Parameters
    ----------
    points : ndarray, shape (k, 2)
    values : ndarray, shape (k, d)
    queries : ndarray, shape (q, 2)

    Returns
    -------
    ndarray, shape (q, d)
        Exactly the value of a data point at that point (the mean where data points coincide).
    """
    d2 = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    on = d2 == 0.0
    with np.errstate(divide="ignore"):
        weights = np.where(on, 0.0, d2 ** (-SHEPARD_POWER / 2))
    hit = on.any(axis=1)
    weights[hit] = on[hit].astype(np.float64)
    return (weights @ values) / weights.sum(axis=1, keepdims=True)


def _jacobian_min(coords: np.ndarray) -> float:
    gr, gc = coords
    if min(gr.shape) < 2:
        return 1.0
    dr_dr, dr_dc = np.gradient(gr)
    dc_dr, dc_dc = np.gradient(gc)
    return float((dr_dr * dc_dc - dr_dc * dc_dr).min())


def _points(name: str, arr: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    a = np.asarray(arr, dtype=np.float64)
    if a.size == 0:
        return np.zeros((0, 2))
    if a.ndim != 2 or a.shape[1] != 2:
        raise InvalidInput(name, f"must be (k, 2) (row, col) pairs, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise InvalidInput(name, "holds NaN/inf")
    h, w = shape
    if (a[:, 0] < 0).any() or (a[:, 0] > h - 1).any() or (a[:, 1] < 0).any() or (a[:, 1] > w - 1).any():
        raise InvalidInput(
            name, f"points must lie inside the {h}x{w} patch (rows 0..{h - 1}, cols 0..{w - 1})"
        )
    return a


def _sides(fixed: Side | Iterable[Side] | None) -> tuple[Side, ...]:
    if fixed is None:
        return ()
    if isinstance(fixed, str):
        fixed = (fixed,)  # type: ignore[assignment]
    sides = tuple(fixed)  # type: ignore[arg-type]
    for s in sides:
        if s not in SIDES:
            raise InvalidParameter("fixed", fixed, f"sides must be among {', '.join(SIDES)}")
    return sides


def warp_coordinates(
    shape: tuple[int, int],
    sources: np.ndarray,
    targets: np.ndarray,
    *,
    fixed: Side | Iterable[Side] | None = ("bottom", "right"),
    method: Literal["auto", "tps", "shepard"] = "auto",
    smoothing: float = 0.0,
    falloff: np.ndarray | None = None,
) -> tuple[np.ndarray, WarpMethod, str | None]:
    """The backward map ``g`` of the warp on the pixel grid (module docstring).

    Parameters
    ----------
    shape : (int, int)
        ``(h, w)`` of the patch.
    sources : ndarray, shape (k, 2)
        ``x'_i``: patch feature positions ``(row, col)``.
    targets : ndarray, shape (k, 2)
        ``x_i``: where they must go (context feature positions), same frame.
    fixed : sides or None
        Borders whose pixels stay in place; the paper fixes ``('bottom', 'right')``.
    method : {'auto', 'tps', 'shepard'}
        ``'auto'``: the spline, Shepard when it fails (the paper); ``'tps'`` raises instead of
        falling back; ``'shepard'`` skips the spline.
    smoothing : float
        Regularisation of the spline at the feature constraints (scipy's ``smoothing``; 0 =
        exact interpolation, the paper). The fixed borders are always exact.
    falloff : ndarray of float, shape (h, w), optional
        Weight in ``[0, 1]`` that multiplies the displacement (:func:`band_falloff`); constraints
        where it is below 1 are met only in proportion.

    Returns
    -------
    coordinates : ndarray, shape (2, h, w)
        ``g(y)`` for every pixel ``y``.
    method : {'identity', 'tps', 'shepard'}
    reason : str or None
        Why the spline was rejected.
    """
    if not (isinstance(shape, tuple | list) and len(shape) == 2 and all(int(s) >= 1 for s in shape)):
        raise InvalidParameter("shape", shape, "must be (h, w) with h, w >= 1")
    h, w = int(shape[0]), int(shape[1])
    if method not in ("auto", "tps", "shepard"):
        raise InvalidParameter("method", method, "must be 'auto', 'tps' or 'shepard'")
    if not (isinstance(smoothing, int | float) and np.isfinite(smoothing) and smoothing >= 0):
        raise InvalidParameter("smoothing", smoothing, "must be a finite number >= 0")
    weight = None
    if falloff is not None:
        weight = np.asarray(falloff, dtype=np.float64)
        if weight.shape != (h, w) or not np.isfinite(weight).all() or weight.min() < 0 or weight.max() > 1:
            raise InvalidInput("falloff", f"must be an ({h}, {w}) array of weights in [0, 1]")
    src = _points("sources", sources, (h, w))
    dst = _points("targets", targets, (h, w))
    if src.shape != dst.shape:
        raise InvalidInput("targets", f"{len(dst)} targets for {len(src)} sources: they must pair up")
    grid = np.stack(np.mgrid[0:h, 0:w], axis=0).astype(np.float64)
    if len(src) == 0 or np.array_equal(src, dst):
        return grid, "identity", None
    anchors = fixed_points((h, w), _sides(fixed))
    # repeated pairs add nothing but a singular row; a pair whose target is a fixed pixel would
    # contradict it: the fixed borders win
    pairs = np.unique(np.concatenate([dst, src], axis=1), axis=0)
    dst, src = pairs[:, :2], pairs[:, 2:]
    on_anchor = (dst[:, None, :] == anchors[None, :, :]).all(axis=2).any(axis=1)
    dst, src = dst[~on_anchor], src[~on_anchor]
    if len(src) == 0 or np.array_equal(src, dst):
        return grid, "identity", None
    points = np.concatenate([dst, anchors], axis=0)
    values = np.concatenate([src - dst, np.zeros_like(anchors)], axis=0)
    smooth = np.concatenate([np.full(len(dst), float(smoothing)), np.zeros(len(anchors))])
    strict = smooth == 0.0
    queries = grid.reshape(2, -1).T

    def exact(coords: np.ndarray) -> np.ndarray:
        # the constraints hold to CONSTRAINT_TOLERANCE; make them exact on the pixels they sit on,
        # so that fixed borders and features on pixel centres are copied bit for bit
        _, inverse, counts = np.unique(points, axis=0, return_inverse=True, return_counts=True)
        on_grid = (points == np.rint(points)).all(axis=1) & (counts[inverse.ravel()] == 1) & strict
        r, c = points[on_grid].astype(np.intp).T
        scale = 1.0 if weight is None else weight[r, c][:, None]
        coords[:, r, c] = (points[on_grid] + scale * values[on_grid]).T
        return coords

    def displaced(disp: np.ndarray) -> np.ndarray:
        field_ = disp.T.reshape(2, h, w)
        return grid + (field_ if weight is None else field_ * weight)

    reason: str | None = None
    if method in ("auto", "tps"):
        try:
            spline = RBFInterpolator(points, values, kernel="thin_plate_spline", smoothing=smooth, degree=1)
            residual = float(np.abs(spline(points[strict]) - values[strict]).max())
            coords = displaced(spline(queries))
            if residual > CONSTRAINT_TOLERANCE:
                reason = f"the spline misses a constraint by {residual:.3g} px (ill-conditioned)"
            elif _jacobian_min(coords) <= 0.0:
                reason = "the spline folds (non-positive Jacobian determinant)"
            else:
                return exact(coords), "tps", None
        except (np.linalg.LinAlgError, ValueError) as exc:
            reason = f"the spline's system cannot be solved ({exc})"
        if method == "tps":
            raise InvalidInput("sources", f"thin-plate spline failed: {reason}")
    coords = displaced(shepard_displacement(points, values, queries))
    return exact(coords), "shepard", reason


def warp_patch(
    patch: np.ndarray,
    sources: np.ndarray,
    targets: np.ndarray,
    *,
    fixed: Side | Iterable[Side] | None = ("bottom", "right"),
    method: Literal["auto", "tps", "shepard"] = "auto",
    order: Literal[1, 3] = 1,
    smoothing: float = 0.0,
    falloff: np.ndarray | None = None,
) -> WarpResult:
    """Warp a patch so that its features at ``sources`` move to ``targets`` (Wu & Yu 2004, section 2.2).

    Parameters
    ----------
    patch : ndarray, shape (h, w) or (h, w, C)
        The chosen patch (image, or any per-pixel field such as a float feature response).
    sources : ndarray, shape (k, 2)
        ``x'_i``: patch feature positions, ``(row, col)``.
    targets : ndarray, shape (k, 2)
        ``x_i``: the corresponding context feature positions, same frame.
    fixed : sides or None
        Borders held in place (paper: bottom and right, the default).
    method : {'auto', 'tps', 'shepard'}
        See :func:`warp_coordinates`.
    order : {1, 3}
        Spline order of the resampling: 1 (bilinear, default) or 3 (cubic, clipped to the range of
        the four pixels around each source: :func:`resample`).
    smoothing, falloff
        See :func:`warp_coordinates`.

    Returns
    -------
    WarpResult
        The warped patch, the method used, why the spline was rejected, the backward map, and
        whether that map folds.

    Examples
    --------
    >>> import numpy as np
    >>> patch = np.zeros((16, 16)); patch[:, 6] = 1.0          # a vertical line at column 6
    >>> res = warp_patch(patch, [[4, 6]], [[4, 8]])              # move it to column 8 at row 4
    >>> res.method, float(res.image[4, 8]), float(res.image[15, 6])   # bottom row is held fixed
    ('tps', 1.0, 1.0)
    """
    arr = np.asarray(patch)
    if arr.ndim not in (2, 3) or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise InvalidInput("patch", f"must be (h, w) or (h, w, C), got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number) or not np.isfinite(arr).all():
        raise InvalidInput("patch", "holds NaN/inf or non-numeric values")
    if order not in (1, 3):
        raise InvalidParameter("order", order, "must be 1 (bilinear) or 3 (cubic)")
    h, w = arr.shape[:2]
    coords, used, reason = warp_coordinates(
        (h, w), sources, targets, fixed=fixed, method=method, smoothing=smoothing, falloff=falloff
    )
    if used == "identity":
        return WarpResult(image=arr.copy(), method=used, reason=None, coordinates=coords, folds=False)
    channels = arr[..., None] if arr.ndim == 2 else arr
    out = resample(channels.astype(np.float64), coords, order=order)
    out = out[..., 0] if arr.ndim == 2 else out
    return WarpResult(
        image=out.astype(arr.dtype, copy=False),
        method=used,
        reason=reason,
        coordinates=coords,
        folds=_jacobian_min(coords) <= 0.0,
    )


def resample(
    image: np.ndarray, coords: np.ndarray, *, order: Literal[1, 3] = 3, coefficients: np.ndarray | None = None
) -> np.ndarray:
    """Sample ``image`` ``(H, W, C)`` at the positions ``coords`` ``(2, ...)`` (row, col).

    ``order=1``: bilinear. ``order=3``: cubic B-spline interpolation, clipped to the range of the
    four pixels around each position (a cubic overshoots next to a sharp edge; the clip keeps it
    from ringing while keeping it sharper than bilinear). Positions on pixel centres return those
    pixels (to rounding). Outside the image, the nearest border pixel. ``coefficients`` are the
    spline coefficients of ``image`` (:func:`scipy.ndimage.spline_filter`, ``order=3``,
    ``mode='nearest'``, per channel), when the caller samples one image many times.
    """
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 3:
        raise InvalidInput("image", f"must be (H, W, C), got shape {img.shape}")
    if order not in (1, 3):
        raise InvalidParameter("order", order, "must be 1 (bilinear) or 3 (cubic)")
    pos = np.asarray(coords, dtype=np.float64)
    channels = range(img.shape[2])
    if order == 1:
        return np.stack(
            [ndi.map_coordinates(img[..., c], pos, order=1, mode="nearest") for c in channels], axis=-1
        )
    coef = coefficients
    if coef is None:
        coef = np.stack([ndi.spline_filter(img[..., c], order=3, mode="nearest") for c in channels], axis=-1)
    out = np.stack(
        [ndi.map_coordinates(coef[..., c], pos, order=3, mode="nearest", prefilter=False) for c in channels],
        axis=-1,
    )
    H, W = img.shape[:2]
    r0 = np.clip(np.floor(pos[0]).astype(np.intp), 0, H - 1)
    c0 = np.clip(np.floor(pos[1]).astype(np.intp), 0, W - 1)
    r1, c1 = np.minimum(r0 + 1, H - 1), np.minimum(c0 + 1, W - 1)
    corners = np.stack([img[r0, c0], img[r0, c1], img[r1, c0], img[r1, c1]])
    return np.clip(out, corners.min(axis=0), corners.max(axis=0))
