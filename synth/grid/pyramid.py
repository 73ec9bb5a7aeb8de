"""Gaussian pyramids of images and tensor fields (smooth, then subsample 2:1).

Level 0 is the finest. Tensor fields are pyramided component by component: a Gaussian average of
positive semi-definite tensors stays positive semi-definite (Akl 2014, section 2).
"""

from __future__ import annotations

import numpy as np
from skimage.transform import pyramid_reduce

__all__ = ["gaussian_pyramid", "level_shapes"]


def gaussian_pyramid(
    image: np.ndarray, levels: int, *, mode: str = "reflect", volume: bool = False
) -> list[np.ndarray]:
    """``levels`` arrays, finest first; an ``(H, W, C)`` array is reduced channel by channel.

    Uses :func:`skimage.transform.pyramid_reduce` (downscale 2, its default ``sigma = 2/3``).
    ``mode='wrap'`` for toroidal images. Every level is C-contiguous float32. With ``volume=True``
    the array is a volume ``(D, H, W)`` (or ``(D, H, W, C)``) reduced along its three axes.
    """
    spatial = 3 if volume else 2
    out = [np.ascontiguousarray(image, dtype=np.float32)]
    for _ in range(levels - 1):
        prev = out[-1]
        reduced = pyramid_reduce(
            prev,
            downscale=2,
            channel_axis=-1 if prev.ndim > spatial else None,
            mode=mode,
            preserve_range=True,
        )
        out.append(np.ascontiguousarray(reduced, dtype=np.float32))
    return out


def level_shapes(shape: tuple[int, int], levels: int) -> list[tuple[int, int]]:
    """Shapes of a pyramid's levels, finest first (each side halved, rounded up, as pyramid_reduce)."""
    shapes = [tuple(shape)]
    for _ in range(levels - 1):
        shapes.append(tuple(int(np.ceil(s / 2)) for s in shapes[-1]))
    return shapes  # type: ignore[return-value]
