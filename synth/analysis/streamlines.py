"""Streamlines of an orientation field: curves that follow a line field (an angle mod pi) wherever it turns.

Used to measure grey levels along a texture's strands (:mod:`texsynth.synth.evaluate.strands`) and to lay
arbitrary-shape synthesis's hints along the constraint's strands (:mod:`texsynth.synth.methods.strand_hints`).

How: every start point moves by ``step`` pixels per step along the field's direction at its position,
second-order (midpoint) Runge-Kutta. The field is an *orientation* (defined modulo pi), so it is
interpolated bilinearly in its doubled-angle form ``(cos 2 phi, sin 2 phi)`` (no jump between
``pi/2`` and ``-pi/2``), and the sign of each step is the one that keeps the curve going the way it
went (the first step takes the sign given by ``forward``). Angles follow the project's convention
(``x`` right, ``y`` up, counter-clockwise), positions are ``(row, col)``. All points move at once
(numpy, vectorised): the cost is ``steps`` bilinear look-ups of the whole set.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

__all__ = ["doubled_angle", "sample_along", "trace"]


def doubled_angle(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cos 2 phi, sin 2 phi)`` of an orientation field, float64 (interpolable without wrapping)."""
    a = np.asarray(angle, dtype=np.float64)
    return np.cos(2 * a), np.sin(2 * a)


def _direction_at(field: tuple[np.ndarray, np.ndarray], pos: np.ndarray, mode: str) -> np.ndarray:
    """Unit direction ``(d_row, d_col)`` of the field at positions ``pos`` (N, 2), sign undecided."""
    c2 = ndi.map_coordinates(field[0], pos.T, order=1, mode=mode)
    s2 = ndi.map_coordinates(field[1], pos.T, order=1, mode=mode)
    phi = 0.5 * np.arctan2(s2, c2)
    return np.stack([-np.sin(phi), np.cos(phi)], axis=-1)


def _aligned(d: np.ndarray, ref: np.ndarray) -> np.ndarray:
    sign = np.where((d * ref).sum(axis=-1) < 0, -1.0, 1.0)
    return d * sign[:, None]


def trace(
    angle: np.ndarray,
    starts: np.ndarray,
    steps: int,
    *,
    step: float = 1.0,
    forward: np.ndarray | None = None,
    periodic: bool = False,
) -> np.ndarray:
    """Positions ``(steps + 1, N, 2)`` (row, col, float64) of the streamlines of the orientation field
    ``angle`` (H, W) from ``starts`` (N, 2).

    ``forward`` (N, 2): a direction each curve's first step should not go against (default: the
    field's own, with a positive column component, i.e. rightwards). Outside the image the field is
    mirrored (``periodic``: wrapped) and the curves go on; callers drop the points they do not want.
    """
    mode = "grid-wrap" if periodic else "mirror"
    field = doubled_angle(angle)
    pos = np.asarray(starts, dtype=np.float64).copy()
    out = np.empty((steps + 1, len(pos), 2))
    out[0] = pos
    d = _direction_at(field, pos, mode)
    ref = np.asarray(forward, dtype=np.float64) if forward is not None else np.array([[0.0, 1.0]]) + 0 * d
    prev = _aligned(d, ref + 1e-9 * np.array([[1.0, 0.0]]))  # vertical ties go down, deterministically
    for i in range(steps):
        k1 = _aligned(_direction_at(field, pos, mode), prev)
        k2 = _aligned(_direction_at(field, pos + 0.5 * step * k1, mode), k1)
        pos = pos + step * k2
        prev = k2
        out[i + 1] = pos
    return out


def sample_along(
    image: np.ndarray, angle: np.ndarray, starts: np.ndarray, length: int
) -> tuple[np.ndarray, np.ndarray]:
    """The grey levels (bilinear) of ``image`` (H, W) along the streamline of ``angle`` through each of
    ``starts`` (N, 2), ``length`` pixels each way: ``(values, inside)``, both ``(2 length + 1, N)``,
    ``inside`` False where the curve has left the image (those values are meaningless)."""
    ahead = trace(angle, starts, length)
    behind = trace(angle, starts, length, forward=-(ahead[1] - ahead[0]))
    pts = np.concatenate([behind[:0:-1], ahead], axis=0)  # (2 length + 1, N, 2)
    h, w = image.shape
    inside = (pts[..., 0] >= 0) & (pts[..., 0] <= h - 1) & (pts[..., 1] >= 0) & (pts[..., 1] <= w - 1)
    vals = ndi.map_coordinates(image, pts.reshape(-1, 2).T, order=1, mode="nearest").reshape(inside.shape)
    return vals, inside
