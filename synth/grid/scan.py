"""Scan orders: the sequence in which pixels (2D) or voxels (3D) are synthesized.

Four orders, as compared by the volumetric-synthesis study: ``lexicographic`` (raster),
``random`` (a random walk: a seeded permutation), and the space-filling ``morton`` (Z-order) and
``hilbert`` curves, which keep successive positions close in every dimension. Every order is
returned as flat (C-order) indices into an array of the given shape.

References
----------
J. Skilling, "Programming the Hilbert curve", AIP Conf. Proc. 707, 381 (2004): the transpose
representation and its conversion to axes, used here for n-dimensional Hilbert indices.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from texsynth.synth.errors import InvalidParameter

__all__ = ["SCAN_ORDERS", "ScanOrder", "hilbert_points", "morton_points", "scan_order"]

ScanOrder = Literal["lexicographic", "random", "morton", "hilbert"]
SCAN_ORDERS: tuple[ScanOrder, ...] = ("lexicographic", "random", "morton", "hilbert")


def _bits_for(shape: tuple[int, ...]) -> int:
    return max(1, int(np.ceil(np.log2(max(shape)))))


def morton_points(ndim: int, bits: int) -> np.ndarray:
    """All points of the ``2**bits`` cube in Morton (Z) order, shape ``(2**(bits*ndim), ndim)``."""
    codes = np.arange(1 << (bits * ndim), dtype=np.int64)
    coords = np.zeros((codes.size, ndim), dtype=np.int64)
    for b in range(bits):
        for axis in range(ndim):
            # The last axis takes the least significant bit of each group (rows vary slowest).
            bit = (codes >> (b * ndim + (ndim - 1 - axis))) & 1
            coords[:, axis] |= bit << b
    return coords


def hilbert_points(ndim: int, bits: int) -> np.ndarray:
    """All points of the ``2**bits`` cube in Hilbert order (Skilling 2004), ``(2**(bits*ndim), ndim)``.

    Successive points differ by one step along one axis.
    """
    d = np.arange(1 << (bits * ndim), dtype=np.int64)
    # De-interleave the index into Skilling's transpose form: bit j of X[i] is bit j*n + (n-1-i) of d.
    x = np.zeros((ndim, d.size), dtype=np.int64)
    for j in range(bits):
        for i in range(ndim):
            x[i] |= ((d >> (j * ndim + (ndim - 1 - i))) & 1) << j
    top = 1 << bits
    # Gray decode.
    t = x[ndim - 1] >> 1
    for i in range(ndim - 1, 0, -1):
        x[i] ^= x[i - 1]
    x[0] ^= t
    # Undo the excess work.
    q = 2
    while q != top:
        p = q - 1
        for i in range(ndim - 1, -1, -1):
            has = (x[i] & q) != 0
            x[0] = np.where(has, x[0] ^ p, x[0])
            swap = np.where(has, 0, (x[0] ^ x[i]) & p)
            x[0] ^= swap
            if i != 0:
                x[i] ^= swap
        q <<= 1
    return x.T.copy()


def scan_order(shape: tuple[int, ...], kind: ScanOrder, rng: np.random.Generator | None = None) -> np.ndarray:
    """Flat indices (int64) of every position of ``shape`` in the order ``kind``.

    Space-filling curves are drawn on the enclosing power-of-two cube and clipped to ``shape``.
    ``random`` needs ``rng`` (a seeded generator) so that runs reproduce.
    """
    shape = tuple(int(s) for s in shape)
    n = int(np.prod(shape))
    if kind == "lexicographic":
        return np.arange(n, dtype=np.int64)
    if kind == "random":
        if rng is None:
            raise InvalidParameter("rng", None, "a random scan needs a seeded generator")
        return rng.permutation(n).astype(np.int64, copy=False)
    if kind in ("morton", "hilbert"):
        pts = (morton_points if kind == "morton" else hilbert_points)(len(shape), _bits_for(shape))
        inside = np.all(pts < np.asarray(shape), axis=1)
        return np.ravel_multi_index(tuple(pts[inside].T), shape).astype(np.int64)
    raise InvalidParameter("scan", kind, f"must be one of {', '.join(SCAN_ORDERS)}")
