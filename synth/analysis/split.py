"""Big images' filters and per-pixel maps on the job's threads, bit for bit what one call gives.

SciPy's separable Gaussian filter is a chain of 1-D correlations (``correlate1d``), each line along its
axis computed from that line alone; its C loop releases the GIL. :func:`gaussian_filter` runs each pass
as pieces cut across another axis, one per thread (:func:`texsynth.synth.threads.thread_map`), in the
order and with the intermediate dtype of :func:`scipy.ndimage.gaussian_filter`: every value is the one
the single call computes, whatever the thread count (tested). :func:`per_pixel` does the same for a
NumPy function of a field that maps each pixel on its own (coherence, orientation): contiguous runs of
pixels, one per thread.

Images below :data:`SPLIT_PIXELS` (per plane) go to the single call: a volume's evaluation already runs
its slices on the threads, and a hand-over costs more than a small filter. Work already running as one
task of :func:`~texsynth.synth.threads.thread_map` is not split again (``thread_map`` runs it in line).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from functools import partial

import numpy as np
from scipy import ndimage as ndi

from texsynth.synth.threads import current_threads, thread_map

__all__ = ["SPLIT_PIXELS", "gaussian_filter", "per_pixel", "split_rows"]

#: Pixels of one plane from which the work is split over the threads (1024^2: a big output's evaluation
#: and pictures, not a volume's slices nor a 256^2 command's).
SPLIT_PIXELS = 1 << 20


def _pieces(length: int, parts: int) -> list[tuple[int, int]]:
    """``[start, stop)`` bounds of ``parts`` near-equal pieces of ``range(length)``."""
    cuts = np.linspace(0, length, parts + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in itertools.pairwise(cuts) if b > a]


def _threads_for(shape: Sequence[int], axes: Sequence[int]) -> int:
    """The threads to split over: the job's, if a plane of the filtered axes is big enough."""
    plane = int(np.prod([shape[a] for a in axes])) if axes else 0
    return current_threads() if plane >= SPLIT_PIXELS else 1


def gaussian_filter(
    image: np.ndarray,
    sigma: float,
    *,
    order: int | Sequence[int] = 0,
    mode: str = "reflect",
    axes: Sequence[int] | None = None,
) -> np.ndarray:
    """:func:`scipy.ndimage.gaussian_filter` (``sigma``, ``order``, ``mode``, ``axes``; float input),
    each 1-D pass split across the longest other axis over the job's threads; the same values."""
    img = np.asarray(image)
    axes = tuple(range(img.ndim)) if axes is None else tuple(int(a) % img.ndim for a in axes)
    threads = _threads_for(img.shape, axes)
    if threads < 2 or img.dtype.kind != "f" or img.ndim < 2 or not float(sigma) > 1e-15:
        return ndi.gaussian_filter(img, sigma, order=order, mode=mode, axes=axes)
    orders = [int(order)] * len(axes) if np.ndim(order) == 0 else [int(o) for o in order]  # type: ignore[arg-type]
    out = np.zeros(img.shape, dtype=img.dtype.name)
    source = img
    for axis, axis_order in zip(axes, orders, strict=True):
        across = max((a for a in range(img.ndim) if a != axis), key=lambda a: img.shape[a])
        pieces = [
            tuple(slice(a, b) if d == across else slice(None) for d in range(img.ndim))
            for a, b in _pieces(img.shape[across], threads)
        ]
        thread_map(partial(_pass, source, out, sigma, axis, axis_order, mode), pieces, threads)
        source = out
    return out


def _pass(
    source: np.ndarray, out: np.ndarray, sigma: float, axis: int, order: int, mode: str, piece: tuple
) -> None:
    """One piece of one 1-D pass of :func:`gaussian_filter`."""
    ndi.gaussian_filter1d(source[piece], sigma, axis, order, out[piece], mode)


def per_pixel(function: Callable[[np.ndarray], np.ndarray], field: np.ndarray) -> np.ndarray:
    """``function(field)`` for a ``function`` that maps each pixel of a ``(..., K)`` field on its own to a
    value of the field's dtype, run on contiguous runs of pixels over the threads, each written in place."""
    arr = np.asarray(field)
    threads = _threads_for(arr.shape[-3:-1], (0, 1)) if arr.ndim >= 3 else 1
    if threads < 2 or not arr.flags.c_contiguous:
        return function(arr)
    flat = arr.reshape(-1, arr.shape[-1])
    out = np.empty(len(flat), dtype=arr.dtype)

    def run(bounds: tuple[int, int]) -> None:
        a, b = bounds
        out[a:b] = function(flat[a:b])

    thread_map(run, _pieces(len(flat), threads), threads)
    return out.reshape(arr.shape[:-1])


def split_rows(function: Callable[[int, int], None], shape: Sequence[int]) -> None:
    """``function(a, b)`` for runs of rows ``[a, b)`` covering the rows (``shape[-2]``) of images of
    ``shape`` (``(..., H, W)``), one run per thread; ``function`` writes only its own rows."""
    rows = int(shape[-2])
    threads = _threads_for(shape[-2:], (0, 1))
    thread_map(lambda ab: function(*ab), _pieces(rows, threads), threads)
