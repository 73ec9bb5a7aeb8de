"""Raster layout of overlapping square patches (Efros & Freeman 2001, Raad et al. 2015, Fig. 1).

Patches of side ``w`` are placed left to right, top to bottom, with step ``w - overlap``; the output is
grown to ``(rows - 1) * step + w`` along each axis and cropped to the requested size at the end. Each patch
knows which of its borders overlap the earlier ones: none (the first), ``'left'`` (first row), ``'top'``
(first column) or ``'L'`` (both).

**Periodic layout** (``periodic=True``, a tileable output): the output is a torus of the requested size and
nothing is cropped. Along an axis of ``n`` pixels there are ``k = ceil(n / step)`` patches at
``floor(i n / k)``, ``i < k``: the step itself when ``n`` is a multiple of it, else the ``k`` steps are
spread evenly and are at most one pixel apart, each at most ``step``, so every overlap is at least the
requested one (``w - floor(n / k)`` px at most). Patches that cross the right or bottom border wrap around
(read and write them through :meth:`PatchLayout.index`). The last patch of a row then overlaps the row's
first patch too: besides its left strip it has a ``right`` strip (``w`` minus its own step wide), and the
last row has ``bottom`` strips over the first row. Each patch's known region is described by its
:class:`Strips` (the widths of its four border strips); its kind names them: ``'left'``, ``'top'``,
``'L'`` as above, ``'left+right'``, ``'top+bottom'``, ``'L+right'``, ``'L+bottom'``, ``'L+right+bottom'``.
A periodic axis needs at least two steps (:func:`check_periodic_size`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from texsynth.synth.errors import InvalidParameter
from texsynth.synth.threads import current_threads, thread_map

__all__ = [
    "PatchLayout",
    "Strips",
    "check_periodic_size",
    "overlap_mask",
    "patch_rng",
    "patch_workers",
    "periodic_positions",
]


def patch_rng(base: int, n: int) -> np.random.Generator:
    """Patch ``n``'s own random stream (``base``: a number drawn once from the method's seeded generator):
    a patch draws the same numbers whichever thread places it and whenever (:meth:`PatchLayout.waves`)."""
    return np.random.default_rng((int(base), int(n)))


@contextmanager
def patch_workers(
    gil_bound: bool = False,
) -> Iterator[Callable[[Callable[[int], Any], list[int]], list[Any]]]:
    """A runner for the patches of one wave (:meth:`PatchLayout.waves`): ``run(place, wave)`` returns
    ``[place(n) for n in wave]``, computed on the job's threads (``current_threads``, read here, in the
    thread that runs the job; :func:`texsynth.synth.threads.thread_map`). The results do not depend on
    the count when ``place`` writes only its own patch's pixels and draws its own random numbers.

    ``gil_bound``: ``place`` is a Python pipeline that holds the GIL most of its time (the Gaussian
    models' and feature-guided's per-patch steps): the wave is placed on the calling thread, because a
    second Python thread there only queues for the GIL and slows the wave down (docs/patch.md); the
    job's threads still serve the steps inside ``place`` that release it."""
    threads = 1 if gil_bound else current_threads()
    yield lambda place, wave: thread_map(place, wave, threads)


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
    return Strips.of_kind(overlap, kind).mask(w).copy()


@lru_cache(maxsize=256)
def _strips_mask(top: int, left: int, bottom: int, right: int, w: int) -> np.ndarray:
    mask = np.zeros((w, w), dtype=bool)
    mask[:top, :] = True
    mask[:, :left] = True
    if bottom:
        mask[w - bottom :, :] = True
    if right:
        mask[:, w - right :] = True
    mask.setflags(write=False)
    return mask


@dataclass(frozen=True)
class Strips:
    """Widths of the known strips along a patch's four borders, pixels (0: that border is free).

    A raster patch has ``top`` and/or ``left`` strips over the earlier patches; in a periodic layout the
    last column's patches also have a ``right`` strip (over the row's first patch, wrapped around) and the
    last row's a ``bottom`` strip (over the first row).

    Examples
    --------
    >>> Strips(top=3, left=3).kind, Strips(left=2, right=4).kind, Strips(4, 4, 5, 6).kind
    ('L', 'left+right', 'L+right+bottom')
    """

    top: int = 0
    left: int = 0
    bottom: int = 0
    right: int = 0

    @classmethod
    def of_kind(cls, overlap: int, kind: str) -> Strips:
        """The strips of a raster kind (``'none'``, ``'left'``, ``'top'``, ``'L'``) of width ``overlap``."""
        if kind not in ("none", "left", "top", "L"):
            raise ValueError(f"unknown overlap kind {kind!r}")
        return cls(
            top=overlap if kind in ("top", "L") else 0,
            left=overlap if kind in ("left", "L") else 0,
        )

    @property
    def kind(self) -> str:
        """``'none'``, ``'left'``, ``'top'``, ``'L'``, or those joined with ``'right'``/``'bottom'``
        by ``+``."""
        head = {(False, False): "none", (False, True): "left", (True, False): "top", (True, True): "L"}[
            (self.top > 0, self.left > 0)
        ]
        tail = [side for side in ("right", "bottom") if getattr(self, side) > 0]
        if not tail:
            return head
        if head == "none":
            return "+".join(tail)
        return "+".join([head, *tail])

    @property
    def two_sided(self) -> bool:
        """Whether an axis is known on both sides (a wrapped patch of a periodic layout)."""
        return self.right > 0 or self.bottom > 0

    def mask(self, w: int) -> np.ndarray:
        """Boolean ``(w, w)`` mask of the union of the strips (made once per strips and side, read-only:
        the patch loops ask for it at every patch)."""
        return _strips_mask(self.top, self.left, self.bottom, self.right, w)


def periodic_positions(n: int, step: int) -> list[int]:
    """Top-left coordinates of the patches along a periodic axis of ``n`` pixels: ``floor(i n / k)``,
    ``k = ceil(n / step)`` (every step at most ``step``; all equal to it when ``step`` divides ``n``).

    Examples
    --------
    >>> periodic_positions(96, 24), periodic_positions(100, 24)
    ([0, 24, 48, 72], [0, 20, 40, 60, 80])
    """
    k = max(1, math.ceil(n / step))
    return [i * n // k for i in range(k)]


def check_periodic_size(size: tuple[int, ...], w: int, overlap: int, role: str = "output") -> None:
    """Errors before any work for a periodic layout: each output side must hold at least two patch steps
    (so the patches can wrap around), and the last patch of a row or column must keep pixels of its own
    between its two overlaps. Raises :class:`InvalidParameter` naming ``height`` or ``width``."""
    step = w - overlap
    for name, n in (("height", int(size[0])), ("width", int(size[1]))):
        if n < 2 * step:
            raise InvalidParameter(
                name,
                n,
                f"with periodic=True the {role} must be at least two patch steps, 2 x (patch_size - overlap) "
                f"= 2 x ({w} - {overlap}) = {2 * step} px, so that the patches wrap around",
            )
        pos = periodic_positions(n, step)
        own = n - (pos[-2] + w)  # the last patch's pixels between its left (top) and right (bottom) strips
        if own < 1:
            raise InvalidParameter(
                name,
                n,
                f"with periodic=True, patch_size {w} and overlap {overlap}, the last patch along the "
                f"{role}'s {name} would keep no pixel of its own between its two overlaps; use a smaller "
                "overlap or another size",
            )


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
    periodic : bool
        A torus of the output's size (module docstring); the caller checks the size with
        :func:`check_periodic_size`.
    """

    size: tuple[int, int]
    w: int
    overlap: int
    periodic: bool = False

    @property
    def step(self) -> int:
        return self.w - self.overlap

    @property
    def rows(self) -> int:
        if self.periodic:
            return len(self.row_positions)
        return max(1, math.ceil((self.size[0] - self.overlap) / self.step))

    @property
    def cols(self) -> int:
        if self.periodic:
            return len(self.col_positions)
        return max(1, math.ceil((self.size[1] - self.overlap) / self.step))

    @property
    def row_positions(self) -> list[int]:
        """The patches' top rows."""
        if self.periodic:
            return periodic_positions(self.size[0], self.step)
        return [i * self.step for i in range(self.rows)]

    @property
    def col_positions(self) -> list[int]:
        """The patches' left columns."""
        if self.periodic:
            return periodic_positions(self.size[1], self.step)
        return [j * self.step for j in range(self.cols)]

    @property
    def grown_shape(self) -> tuple[int, int]:
        """The shape the patches cover, at least :attr:`size`; the result is cropped from it (a periodic
        layout covers the torus of :attr:`size` exactly)."""
        if self.periodic:
            return self.size
        return ((self.rows - 1) * self.step + self.w, (self.cols - 1) * self.step + self.w)

    def __len__(self) -> int:
        return self.rows * self.cols

    def strips(self, i: int, j: int) -> Strips:
        """The known strips of patch ``(i, j)`` when it is placed (raster order)."""
        if self.overlap == 0 and not self.periodic:
            return Strips()
        if not self.periodic:
            return Strips(top=self.overlap if i > 0 else 0, left=self.overlap if j > 0 else 0)
        ys, xs = self.row_positions, self.col_positions
        h, wd = self.size
        last_i, last_j = len(ys) - 1, len(xs) - 1
        return Strips(
            top=ys[i - 1] + self.w - ys[i] if i > 0 else 0,
            left=xs[j - 1] + self.w - xs[j] if j > 0 else 0,
            bottom=ys[i] + self.w - h if i == last_i and i > 0 else 0,
            right=xs[j] + self.w - wd if j == last_j and j > 0 else 0,
        )

    def kind(self, i: int, j: int) -> str:
        """The overlap kind of patch ``(i, j)``: ``'none'``, ``'left'``, ``'top'``, ``'L'`` (and, in a
        periodic layout, those with ``'+right'``/``'+bottom'``: :attr:`Strips.kind`)."""
        if self.overlap == 0 and not self.periodic:
            return "none"
        return self.strips(i, j).kind

    def mask(self, i: int, j: int) -> np.ndarray:
        """Boolean ``(w, w)`` known region of patch ``(i, j)`` when it is placed."""
        return self.strips(i, j).mask(self.w)

    def sealed(self, i: int, j: int) -> np.ndarray | None:
        """Known pixels of patch ``(i, j)`` on its border next to output already written outside it, that a
        cut must leave old (``None``: none beyond the outer borders of the strips).

        In a periodic layout, the top (and, in the last row, bottom) strip of a row's first patch ends on
        the patch's left border, where the torus continues into the previous row's last patch; in the raster
        layout that border is the image's (or a known left strip, whose border is kept old anyway).
        """
        strips = self.strips(i, j)
        if not self.periodic or j > 0 or not (strips.top or strips.bottom):
            return None
        sealed = np.zeros((self.w, self.w), dtype=bool)
        sealed[: strips.top, 0] = True
        if strips.bottom:
            sealed[self.w - strips.bottom :, 0] = True
        return sealed

    def patches(self) -> list[tuple[int, int, int, int, str]]:
        """``(i, j, y, x, kind)`` of every patch in raster order; ``(y, x)`` is its top-left corner."""
        ys, xs = self.row_positions, self.col_positions
        return [(i, j, ys[i], xs[j], self.kind(i, j)) for i in range(self.rows) for j in range(self.cols)]

    def waves(self) -> list[list[int]]:
        """The patches (indices into :meth:`patches`) in waves that can be placed in parallel.

        A patch's wave is one more than the highest wave among the earlier patches (raster order) whose
        ``w x w`` regions meet its own (on the torus when periodic), so overlapping patches keep their
        order and the patches of a wave are disjoint: placing a wave's patches at once gives the raster
        result (Lefebvre & Hoppe 2005's idea, on patches). Without wrap-around the waves are the grid's
        diagonals ``j + 2 i`` (overlap below half a patch); a periodic layout's last column meets the next
        row's first patch, which chains the rows: one patch per wave.
        """
        ys, xs = self.row_positions, self.col_positions

        def meets(pos: list[int], n: int) -> list[list[int]]:
            out = []
            for a in pos:
                d = [abs(b - a) if not self.periodic else min((b - a) % n, (a - b) % n) for b in pos]
                out.append([k for k, dk in enumerate(d) if dk < self.w])
            return out

        row_hits, col_hits = meets(ys, self.size[0]), meets(xs, self.size[1])
        cols = len(xs)
        wave = np.zeros(len(ys) * cols, dtype=np.int64)
        for i in range(len(ys)):
            for j in range(cols):
                n = i * cols + j
                earlier = [wave[a * cols + b] for a in row_hits[i] for b in col_hits[j] if a * cols + b < n]
                wave[n] = 1 + max(earlier) if earlier else 0
        return [np.flatnonzero(wave == k).tolist() for k in range(int(wave.max()) + 1)] if len(wave) else []

    def index(self, y: int, x: int) -> tuple[np.ndarray, np.ndarray]:
        """:func:`numpy.ix_` indices of the ``w x w`` output region at ``(y, x)``, wrapped around the torus
        in a periodic layout: ``out[layout.index(y, x)]`` reads a copy, ``out[layout.index(y, x)] = ...``
        writes it back."""
        rows = np.arange(y, y + self.w)
        cols = np.arange(x, x + self.w)
        if self.periodic:
            rows, cols = rows % self.size[0], cols % self.size[1]
        return np.ix_(rows, cols)

    def rows_cols(self, y: int, x: int) -> tuple[np.ndarray, np.ndarray]:
        """The output rows and columns of the ``w x w`` region at ``(y, x)`` (int64, wrapped around the
        torus in a periodic layout): :meth:`index` without :func:`numpy.ix_`, for the kernels."""
        rows = np.arange(y, y + self.w)
        cols = np.arange(x, x + self.w)
        if self.periodic:
            rows, cols = rows % self.size[0], cols % self.size[1]
        return rows, cols

    def describe(self) -> dict[str, Any]:
        """The layout as plain numbers, for ``Result.stats['layout']`` and :func:`seam_visibility`.

        ``seam_rows``/``seam_cols`` are the first rows/columns of the horizontal/vertical overlap strips
        inside the cropped output: a patch pasted there meets the earlier ones somewhere in
        ``[start, start + overlap)`` (at ``start`` itself when it is pasted without blending). In a
        periodic layout ``overlap`` is the widest strip (the steps may be shorter than ``patch_size -
        overlap``, module docstring), ``step`` the longest, and row / column 0 is a seam too (the last
        row / column of patches meets the first there).
        """
        h, w = self.size
        if self.periodic:
            ys, xs = self.row_positions, self.col_positions
            steps = np.diff([*ys, h]).tolist() + np.diff([*xs, w]).tolist()
            return {
                "patch_size": self.w,
                "overlap": self.w - min(steps),
                "step": max(steps),
                "rows": self.rows,
                "cols": self.cols,
                "seam_rows": ys,
                "seam_cols": xs,
                "periodic": True,
            }
        return {
            "patch_size": self.w,
            "overlap": self.overlap,
            "step": self.step,
            "rows": self.rows,
            "cols": self.cols,
            "seam_rows": [i * self.step for i in range(1, self.rows) if i * self.step < h],
            "seam_cols": [j * self.step for j in range(1, self.cols) if j * self.step < w],
            "periodic": False,
        }
