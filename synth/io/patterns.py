"""Generated test patterns: fringes with known orientation fields.

Exemplars with long-range orientation variation (the case where Wei-Levoy comes out too regular,
Akl 2014) and constraint images (waves, concentric rings, spirals) for arbitrary-shape synthesis.
Each returns a float32 image in [0, 1] of laminae of period ``period`` pixels, whose *fringe*
direction is known in closed form, so tests and benchmarks can vary them freely.
"""

from __future__ import annotations

import numpy as np

__all__ = ["concentric_rings", "grating", "spiral", "undulating_laminae", "waves"]


def _coords(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates with ``x`` to the right and ``y`` up (ALGORITHMS.md)."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return cols, -rows


def _finish(phase: np.ndarray, noise: float, seed: int) -> np.ndarray:
    img = 0.5 + 0.5 * np.cos(phase)
    if noise > 0:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    img = (img - img.min()) / max(img.max() - img.min(), 1e-12)
    return img.astype(np.float32)


def grating(
    shape: tuple[int, int], angle: float, period: float = 8.0, *, noise: float = 0.0, seed: int = 0
) -> np.ndarray:
    """Straight fringes whose *gradient* points at ``angle`` (radians, counter-clockwise from +x)."""
    x, y = _coords(shape)
    return _finish(2 * np.pi * (x * np.cos(angle) + y * np.sin(angle)) / period, noise, seed)


def undulating_laminae(
    shape: tuple[int, int],
    period: float = 8.0,
    amplitude: float = 10.0,
    wavelength: float = 64.0,
    *,
    noise: float = 0.15,
    seed: int = 0,
) -> np.ndarray:
    """Horizontal laminae bent by a sine of ``amplitude`` px over ``wavelength`` px (curved fringes)."""
    x, y = _coords(shape)
    return _finish(2 * np.pi * (y + amplitude * np.sin(2 * np.pi * x / wavelength)) / period, noise, seed)


def waves(
    shape: tuple[int, int],
    period: float = 8.0,
    amplitude: float = 16.0,
    wavelength: float = 128.0,
    *,
    noise: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """A wave constraint: the same bent laminae, larger and without noise by default."""
    return undulating_laminae(shape, period, amplitude, wavelength, noise=noise, seed=seed)


def concentric_rings(
    shape: tuple[int, int],
    period: float = 8.0,
    centre: tuple[float, float] | None = None,
    *,
    noise: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """Rings around ``centre`` (row, col; default the middle): fringes run tangentially."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    cy, cx = centre if centre is not None else ((shape[0] - 1) / 2, (shape[1] - 1) / 2)
    return _finish(2 * np.pi * np.hypot(rows - cy, cols - cx) / period, noise, seed)


def spiral(
    shape: tuple[int, int], period: float = 8.0, arms: int = 1, *, noise: float = 0.0, seed: int = 0
) -> np.ndarray:
    """An Archimedean spiral of ``arms`` arms and radial period ``period``."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    dy, dx = rows - (shape[0] - 1) / 2, cols - (shape[1] - 1) / 2
    return _finish(2 * np.pi * np.hypot(dy, dx) / period + arms * np.arctan2(-dy, dx), noise, seed)
