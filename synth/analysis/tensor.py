"""Structure tensor fields: computation, eigen-analysis, rotation and dissimilarities.

A tensor field is a ``float`` array of shape ``(..., 3)`` holding the three distinct components
``(S_xx, S_xy, S_yy)`` of the symmetric 2x2 structure tensor at every pixel.

Conventions (ALGORITHMS.md): ``x`` runs to the right (columns) and ``y`` **up** on screen, so
``y = -row``; angles are radians counter-clockwise from +x, wrapped to ``(-pi/2, pi/2]``.
The orientation of a tensor is that of the eigenvector of its largest eigenvalue: the **gradient**
direction, perpendicular to fringes. :func:`structure_direction` gives the fringe direction.

References
----------
A. Akl, C. Yaacoub, M. Donias, J.-P. Da Costa, C. Germain, "Structure tensor based synthesis of
directional textures for virtual material design", ICIP 2014 (eqs 1-12).
S. Di Zenzo, "A note on the gradient of a multi-image", CVGIP 33(1), 1986 (colour tensors).
V. Arsigny, P. Fillard, X. Pennec, N. Ayache, "Log-Euclidean metrics for fast and simple calculus
on diffusion tensors", MRM 56(2), 2006 (closed-form matrix logarithm, eq 11).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from texsynth.synth.analysis.split import gaussian_filter, per_pixel, split_rows
from texsynth.synth.colour import to_grey
from texsynth.synth.errors import InvalidParameter

__all__ = [
    "METRICS",
    "ORIENTED_COHERENCE",
    "Metric",
    "coherence",
    "cross_orientation_fraction",
    "dominant_orientation",
    "eigenvalues",
    "log_tensors",
    "mean_coherence",
    "neighbourhood_dissimilarity",
    "orientation",
    "orientation_histogram",
    "rotate_tensors",
    "structure_direction",
    "structure_tensor",
    "structure_tensor_stack",
    "tensor_dissimilarity",
    "wrap_angle",
]

Metric = Literal["ED", "SO", "FN", "LE"]
METRICS: tuple[Metric, ...] = ("ED", "SO", "FN", "LE")

#: Added to eigenvalues before taking logarithms so that flat regions (zero tensors) stay
#: positive definite; small against the tensors of images in [0, 1].
LOG_EPSILON = 1e-6
#: An image whose mean structure-tensor coherence (default scales) is at least this is strongly oriented:
#: fibres, laminae, fringes, brick joints (0.83-0.97 on docs/quality.md's exemplars); below it, weakly
#: oriented (HRTEM soot 0.39, grass and gravel 0.44). The 2D methods' automatic settings split on it.
ORIENTED_COHERENCE = 0.7
#: Below this trace (relative to nothing: images are in [0, 1]) a tensor counts as isotropic zero.
_TRACE_FLOOR = 1e-12
#: Coherences are clipped to at least this before the ratio of eq 9 (a zero would divide by zero).
_COHERENCE_FLOOR = 1e-3


def wrap_angle(angle: np.ndarray | float) -> np.ndarray:
    """Wrap orientations (angles modulo pi) into ``(-pi/2, pi/2]``."""
    a = np.asarray(angle)
    wrapped = np.pi / 2 - np.mod(np.pi / 2 - a, np.pi)
    return wrapped


def _float_image(image: np.ndarray) -> np.ndarray:
    """One dtype policy: float32 and float64 stay as they are, anything else becomes float32."""
    arr = np.asarray(image)
    if arr.dtype in (np.float32, np.float64):
        return arr
    return arr.astype(np.float32)


def _check_scales(sigma_d: float, sigma_w: float) -> None:
    """Both filter scales positive and finite (``not value > 0`` alone lets ``inf`` through, which scipy
    turns into an OverflowError)."""
    for name, value in (("sigma_d", sigma_d), ("sigma_w", sigma_w)):
        if not (np.isfinite(value) and value > 0):
            raise InvalidParameter(name, value, "must be a positive, finite number of pixels")


def structure_tensor(
    image: np.ndarray,
    sigma_d: float = 1.0,
    sigma_w: float = 3.0,
    *,
    mode: str = "reflect",
) -> np.ndarray:
    """Structure tensor field of a grey or RGB image (Akl 2014, eqs 1-3).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Grey image, or a multi-channel image whose channels' tensors are summed (Di Zenzo).
    sigma_d : float
        Scale of the Gaussian derivative filters ``G_x``, ``G_y`` (eq 1), in pixels.
    sigma_w : float
        Scale of the Gaussian window ``W`` that averages the gradient outer products (eq 3).
    mode : {'reflect', 'wrap', 'nearest', 'mirror', 'constant'}
        Border handling of both filters (``'wrap'`` for toroidal images).

    Returns
    -------
    ndarray, shape (H, W, 3)
        ``(S_xx, S_xy, S_yy)`` with ``y`` pointing up (``I_y = -dI/drow``).

    Examples
    --------
    >>> import numpy as np
    >>> x = np.arange(32, dtype=np.float32)
    >>> stripes = np.tile(np.sin(2 * np.pi * x / 8), (32, 1))   # vertical fringes
    >>> round(float(np.degrees(orientation(structure_tensor(stripes))[16, 16])), 3)
    0.0
    """
    img = _float_image(image)
    if img.ndim not in (2, 3):
        raise InvalidParameter("image", f"shape {img.shape}", "must be (H, W) or (H, W, C)")
    _check_scales(sigma_d, sigma_w)
    channels = img[..., None] if img.ndim == 2 else img
    out = np.zeros((*channels.shape[:2], 3), dtype=img.dtype)
    for c in range(channels.shape[2]):
        band = channels[..., c]
        ix = gaussian_filter(band, sigma_d, order=(0, 1), mode=mode)
        iy = -gaussian_filter(band, sigma_d, order=(1, 0), mode=mode)
        _add_products(out, ix, iy)
    for k in range(3):
        out[..., k] = gaussian_filter(out[..., k], sigma_w, mode=mode)
    return out


def _add_products(out: np.ndarray, ix: np.ndarray, iy: np.ndarray) -> None:
    """``out[..., :] += (ix * ix, ix * iy, iy * iy)`` (eq 2), in runs of rows over the threads."""

    def rows(a: int, b: int) -> None:
        x, y, o = ix[..., a:b, :], iy[..., a:b, :], out[..., a:b, :, :]
        o[..., 0] += x * x
        o[..., 1] += x * y
        o[..., 2] += y * y

    split_rows(rows, ix.shape)


def structure_tensor_stack(
    images: np.ndarray,
    sigma_d: float = 1.0,
    sigma_w: float = 3.0,
    *,
    mode: str = "reflect",
) -> np.ndarray:
    """:func:`structure_tensor` of each grey image of a stack ``(N, H, W)``, in one filter call per step.

    Returns ``(N, H, W, 3)``, image ``i`` bit for bit ``structure_tensor(images[i], ...)`` (the filters run
    along the two image axes only; tested): a volume's evaluation filters a run of slices in a few long
    calls that release the GIL instead of many short ones.
    """
    img = _float_image(images)
    if img.ndim != 3:
        raise InvalidParameter("images", f"shape {img.shape}", "must be a stack of grey images (N, H, W)")
    _check_scales(sigma_d, sigma_w)
    ix = gaussian_filter(img, sigma_d, order=(0, 1), mode=mode, axes=(1, 2))
    iy = -gaussian_filter(img, sigma_d, order=(1, 0), mode=mode, axes=(1, 2))
    out = np.zeros((*img.shape, 3), dtype=img.dtype)
    _add_products(out, ix, iy)
    for k in range(3):
        out[..., k] = gaussian_filter(out[..., k], sigma_w, mode=mode, axes=(1, 2))
    return out


def eigenvalues(tensors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form eigenvalues ``(l1, l2)``, ``l1 >= l2``, of a field of symmetric 2x2 tensors."""
    a, b, c = tensors[..., 0], tensors[..., 1], tensors[..., 2]
    half_trace = 0.5 * (a + c)
    radius = np.sqrt((0.5 * (a - c)) ** 2 + b * b)
    return half_trace + radius, half_trace - radius


def mean_coherence(image: np.ndarray, sigma_d: float = 1.0, sigma_w: float = 3.0) -> float:
    """Mean coherence of a (grey or RGB) image's structure tensors: how strongly oriented it is.

    The number the methods' automatic settings compare with :data:`ORIENTED_COHERENCE` (and the solid
    methods with their own threshold): fibres, laminae, fringes, brick joints 0.83-0.97; HRTEM soot 0.39.
    """
    return float(coherence(structure_tensor(to_grey(image), sigma_d, sigma_w)).mean())


def cross_orientation_fraction(tensors: np.ndarray) -> float:
    """The coherence-weighted fraction of positions oriented more than 45 degrees away from the
    exemplar's dominant orientation (the coherence-weighted mean of the doubled angles): how much of
    its oriented structure runs across the rest (brick's horizontal joints across the vertical ones)."""
    coh = coherence(tensors).astype(np.float64)
    theta = orientation(tensors).astype(np.float64)
    total = float(coh.sum())
    if total <= 0.0:
        return 0.0
    dominant = 0.5 * np.angle(np.sum(coh * np.exp(2j * theta)))
    off = 0.5 * np.abs(np.angle(np.exp(2j * (theta - dominant))))
    return float(coh[off > np.pi / 4].sum() / total)


def coherence(tensors: np.ndarray) -> np.ndarray:
    """Coherence ``C = (l1 - l2) / (l1 + l2)`` in [0, 1] (eq 4); 0 where the trace vanishes."""
    return per_pixel(_coherence, tensors)


def _coherence(tensors: np.ndarray) -> np.ndarray:
    a, b, c = tensors[..., 0], tensors[..., 1], tensors[..., 2]
    trace = a + c
    spread = np.sqrt((a - c) ** 2 + 4.0 * b * b)
    safe = np.where(trace > _TRACE_FLOOR, trace, 1.0)
    return np.where(trace > _TRACE_FLOOR, np.clip(spread / safe, 0.0, 1.0), 0.0).astype(tensors.dtype)


def orientation(tensors: np.ndarray) -> np.ndarray:
    """Orientation of the dominant eigenvector (gradient direction, eq 5), in ``(-pi/2, pi/2]``."""
    return per_pixel(_orientation, tensors)


def _orientation(tensors: np.ndarray) -> np.ndarray:
    a, b, c = tensors[..., 0], tensors[..., 1], tensors[..., 2]
    theta = 0.5 * np.arctan2(2.0 * b, a - c)
    return wrap_angle(theta).astype(tensors.dtype)


def structure_direction(tensors: np.ndarray) -> np.ndarray:
    """Fringe (structure) direction: the gradient orientation plus pi/2, wrapped."""
    return wrap_angle(orientation(tensors) + np.pi / 2).astype(tensors.dtype)


def dominant_orientation(tensors: np.ndarray, weights: np.ndarray | None = None) -> float:
    """Gradient orientation of the (weighted) mean tensor: the field's dominant orientation.

    Orientations are averaged through their tensors, not as angles, so that ``pi/2`` and ``-pi/2``
    (the same orientation) do not cancel.
    """
    flat = tensors.reshape(-1, 3).astype(np.float64)
    if weights is None:
        mean = flat.mean(axis=0)
    else:
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        mean = (flat * w[:, None]).sum(axis=0) / max(w.sum(), _TRACE_FLOOR)
    return float(orientation(mean[None, :])[0])


def orientation_histogram(
    tensors: np.ndarray, bins: int = 36, *, weight: Literal["energy", "none"] = "energy"
) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of gradient orientations over ``(-pi/2, pi/2]``, normalised to sum 1.

    With ``weight='energy'`` each pixel counts by its tensor trace ``l1 + l2`` (gradient energy), so
    that flat, orientation-less regions do not vote. Returns ``(hist, bin_edges)``.
    """
    theta = orientation(tensors).ravel()
    w = None if weight == "none" else (tensors[..., 0] + tensors[..., 2]).ravel().astype(np.float64)
    hist, edges = np.histogram(theta, bins=bins, range=(-np.pi / 2, np.pi / 2), weights=w)
    total = hist.sum()
    hist = hist / total if total > 0 else np.full(bins, 1.0 / bins)
    return hist, edges


def rotate_tensors(tensors: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """Rotate every tensor by ``angle`` (radians, per pixel or scalar): ``S' = R S R^T``.

    ``R = [[cos t, -sin t], [sin t, cos t]]`` in the y-up frame, so the orientation of ``S'`` is
    that of ``S`` plus ``angle`` and the eigenvalues (hence the coherence) are unchanged. The GRETSI
    paper writes ``R = [[cos O, sin O], [-sin O, cos O]]`` in image (y-down) coordinates: the same
    geometric rotation.
    """
    t = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(t), np.sin(t)
    a, b, d = (tensors[..., k].astype(np.float64) for k in range(3))
    sxx = c * c * a - 2 * c * s * b + s * s * d
    sxy = c * s * (a - d) + (c * c - s * s) * b
    syy = s * s * a + 2 * c * s * b + c * c * d
    return np.stack([sxx, sxy, syy], axis=-1).astype(tensors.dtype)


def log_tensors(tensors: np.ndarray, epsilon: float = LOG_EPSILON) -> np.ndarray:
    """Closed-form matrix logarithm of SPD 2x2 tensors, ``(L_xx, L_xy, L_yy)``.

    Eigen-decompose, take ``log(l + epsilon)`` of the eigenvalues, recompose; the epsilon keeps
    zero (flat-region) tensors positive definite (ALGORITHMS.md, LE metric).
    """
    t64 = tensors.astype(np.float64)
    l1, l2 = eigenvalues(t64)
    g1 = np.log(np.maximum(l1, 0.0) + epsilon)
    g2 = np.log(np.maximum(l2, 0.0) + epsilon)
    theta = 0.5 * np.arctan2(2.0 * t64[..., 1], t64[..., 0] - t64[..., 2])
    c, s = np.cos(theta), np.sin(theta)
    out = np.stack([g1 * c * c + g2 * s * s, (g1 - g2) * c * s, g1 * s * s + g2 * c * c], axis=-1)
    return out.astype(tensors.dtype)


def _component_distance_sq(t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
    d = t1 - t2
    return d[..., 0] ** 2 + 2.0 * d[..., 1] ** 2 + d[..., 2] ** 2


def tensor_dissimilarity(
    t1: np.ndarray, t2: np.ndarray, metric: Metric = "ED", alpha: float = 0.5
) -> np.ndarray:
    """Dissimilarity of tensors, element-wise over the leading axes (Akl 2014, eqs 6-11).

    - ``ED``: ``(a11-b11)^2 + (a22-b22)^2 + 2 (a12-b12)^2`` (eq 6, squared as in the paper);
    - ``SO``: ``M_or^alpha * M_coh^(1-alpha)`` with ``M_or = |sin(O1-O2)| min(C1, C2)`` and
      ``M_coh = max(C1/C2, C2/C1)`` (eqs 7-9; coherences floored at 1e-3);
    - ``FN``: Frobenius norm of the difference (eq 10);
    - ``LE``: Frobenius norm of the difference of matrix logarithms (eq 11).
    """
    if metric == "ED":
        return _component_distance_sq(t1, t2)
    if metric == "FN":
        return np.sqrt(_component_distance_sq(t1, t2))
    if metric == "LE":
        return np.sqrt(_component_distance_sq(log_tensors(t1), log_tensors(t2)))
    if metric == "SO":
        if not 0.0 <= alpha <= 1.0:
            raise InvalidParameter("alpha", alpha, "must lie in [0, 1]")
        c1 = np.maximum(coherence(t1), _COHERENCE_FLOOR)
        c2 = np.maximum(coherence(t2), _COHERENCE_FLOOR)
        m_or = np.abs(np.sin(orientation(t1) - orientation(t2))) * np.minimum(c1, c2)
        m_coh = np.maximum(c1 / c2, c2 / c1)
        return m_or**alpha * m_coh ** (1.0 - alpha)
    raise InvalidParameter("metric", metric, f"must be one of {', '.join(METRICS)}")


def neighbourhood_dissimilarity(
    f1: np.ndarray, f2: np.ndarray, metric: Metric = "ED", alpha: float = 0.5
) -> np.ndarray:
    """Sum of tensor dissimilarities over a neighbourhood (STD, eq 12).

    ``f1`` and ``f2`` have shape ``(..., N, 3)``: ``N`` tensors per neighbourhood.
    """
    return tensor_dissimilarity(f1, f2, metric, alpha).sum(axis=-1)
