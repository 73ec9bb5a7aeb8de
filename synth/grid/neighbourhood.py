"""Neighbourhood shapes: the offsets around a pixel that a search compares.

Wei & Levoy (2000) compare a **causal L-shaped** neighbourhood (the rows above and the pixels to
the left: everything a lexicographic scan has already produced) or, with a random walk, a
**square** non-causal one. Offsets are ``(d_row, d_col)`` pairs; the centre is never included in a
same-level neighbourhood (it is the pixel being chosen) and always included in a parent-level one.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from texsynth.synth.errors import InvalidParameter

__all__ = ["Shape", "neighbourhood_offsets", "parent_offsets"]

Shape = Literal["causal", "square"]


def _check_size(size: int, name: str) -> int:
    if not isinstance(size, int | np.integer) or size < 3 or size % 2 == 0:
        raise InvalidParameter(name, size, "must be an odd integer >= 3")
    return int(size)


def neighbourhood_offsets(size: int, shape: Shape = "causal") -> np.ndarray:
    """Offsets ``(K, 2)`` int32 of a ``size x size`` neighbourhood, centre excluded.

    ``'causal'`` keeps the ``(size*size - 1) / 2`` offsets that precede the centre in raster
    order (rows above, then the pixels to the left on the centre's row); ``'square'`` keeps all
    ``size*size - 1``.

    >>> neighbourhood_offsets(3, "causal").tolist()
    [[-1, -1], [-1, 0], [-1, 1], [0, -1]]
    """
    size = _check_size(size, "neighbourhood_size")
    r = size // 2
    rows, cols = np.mgrid[-r : r + 1, -r : r + 1]
    offsets = np.stack([rows.ravel(), cols.ravel()], axis=1)
    raster = offsets[:, 0] * size + offsets[:, 1]
    if shape == "causal":
        keep = raster < 0
    elif shape == "square":
        keep = raster != 0
    else:
        raise InvalidParameter("neighbourhood", shape, "must be 'causal' or 'square'")
    return np.ascontiguousarray(offsets[keep], dtype=np.int32)


def parent_offsets(size: int) -> np.ndarray:
    """Offsets ``(size*size, 2)`` of the full square parent-level neighbourhood, centre included."""
    size = _check_size(size, "parent_size")
    r = size // 2
    rows, cols = np.mgrid[-r : r + 1, -r : r + 1]
    return np.ascontiguousarray(np.stack([rows.ravel(), cols.ravel()], axis=1), dtype=np.int32)
