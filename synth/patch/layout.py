"""Raster layout of overlapping square patches (Efros & Freeman 2001, Raad et al. 2015, Fig. 1).

Patches of side ``w`` are placed left to right, top to bottom, with step ``w - overlap``; the output is
grown to ``(rows - 1) * step + w`` along each axis and cropped to the requested size at the end. Each patch
knows which of its borders overlap the earlier ones: none (the first), ``'left'`` (first row), ``'top'``
(first column) or ``'L'`` (both).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["PatchLayout", "overlap_mask"]


def overlap_mask(w: int, overlap: int, kind: str) -> np.ndarray:
    """Boolean ``(w, w)`` mask of a patch's overlap with earlier patches.

    Parameters
    ----------
    w : int
        Patch side.
    overlap : int
        Overlap width in pixels.
    kind : {'none', 'left', 'top', 'L'}
        Which borders overlap.
    """
    mask = np.zeros((w, w), dtype=bool)
    if kind in ("left", "L"):
        mask[:, :overlap] = True
    if kind in ("top", "L"):
        mask[:overlap, :] = True
    return mask


@dataclass(frozen=True)
class PatchLayout:
    """Where the patches go: ``rows x cols`` patches of side ``w`` with step ``w - overlap``.

    Attributes
    ----------
    size : (int, int)
        The requested output shape ``(H, W)``.
    w : int
        Patch side.
    overlap : int
        Overlap between neighbouring patches, ``0 <= overlap < w``.
    """

    size: tuple[int, int]
    w: int
    overlap: int

    @property
    def step(self) -> int:
        return self.w - self.overlap

    @property
    def rows(self) -> int:
        return max(1, math.ceil((self.size[0] - self.overlap) / self.step))

    @property
    def cols(self) -> int:
        return max(1, math.ceil((self.size[1] - self.overlap) / self.step))

    @property
    def grown_shape(self) -> tuple[int, int]:
        """The shape the patches cover, at least :attr:`size`; the result is cropped from it."""
        return ((self.rows - 1) * self.step + self.w, (self.cols - 1) * self.step + self.w)

    def __len__(self) -> int:
        return self.rows * self.cols

    def kind(self, i: int, j: int) -> str:
        """The overlap kind of patch ``(i, j)``: ``'none'``, ``'left'``, ``'top'`` or ``'L'``."""
        if self.overlap == 0:
            return "none"
        return {(False, False): "none", (False, True): "left", (True, False): "top", (True, True): "L"}[
            (i > 0, j > 0)
        ]

    def patches(self) -> list[tuple[int, int, int, int, str]]:
        """``(i, j, y, x, kind)`` of every patch in raster order; ``(y, x)`` is its top-left corner."""
        return [
            (i, j, i * self.step, j * self.step, self.kind(i, j))
            for i in range(self.rows)
            for j in range(self.cols)
        ]

    def describe(self) -> dict[str, Any]:
        """The layout as plain numbers, for ``Result.stats['layout']`` and :func:`seam_visibility`.

        ``seam_rows``/``seam_cols`` are the first rows/columns of the horizontal/vertical overlap strips
        inside the cropped output: a patch pasted there meets the earlier ones somewhere in
        ``[start, start + overlap)`` (at ``start`` itself when it is pasted without blending).
        """
        h, w = self.size
        return {
            "patch_size": self.w,
            "overlap": self.overlap,
            "step": self.step,
            "rows": self.rows,
            "cols": self.cols,
            "seam_rows": [i * self.step for i in range(1, self.rows) if i * self.step < h],
            "seam_cols": [j * self.step for j in range(1, self.cols) if j * self.step < w],
        }
