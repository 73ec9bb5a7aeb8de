"""Per-axis ``S2`` (texsynth.synth.evaluate.correlation) versus PoreSpy's direction-averaged default.

PoreSpy's ``porespy.metrics.two_point_correlation(im)`` (2.x) takes the periodic autocorrelation of the
whole image by FFT (``fftshift``, ``rfftn``, ``|F|^2``, ``irfftn``), averages it over rings
``r - 1 < |d| <= r`` of every direction ``d`` (one-pixel bins up to half the shorter side), divides by
its maximum and multiplies by the phase fraction (``probability_scaled``). texsynth's ``S2`` is per
axis. This script re-types PoreSpy's steps in numpy (PoreSpy is not a dependency; with it installed,
``--porespy`` runs the real function too) and prints, at small ``r``:

- ours along rows and columns, and with ``periodic=True``;
- PoreSpy's FFT autocorrelation run line by line (each row, or column, as its own 1-D image),
  summed over lines and divided by ``N L``: equal to ours with ``periodic=True``;
- PoreSpy's default, and how far it is from each axis.

Usage: ``python -m benchmarks.s2_porespy [IMAGE ...]`` (default: the shared HRTEM exemplars and a level
cut of a Gaussian random field). Figures: docs/evaluation.md, "Two-point correlation and PoreSpy".
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import fft, ndimage

from texsynth.synth.evaluate.correlation import binarize, two_point_correlation
from texsynth.synth.io import load_image

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


def porespy_default(phase: np.ndarray) -> np.ndarray:
    """PoreSpy's ``two_point_correlation(phase).probability_scaled`` at r = 1, 2, ... (bins of 1 px)."""
    im = phase.astype(np.float64)
    power = np.abs(fft.ifftshift(fft.rfftn(fft.fftshift(im))) ** 2)
    autoc = np.abs(fft.ifftshift(fft.irfftn(fft.fftshift(power), s=im.shape)))
    centre = np.round(np.array(im.shape) / 2)
    offsets = np.indices(im.shape) - centre.reshape(-1, 1, 1)
    dist = np.sqrt((offsets**2).sum(axis=0))
    r_max = int(np.ceil(min(im.shape)) / 2)
    ring_means = [
        float(
            np.sum(autoc[(dist <= r) & (dist > r - 1)].astype(np.int64))
            / np.sum((dist <= r) & (dist > r - 1))
        )
        for r in range(1, r_max + 1)
    ]
    return np.array([float(autoc.max()), *ring_means]) / autoc.max() * phase.mean()


def porespy_line_by_line(phase: np.ndarray, axis: int) -> np.ndarray:
    """PoreSpy's FFT autocorrelation of every line along ``axis`` (``rfftn``/``irfftn`` of a 1-D image),
    summed over the lines and divided by ``N L``: the periodic per-axis ``S2``."""
    lines = np.moveaxis(phase.astype(np.float64), axis, -1).reshape(-1, phase.shape[axis])
    n = lines.shape[1]
    total = np.zeros(n)
    for line in lines:
        power = np.abs(fft.rfftn(line) ** 2)
        total += np.abs(fft.irfftn(power, s=(n,)))
    return total / (n * lines.shape[0])


def _grf(shape: tuple[int, int], seed: int = 0) -> np.ndarray:
    noise = np.random.default_rng(seed).standard_normal(shape)
    return ndimage.gaussian_filter(noise, (2.0, 5.0), mode="wrap")  # elongated along x


def main(argv: list[str]) -> None:
    use_porespy = "--porespy" in argv
    paths = [a for a in argv if a != "--porespy"]
    sources = {Path(p).name: load_image(p, mode="grey") for p in paths} or {
        **{p.name: load_image(p, mode="grey") for p in sorted(SHARED.glob("hrtem-soot-*.png"))},
        "grf-level-cut-256 (sigma 2 x 5)": _grf((256, 256)),
    }
    for name, grey in sources.items():
        phase = binarize(grey)
        rows = two_point_correlation(phase, 0)
        cols = two_point_correlation(phase, 1)
        rows_p = two_point_correlation(phase, 0, periodic=True)
        cols_p = two_point_correlation(phase, 1, periodic=True)
        default = porespy_default(phase)
        lbl = max(
            np.abs(porespy_line_by_line(phase, 0)[: len(rows_p)] - rows_p).max(),
            np.abs(porespy_line_by_line(phase, 1)[: len(cols_p)] - cols_p).max(),
        )
        print(f"{name}: shape {phase.shape}, phi {phase.mean():.4f}")
        print(f"  line by line vs ours periodic=True: max |difference| {lbl:.1e}")
        print("  r   S2 rows   S2 cols   rows(per) cols(per)  PoreSpy avg  avg/rows-1  avg/cols-1")
        for r in range(1, 6):
            print(
                f"  {r}   {rows[r]:.5f}   {cols[r]:.5f}   {rows_p[r]:.5f}   {cols_p[r]:.5f}"
                f"    {default[r]:.5f}      {default[r] / rows[r] - 1:+.3f}"
                f"      {default[r] / cols[r] - 1:+.3f}"
            )
        if use_porespy:
            import porespy

            real = porespy.metrics.two_point_correlation(phase).probability_scaled
            print(f"  porespy itself: {np.round(real[:5], 5)}")


if __name__ == "__main__":
    main(sys.argv[1:])
