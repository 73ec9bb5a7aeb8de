"""Per-voxel exemplar positions of a solid synthesis: spread from a sparse grid, carried to a finer level.

A solid optimisation keeps, for every voxel and plane, the exemplar position its slice neighbourhood
came from (the coherent sources of Tong et al.'s k-coherence search). Two passes over the whole volume
maintain them, each a loop over voxels that reads only its own voxel's inputs:

- :func:`dense_sources`: the positions matched on Kopf's sparse grid of centres spread to every voxel,
  each voxel taking its grid centre's match shifted by its offset from that centre;
- :func:`upsample_sources`: a level's positions at the next finer level, ``2 * src(v // 2) + (v mod 2)``
  along the plane's axes (Wei-Levoy / Lefebvre-Hoppe coordinate upsampling).

The kernels write into a given output row (int32, or int64), so that a volume of 256^3 voxels and more
needs no full-size temporaries (the NumPy versions, kept as ``*_reference`` for the tests, allocated about ten
int64 arrays of the volume's size per call: 1.3 GiB at 256^3, and the page faults of fresh memory
every iteration). Each voxel's answer is integer arithmetic on its own coordinates: the same values on
any number of threads.

References
----------
X. Tong, J. Zhang, L. Liu, X. Wang, B. Guo, H.-Y. Shum, "Synthesis of bidirectional texture functions
on arbitrary surfaces", SIGGRAPH 2002 (k-coherence). S. Lefebvre, H. Hoppe, "Parallel controllable
texture synthesis", SIGGRAPH 2005 (coordinate upsampling).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from texsynth.synth.kernels.options import kernel

__all__ = [
    "dense_sources",
    "dense_sources_reference",
    "upsample_sources",
    "upsample_sources_reference",
]

#: Index types the kernels read and write: int32 halves a volume's per-voxel positions (an exemplar position
#: is below 2^31), int64 is accepted as well; other types are converted to int64.
INDEX_TYPES = (np.dtype(np.int32), np.dtype(np.int64))

#: Volume axes ``(row axis, column axis)`` of each plane's slices, as ``texsynth.synth.pixel.solid``.
_PLANE_AXES: dict[str, tuple[int, int]] = {"xy": (1, 2), "xz": (0, 2), "yz": (0, 1)}


def _indices(values: np.ndarray) -> np.ndarray:
    """``values`` as a C-contiguous int32 or int64 array (no copy when it already is one)."""
    values = np.asarray(values)
    return np.ascontiguousarray(values, dtype=values.dtype if values.dtype in INDEX_TYPES else np.int64)


def _check_out(out: np.ndarray | None, n: int, dtype: np.dtype) -> np.ndarray:
    """A new ``(n,)`` array of ``dtype``, or ``out`` checked: C-contiguous int32 or int64, ``n`` entries."""
    if out is None:
        return np.empty(n, dtype=dtype)
    if out.shape != (n,) or out.dtype not in INDEX_TYPES or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous int32 or int64 array of {n} entries")
    return out


@kernel(inline="always")
def _snap(g, q, stride, last):
    """The grid coordinate (``q`` modulo ``stride``) at or before ``g``, else after it, at most ``last``."""
    t = (g - q) % stride
    if t < 0:
        t += stride
    snapped = g - t
    if snapped < 0:
        snapped += stride
    return min(snapped, last)


@kernel(parallel=True)
def _dense_sources_kernel(match, shape, a, b, stride, phase, h, w, out):
    d0, d1, d2 = shape[0], shape[1], shape[2]
    q = (phase[0] % stride, phase[1] % stride)
    lasts = np.empty(3, dtype=np.int64)
    for axis in range(3):
        lasts[axis] = shape[axis] - 1
    last_a = lasts[a] - (lasts[a] - q[0]) % stride
    last_b = lasts[b] - (lasts[b] - q[1]) % stride
    for z in prange(d0):
        coord = np.empty(3, dtype=np.int64)
        cen = np.empty(3, dtype=np.int64)
        coord[0] = z
        for y in range(d1):
            coord[1] = y
            for x in range(d2):
                coord[2] = x
                cen[0] = z
                cen[1] = y
                cen[2] = x
                cen[a] = _snap(coord[a], q[0], stride, last_a)
                cen[b] = _snap(coord[b], q[1], stride, last_b)
                m = match[(cen[0] * d1 + cen[1]) * d2 + cen[2]]
                v = (z * d1 + y) * d2 + x
                if m < 0:
                    out[v] = 0
                    continue
                row = m // w + coord[a] - cen[a]
                col = m % w + coord[b] - cen[b]
                row = min(max(row, 0), h - 1)
                col = min(max(col, 0), w - 1)
                out[v] = row * w + col


def dense_sources(
    match: np.ndarray,
    shape: tuple[int, int, int],
    plane: str,
    stride: int,
    phase: tuple[int, int],
    ex_shape: tuple[int, int],
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Every voxel's exemplar position ``(N,)`` in ``plane``, from matches on a sparse grid.

    ``match`` (N,) holds the matched centre position at the grid's centres (every ``stride``-th voxel
    from ``phase`` along the plane's two axes, -1 elsewhere). A voxel takes the position its grid centre
    (the one at or before it along each plane axis, else after it) matched, shifted by its offset from
    that centre and clamped inside the exemplar (0 when that centre has no match). ``match`` and
    ``out`` are int32 or int64 (:data:`INDEX_TYPES`); ``out``: a C-contiguous array of N entries to write
    into (else a new one of ``match``'s type); it must not be ``match``.
    """
    a, b = _PLANE_AXES[plane]
    n = int(np.prod(shape))
    match = _indices(match)
    out = _check_out(out, n, match.dtype)
    if np.shares_memory(out, match):
        raise ValueError("out must not share memory with match")
    _dense_sources_kernel(
        match,
        np.asarray(shape, dtype=np.int64),
        a,
        b,
        int(stride),
        np.asarray(phase, dtype=np.int64),
        int(ex_shape[0]),
        int(ex_shape[1]),
        out,
    )
    return out


def dense_sources_reference(
    match: np.ndarray,
    shape: tuple[int, int, int],
    plane: str,
    stride: int,
    phase: tuple[int, int],
    ex_shape: tuple[int, int],
) -> np.ndarray:
    """:func:`dense_sources` in NumPy on whole-volume coordinate arrays (the definition, for the tests)."""
    a, b = _PLANE_AXES[plane]
    h, w = ex_shape
    grids = np.meshgrid(*[np.arange(s, dtype=np.int64) for s in shape], indexing="ij")
    cen = [g.copy() for g in grids]
    for axis, ph in ((a, phase[0]), (b, phase[1])):
        snapped = grids[axis] - (grids[axis] - ph % stride) % stride
        snapped = np.where(snapped < 0, snapped + stride, snapped)
        cen[axis] = np.minimum(snapped, shape[axis] - 1 - (shape[axis] - 1 - ph % stride) % stride)
    flat = np.ravel_multi_index(tuple(cen), shape).ravel()
    m = match[flat]
    row = m // w + (grids[a] - cen[a]).ravel()
    col = m % w + (grids[b] - cen[b]).ravel()
    out = np.clip(row, 0, h - 1) * w + np.clip(col, 0, w - 1)
    return np.ascontiguousarray(np.where(m >= 0, out, 0), dtype=np.int64)


@kernel(parallel=True)
def _upsample_sources_kernel(src, coarse_shape, shape, a, b, h, w, cw, out):
    d0, d1, d2 = shape[0], shape[1], shape[2]
    c1, c2 = coarse_shape[1], coarse_shape[2]
    for z in prange(d0):
        coord = np.empty(3, dtype=np.int64)
        coord[0] = z
        pz = min(z // 2, coarse_shape[0] - 1)
        for y in range(d1):
            coord[1] = y
            py = min(y // 2, c1 - 1)
            for x in range(d2):
                coord[2] = x
                px = min(x // 2, c2 - 1)
                s = src[(pz * c1 + py) * c2 + px]
                row = 2 * (s // cw) + coord[a] % 2
                col = 2 * (s % cw) + coord[b] % 2
                row = min(max(row, 0), h - 1)
                col = min(max(col, 0), w - 1)
                out[(z * d1 + y) * d2 + x] = row * w + col


def upsample_sources(
    src: np.ndarray,
    coarse_shape: tuple[int, int, int],
    shape: tuple[int, int, int],
    plane: str,
    ex_shape: tuple[int, int],
    coarse_ex_shape: tuple[int, int],
    out: np.ndarray | None = None,
) -> np.ndarray:
    """A plane's per-voxel exemplar positions at the next finer level: voxel ``v`` takes
    ``2 * src(v // 2) + (v mod 2)`` along the plane's axes, clamped inside the finer exemplar ``ex_shape``.

    ``src`` (``prod(coarse_shape)``,) holds non-negative positions in the coarser exemplar (of width
    ``coarse_ex_shape[1]``), int32 or int64. ``out``: a C-contiguous int32 or int64 array of
    ``prod(shape)`` entries (else a new one of ``src``'s type).
    """
    a, b = _PLANE_AXES[plane]
    n = int(np.prod(shape))
    src = _indices(src)
    out = _check_out(out, n, src.dtype)
    _upsample_sources_kernel(
        src,
        np.asarray(coarse_shape, dtype=np.int64),
        np.asarray(shape, dtype=np.int64),
        a,
        b,
        int(ex_shape[0]),
        int(ex_shape[1]),
        int(coarse_ex_shape[1]),
        out,
    )
    return out


def upsample_sources_reference(
    src: np.ndarray,
    coarse_shape: tuple[int, int, int],
    shape: tuple[int, int, int],
    plane: str,
    ex_shape: tuple[int, int],
    coarse_ex_shape: tuple[int, int],
) -> np.ndarray:
    """:func:`upsample_sources` in NumPy on whole-volume coordinate arrays (the definition, for the tests)."""
    a, b = _PLANE_AXES[plane]
    h, w = ex_shape
    grids = np.meshgrid(*[np.arange(s, dtype=np.int64) for s in shape], indexing="ij")
    parent = np.ravel_multi_index(
        tuple(np.minimum(g // 2, cs - 1) for g, cs in zip(grids, coarse_shape, strict=True)), coarse_shape
    )
    s = src[parent.ravel()]
    cw = coarse_ex_shape[1]
    row = 2 * (s // cw) + (grids[a] % 2).ravel()
    col = 2 * (s % cw) + (grids[b] % 2).ravel()
    return np.ascontiguousarray(np.clip(row, 0, h - 1) * w + np.clip(col, 0, w - 1), dtype=np.int64)
