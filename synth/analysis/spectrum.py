"""The dominant period of fringes, from the radially averaged power spectrum of an image or a volume.

Lattice fringes (HRTEM of graphitic carbon: 0.34 nm, about 6 px at 18 px/nm) put a ring (a shell in 3D)
of power at the spatial frequency ``1 / period`` whatever their orientation. The period is read at the
peak of the power summed over rings (shells) of equal ``|k|`` (bins one frequency step wide: the power
per unit of ``|k|``, which does not favour the few lowest frequencies as a ring *mean* does), refined
as the power-weighted mean ``|k|`` of the frequencies within a factor 1.4 of the peak's (a broad
ring, as crumpled sheets give, is read at its centre of mass rather than at its noisiest bin);
frequencies below three cycles per sample are ignored (the mean and slow shading). A known answer for
the generators of :mod:`texsynth.synth.io.laminar`, and a scale to express neighbourhoods in periods.
"""

from __future__ import annotations

import numpy as np

from texsynth.synth.errors import InvalidInput

__all__ = ["dominant_period", "radial_power_spectrum"]

#: The refinement's band around the peak frequency: from ``f / _BAND`` to ``f * _BAND``.
_BAND = 1.4


def _checked(array: np.ndarray) -> np.ndarray:
    arr = np.asarray(array, dtype=np.float64)
    if arr.ndim not in (2, 3) or min(arr.shape) < 8:
        raise InvalidInput(
            "image", f"expected a grey image or volume, every side >= 8; got shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise InvalidInput("image", "contains NaN or infinite values")
    return arr


def _spectrum(array: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(|k| of every rfft sample, its power, the bin step 1 / min(shape))``."""
    arr = _checked(array)
    arr = arr - arr.mean()
    for axis, n in enumerate(arr.shape):
        arr = arr * np.hanning(n).reshape([-1 if k == axis else 1 for k in range(arr.ndim)])
    power = np.abs(np.fft.rfftn(arr)) ** 2
    # rfft keeps half of the last axis: its inner columns stand for two samples each
    twice = np.full(power.shape[-1], 2.0)
    twice[0] = 1.0
    if arr.shape[-1] % 2 == 0:
        twice[-1] = 1.0
    power = power * twice
    freqs = [np.fft.fftfreq(n) for n in arr.shape[:-1]] + [np.fft.rfftfreq(arr.shape[-1])]
    grids = np.meshgrid(*freqs, indexing="ij", sparse=True)
    radius = np.sqrt(sum(g**2 for g in grids))
    return radius.ravel(), power.ravel(), 1.0 / min(arr.shape)


def radial_power_spectrum(array: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Power summed over rings (shells) of equal frequency: ``(frequencies, power)``.

    Parameters
    ----------
    array : ndarray, shape (H, W) or (D, H, W)
        Grey values; the mean is removed and a Hann window applied along every axis first.

    Returns
    -------
    frequencies : ndarray
        Bin centres, cycles per pixel, from 0 to 0.5 in steps of ``1 / min(shape)``.
    power : ndarray
        Sum of ``|F(k)|^2`` over the frequencies ``k`` of each bin, over the whole spectrum.
    """
    radius, power, step = _spectrum(array)
    bins = np.rint(radius / step).astype(np.int64)
    n_bins = round(0.5 / step) + 1
    keep = bins < n_bins
    total = np.bincount(bins[keep], weights=power[keep], minlength=n_bins)
    return np.arange(n_bins) * step, total


def dominant_period(array: np.ndarray) -> float:
    """The period, pixels, of the strongest ring of the radial power spectrum (fringe spacing).

    Examples
    --------
    >>> from texsynth.synth.io.patterns import grating
    >>> round(dominant_period(grating((64, 64), 0.3, period=6.0)), 1)
    6.0
    """
    radius, power, step = _spectrum(array)
    bins = np.rint(radius / step).astype(np.int64)
    n_bins = round(0.5 / step) + 1
    keep = bins < n_bins
    total = np.bincount(bins[keep], weights=power[keep], minlength=n_bins)
    low = 3  # at least three cycles across the shortest side
    if not np.any(total[low:] > 0):
        raise InvalidInput("image", "has no fringes: its power spectrum is flat")
    peak = low + int(np.argmax(total[low:]))
    near = (radius >= peak * step / _BAND) & (radius <= peak * step * _BAND)
    centre = float(np.sum(radius[near] * power[near]) / np.sum(power[near]))
    return 1.0 / centre
