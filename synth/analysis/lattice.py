"""Does an image show lattice fringes? Two measures, so that fringe statistics are shown only where
they mean something (issue 27: brick's "fringe length KS 0.667" came from its 3 mortar joints).

HRTEM lattice fringes of carbon are many short dark lines, nearly parallel to their neighbours at an
almost constant spacing (0.34 nm: about 6 px at 18 px/nm). Two numbers say it:

- ``density_per_10k_px``: fringes per 10 000 pixels that
  :func:`texsynth.synth.analysis.fringes.extract_fringes` finds with its defaults (a few mortar joints or
  straw edges are not a lattice);
- ``peak_ratio``: the radially averaged power spectrum's highest point between periods of
  :data:`PERIOD_RANGE` pixels over a power law fitted to the whole spectrum (``P(k) ~ a k^b``, least
  squares in log-log, radii 2 to N/2), with the period where it lies: a near-periodic stack of fringes
  rises far above the smooth decay of natural textures (grass, gravel: 2-4; soot: 13-30).

:func:`texsynth.synth.evaluate.glossary.fringes_shown` turns them into a yes or no with the thresholds it
documents; the measurements behind them are in docs/evaluation.md ("Which exemplars have fringes").
"""

from __future__ import annotations

import numpy as np

from texsynth.synth.analysis.fringes import extract_fringes

__all__ = ["PERIOD_RANGE", "fringe_presence", "spectral_peak"]

#: Periods (pixels) where lattice fringes are looked for: 3 px is the finest a fringe can be drawn with,
#: 16 px covers HRTEM at 2.5 times the usual magnification.
PERIOD_RANGE: tuple[float, float] = (3.0, 16.0)


def spectral_peak(image: np.ndarray) -> tuple[float, float | None]:
    """``(peak_ratio, period_px)``: the radially averaged power spectrum's highest point in
    :data:`PERIOD_RANGE` over a power law fitted to the spectrum (module docstring); ``(0.0, None)``
    for an image too small (a side below 32 px) or flat."""
    grey = np.asarray(image, dtype=np.float64)
    side = min(grey.shape[:2])
    if grey.ndim != 2 or side < 32 or not np.ptp(grey) > 0:
        return 0.0, None
    h, w = grey.shape
    window = np.outer(np.hanning(h), np.hanning(w))
    power = np.abs(np.fft.fftshift(np.fft.fft2((grey - grey.mean()) * window))) ** 2
    yy, xx = np.indices(power.shape)
    radius = np.round(np.hypot(yy - h // 2, xx - w // 2)).astype(np.int64).ravel()
    profile = np.bincount(radius, power.ravel()) / np.maximum(np.bincount(radius), 1)
    profile = profile[: side // 2]
    k = np.arange(len(profile), dtype=np.float64)
    slope, intercept = np.polyfit(np.log(k[2:]), np.log(profile[2:] + 1e-30), 1)
    lo, hi = int(np.ceil(side / PERIOD_RANGE[1])), int(np.floor(side / PERIOD_RANGE[0]))
    hi = min(hi, len(profile) - 1)
    band = np.arange(lo, hi + 1)
    ratio = profile[band] / np.exp(intercept + slope * np.log(band))
    best = int(np.argmax(ratio))
    return float(ratio[best]), float(side / band[best])


def fringe_presence(image: np.ndarray) -> dict[str, float | int | None]:
    """The two measures of the module docstring, and the fringe count, of a grey image in [0, 1]."""
    grey = np.asarray(image, dtype=np.float32)
    fringes = extract_fringes(grey)
    count = len(fringes.lengths)
    ratio, period = spectral_peak(grey)
    return {
        "count": count,
        "density_per_10k_px": 10_000.0 * count / grey.size,
        "peak_ratio": ratio,
        "peak_period_px": period,
    }
