"""The rotated dictionary ``D_M``: an exemplar and its tensor field under M rotations, on one canvas.

Akl et al. (GRETSI, section 2.2) search neighbourhoods (intensity + structure tensors) of the
exemplar rotated by ``phi_m = 2 pi m / M``, ``m = 0..M-1``, each with its own tensor field, keeping
only neighbourhoods that lie fully inside the rotated (non-padded) image. Here the M rotated copies
are laid side by side in one canvas (a grid of equal tiles) so that the shared search
(:func:`texsynth.synth.pixel.synthesis.synthesize_source_map`) sees one exemplar; per-level masks mark the
positions whose neighbourhoods (and parent neighbourhoods) are fully inside a rotated copy.

Geometry (ALGORITHMS.md conventions: ``x`` right, ``y`` up, angles counter-clockwise): copy ``m``
is the exemplar turned by ``phi_m`` counter-clockwise on screen about its centre, centred in its
tile, so a fringe system of gradient orientation ``O`` becomes ``O + phi_m``. The outside of the
exemplar is filled by mirroring it (never copied: masked out) so that filters see texture, not a
step, near the copies' borders.

Tensor field of a copy: the exemplar's field ``S_en`` rotated in place and in value,
``S_m(T_m p) = R(phi_m) S_en(p) R(phi_m)^T`` (:func:`texsynth.synth.analysis.tensor.rotate_tensors`), which
equals the structure tensor of the rotated image in the continuous limit, without the mirror seams that a
tensor computed on the padded copy would pick up, and in exactly the frame of the constraint field built
from ``S_en`` (so that the right rotation matches it exactly).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi

from texsynth.synth.analysis.tensor import rotate_tensors, structure_tensor, wrap_angle
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.grid.pyramid import level_shapes
from texsynth.synth.threads import current_threads, thread_map

__all__ = [
    "RotatedDictionary",
    "build_rotated_dictionary",
    "dictionary_bytes",
    "rotation_candidates",
]

#: Pixels kept between a copy's bounding box and its tile's border.
_TILE_GUARD = 2
#: Pixels a pyramid level's smoothing may carry across a copy's border (kept out of the masks).
_BLEED = 1


@dataclass(frozen=True)
class RotatedDictionary:
    """M rotated copies of an exemplar on one canvas.

    Attributes
    ----------
    image : ndarray (H, W, C) float32
        Intensities of the copies (``C`` = 1 grey, 3 RGB).
    tensors : ndarray (H, W, 3) float32
        Their structure tensor fields ``(S_xx, S_xy, S_yy)``.
    area : ndarray (H, W) bool
        Positions inside a rotated copy (not in the mirrored fill or between tiles).
    tile_index : ndarray (H, W) int32
        The copy ``m`` each canvas position belongs to (-1 in unused tiles of the grid).
    angles : ndarray (M,) float64
        ``phi_m = 2 pi m / M`` (radians, counter-clockwise).
    tile_shape : (int, int)
    grid_columns : int
    exemplar_shape : (int, int)
    """

    image: np.ndarray
    tensors: np.ndarray
    area: np.ndarray
    tile_index: np.ndarray
    angles: np.ndarray
    tile_shape: tuple[int, int]
    grid_columns: int
    exemplar_shape: tuple[int, int]

    @property
    def n_rotations(self) -> int:
        return len(self.angles)

    def tile_origin(self, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Top-left canvas corner ``(row, col)`` of copy ``m`` (vectorised)."""
        th, tw = self.tile_shape
        m = np.asarray(m)
        return (m // self.grid_columns) * th, (m % self.grid_columns) * tw

    def to_canvas(self, positions: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Canvas position ``(row, col)`` of exemplar position(s) ``positions`` in copy ``m``.

        ``positions`` has shape ``(..., 2)`` and ``m`` broadcasts with ``positions[..., 0]``;
        returns int64 ``(..., 2)`` (rounded to the nearest pixel).
        """
        p = np.asarray(positions, dtype=np.float64)
        phi = self.angles[np.asarray(m)]
        h, w = self.exemplar_shape
        th, tw = self.tile_shape
        x = p[..., 1] - (w - 1) / 2
        y = (h - 1) / 2 - p[..., 0]
        c, s = np.cos(phi), np.sin(phi)
        xr, yr = c * x - s * y, s * x + c * y
        r0, c0 = self.tile_origin(m)
        rows = np.rint(r0 + (th - 1) / 2 - yr)
        cols = np.rint(c0 + (tw - 1) / 2 + xr)
        return np.stack([rows, cols], axis=-1).astype(np.int64)

    def affine_maps(self, level: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Every copy's map between its canvas positions and the exemplar's, at a pyramid ``level``.

        Returns ``(to_exemplar, to_canvas)``, each ``(M, 2, 3)`` float64: ``to_canvas[m] @ (row, col, 1)``
        is the (unrounded) canvas position of exemplar position ``(row, col)`` in copy ``m``, as
        :meth:`to_canvas` before rounding; ``to_exemplar[m]`` is its inverse. At ``level`` ``l`` canvas
        positions are subsampled by ``2^l`` (exemplar positions stay the finest level's), so that a
        position of one copy can be moved to the same exemplar point of another copy at any level.
        """
        h, w = self.exemplar_shape
        th, tw = self.tile_shape
        r0, c0 = self.tile_origin(np.arange(self.n_rotations))
        c, s = np.cos(self.angles), np.sin(self.angles)
        cw, ch = (w - 1) / 2, (h - 1) / 2
        fwd = np.empty((self.n_rotations, 2, 3))
        fwd[:, 0] = np.stack([c, -s, r0 + (th - 1) / 2 + s * cw - c * ch], axis=-1)
        fwd[:, 1] = np.stack([s, c, c0 + (tw - 1) / 2 - c * cw - s * ch], axis=-1)
        fwd /= 2**level
        back = np.empty_like(fwd)
        inv = np.linalg.inv(fwd[:, :, :2])
        back[:, :, :2] = inv
        back[:, :, 2] = -np.einsum("mij,mj->mi", inv, fwd[:, :, 2])
        return back, fwd

    def level_masks(self, radii: list[int], parent_radii: list[int]) -> list[np.ndarray]:
        """Per pyramid level (finest first), uint8 masks of the positions a search may copy.

        A position counts when its ``radii[l]`` neighbourhood lies inside the copy at level ``l``
        and, below the top level, its parent's ``parent_radii[l]`` neighbourhood lies inside the
        copy at level ``l + 1`` (levels are subsampled 2:1 like
        :func:`texsynth.synth.grid.pyramid.level_shapes`).
        """
        levels = len(radii)
        shapes = level_shapes(self.area.shape, levels)
        areas = [self.area]
        for lvl in range(1, levels):
            # A coarse position is inside when the fine positions its smoothing reads are.
            areas.append(_erode(areas[-1], _BLEED)[::2, ::2])
            assert areas[-1].shape == shapes[lvl]
        masks = []
        for lvl in range(levels):
            mask = _erode(areas[lvl], radii[lvl] + _BLEED)
            if lvl < levels - 1:
                parent_ok = _erode(areas[lvl + 1], parent_radii[lvl] + _BLEED)
                h, w = mask.shape
                mask &= np.repeat(np.repeat(parent_ok, 2, axis=0), 2, axis=1)[:h, :w]
            masks.append(np.ascontiguousarray(mask, dtype=np.uint8))
        return masks


def _erode(area: np.ndarray, radius: int) -> np.ndarray:
    """Positions whose ``(2 radius + 1)^2`` square lies inside ``area`` (outside counts as out)."""
    if radius <= 0:
        return area.copy()
    # A square minimum filter is separable (fast); outside the canvas counts as outside.
    return ndi.minimum_filter(area.astype(np.uint8), size=2 * radius + 1, mode="constant", cval=0) > 0


def _tiles(shape: tuple[int, int], n_rotations: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """The dictionary's tile (a square of the exemplar's diagonal and guard, the sides keeping the
    exemplar's parity so that centres fall on pixels) and its grid of rows and columns of copies."""
    h, w = shape
    side = int(np.ceil(np.hypot(h, w))) + 2 * _TILE_GUARD
    cols = int(np.ceil(np.sqrt(n_rotations)))
    return (side + (side - h) % 2, side + (side - w) % 2), (int(np.ceil(n_rotations / cols)), cols)


def dictionary_bytes(shape: tuple[int, ...], n_rotations: int) -> int:
    """Bytes of :func:`build_rotated_dictionary`'s canvas for an exemplar of ``shape`` ((h, w) or (h, w,
    channels)): the copies (float32 a channel), their tensors (3 float32), mask (bool) and tile index
    (int32), before any feature or pyramid made from it."""
    (th, tw), (rows, cols) = _tiles((int(shape[0]), int(shape[1])), int(n_rotations))
    channels = int(shape[2]) if len(shape) > 2 else 1
    return rows * th * cols * tw * (4 * channels + 12 + 1 + 4)


def build_rotated_dictionary(
    exemplar: np.ndarray,
    n_rotations: int,
    *,
    tensors: np.ndarray | None = None,
    sigma_d: float = 1.0,
    sigma_w: float = 3.0,
    order: int = 3,
) -> RotatedDictionary:
    """Rotate ``exemplar`` (and its tensor field) by ``2 pi m / M`` and lay the copies on one canvas.

    Parameters
    ----------
    exemplar : ndarray (h, w) or (h, w, 3), float32 in [0, 1]
    n_rotations : int
        ``M >= 1``; the angular step is ``360 / M`` degrees (the paper's 5 degrees: ``M = 72``).
    tensors : ndarray (h, w, 3), optional
        The exemplar's tensor field; computed with ``sigma_d``, ``sigma_w`` when not given.
    order : int
        Spline order of the intensity interpolation (3: bicubic, which blurs the grey-level
        histogram less than bilinear; values are clipped back to [0, 1]). Tensors are always
        interpolated linearly, which keeps them positive semi-definite.

    Returns
    -------
    RotatedDictionary
    """
    if not isinstance(n_rotations, int | np.integer) or n_rotations < 1:
        raise InvalidParameter("n_rotations", n_rotations, "must be a positive integer")
    ex = np.asarray(exemplar, dtype=np.float32)
    h, w = ex.shape[:2]
    channels = ex[..., None] if ex.ndim == 2 else ex
    field = structure_tensor(ex, sigma_d, sigma_w) if tensors is None else np.asarray(tensors, np.float32)
    m_count = int(n_rotations)
    angles = 2 * np.pi * np.arange(m_count) / m_count
    # Every copy's bounding box fits in a square of the exemplar's diagonal; the tile's sides keep
    # the exemplar's parity so that centres fall on pixels (copy 0 is then the exemplar, exactly).
    (th, tw), (rows, cols) = _tiles((h, w), m_count)
    H, W = rows * th, cols * tw
    image = np.zeros((H, W, channels.shape[2]), dtype=np.float32)
    tensors_out = np.zeros((H, W, 3), dtype=np.float32)
    area = np.zeros((H, W), dtype=bool)
    tile_index = np.full((H, W), -1, dtype=np.int32)
    lr, lc = np.mgrid[0:th, 0:tw]
    xp = lc - (tw - 1) / 2
    yp = (th - 1) / 2 - lr
    prefiltered = [
        ndi.spline_filter(channels[..., k], order=order, mode="mirror") for k in range(channels.shape[2])
    ]

    def warp(m: int) -> None:  # one vectorised warp per copy, into its own tile of the canvas
        phi = angles[m]
        # Inverse map: tile (x', y') -> exemplar (row, col), a rotation by -phi.
        c, s = np.cos(phi), np.sin(phi)
        src_r = (h - 1) / 2 - (-s * xp + c * yp)
        src_c = (c * xp + s * yp) + (w - 1) / 2
        coords = np.stack([src_r, src_c])
        r0, c0 = (m // cols) * th, (m % cols) * tw
        win = (slice(r0, r0 + th), slice(c0, c0 + tw))
        for k, band in enumerate(prefiltered):
            image[(*win, k)] = ndi.map_coordinates(band, coords, order=order, mode="mirror", prefilter=False)
        turned = rotate_tensors(field, phi)
        for k in range(3):
            tensors_out[(*win, k)] = ndi.map_coordinates(turned[..., k], coords, order=1, mode="mirror")
        eps = 1e-6  # rounding of the rotation must not drop the copies' border pixels
        area[win] = (src_r >= -eps) & (src_r <= h - 1 + eps) & (src_c >= -eps) & (src_c <= w - 1 + eps)
        tile_index[win] = m

    # SciPy's interpolation releases the GIL: the copies on the job's threads (disjoint tiles, same bytes).
    thread_map(warp, range(m_count), current_threads())
    np.clip(image, 0.0, 1.0, out=image)
    return RotatedDictionary(
        image=image,
        tensors=tensors_out,
        area=area,
        tile_index=tile_index,
        angles=angles,
        tile_shape=(th, tw),
        grid_columns=cols,
        exemplar_shape=(h, w),
    )


def rotation_candidates(
    target: np.ndarray, n_rotations: int, window: float, rng: np.random.Generator
) -> np.ndarray:
    """For every target orientation, one rotation index drawn among those within ``window``.

    A copy turned by ``phi_m`` matches orientation ``target`` when ``phi_m = target`` modulo ``pi``
    (a copy and its half-turn twin show the same orientations), so the allowed set is
    ``{m : |wrap(phi_m - target)| <= max(window, step / 2)}``: at least the nearest rotation (and its
    twin when ``M`` is even). One member is drawn uniformly per position (seeded).

    Parameters
    ----------
    target : ndarray
        Orientations (radians).
    n_rotations : int
    window : float
        Half-width (radians) of the allowed window.
    rng : numpy.random.Generator
    """
    step = 2 * np.pi / n_rotations
    half = max(float(window), step / 2)
    t = np.asarray(target, dtype=np.float64)
    # Rotations within the window modulo pi: offsets k*step around the nearest, plus the twins.
    span = int(np.floor(half / step + 1e-9))
    nearest = np.rint(wrap_angle(t) / step).astype(np.int64)
    offsets = np.arange(-span - 1, span + 2)
    cands = nearest[..., None] + offsets  # (..., K)
    ok = np.abs(wrap_angle(cands * step - t[..., None])) <= half + 1e-9
    ok[..., :] |= ~ok.any(axis=-1, keepdims=True) & (offsets == 0)
    counts = ok.sum(axis=-1)
    pick = np.floor(rng.random(t.shape) * counts).astype(np.int64)
    # Index of the pick-th allowed offset.
    rank = np.cumsum(ok, axis=-1) - 1
    chosen = np.where(ok & (rank == pick[..., None]), cands, 0).sum(axis=-1)
    twin = rng.random(t.shape) < 0.5
    if n_rotations % 2 == 0:
        chosen = np.where(twin, chosen + n_rotations // 2, chosen)
    return np.mod(chosen, n_rotations).astype(np.int64)
