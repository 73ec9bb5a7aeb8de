"""The quantitative benchmark of a synthesis result: how close the output is to the exemplar.

The measures of the volumetric-synthesis study (Urs et al. 2012, section 3.2, Figs 7-10), for a
2-D output (:func:`evaluate_pair`) and, "multi-2D", for a volume whose every slice along each axis is
compared with the exemplar (:func:`evaluate_volume`):

- **first-order statistics** (Fig. 7): grey-level histograms and their Kullback-Leibler divergence;
  mean, standard deviation, skewness and kurtosis;
- **structure** (Figs 8-9): energy-weighted histograms of the structure-tensor orientation and their
  KL divergence; the coherence distribution; the Log-Euclidean distance of the mean tensors;
- **fringe morphology** (Fig. 10): fringe length and tortuosity distributions
  (:mod:`texsynth.synth.analysis.fringes`), compared by Kolmogorov-Smirnov tests and KL divergences;
- for volumes, beyond the study: the two-point correlation ``S2(r)`` along each axis
  (:mod:`texsynth.synth.evaluate.correlation`).

The choices the paper leaves open (64 grey bins, ``D(exemplar || output)`` smoothed by ``eps = 1e-5``,
the 7x7 window as ``sigma_w = 2``, energy-weighted orientation bins, BT.601 luma for RGB, pooled
slices per axis, per-plane exemplars) are recorded in every result's ``settings`` and explained in
docs/evaluation.md ("What is measured, and the choices the paper leaves open"). The moments and the
exact KS test repeat scipy 1.17's operations (same bits) so that ``scipy.stats`` is rarely imported.

References
----------
R. D. Urs, J.-P. Da Costa, J.-M. Leyssale, G. Vignoles, C. Germain, "Non-parametric synthesis of
laminar volumetric textures from a 2D sample", Proc. BMVC 2012, pp. 54.1-54.11. J. Bigun et al.,
"Multidimensional orientation estimation ...", IEEE TPAMI 13(8), 1991. V. Arsigny et al., "Log-Euclidean
metrics ...", Magn. Reson. Med. 56(2), 2006. M. L. Botero et al., "HRTEM evaluation of soot particles
...", Carbon 96 (2016) 459-473. S. Torquato, *Random Heterogeneous Materials*, Springer, 2002, ch. 2.
"""

from __future__ import annotations

import inspect
import math
import sys
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from typing import Any, NamedTuple

import numpy as np

from texsynth.synth.analysis.fringes import (
    MIN_LENGTH,
    Fringes,
    extract_fringes,
    extract_fringes_stack,
    fringe_summary,
)
from texsynth.synth.analysis.grain import fine_energies
from texsynth.synth.analysis.tensor import (
    coherence,
    orientation_histogram,
    structure_direction,
    structure_tensor_stack,
    tensor_dissimilarity,
)
from texsynth.synth.colour import to_grey
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.io import MIN_SIDE, array_to_unit
from texsynth.synth.threads import current_threads, use_threads

__all__ = [
    "COHERENCE_BINS",
    "GREY_BINS",
    "HIST_EPSILON",
    "ORIENTATION_BINS",
    "PLANES",
    "PLANE_AXES",
    "WINDOW",
    "ExemplarSide",
    "ImageStats",
    "MeasureSettings",
    "as_grey",
    "check_values",
    "compare_stats",
    "evaluate_pair",
    "evaluate_pair_fringes",
    "evaluate_volume",
    "exemplar_side",
    "grey_histogram",
    "image_stats",
    "kl_divergence",
    "moments",
    "to_json_types",
    "window_sigma",
]

GREY_BINS = 64
ORIENTATION_BINS = 36
COHERENCE_BINS = 20
#: Additive smoothing of normalised histograms before the KL divergence (module docstring).
HIST_EPSILON = 1e-5
#: The study's structure-tensor neighbourhood, pixels (a 7x7 window).
WINDOW = 7
SIGMA_D = 1.0
LENGTH_BINS = 24
TORTUOSITY_BINS = 20
TORTUOSITY_MAX = 3.0
_DENSITY_AREA = 10_000.0


def window_sigma(window: int = WINDOW) -> float:
    """Gaussian scale with the variance of a ``window x window`` box: ``sqrt((n^2 - 1) / 12)``."""
    if window < 1:
        raise InvalidParameter("window", window, "must be a positive number of pixels")
    return math.sqrt((window * window - 1) / 12.0) if window > 1 else 0.5


def as_grey(image: np.ndarray, name: str = "image") -> np.ndarray:
    """Validate an image and return it grey, float64, shape (H, W).

    RGB ``(H, W, 3)`` becomes BT.601 luma (:data:`texsynth.synth.colour.LUMA_WEIGHTS`, as ``load_image``).
    Raises
    :class:`~texsynth.synth.errors.InvalidInput` naming ``name`` for other shapes, NaN/inf, values outside
    [0, 1] or images smaller than 8 px along a side. uint8, uint16 and bool arrays are scaled by the
    one dtype policy (:mod:`texsynth.synth.io.depth`: by the bit depth their values use), as ``load_image``
    does.
    """
    arr = np.asarray(image)
    if not np.issubdtype(arr.dtype, np.floating):
        arr = array_to_unit(arr, name)[0]
    if arr.ndim == 3 and arr.shape[-1] == 3:
        arr = to_grey(arr, np.float64)
    elif arr.ndim != 2:
        raise InvalidInput(name, f"expected a grey (H, W) or RGB (H, W, 3) image, got shape {arr.shape}")
    arr = arr.astype(np.float64, copy=False)
    check_values(arr, name)
    if min(arr.shape) < MIN_SIDE:
        raise InvalidInput(name, f"image of shape {arr.shape} is too small to evaluate (< {MIN_SIDE} px)")
    return arr


def check_values(arr: np.ndarray, name: str) -> None:
    if arr.size == 0 or not np.isfinite(arr).all():
        raise InvalidInput(name, "is empty or holds NaN/inf values")
    lo, hi = float(arr.min()), float(arr.max())
    if lo < -1e-6 or hi > 1 + 1e-6:
        raise InvalidInput(
            name,
            f"values must lie in [0, 1] (found {lo:.4g} to {hi:.4g}): scale float data first, e.g. a / 255 "
            "for 8-bit values, (a - a.min()) / (a.max() - a.min()) otherwise, or pass the integer array",
        )


def grey_histogram(image: np.ndarray, bins: int = GREY_BINS) -> np.ndarray:
    """Counts of grey levels in ``bins`` equal bins on [0, 1] (1.0 falls in the last bin)."""
    counts, _ = np.histogram(np.clip(image, 0.0, 1.0), bins=bins, range=(0.0, 1.0))
    return counts.astype(np.float64)


def _smoothed(h: np.ndarray, epsilon: float) -> np.ndarray:
    h = np.asarray(h, dtype=np.float64)
    total = h.sum()
    p = h / total if total > 0 else np.full(h.shape, 1.0 / h.size)
    return (p + epsilon) / (1.0 + h.size * epsilon)


def kl_divergence(p: np.ndarray, q: np.ndarray, epsilon: float = HIST_EPSILON) -> float:
    """Kullback-Leibler divergence ``D(p || q)`` in nats of two histograms on the same bins.

    Parameters
    ----------
    p, q : ndarray, shape (n,)
        Non-negative weights (counts or frequencies); each is normalised to sum 1, then smoothed
        additively: ``p <- (p + epsilon) / (1 + n epsilon)`` (an all-zero histogram counts as uniform).
    epsilon : float
        The additive smoothing; it bounds the penalty of an empty ``q`` bin.

    Returns
    -------
    float
        ``sum_i p_i log(p_i / q_i) >= 0``; exactly 0 for proportional histograms.

    Examples
    --------
    >>> kl_divergence([1, 2, 3], [2, 4, 6])
    0.0
    """
    p_arr, q_arr = np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
    if p_arr.shape != q_arr.shape or p_arr.ndim != 1:
        raise InvalidParameter("histograms", (p_arr.shape, q_arr.shape), "must be 1-D and of equal length")
    ps, qs = _smoothed(p_arr, epsilon), _smoothed(q_arr, epsilon)
    return max(0.0, float(np.sum(ps * np.log(ps / qs))))


#: Above this many values, :func:`moments` works on float64 pieces of this many instead of one float64
#: copy of all of them (a 512^3 volume would need 1 GiB per temporary), with the same bits.
MOMENT_CHUNK = 1 << 20


def moments(values: np.ndarray | Sequence[np.ndarray]) -> dict[str, float | None]:
    """Mean, standard deviation (ddof 0), skewness and excess kurtosis (scipy.stats) of grey levels.

    Skewness and kurtosis are ``None`` for a constant image (they are undefined). ``values``: an array,
    or a sequence of arrays taken as their ravelled concatenation (pooled slices, without the copy).
    Above :data:`MOMENT_CHUNK` values the sums are taken in float64 pieces along numpy's own pairwise
    summation tree (:func:`_pairwise_sums`): the same bits as one float64 copy, in bounded memory.
    """
    parts = [np.asarray(values)] if isinstance(values, np.ndarray) else [np.asarray(v) for v in values]
    total = sum(p.size for p in parts)
    if total > MOMENT_CHUNK:
        return _streamed_moments(_Flat(parts), total)
    flat = (
        np.concatenate([p.astype(np.float64).ravel() for p in parts])
        if len(parts) > 1
        else (parts[0].astype(np.float64, copy=False).ravel())
    )
    std = float(flat.std())
    constant = not np.ptp(flat) > 0
    skewness, kurtosis = (None, None) if constant else _skew_kurtosis(flat)
    return {"mean": float(flat.mean()), "std": std, "skewness": skewness, "kurtosis": kurtosis}


def _skew_kurtosis(flat: np.ndarray) -> tuple[float, float]:
    """``scipy.stats.skew(flat)`` and ``scipy.stats.kurtosis(flat)`` (biased, Fisher), bit for bit.

    The same operations as scipy 1.17's ``_moment`` (exponentiation by squares about the mean):
    ``m2 = mean(d**2)``, ``m3 = mean(d**2 * d)``, ``m4 = mean((d**2)**2)``; NaN where scipy calls the
    variance zero.
    """
    mean = np.mean(flat, axis=0, keepdims=True)
    d = flat - mean
    m2 = np.mean(d**2, axis=0)
    m3 = np.mean(d**2 * d, axis=0)
    m4 = np.mean((d**2) ** 2, axis=0)
    with np.errstate(all="ignore"):
        zero = m2 <= (np.finfo(m2.dtype).eps * mean[0]) ** 2
        skewness = np.nan if zero else m3 / m2**1.5
        kurtosis = np.nan if zero else m4 / m2**2.0 - 3
    return float(skewness), float(kurtosis)


class _Flat:
    """The ravelled concatenation of ``parts``, read as float64 pieces (no copy of the whole)."""

    def __init__(self, parts: Sequence[np.ndarray]) -> None:
        self.parts = [p for p in parts if p.size]
        self.starts = np.cumsum([0] + [p.size for p in self.parts])

    def piece(self, start: int, stop: int) -> np.ndarray:
        """Values ``[start, stop)`` as a contiguous float64 array."""
        out = np.empty(stop - start, dtype=np.float64)
        first = int(np.searchsorted(self.starts, start, side="right")) - 1
        done = 0
        for i in range(first, len(self.parts)):
            if start + done >= stop:
                break
            part = self.parts[i]
            lo = start + done - int(self.starts[i])
            hi = min(part.size, stop - int(self.starts[i]))
            rows = part.reshape(-1, part.shape[-1]) if part.ndim > 1 else part.reshape(1, -1)
            width = rows.shape[1]
            # rows first (a strided slice of a volume ravels without copying all of it)
            r0, r1 = lo // width, -(-hi // width)
            block = np.asarray(rows[r0:r1], dtype=np.float64).ravel()[lo - r0 * width : hi - r0 * width]
            out[done : done + block.size] = block
            done += block.size
        return out


def _pairwise_sums(
    flat: _Flat, start: int, n: int, terms: Callable[[np.ndarray], list[np.ndarray]]
) -> np.ndarray:
    """``[sum(t) for t in terms(values[start:start + n])]`` along numpy's pairwise summation tree.

    numpy (2.x) sums a contiguous float64 array by halving it (the first half a multiple of 8 long)
    down to blocks of 128; a piece that is one node of that tree sums, alone, to the node's value. So
    the tree is walked here down to nodes of at most :data:`MOMENT_CHUNK` values, each summed by numpy,
    and the nodes are added as numpy adds them: the bits of one sum over a float64 copy of everything
    (tested against it).
    """
    if n <= MOMENT_CHUNK:
        return np.array([np.add.reduce(t, initial=0.0) for t in terms(flat.piece(start, start + n))])
    half = n // 2
    half -= half % 8
    return _pairwise_sums(flat, start, half, terms) + _pairwise_sums(flat, start + half, n - half, terms)


def _streamed_moments(flat: _Flat, n: int) -> dict[str, float | None]:
    """:func:`moments` of ``n`` values read in pieces: two passes, the same operations as numpy and scipy."""
    lo, hi = math.inf, -math.inf
    for start in range(0, n, MOMENT_CHUNK):
        piece = flat.piece(start, min(n, start + MOMENT_CHUNK))
        lo, hi = min(lo, float(piece.min())), max(hi, float(piece.max()))
    (total,) = _pairwise_sums(flat, 0, n, lambda v: [v])
    mean = np.float64(total) / n

    def central(v: np.ndarray) -> list[np.ndarray]:
        d = v - mean
        d2 = d**2
        return [d2, d2 * d, d2**2]

    s2, s3, s4 = _pairwise_sums(flat, 0, n, central)
    m2, m3, m4 = np.float64(s2) / n, np.float64(s3) / n, np.float64(s4) / n
    std = float(np.sqrt(m2))
    if not hi - lo > 0:
        return {"mean": float(mean), "std": std, "skewness": None, "kurtosis": None}
    with np.errstate(all="ignore"):
        zero = m2 <= (np.finfo(np.float64).eps * mean) ** 2
        skewness = np.nan if zero else m3 / m2**1.5
        kurtosis = np.nan if zero else m4 / m2**2.0 - 3
    return {"mean": float(mean), "std": std, "skewness": float(skewness), "kurtosis": float(kurtosis)}


@dataclass
class MeasureSettings:
    grey_bins: int = GREY_BINS
    orientation_bins: int = ORIENTATION_BINS
    coherence_bins: int = COHERENCE_BINS
    sigma_d: float = SIGMA_D
    window: int = WINDOW
    epsilon: float = HIST_EPSILON
    fringes: bool = True
    pixel_size: float | None = None
    fringe_options: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("grey_bins", "orientation_bins", "coherence_bins"):
            value = getattr(self, name)
            if not (isinstance(value, int | np.integer) and 2 <= value <= 4096):
                raise InvalidParameter(name, value, "must be an integer between 2 and 4096")
        if not (np.isfinite(self.sigma_d) and self.sigma_d > 0):
            raise InvalidParameter("sigma_d", self.sigma_d, "must be a positive number of pixels")
        if not (isinstance(self.window, int | np.integer) and self.window >= 1):
            raise InvalidParameter("window", self.window, "must be a positive number of pixels")
        if not (np.isfinite(self.epsilon) and self.epsilon > 0):
            raise InvalidParameter("epsilon", self.epsilon, "must be a small positive number")
        if self.pixel_size is not None and not (np.isfinite(self.pixel_size) and self.pixel_size > 0):
            raise InvalidParameter("pixel_size", self.pixel_size, "must be a positive number of nm per pixel")
        if "pixel_size" in self.fringe_options:
            raise InvalidParameter("fringe_options", "pixel_size", "pass pixel_size on its own")
        allowed = set(inspect.signature(extract_fringes).parameters) - {"image", "pixel_size"}
        unknown = sorted(set(self.fringe_options) - allowed)
        if unknown:
            raise InvalidParameter(
                "fringe_options", unknown, f"unknown option(s); expected some of {', '.join(sorted(allowed))}"
            )

    @property
    def sigma_w(self) -> float:
        return window_sigma(self.window)

    def record(self) -> dict[str, Any]:
        return {
            "grey_bins": self.grey_bins,
            "grey_range": [0.0, 1.0],
            "histogram_smoothing_epsilon": self.epsilon,
            "kl": "D(exemplar || output), nats",
            "orientation_bins": self.orientation_bins,
            "orientation": "gradient orientation (perpendicular to fringes), energy-weighted, (-90, 90] deg",
            "coherence_bins": self.coherence_bins,
            "window": self.window,
            "sigma_w": self.sigma_w,
            "sigma_d": self.sigma_d,
            "grey_conversion": "RGB -> BT.601 luma 0.299 R + 0.587 G + 0.114 B (as "
            "texsynth.synth.io.load_image)",
            "fringes": self.fringes,
            "fringe_options": dict(self.fringe_options),
            "pixel_size_nm": self.pixel_size,
        }


@dataclass
class ImageStats:
    """Poolable statistics of one or more images (sums, counts and samples)."""

    grey: np.ndarray
    orientation: np.ndarray
    coherence: np.ndarray
    coherence_sum: float
    tensor_sum: np.ndarray
    n_pixels: int
    lengths: np.ndarray
    tortuosity: np.ndarray
    n_loops: int
    fringe_area: int
    n_images: int = 1
    #: The fringes extracted from this one image (not pooled), for overlays drawn after the metrics.
    extracted: Fringes | None = None
    #: Grain (:func:`~texsynth.synth.analysis.grain.fine_energies`): the high-passed and the centred sums
    #: of squares, pooled by summing (their ratio is the images' share of variance finer than 1 px).
    fine_energy: float = 0.0
    centred_energy: float = 0.0

    @staticmethod
    def pool(items: Iterable[ImageStats]) -> ImageStats:
        items = list(items)
        return ImageStats(
            grey=np.sum([s.grey for s in items], axis=0),
            orientation=np.sum([s.orientation for s in items], axis=0),
            coherence=np.sum([s.coherence for s in items], axis=0),
            coherence_sum=float(sum(s.coherence_sum for s in items)),
            tensor_sum=np.sum([s.tensor_sum for s in items], axis=0),
            n_pixels=sum(s.n_pixels for s in items),
            lengths=np.concatenate([s.lengths for s in items]),
            tortuosity=np.concatenate([s.tortuosity for s in items]),
            n_loops=sum(s.n_loops for s in items),
            fringe_area=sum(s.fringe_area for s in items),
            n_images=sum(s.n_images for s in items),
            fine_energy=float(sum(s.fine_energy for s in items)),
            centred_energy=float(sum(s.centred_energy for s in items)),
        )

    @property
    def fine_share(self) -> float | None:
        """The pooled share of variance finer than 1 px (None for flat images)."""
        return self.fine_energy / self.centred_energy if self.centred_energy > 0 else None

    @property
    def mean_tensor(self) -> np.ndarray:
        return self.tensor_sum / max(self.n_pixels, 1)


def image_stats(grey: np.ndarray, settings: MeasureSettings) -> ImageStats:
    return stack_stats(grey[None], settings)[0]


def stack_stats(greys: np.ndarray, settings: MeasureSettings) -> list[ImageStats]:
    """:func:`image_stats` of each grey image of a stack ``(N, H, W)`` (float64), the same bits: the
    filters run on the whole stack (:func:`~texsynth.synth.analysis.tensor.structure_tensor_stack`,
    :func:`~texsynth.synth.analysis.fringes.extract_fringes_stack`), the histograms and sums image by
    image."""
    all_tensors = structure_tensor_stack(greys, settings.sigma_d, settings.sigma_w)
    if settings.fringes:
        extracted: list[Fringes | None] = list(
            extract_fringes_stack(greys, pixel_size=settings.pixel_size, **settings.fringe_options)
        )
    else:
        extracted = [None] * len(greys)
    out = []
    for grey, tensors, fr in zip(greys, all_tensors, extracted, strict=True):
        energy = float((tensors[..., 0] + tensors[..., 2]).sum(dtype=np.float64))
        hist, _ = orientation_histogram(tensors, bins=settings.orientation_bins, weight="energy")
        coh = coherence(tensors)
        coh_counts, _ = np.histogram(coh, bins=settings.coherence_bins, range=(0.0, 1.0))
        if fr is not None:
            lengths, tortuosity, loops = fr.lengths, fr.tortuosity, fr.n_loops
        else:
            lengths, tortuosity, loops = np.zeros(0), np.zeros(0), 0
        fine, centred = fine_energies(grey)
        out.append(
            ImageStats(
                grey=grey_histogram(grey, settings.grey_bins),
                orientation=hist * energy,
                coherence=coh_counts.astype(np.float64),
                coherence_sum=float(coh.sum(dtype=np.float64)),
                tensor_sum=tensors.reshape(-1, 3).sum(axis=0, dtype=np.float64),
                n_pixels=grey.size,
                lengths=lengths,
                tortuosity=tortuosity,
                n_loops=loops,
                fringe_area=grey.size,
                extracted=fr,
                fine_energy=fine,
                centred_energy=centred,
            )
        )
    return out


def _normalised(h: np.ndarray) -> list[float]:
    total = float(h.sum())
    return [float(v) for v in (h / total if total > 0 else np.full(h.shape, 1.0 / h.size))]


def _direction_deg(tensor: np.ndarray) -> float | None:
    if not tensor[0] + tensor[2] > 0:
        return None
    return float(np.degrees(structure_direction(tensor[None, :])[0]))


def _ks(a: np.ndarray, b: np.ndarray) -> dict[str, float | None]:
    if len(a) == 0 or len(b) == 0:
        return {"statistic": None, "pvalue": None}
    exact = _ks_2samp_exact(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    if exact is not None:
        return {"statistic": exact[0], "pvalue": exact[1]}
    from scipy import stats  # the cases the exact test leaves to scipy's asymptotic one

    res = stats.ks_2samp(a, b)
    return {"statistic": float(res.statistic), "pvalue": float(res.pvalue)}


#: ``scipy.stats.ks_2samp(method='auto')`` is exact up to this many values per sample.
_KS_EXACT_MAX_N = 10_000
#: Work bound (inner-loop steps) of the exact p-value in Python; beyond it scipy computes it.
_KS_MAX_STEPS = 400_000


def _ks_2samp_exact(data1: np.ndarray, data2: np.ndarray) -> tuple[float, float] | None:
    """Two-sided two-sample KS ``(statistic, p-value)`` as ``scipy.stats.ks_2samp`` gives them with its
    exact method (scipy 1.17, bit for bit), or ``None`` where scipy would not use it or where it would
    take long here (then :func:`_ks` asks scipy).

    References: J. L. Hodges Jr., "The significance probability of the Smirnov two-sample test",
    Arkiv för Matematik 3 (1958) 469-486; T. Viehmann, "Numerically more stable computation of the
    p-values for the two-sample Kolmogorov-Smirnov test", arXiv:2102.08037.
    """
    data1, data2 = np.sort(data1), np.sort(data2)
    n1, n2 = data1.shape[0], data2.shape[0]
    if max(n1, n2) > _KS_EXACT_MAX_N:
        return None
    data_all = np.concatenate([data1, data2])
    cdf1 = np.searchsorted(data1, data_all, side="right") / n1
    cdf2 = np.searchsorted(data2, data_all, side="right") / n2
    cddiffs = cdf1 - cdf2
    min_s = np.clip(-cddiffs[np.argmin(cddiffs)], 0, 1)
    max_s = cddiffs[np.argmax(cddiffs)]
    d = min_s if min_s > max_s else max_s
    g = math.gcd(n1, n2)
    lcm = (n1 // g) * n2
    h = int(np.round(d * lcm))
    d = h * 1.0 / lcm
    if h == 0:
        return float(d), 1.0
    m, n = max(n1, n2), min(n1, n2)
    if m * min(n + 1, 2 * math.ceil(h / (m // g)) + 2) > _KS_MAX_STEPS:
        return None
    try:
        with np.errstate(invalid="raise", over="raise"):
            prob = _ks_prob_outside_square(n1, h) if n1 == n2 else _outer_prob_inside(n1, n2, g, h)
    except (FloatingPointError, OverflowError):
        return None
    if not 0 <= prob <= 1:
        return None
    return float(d), float(np.clip(prob, 0, 1))


def _ks_prob_outside_square(n: int, h: int) -> float:
    """``P(D_{n,n} >= h / n)``: scipy's ``_compute_prob_outside_square`` (Horner-like sum)."""
    p = 0.0
    k = int(np.floor(n / h))
    while k >= 0:
        p1 = 1.0
        for j in range(h):
            p1 = (n - k * h - j) * p1 / (n + k * h + j + 1)
        p = p1 * (1.0 - p)
        k -= 1
    return 2 * p


def _outer_prob_inside(m: int, n: int, g: int, h: int) -> float:
    """:func:`_ks_outer_prob_inside` by its nogil kernel (:mod:`texsynth.synth.kernels.ks_exact`, the same
    bits) once numba is loaded, else by the Python loop (numba's start-up costs more than the loop saves)."""
    if "numba" in sys.modules:
        from texsynth.synth.kernels.ks_exact import ks_outer_prob_inside

        return float(ks_outer_prob_inside(int(m), int(n), int(g), int(h)))
    return _ks_outer_prob_inside(m, n, g, h)


def _ks_outer_prob_inside(m: int, n: int, g: int, h: int) -> float:
    """Share of lattice paths leaving ``|x/m - y/n| < h / lcm(m, n)``: scipy's
    ``_compute_outer_prob_inside_method`` (Hodges' inside method for ``1 - p``, Viehmann's recursion).
    The plain reference of :func:`texsynth.synth.kernels.ks_exact.ks_outer_prob_inside`."""
    if m < n:
        m, n = n, m
    mg, ng = m // g, n // g
    minj, maxj = 0, min(int(np.ceil(h / mg)), n + 1)
    curlen = maxj - minj
    a = np.ones(min(2 * maxj + 2, n + 1), dtype=np.float64).tolist()
    for k in range(minj, maxj):
        a[k] = 0.0
    for i in range(1, m + 1):
        lastminj, lastlen = minj, curlen
        minj = min(max(int(np.floor((ng * i - h) / mg)) + 1, 0), n)
        maxj = min(int(np.ceil((ng * i + h) / mg)), n + 1)
        if maxj <= minj:
            return 1.0
        val = 0.0 if minj == 0 else 1.0
        for jj in range(maxj - minj):
            j = jj + minj
            val = (a[jj + minj - lastminj] * i + val * j) / (i + j)
            a[jj] = val
        curlen = maxj - minj
        if lastlen > curlen:
            for k in range(maxj - minj, min(maxj - minj + (lastlen - curlen), len(a))):
                a[k] = 1.0
    return a[maxj - minj - 1]


def _fringe_block(ref: ImageStats, out: ImageStats, settings: MeasureSettings) -> dict[str, Any]:
    min_length = float(settings.fringe_options.get("min_length", MIN_LENGTH))
    longest = max([min_length + 1.0, *(float(s.lengths.max()) for s in (ref, out) if len(s.lengths))])
    length_edges = np.linspace(min_length, longest, LENGTH_BINS + 1)
    tort_edges = np.linspace(1.0, TORTUOSITY_MAX, TORTUOSITY_BINS + 1)

    def hist(values: np.ndarray, edges: np.ndarray) -> np.ndarray:
        clipped = np.clip(values, edges[0], edges[-1])
        return np.histogram(clipped, bins=edges)[0].astype(np.float64)

    def side(s: ImageStats) -> dict[str, Any]:
        summary: dict[str, Any] = fringe_summary(s.lengths, s.tortuosity, settings.pixel_size)
        summary["density_per_10k_px"] = _DENSITY_AREA * len(s.lengths) / max(s.fringe_area, 1)
        summary["loops"] = s.n_loops
        return summary

    lh = {k: hist(s.lengths, length_edges) for k, s in (("exemplar", ref), ("output", out))}
    th = {k: hist(s.tortuosity, tort_edges) for k, s in (("exemplar", ref), ("output", out))}
    both = len(ref.lengths) > 0 and len(out.lengths) > 0
    return {
        "exemplar": side(ref),
        "output": side(out),
        "ks_length": _ks(ref.lengths, out.lengths),
        "ks_tortuosity": _ks(ref.tortuosity, out.tortuosity),
        "kl_length": kl_divergence(lh["exemplar"], lh["output"], settings.epsilon) if both else None,
        "kl_tortuosity": kl_divergence(th["exemplar"], th["output"], settings.epsilon) if both else None,
        "length_histogram": {
            "edges": [float(e) for e in length_edges],
            "exemplar": _normalised(lh["exemplar"]),
            "output": _normalised(lh["output"]),
        },
        "tortuosity_histogram": {
            "edges": [float(e) for e in tort_edges],
            "exemplar": _normalised(th["exemplar"]),
            "output": _normalised(th["output"]),
        },
    }


def compare_stats(
    ref: ImageStats,
    out: ImageStats,
    ref_moments: dict[str, Any],
    out_moments: dict[str, Any],
    settings: MeasureSettings,
) -> dict[str, Any]:
    eps = settings.epsilon
    ref_mean, out_mean = ref.mean_tensor, out.mean_tensor
    le = float(tensor_dissimilarity(ref_mean[None, :], out_mean[None, :], "LE")[0])
    result: dict[str, Any] = {
        "grey": {
            "kl": kl_divergence(ref.grey, out.grey, eps),
            "histogram": {"exemplar": _normalised(ref.grey), "output": _normalised(out.grey)},
        },
        "moments": {
            "exemplar": ref_moments,
            "output": out_moments,
            "difference": {
                k: None
                if ref_moments[k] is None or out_moments[k] is None
                else out_moments[k] - ref_moments[k]
                for k in ref_moments
            },
        },
        "structure": {
            "orientation_kl": kl_divergence(ref.orientation, out.orientation, eps),
            "orientation_histogram": {
                "bin_edges_deg": [float(e) for e in np.linspace(-90.0, 90.0, settings.orientation_bins + 1)],
                "exemplar": _normalised(ref.orientation),
                "output": _normalised(out.orientation),
            },
            "dominant_structure_direction_deg": {
                "exemplar": _direction_deg(ref_mean),
                "output": _direction_deg(out_mean),
            },
            "coherence_kl": kl_divergence(ref.coherence, out.coherence, eps),
            "coherence_mean": {
                "exemplar": ref.coherence_sum / max(ref.n_pixels, 1),
                "output": out.coherence_sum / max(out.n_pixels, 1),
            },
            "coherence_histogram": {
                "exemplar": _normalised(ref.coherence),
                "output": _normalised(out.coherence),
            },
            "mean_tensor": {
                "exemplar": [float(v) for v in ref_mean],
                "output": [float(v) for v in out_mean],
            },
            "log_euclidean": le,
        },
        "grain": {
            "exemplar": ref.fine_share,
            "output": out.fine_share,
            "ratio": out.fine_share / ref.fine_share
            if ref.fine_share and out.fine_share is not None
            else None,
        },
    }
    if settings.fringes:
        result["fringes"] = _fringe_block(ref, out, settings)
    result["summary"] = _headline(result)
    return result


def _headline(block: Mapping[str, Any]) -> dict[str, Any]:
    """The few numbers a person reads first."""
    head = {
        "grey_kl": block["grey"]["kl"],
        "std_difference": block["moments"]["difference"]["std"],
        "skewness_difference": block["moments"]["difference"]["skewness"],
        "orientation_kl": block["structure"]["orientation_kl"],
        "log_euclidean": block["structure"]["log_euclidean"],
        "grain_ratio": block["grain"]["ratio"],
    }
    if "fringes" in block:
        fr = block["fringes"]
        head["fringe_ks_length"] = fr["ks_length"]["statistic"]
        head["fringe_ks_tortuosity"] = fr["ks_tortuosity"]["statistic"]
    return head


def to_json_types(obj: Any) -> Any:
    """Plain JSON types: numpy scalars to Python, NaN/inf to None, tuples to lists."""
    if isinstance(obj, Mapping):
        return {str(k): to_json_types(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_json_types(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [to_json_types(v) for v in obj.tolist()]
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        value = float(obj)
        return value if math.isfinite(value) else None
    return obj


def evaluate_pair(
    exemplar: np.ndarray,
    output: np.ndarray,
    *,
    pixel_size: float | None = None,
    fringes: bool = True,
    grey_bins: int = GREY_BINS,
    orientation_bins: int = ORIENTATION_BINS,
    coherence_bins: int = COHERENCE_BINS,
    sigma_d: float = SIGMA_D,
    window: int = WINDOW,
    epsilon: float = HIST_EPSILON,
    fringe_options: Mapping[str, Any] | None = None,
    threads: int | None = None,
) -> dict[str, Any]:
    """Compare a 2-D synthesis output with its exemplar (the study's benchmark, section 3.2).

    Parameters
    ----------
    exemplar, output : ndarray, shape (H, W) or (H, W, 3)
        Images in [0, 1]; sizes may differ. RGB is converted to grey (BT.601 luma).
    pixel_size : float, optional
        Nanometres per pixel: fringe lengths are also reported in nm.
    fringes : bool
        Run the fringe analysis (skip it for textures without lattice fringes, or for speed).
    grey_bins, orientation_bins, coherence_bins : int
        Histogram bins: grey levels on [0, 1], gradient orientations on (-90, 90] degrees, coherence
        on [0, 1].
    sigma_d : float
        Derivative scale of the structure tensor, pixels.
    window : int
        Side of the square window the study uses for the tensor (7); mapped to the Gaussian
        ``sigma_w = sqrt((window^2 - 1) / 12)`` of equal variance.
    epsilon : float
        Additive smoothing of normalised histograms before the KL divergences.
    fringe_options : mapping, optional
        Keyword arguments of :func:`texsynth.synth.analysis.fringes.extract_fringes` (``sigma``,
        ``background``,
        ``min_length``, ...).
    threads : int, optional
        Threads for the measures (:func:`texsynth.synth.threads.use_threads`; default: as set, else every
        core).

    Returns
    -------
    dict
        JSON-serialisable (plain floats, ints, lists; undefined values are ``None``)::

            {"kind": "pair", "settings": {...}, "shape": {"exemplar": [H, W], "output": [H, W]},
             "grey": {"kl", "histogram": {"exemplar", "output"}},
             "moments": {"exemplar", "output", "difference"},     # mean, std, skewness, kurtosis
             "structure": {"orientation_kl", "orientation_histogram", "coherence_kl",
                           "coherence_mean", "coherence_histogram", "mean_tensor",
                           "log_euclidean", "dominant_structure_direction_deg"},
             "fringes": {"exemplar", "output", "ks_length", "ks_tortuosity", "kl_length",
                         "kl_tortuosity", "length_histogram", "tortuosity_histogram"},
             "summary": {"grey_kl", "orientation_kl", "log_euclidean", ...}}

    Notes
    -----
    ``KL = sum_i p_i log(p_i / q_i)`` with ``p`` the exemplar's smoothed histogram (module
    docstring); the Log-Euclidean distance is ``||log(S_ex) - log(S_out)||_F`` of the mean tensors.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> img = rng.random((32, 32))
    >>> m = evaluate_pair(img, img, fringes=False)
    >>> m["grey"]["kl"], m["structure"]["orientation_kl"]
    (0.0, 0.0)
    """
    settings = MeasureSettings(
        grey_bins=grey_bins,
        orientation_bins=orientation_bins,
        coherence_bins=coherence_bins,
        sigma_d=sigma_d,
        window=window,
        epsilon=epsilon,
        fringes=fringes,
        pixel_size=pixel_size,
        fringe_options=dict(fringe_options or {}),
    )
    with use_threads(threads):
        return _evaluate_pair(exemplar, output, settings)[0]


def evaluate_pair_fringes(
    exemplar: np.ndarray, output: np.ndarray, **options: Any
) -> tuple[dict[str, Any], dict[str, Fringes]]:
    """:func:`evaluate_pair` (the same keyword arguments), and the fringes it extracted.

    Returns ``(metrics, {'exemplar': Fringes, 'output': Fringes})`` (no fringes with
    ``fringes=False``), so that the fringe overlays (:func:`texsynth.synth.output.plots.write_plots`) reuse
    them instead of extracting them a second time. ``exemplar_side``: the exemplar's half made ahead
    (:func:`exemplar_side`), used when made from this very array with the same options.
    """
    threads = options.pop("threads", None)
    side = options.pop("exemplar_side", None)
    settings = MeasureSettings(**{**options, "fringe_options": dict(options.get("fringe_options") or {})})
    with use_threads(threads):
        return _evaluate_pair(exemplar, output, settings, side)


class ExemplarSide(NamedTuple):
    """The exemplar's half of :func:`evaluate_pair_fringes` (:func:`exemplar_side`), made before the output
    exists (while it is synthesized) and handed to it: its grey image, statistics and moments."""

    exemplar: np.ndarray  # the array it was made from (the one handed to the evaluation)
    settings: MeasureSettings
    grey: np.ndarray
    stats: ImageStats
    moments: dict[str, float | None]


def exemplar_side(exemplar: np.ndarray, **options: Any) -> ExemplarSide:
    """The exemplar's statistics of :func:`evaluate_pair_fringes` with the same ``options`` (``threads``
    too), for its ``exemplar_side``: the same values as it computes itself."""
    threads = options.pop("threads", None)
    settings = MeasureSettings(**{**options, "fringe_options": dict(options.get("fringe_options") or {})})
    with use_threads(threads):
        grey = as_grey(exemplar, "exemplar")
        return ExemplarSide(exemplar, settings, grey, image_stats(grey, settings), moments(grey))


def _evaluate_pair(
    exemplar: np.ndarray, output: np.ndarray, settings: MeasureSettings, side: ExemplarSide | None = None
) -> tuple[dict[str, Any], dict[str, Fringes]]:
    """:func:`evaluate_pair`'s work; with ``side`` made from this exemplar and settings, its half is not
    computed again."""
    if side is not None and side.exemplar is exemplar and side.settings == settings:
        ex, ex_stats, ex_moments = side.grey, side.stats, side.moments
    else:
        ex = as_grey(exemplar, "exemplar")
        ex_stats, ex_moments = image_stats(ex, settings), moments(ex)
    out = as_grey(output, "output")
    out_stats = image_stats(out, settings)
    block = compare_stats(ex_stats, out_stats, ex_moments, moments(out), settings)
    result = {
        "kind": "pair",
        "settings": settings.record(),
        "shape": {"exemplar": list(ex.shape), "output": list(out.shape)},
        **block,
    }
    extracted = {"exemplar": ex_stats.extracted, "output": out_stats.extracted}
    return to_json_types(result), {k: v for k, v in extracted.items() if v is not None}


def _spread(values: list[float | None]) -> dict[str, float | None]:
    arr = np.array([v for v in values if v is not None], dtype=np.float64)
    if arr.size == 0:
        return {"mean": None, "std": None, "min": None, "max": None}
    return {
        "mean": float(arr.mean()),
        "std": float(arr.std()),
        "min": float(arr.min()),
        "max": float(arr.max()),
    }


#: The plane each slicing axis of a ``(D, H, W) = (z, y, x)`` volume shows (as
# :data:`texsynth.synth.api.PLANES`):
#: slices along axis 0 are ``xy`` planes, along axis 1 ``xz``, along axis 2 ``yz``.
PLANES: tuple[str, ...] = ("xy", "xz", "yz")
#: The physical axes down the rows and across the columns of each plane's images (ALGORITHMS.md).
PLANE_AXES: dict[str, tuple[str, str]] = {"xy": ("y", "x"), "xz": ("z", "x"), "yz": ("z", "y")}
_S2_DIRECTION = {0: "row", 1: "col"}


def _volume_exemplars(
    exemplar: np.ndarray | Mapping[str, np.ndarray], planes: tuple[str, ...]
) -> tuple[dict[str, np.ndarray], bool]:
    """The grey exemplar of each plane in ``planes``, and whether one exemplar serves them all."""
    if not isinstance(exemplar, Mapping):
        one = as_grey(exemplar, "exemplar")
        return dict.fromkeys(planes, one), True
    unknown = sorted(str(k) for k in set(exemplar) - set(PLANES))
    if unknown:
        raise InvalidInput(f"exemplar_{unknown[0]}", f"unknown plane (known: {', '.join(PLANES)})")
    missing = [p for p in planes if p not in exemplar]
    if missing:
        raise InvalidInput(
            f"exemplar_{missing[0]}", f"missing: the {missing[0]} slices need an exemplar to be compared with"
        )
    grey = {p: as_grey(exemplar[p], f"exemplar_{p}") for p in planes}
    first = grey[planes[0]]
    isotropic = all(g.shape == first.shape and np.array_equal(g, first) for g in grey.values())
    return grey, isotropic


def _check_volume_values(vol: np.ndarray) -> None:
    """:func:`check_values` of a volume, slab by slab (no float64 or boolean copy of all of it)."""
    step = max(1, MOMENT_CHUNK // max(1, vol[0].size))
    lo, hi, finite = math.inf, -math.inf, vol.size > 0
    for start in range(0, vol.shape[0], step):
        slab = vol[start : start + step]
        finite = finite and bool(np.isfinite(slab).all())
        if not finite:
            break
        lo, hi = min(lo, float(slab.min())), max(hi, float(slab.max()))
    if not finite:
        raise InvalidInput("volume", "is empty or holds NaN/inf values")
    if lo < -1e-6 or hi > 1 + 1e-6:
        check_values(np.array([lo, hi]), "volume")  # the one message, with the volume's range


def _s2_comparisons(
    planes: Mapping[str, np.ndarray],
    vol: np.ndarray,
    threshold: float | None,
    periodic: bool,
) -> dict[str, Any]:
    """S2 along each physical axis of ``vol`` against each plane exemplar that contains that axis.

    Every exemplar is thresholded at its own Otsu level (or ``threshold``) and the volume at the same
    level for that comparison, so each plane's phase 1 is defined by its own exemplar.
    """
    from texsynth.synth.evaluate.correlation import (  # volumes only
        compare_s2,
        image_s2,
        otsu_threshold,
        volume_s2,
    )

    thresholds = {p: threshold if threshold is not None else otsu_threshold(ex) for p, ex in planes.items()}
    ex_curves = {p: image_s2(ex, threshold=thresholds[p], periodic=periodic) for p, ex in planes.items()}
    vol_curves: dict[float, dict[str, np.ndarray]] = {}
    per_axis: dict[str, dict[str, Any]] = {"x": {}, "y": {}, "z": {}}
    for plane in planes:
        t = thresholds[plane]
        if t not in vol_curves:
            vol_curves[t] = volume_s2(vol, threshold=t, periodic=periodic)
        for image_axis, axis_name in enumerate(PLANE_AXES[plane]):
            direction = _S2_DIRECTION[image_axis]
            ex_curve, vol_curve = ex_curves[plane][direction], vol_curves[t][axis_name]
            per_axis[axis_name][plane] = {
                **compare_s2(ex_curve, vol_curve),
                "threshold": t,
                "exemplar_direction": direction,
                "s2": {"exemplar": [float(v) for v in ex_curve], "volume": [float(v) for v in vol_curve]},
            }
    per_axis = {k: v for k, v in per_axis.items() if v}
    summary: dict[str, float | None] = {
        axis: _mean([c["relative_error"] for c in comps.values()]) for axis, comps in per_axis.items()
    }
    summary["mean"] = _mean([c["relative_error"] for comps in per_axis.values() for c in comps.values()])
    return {"thresholds": thresholds, "axes": per_axis, "summary": summary}


def _mean(values: Iterable[float | None]) -> float | None:
    kept = [v for v in values if v is not None]
    return float(np.mean(kept)) if kept else None


def _s2_settings(threshold: float | None, periodic: bool) -> dict[str, Any]:
    return {
        "phase": "phase 1 = grey >= threshold (the bright phase)",
        "threshold": "given"
        if threshold is not None
        else "Otsu threshold of each plane's exemplar, applied to the volume in that comparison",
        "periodic": periodic,
        "lags": "r = 0 .. N // 2 of each line length N; compared over the common lags",
        "correlation_length": "first r where S2(r) - phi^2 < (S2(0) - phi^2) / e, on the exemplar's curve",
        "relative_error": "sum_{r <= R} |S2_volume - S2_exemplar| / sum_{r <= R} S2_exemplar, "
        "R = the exemplar's correlation length",
    }


def evaluate_volume(
    exemplar: np.ndarray | Mapping[str, np.ndarray],
    volume: np.ndarray,
    *,
    axes: Iterable[int] = (0, 1, 2),
    slice_step: int = 1,
    pixel_size: float | None = None,
    fringes: bool = True,
    s2: bool = True,
    threshold: float | None = None,
    s2_periodic: bool = False,
    grey_bins: int = GREY_BINS,
    orientation_bins: int = ORIENTATION_BINS,
    coherence_bins: int = COHERENCE_BINS,
    sigma_d: float = SIGMA_D,
    window: int = WINDOW,
    epsilon: float = HIST_EPSILON,
    fringe_options: Mapping[str, Any] | None = None,
    threads: int | None = None,
    progress: Callable[[str, float], None] | None = None,
) -> dict[str, Any]:
    """Multi-2D comparison of a volume with its exemplar(s), per axis and overall, plus ``S2(r)``.

    Parameters
    ----------
    exemplar : ndarray, shape (H, W) or (H, W, 3), or mapping ``{'xy', 'xz', 'yz'} -> ndarray``
        One 2-D exemplar in [0, 1] for every plane (an isotropic material; RGB converted to grey), or
        one per plane (anisotropic): the slices along axis 0 (``xy`` planes, rows ``y``, columns
        ``x``) are compared with ``exemplar['xy']``, along axis 1 (``xz``: rows ``z``, columns ``x``)
        with ``exemplar['xz']``, along axis 2 (``yz``: rows ``z``, columns ``y``) with
        ``exemplar['yz']``. A mapping needs the planes of the evaluated ``axes``.
    volume : ndarray, shape (D, H, W)
        Grey volume in [0, 1], ``(z, y, x)``; every side at least 8 voxels.
    axes : iterable of int
        Axes whose slices are compared (the study: all three; front and side views are 2 of them).
    slice_step : int
        Take every ``slice_step``-th slice along each axis (1: all; larger for speed on big volumes).
        ``S2`` always uses every voxel.
    s2 : bool
        Compare two-point correlations (:mod:`texsynth.synth.evaluate.correlation`): ``S2`` of the volume
        along each physical axis ``x``, ``y``, ``z`` (averaged over all lines) against ``S2`` along the same
        physical axis of each evaluated plane's exemplar that contains it (``x``: columns of the ``xy``
        and ``xz`` exemplars; ``y``: rows of ``xy``, columns of ``yz``; ``z``: rows of ``xz`` and ``yz``).
    threshold : float, optional
        Grey level of the phase boundary for ``S2`` (phase 1 is ``grey >= threshold``); by default the
        Otsu threshold of each exemplar, applied to the volume in the comparisons with that exemplar.
    s2_periodic : bool
        Periodic ``S2`` estimates (for toroidal samples); by default non-periodic (zero-padded).
    pixel_size, fringes, grey_bins, orientation_bins, coherence_bins, sigma_d, window, epsilon
    fringe_options, threads
        As in :func:`evaluate_pair`.
    progress : callable ``(stage, fraction)``, optional
        Told how many of the slices are done (a 512^3 volume has 1536 of them).

    Returns
    -------
    dict
        JSON-serialisable::

            {"kind": "volume", "settings": {...}, "isotropic": bool,
             "shape": {"exemplar": [h, w], "exemplars": {"xy": [h, w], ...}, "volume": [D, H, W]},
             "axes": {"0": {<evaluate_pair blocks on the pooled slices>, "plane": "xy",
                            "slices": {"count", "grey_kl", "orientation_kl", "std", "skewness"},
                            "s2": {"x": {<S2 comparison>}, "y": {...}}},
                      "1": ..., "2": ...},
             "overall": {<evaluate_pair blocks on all slices of all axes>},
             "s2": {"thresholds": {"xy": t, ...},
                    "axes": {"x": {"xy": {<S2 comparison>, "threshold", "exemplar_direction",
                                          "s2": {"exemplar": [...], "volume": [...]}}, "xz": ...},
                             "y": ..., "z": ...},
                    "summary": {"x", "y", "z", "mean"}},
             "summary": {..., "s2_relative_error", "per_axis": {"0": {..., "s2_relative_error"}, ...}}}

        where each ``"slices"`` entry is ``{"mean", "std", "min", "max"}`` over that axis's slices and
        an S2 comparison is :func:`texsynth.synth.evaluate.correlation.compare_s2` (volume fractions,
        correlation lengths, the lag window and the relative and maximum errors).

    Notes
    -----
    Slices along axis 0 are ``volume[k]`` (shape ``(H, W)``), along axis 1 ``volume[:, k]``
    (``(D, W)``), along axis 2 ``volume[:, :, k]`` (``(D, H)``): the first image axis of a slice is
    always the lower volume axis. Pooling is described in the module docstring. With per-plane
    exemplars, ``overall`` compares the pooled slices of all axes with the pooled exemplars of their
    planes (each exemplar weighted by its pixel count). The slices are measured in runs on the work's
    threads, with the same results whatever the thread count; times in docs/benchmarks.md ("A volume's
    evaluation on both cores").
    """
    with use_threads(threads):
        return _evaluate_volume(
            exemplar,
            volume,
            axes=axes,
            slice_step=slice_step,
            pixel_size=pixel_size,
            fringes=fringes,
            s2=s2,
            threshold=threshold,
            s2_periodic=s2_periodic,
            grey_bins=grey_bins,
            orientation_bins=orientation_bins,
            coherence_bins=coherence_bins,
            sigma_d=sigma_d,
            window=window,
            epsilon=epsilon,
            fringe_options=fringe_options,
            progress=progress,
        )


def _exemplar_stats(ex: np.ndarray, settings: MeasureSettings) -> tuple[ImageStats, dict[str, Any]]:
    return image_stats(ex, settings), moments(ex)


def _chunk_stats(chunk: np.ndarray, settings: MeasureSettings) -> list[tuple[ImageStats, dict[str, Any]]]:
    """Each slice's statistics and moments, for a run of slices ``(n, h, w)`` (one float64 copy of it)."""
    greys = np.array(chunk, dtype=np.float64)
    out = []
    for grey, stats in zip(greys, stack_stats(greys, settings), strict=True):
        stats.extracted = None  # each slice's fringe objects: unused here, 100s of MB at 512^3
        out.append((stats, moments(grey)))
    return out


#: Pixels of the slices one task of the volume's evaluation takes (a run of 32 slices of 64^2, 2 of
#: 256^2, one of 512^2): long filter calls that release the GIL, a bounded float64 copy per thread.
CHUNK_PIXELS = 1 << 17
#: Tasks handed to the evaluation's threads ahead of the one being pooled, per thread.
CHUNKS_AHEAD = 2


def _chunks(n: int, pixels: int, threads: int) -> list[range]:
    """Runs of consecutive slice numbers ``0 .. n - 1``: at most :data:`CHUNK_PIXELS` pixels each (one
    slice at least) and, with several threads, at least two runs per thread to balance them."""
    size = max(1, CHUNK_PIXELS // max(pixels, 1))
    if threads > 1:
        size = min(size, max(1, -(-n // (2 * threads))))
    return [range(i, min(n, i + size)) for i in range(0, n, size)]


def _map_chunks(function: Callable[[Any], Any], tasks: Sequence[Any]) -> Iterator[Any]:
    """``function`` of each task, in order: on the work's threads (:func:`current_threads`) when it has
    several. Each slice's answer depends on that slice alone and the caller pools them in order, so the
    results do not depend on the thread count (nor on how the slices are cut into tasks); the filters and
    the fringe kernel inside release the GIL. At most ``threads * CHUNKS_AHEAD`` tasks are in flight."""
    threads = current_threads()
    if threads < 2 or len(tasks) < 2:
        yield from map(function, tasks)
        return
    ahead = threads * CHUNKS_AHEAD
    with ThreadPoolExecutor(max_workers=threads) as pool:
        pending: deque[Future[Any]] = deque()
        for task in tasks:
            pending.append(pool.submit(function, task))
            if len(pending) >= ahead:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def _evaluate_volume(
    exemplar: np.ndarray | Mapping[str, np.ndarray],
    volume: np.ndarray,
    *,
    axes: Iterable[int] = (0, 1, 2),
    slice_step: int = 1,
    pixel_size: float | None = None,
    fringes: bool = True,
    s2: bool = True,
    threshold: float | None = None,
    s2_periodic: bool = False,
    grey_bins: int = GREY_BINS,
    orientation_bins: int = ORIENTATION_BINS,
    coherence_bins: int = COHERENCE_BINS,
    sigma_d: float = SIGMA_D,
    window: int = WINDOW,
    epsilon: float = HIST_EPSILON,
    fringe_options: Mapping[str, Any] | None = None,
    progress: Callable[[str, float], None] | None = None,
) -> dict[str, Any]:

    settings = MeasureSettings(
        grey_bins=grey_bins,
        orientation_bins=orientation_bins,
        coherence_bins=coherence_bins,
        sigma_d=sigma_d,
        window=window,
        epsilon=epsilon,
        fringes=fringes,
        pixel_size=pixel_size,
        fringe_options=dict(fringe_options or {}),
    )
    axes = tuple(int(a) for a in axes)
    if not axes or any(a not in (0, 1, 2) for a in axes) or len(set(axes)) != len(axes):
        raise InvalidParameter("axes", axes, "must be distinct values among 0, 1, 2")
    if not (isinstance(slice_step, int | np.integer) and slice_step >= 1):
        raise InvalidParameter("slice_step", slice_step, "must be a positive integer")
    if threshold is not None and not (
        isinstance(threshold, int | float | np.integer | np.floating) and 0.0 <= threshold <= 1.0
    ):
        raise InvalidParameter("threshold", threshold, "must be a grey level in [0, 1]")
    planes, isotropic = _volume_exemplars(exemplar, tuple(PLANES[a] for a in axes))
    vol = np.asarray(volume)
    if vol.ndim != 3:
        raise InvalidInput("volume", f"expected a grey (D, H, W) volume, got shape {vol.shape}")
    if not np.issubdtype(vol.dtype, np.floating):
        vol = vol.astype(np.float32)  # float32 holds every uint8/uint16/bool voxel exactly
    _check_volume_values(vol)
    if min(vol.shape) < MIN_SIDE:
        raise InvalidInput(
            "volume", f"volume of shape {vol.shape} is too small to evaluate (< {MIN_SIDE} voxels)"
        )

    # one queue for the threads: S2 (the longest single job: first, so that it does not end the queue on
    # one thread while the other waits), each exemplar's statistics (once, however many planes it serves),
    # the volume's moments (with every slice taken, each axis pools every voxel once: they are the
    # volume's), every axis's runs of slices; taken in that order, each axis compared as soon as its slices
    # are in, so the threads do not wait at the end of an axis
    threads = current_threads()
    views = {axis: np.moveaxis(vol, axis, 0)[::slice_step] for axis in axes}
    jobs: list[tuple[str, Any, Callable[[], Any]]] = []
    if s2:
        jobs.append(("s2", None, partial(_s2_comparisons, planes, vol, threshold, bool(s2_periodic))))
    jobs += [
        ("exemplar", key, partial(_exemplar_stats, ex, settings))
        for key, ex in {id(ex): ex for ex in planes.values()}.items()
    ]
    if slice_step == 1:
        jobs.append(("moments", None, partial(moments, vol)))
    jobs += [
        ("slices", axis, partial(_chunk_stats, views[axis][run.start : run.stop], settings))
        for axis in axes
        for run in _chunks(len(views[axis]), views[axis][0].size, threads)
    ]
    ref_stats: dict[int, ImageStats] = {}
    ref_moments: dict[int, dict[str, Any]] = {}
    volume_moments: dict[str, Any] | None = None
    correlations: dict[str, Any] = {}
    per_axis: dict[str, Any] = {}
    pooled_axes: list[ImageStats] = []
    values_axes: list[np.ndarray] = []
    total = sum(len(v) for v in views.values())
    results: dict[int, list[tuple[ImageStats, dict[str, Any]]]] = {axis: [] for axis in axes}
    done = 0
    for (kind, key, _), value in zip(jobs, _map_chunks(lambda job: job[2](), jobs), strict=True):
        if kind == "exemplar":
            ref_stats[key], ref_moments[key] = value
            continue
        if kind == "moments":
            volume_moments = value
            continue
        if kind == "s2":
            correlations = value
            continue
        axis = key
        results[axis].extend(value)
        done += len(value)
        if progress is not None and (done // 16 > (done - len(value)) // 16 or done == total):
            progress("evaluating the volume's slices", done / total)
        if len(results[axis]) < len(views[axis]):
            continue
        ex = planes[PLANES[axis]]
        ref = ref_stats[id(ex)]
        slices = list(views[axis])
        slice_stats = [stats for stats, _ in results[axis]]
        slice_moments = [moment for _, moment in results[axis]]
        results[axis] = []
        pooled = ImageStats.pool(slice_stats)
        pooled_moments = volume_moments if volume_moments is not None else moments(slices)
        block = compare_stats(ref, pooled, ref_moments[id(ex)], pooled_moments, settings)
        block["plane"] = PLANES[axis]
        block["slices"] = {
            "count": len(slice_stats),
            "grey_kl": _spread([kl_divergence(ref.grey, s.grey, settings.epsilon) for s in slice_stats]),
            "orientation_kl": _spread(
                [kl_divergence(ref.orientation, s.orientation, settings.epsilon) for s in slice_stats]
            ),
            "std": _spread([m["std"] for m in slice_moments]),
            "skewness": _spread([m["skewness"] for m in slice_moments]),
        }
        per_axis[str(axis)] = block
        pooled_axes.append(pooled)
        if volume_moments is None:
            values_axes.extend(slices)
    overall_moments = volume_moments if volume_moments is not None else moments(values_axes)
    if isotropic:
        one = next(iter(planes.values()))
        overall_ref, overall_ref_moments = ref_stats[id(one)], ref_moments[id(one)]
    else:
        used = [planes[PLANES[a]] for a in axes]
        overall_ref = ImageStats.pool(ref_stats[id(ex)] for ex in used)
        overall_ref_moments = moments(np.concatenate([ex.ravel() for ex in used]))
    overall = compare_stats(
        overall_ref, ImageStats.pool(pooled_axes), overall_ref_moments, overall_moments, settings
    )
    summary = dict(overall["summary"])
    record = {**settings.record(), "axes": list(axes), "slice_step": int(slice_step), "s2": None}
    result: dict[str, Any] = {"kind": "volume", "settings": record, "isotropic": isotropic}
    if s2:
        record["s2"] = _s2_settings(threshold, bool(s2_periodic))
        for axis in axes:
            plane = PLANES[axis]
            block = per_axis[str(axis)]
            block["s2"] = {
                name: {k: v for k, v in correlations["axes"][name][plane].items() if k != "s2"}
                for name in reversed(PLANE_AXES[plane])
            }
            block["summary"]["s2_relative_error"] = _mean(c["relative_error"] for c in block["s2"].values())
        summary["s2_relative_error"] = correlations["summary"]["mean"]
        result["s2"] = correlations
    summary["per_axis"] = {k: v["summary"] for k, v in per_axis.items()}
    first = planes[PLANES[axes[0]]]
    result.update(
        shape={
            "exemplar": list(first.shape),
            "exemplars": {p: list(ex.shape) for p, ex in planes.items()},
            "volume": list(vol.shape),
        },
        axes=per_axis,
        overall=overall,
        summary=summary,
    )
    return to_json_types(result)
