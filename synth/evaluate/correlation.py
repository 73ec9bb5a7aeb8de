"""Two-point correlation ``S2(r)`` of two-phase images and volumes, along each axis.

``S2(r)`` is the probability that two points a distance ``r`` apart, along a given axis, both lie in
phase 1 (Torquato 2002, chapter 2): the descriptor materials scientists compare microstructures with.
Its known values frame every test of this module: ``S2(0) = phi`` (the volume fraction); ``S2(r) ->
phi^2`` without long-range order; periodic for a periodic medium; a closed form for a level cut of a
Gaussian random field (:func:`level_cut_s2`; Berk 1987, Teubner 1991, Torquato 2002 section 2.5.4).

How: phase 1 is ``grey >= threshold`` (by default Otsu's, :func:`otsu_threshold`; an evaluation cuts
the exemplar and the output at the exemplar's). ``S2`` along an axis is averaged over every line
parallel to it by the Wiener-Khinchin theorem (the FFT of each line, ``|.|^2``, transformed back):
``periodic=True`` wraps lags round (a toroidal synthesis); by default each line is zero-padded so no
pair wraps and lag ``r`` is divided by its own number of pairs, ``L (N - r)``. The sums are counts of
pairs, rounded to integers before the division (exact results); lines go in chunks, so a 512^3 volume
needs a small multiple of its own size in memory (docs/design.md, "two-point correlation").

References
----------
S. Torquato, *Random Heterogeneous Materials: Microstructure and Macroscopic Properties*, Springer,
New York, 2002, chapter 2, section 2.5.4. M. Teubner, "Level surfaces of Gaussian random fields and
microemulsions", Europhys. Lett. 14(5), 1991, 403-408. N. F. Berk, "Scattering properties of a model
bicontinuous structure with a well defined length scale", Phys. Rev. Lett. 58(25), 1987, 2718-2721.
N. Otsu, "A threshold selection method from gray-level histograms", IEEE Trans. SMC 9(1), 1979, 62-66.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import fft

from texsynth.synth.errors import InvalidInput, InvalidParameter

__all__ = [
    "IMAGE_DIRECTIONS",
    "VOLUME_DIRECTIONS",
    "binarize",
    "compare_s2",
    "correlation_length",
    "image_s2",
    "level_cut_s2",
    "otsu_threshold",
    "two_point_correlation",
    "volume_s2",
]

#: Directions of an image's ``S2``: ``'col'`` pairs points ``r`` columns apart on one row (the image's
#: ``x``), ``'row'`` pairs points ``r`` rows apart in one column (``y``, or ``z`` for ``xz``/``yz`` planes).
IMAGE_DIRECTIONS: dict[str, int] = {"row": 0, "col": 1}
#: Directions of a volume's ``S2``, named by the physical axis of ``(D, H, W) = (z, y, x)``.
VOLUME_DIRECTIONS: dict[str, int] = {"z": 0, "y": 1, "x": 2}
#: Samples transformed at once: bounds the memory of the FFTs (about 100 MB of complex128).
_CHUNK_SAMPLES = 1 << 22


def otsu_threshold(image: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold of a grey image or volume: the grey level that best splits it into two classes.

    The histogram (``bins`` equal bins over the data's range) is split where the between-class
    variance ``w0 w1 (m0 - m1)^2`` is largest (Otsu 1979). Where several splits tie, as they do across
    an empty gap between two grey levels, the middle one is taken, so that a two-level image is cut
    half-way between its levels rather than at the top of the darker one. The threshold returned is
    the bin edge of the split, so ``grey >= threshold`` is exactly Otsu's upper class. A constant array
    has no split: its value is returned (the whole array is then phase 1).

    Examples
    --------
    >>> otsu_threshold([[0.0, 1.0], [1.0, 0.0]])
    0.5
    """
    arr = np.asarray(image, dtype=np.float64)
    if arr.size == 0 or not np.isfinite(arr).all():
        raise InvalidInput("image", "is empty or holds NaN/inf values: no threshold")
    lo, hi = float(arr.min()), float(arr.max())
    if not hi > lo:
        return lo
    counts, edges = np.histogram(arr, bins=bins, range=(lo, hi))
    centres = (edges[:-1] + edges[1:]) / 2
    w0 = np.cumsum(counts)[:-1].astype(np.float64)
    w1 = arr.size - w0
    s0 = np.cumsum(counts * centres)[:-1]
    s1 = float(np.sum(counts * centres)) - s0
    with np.errstate(divide="ignore", invalid="ignore"):
        between = np.where((w0 > 0) & (w1 > 0), w0 * w1 * (s0 / w0 - s1 / w1) ** 2, 0.0)
    best = np.flatnonzero(between >= between.max() * (1.0 - 1e-12))
    return float(edges[best[len(best) // 2] + 1])


def binarize(image: np.ndarray, threshold: float | None = None) -> np.ndarray:
    """Phase 1 of a grey array: ``image >= threshold`` (bool), Otsu's threshold when ``None``.

    A bool array is returned as it is (``threshold`` must then be ``None``).
    """
    arr = np.asarray(image)
    if arr.dtype == bool:
        if threshold is not None:
            raise InvalidParameter(
                "threshold", threshold, "a bool array is already two-phase: give no threshold"
            )
        return arr
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise InvalidInput("image", f"array of dtype {arr.dtype} is not a grey image")
    if threshold is None:
        threshold = otsu_threshold(arr)
    if not (isinstance(threshold, int | float | np.integer | np.floating) and math.isfinite(threshold)):
        raise InvalidParameter("threshold", threshold, "must be a finite grey level")
    return arr >= np.float64(threshold)  # in float64 whatever the array's float type (NEP 50)


def _max_lag(max_lag: int | None, n: int) -> int:
    if max_lag is None:
        return n // 2
    if isinstance(max_lag, bool) or not isinstance(max_lag, int | np.integer) or not 0 <= max_lag < n:
        raise InvalidParameter(
            "max_lag", max_lag, f"must be an integer in [0, {n - 1}] (the line length is {n})"
        )
    return int(max_lag)


def two_point_correlation(
    phase: np.ndarray, axis: int, *, periodic: bool = False, max_lag: int | None = None
) -> np.ndarray:
    """``S2(r)`` along one axis of a two-phase array, averaged over all lines parallel to that axis.

    Parameters
    ----------
    phase : ndarray of bool or of 0/1, any number of dimensions
        The indicator of phase 1 (:func:`binarize` makes one from a grey image).
    axis : int
        The axis along which the two points are separated.
    periodic : bool
        ``True``: lines wrap round (a toroidal sample, ``N`` pairs per line at every lag);
        ``False``: no wrap, lag ``r`` averaged over its ``N - r`` pairs per line (module notes).
    max_lag : int, optional
        Largest lag, below the line length ``N``; default ``N // 2``.

    Returns
    -------
    ndarray, shape (max_lag + 1,), float64
        ``S2(r)`` for ``r = 0, 1, ..., max_lag``; ``S2(0)`` is the volume fraction.

    Notes
    -----
    ``S2(r) = <f(x) f(x + r e_axis)>`` (Torquato 2002, eq. 2.13, restricted to one axis), computed as
    the inverse FFT of the line-summed power spectrum (Wiener-Khinchin), divided by the number of pairs.

    Examples
    --------
    >>> import numpy as np
    >>> board = np.indices((8, 8)).sum(axis=0) % 2       # a checkerboard
    >>> two_point_correlation(board, 1, max_lag=3).tolist()
    [0.5, 0.0, 0.5, 0.0]
    """
    arr = np.asarray(phase)
    if arr.ndim == 0 or arr.size == 0:
        raise InvalidInput("phase", f"array of shape {arr.shape} has no lines to correlate")
    if arr.dtype != bool:
        if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
            raise InvalidInput("phase", f"array of dtype {arr.dtype} is not a two-phase indicator")
        if not np.isin(arr, (0, 1)).all():
            raise InvalidInput("phase", "must hold only 0 and 1 (threshold a grey image with binarize)")
    if isinstance(axis, bool) or not isinstance(axis, int | np.integer) or not -arr.ndim <= axis < arr.ndim:
        raise InvalidParameter("axis", axis, f"must be an axis of the {arr.ndim}-D array")
    lines = np.moveaxis(arr, int(axis), -1)
    n = lines.shape[-1]
    lag = _max_lag(max_lag, n)
    lines = lines.reshape(-1, n)
    lines = lines.view(np.uint8) if lines.dtype == bool else lines.astype(np.uint8, copy=False)
    n_fft = n if periodic else fft.next_fast_len(n + lag, real=True)
    power = np.zeros(n_fft // 2 + 1, dtype=np.float64)
    step = max(1, _CHUNK_SAMPLES // n_fft)
    for start in range(0, lines.shape[0], step):
        spectrum = fft.rfft(lines[start : start + step].astype(np.float64), n=n_fft, axis=-1)
        power += np.sum(spectrum.real**2 + spectrum.imag**2, axis=0)
    pairs = np.rint(fft.irfft(power, n=n_fft)[: lag + 1])  # integer counts of phase-1 pairs
    per_line = np.full(lag + 1, float(n)) if periodic else n - np.arange(lag + 1, dtype=np.float64)
    return pairs / (per_line * lines.shape[0])


def _phase(array: np.ndarray, threshold: float | None, ndim: int, name: str) -> np.ndarray:
    arr = np.asarray(array)
    if arr.ndim != ndim:
        shape = "(H, W) image" if ndim == 2 else "(D, H, W) volume"
        raise InvalidInput(name, f"expected a grey {shape}, got shape {arr.shape}")
    if threshold is None and (arr.dtype == bool or np.isin(arr, (0, 1)).all()):
        return arr.astype(bool, copy=False)
    return binarize(arr, threshold)


def image_s2(
    image: np.ndarray,
    *,
    threshold: float | None = None,
    periodic: bool = False,
    max_lag: int | None = None,
) -> dict[str, np.ndarray]:
    """``S2`` of a 2-D image along its rows and its columns.

    Parameters
    ----------
    image : ndarray, shape (H, W)
        Grey levels (thresholded: phase 1 is ``image >= threshold``) or a two-phase image (bool, or
        only 0 and 1, taken as it is when ``threshold`` is ``None``).
    threshold : float, optional
        Grey level of the phase boundary; Otsu's threshold of ``image`` when ``None`` (grey input).
    periodic, max_lag
        As in :func:`two_point_correlation` (``max_lag`` is capped at each axis's ``N // 2`` when ``None``).

    Returns
    -------
    dict
        ``{'col': S2 of points r columns apart (along x), 'row': S2 of points r rows apart}``.
    """
    ph = _phase(image, threshold, 2, "image")
    return {
        name: two_point_correlation(ph, axis, periodic=periodic, max_lag=max_lag)
        for name, axis in IMAGE_DIRECTIONS.items()
    }


def volume_s2(
    volume: np.ndarray,
    *,
    threshold: float | None = None,
    periodic: bool = False,
    max_lag: int | None = None,
) -> dict[str, np.ndarray]:
    """``S2`` of a ``(D, H, W)`` volume along ``z``, ``y`` and ``x``, each averaged over all lines.

    Parameters
    ----------
    volume : ndarray, shape (D, H, W)
        Grey levels or a two-phase volume, as ``image`` in :func:`image_s2`.
    threshold, periodic, max_lag
        As in :func:`image_s2`.

    Returns
    -------
    dict
        ``{'z': S2 along axis 0, 'y': along axis 1, 'x': along axis 2}``.
    """
    ph = _phase(volume, threshold, 3, "volume")
    return {
        name: two_point_correlation(ph, axis, periodic=periodic, max_lag=max_lag)
        for name, axis in VOLUME_DIRECTIONS.items()
    }


def correlation_length(s2: np.ndarray) -> int | None:
    """The first lag ``r`` where ``S2(r) - phi^2`` falls below ``1/e`` of ``S2(0) - phi^2``.

    ``phi = S2(0)``, so ``S2(0) - phi^2 = phi (1 - phi)`` is the variance of the phase indicator and
    ``(S2(r) - phi^2) / (phi (1 - phi))`` its autocorrelation coefficient: this is where that
    coefficient first drops below ``1/e`` (the e-folding length of an exponential ``S2``, Debye's
    random medium; Torquato 2002, eq. 2.25).

    Returns
    -------
    int or None
        ``None`` for a one-phase sample (``phi`` 0 or 1) or when the curve never falls that low
        within the lags given (long-range order, or lags too short).

    Examples
    --------
    >>> import numpy as np
    >>> phi = 0.5
    >>> s2 = phi**2 + phi * (1 - phi) * np.exp(-np.arange(20) / 4.0)   # Debye medium, length 4
    >>> correlation_length(s2)
    5
    """
    s = np.asarray(s2, dtype=np.float64)
    if s.ndim != 1 or s.size == 0:
        raise InvalidParameter("s2", f"array of shape {s.shape}", "must be a 1-D curve S2(r), r = 0, 1, ...")
    phi = s[0]
    excess0 = phi - phi * phi
    if not excess0 > 1e-12:
        return None
    below = np.flatnonzero(s[1:] - phi * phi < excess0 / math.e)
    return int(below[0]) + 1 if below.size else None


def compare_s2(exemplar: np.ndarray, output: np.ndarray) -> dict[str, Any]:
    """How far an output's ``S2`` curve is from the exemplar's, up to the exemplar's correlation length.

    Parameters
    ----------
    exemplar, output : ndarray, shape (n,) and (m,)
        ``S2(r)`` from ``r = 0``; compared over their common lags.

    Returns
    -------
    dict
        ``{"volume_fraction": {"exemplar", "output"}, "correlation_length": {"exemplar", "output"},
        "window": R, "relative_error", "max_abs_error"}`` where, over ``r = 0 .. R``,
        ``relative_error = sum |S2_out - S2_ex| / sum S2_ex`` (``None`` when the exemplar has no phase 1)
        and ``max_abs_error = max |S2_out - S2_ex|``. ``R`` is the exemplar's correlation length, or the
        last common lag when that is undefined or beyond it.

    Notes
    -----
    An L1 error relative to the exemplar's curve: unlike a pointwise ratio it is defined where ``S2`` is
    0 (a checkerboard's odd lags) and weighs each lag by the probability it describes. Including ``r = 0``
    counts a wrong volume fraction; stopping at the correlation length keeps the comparison to the
    lags that hold structure, before both curves flatten at ``phi^2``.
    """
    ex, out = np.asarray(exemplar, dtype=np.float64), np.asarray(output, dtype=np.float64)
    if ex.ndim != 1 or out.ndim != 1 or ex.size == 0 or out.size == 0:
        raise InvalidParameter("s2", (ex.shape, out.shape), "must be two non-empty 1-D curves")
    common = min(ex.size, out.size)
    length = correlation_length(ex)
    window = length if length is not None and length < common else common - 1
    e, o = ex[: window + 1], out[: window + 1]
    total = float(e.sum())
    return {
        "volume_fraction": {"exemplar": float(ex[0]), "output": float(out[0])},
        "correlation_length": {"exemplar": length, "output": correlation_length(out)},
        "window": int(window),
        "relative_error": float(np.abs(o - e).sum() / total) if total > 0 else None,
        "max_abs_error": float(np.abs(o - e).max()),
    }


def level_cut_s2(lags: np.ndarray, correlation_length: float, volume_fraction: float) -> np.ndarray:
    """Exact ``S2(r)`` of a level-cut Gaussian random field with correlation ``rho(r) = exp(-r^2 / l^2)``.

    Phase 1 is where a stationary standard Gaussian field exceeds ``t = Phi^-1(1 - phi)``; then
    (Berk 1987; Teubner 1991; Torquato 2002, section 2.5.4)::

        S2(r) = phi^2 + 1/(2 pi) * integral_0^rho(r) exp(-t^2 / (1 + x)) / sqrt(1 - x^2) dx

    Parameters
    ----------
    lags : array_like
        Distances ``r`` (pixels), non-negative.
    correlation_length : float
        ``l`` of the field's Gaussian correlation (:func:`texsynth.synth.io.patterns.gaussian_random_field`).
    volume_fraction : float
        ``phi`` in (0, 1).

    Returns
    -------
    ndarray
        ``S2`` at each lag; ``S2(0) = phi`` and ``S2 -> phi^2`` far away.

    Examples
    --------
    >>> round(float(level_cut_s2([0.0], 3.0, 0.5)[0]), 6)
    0.5
    """
    from scipy import integrate, special  # here only: they load scipy.optimize, which no command needs

    r = np.asarray(lags, dtype=np.float64)
    if not (math.isfinite(correlation_length) and correlation_length > 0):
        raise InvalidParameter(
            "correlation_length", correlation_length, "must be a positive length in pixels"
        )
    if not 0 < volume_fraction < 1:
        raise InvalidParameter("volume_fraction", volume_fraction, "must lie strictly between 0 and 1")
    t = float(special.ndtri(1.0 - volume_fraction))
    rho = np.exp(-((r / correlation_length) ** 2))

    def excess(upper: float) -> float:
        # substitute x = sin(u): the integrand loses its 1/sqrt(1 - x^2) singularity at x = 1
        value, _ = integrate.quad(lambda u: math.exp(-t * t / (1.0 + math.sin(u))), 0.0, math.asin(upper))
        return value / (2.0 * math.pi)

    flat = [volume_fraction**2 + excess(float(p)) for p in rho.ravel()]
    return np.asarray(flat, dtype=np.float64).reshape(r.shape)
