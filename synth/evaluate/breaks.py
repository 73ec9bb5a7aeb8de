"""Broken curvilinear features at patch boundaries (the claim of Wu & Yu 2004, measured).

Patch methods break curvilinear structures (lattice fringes, cell walls, fibre boundaries, cracks)
where two patches meet: a feature that runs into a seam either ends there (an **endpoint** of the
one-pixel-wide feature map, :func:`feature_endpoints`) or continues with a tangent jump (a **kink**: a
seam crossing, :func:`seam_crossings`, whose two sides' directions differ by more than ``KINK_ANGLE``
= 30 degrees over ``KINK_REACH`` = 3 px). Both are counted near the seams and compared with what the
texture itself does:

- **Seams**: 4-neighbour pixel pairs from different patches (:class:`Seams`, from a label map,
  :func:`seams_from_labels`, or a source map, :func:`seams_from_sources`); the **band** is the pixels
  within ``radius`` of a seam edge; a margin of ``radius + 1`` px along the border is left out.
- ``end_ratio``: endpoints per feature pixel in the band over the exemplar's endpoints per feature pixel;
- ``kink_ratio``: kinks per crossing at the seams over the same at the exemplar's virtual seams
  (``VIRTUAL_BLOCK`` px blocks at four offsets);
- ``ratio = (band endpoints + kinks) / (band feature pixels * exemplar end rate + crossings *
  exemplar kink rate)``: 1 = the seams break features no more often than the texture does.

Also reported: ``density_ratio``, ``per_length``, ``expected_per_length`` and ``interior_ratio`` (a
control away from the seams); their definitions and the reasons for each choice: docs/design.md
("broken features").

References
----------
Q. Wu, Y. Yu, "Feature matching and deformation for texture synthesis", ACM Transactions on Graphics
23(3) (Proc. SIGGRAPH 2004), pp. 364-367: "the presence of broken features at the boundary of two
adjacent patches" (abstract, sections 1 and 4), the claim this measures.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage as ndi
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from texsynth.synth.analysis.features import feature_map
from texsynth.synth.errors import InvalidInput, InvalidParameter

__all__ = [
    "KINK_ANGLE",
    "KINK_REACH",
    "SEAM_RADIUS",
    "VIRTUAL_BLOCK",
    "Seams",
    "broken_features",
    "broken_features_from_masks",
    "count_kinks",
    "feature_endpoints",
    "seam_crossings",
    "seams_from_labels",
    "seams_from_sources",
]

#: Endpoints within this many pixels of a seam count as broken there (the issue's "within 2 px").
SEAM_RADIUS = 2.0
#: A crossing whose two sides' directions differ by more than this (radians) is a kink.
KINK_ANGLE = float(np.radians(30.0))
#: The direction of each side is taken over this many pixels along the feature from the crossing.
KINK_REACH = 3
#: Side of the blocks whose boundaries are the virtual seams laid on the exemplar.
VIRTUAL_BLOCK = 16

_EIGHT = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], dtype=np.int64)


@dataclass(frozen=True)
class Seams:
    """Patch boundaries as cut 4-neighbour pairs.

    Attributes
    ----------
    across_cols : ndarray of bool, shape (H, W - 1)
        ``across_cols[r, c]``: pixels ``(r, c)`` and ``(r, c + 1)`` came from different patches.
    across_rows : ndarray of bool, shape (H - 1, W)
        ``across_rows[r, c]``: pixels ``(r, c)`` and ``(r + 1, c)`` came from different patches.
    """

    across_cols: np.ndarray
    across_rows: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.across_cols.shape[0]), int(self.across_rows.shape[1]))

    def pixels(self) -> np.ndarray:
        """Boolean ``(H, W)``: pixels on either side of a seam edge."""
        out = np.zeros(self.shape, dtype=bool)
        out[:, :-1] |= self.across_cols
        out[:, 1:] |= self.across_cols
        out[:-1, :] |= self.across_rows
        out[1:, :] |= self.across_rows
        return out


def seams_from_labels(labels: np.ndarray) -> Seams:
    """Seams between pixels of different patch labels (e.g. the index of the patch each pixel took).

    Examples
    --------
    >>> import numpy as np
    >>> s = seams_from_labels(np.array([[0, 0, 1], [0, 0, 1]]))
    >>> int(s.across_cols.sum()), int(s.across_rows.sum())
    (2, 0)
    """
    lab = np.asarray(labels)
    if lab.ndim != 2 or min(lab.shape) < 2:
        raise InvalidInput("labels", f"must be an (H, W) label map with H, W >= 2, got shape {lab.shape}")
    return Seams(across_cols=lab[:, 1:] != lab[:, :-1], across_rows=lab[1:, :] != lab[:-1, :])


def seams_from_sources(sources: np.ndarray, labels: np.ndarray | None = None) -> Seams:
    """Seams of a patch method from the exemplar position (row, col) each pixel was copied from.

    Two 4-neighbours lie on a seam when their sources are not 4-neighbours in the same direction
    (``quilting``'s ``Result.extras['source_map']``). With ``labels`` (the patch each pixel came
    from), two neighbours of one patch never lie on a seam: a patch deformed by a smooth warp is one
    piece, although its warped pixels are no verbatim copies; across patches the source rule
    decides, so a patch that happens to continue its neighbour verbatim makes no seam there, warped
    or not.

    Examples
    --------
    >>> import numpy as np
    >>> rows, cols = np.mgrid[0:2, 0:4]
    >>> src = np.stack([rows, cols], axis=-1); src[:, 2:] += 7     # the right half from elsewhere
    >>> int(seams_from_sources(src).across_cols.sum())
    2
    >>> int(seams_from_sources(src, labels=np.zeros((2, 4), int)).across_cols.sum())  # one patch
    0
    """
    src = np.asarray(sources)
    if src.ndim != 3 or src.shape[2] != 2 or min(src.shape[:2]) < 2:
        raise InvalidInput(
            "sources", f"must be an (H, W, 2) map of (row, col) positions, got shape {src.shape}"
        )
    s = src.astype(np.int64)
    across_cols = (s[:, 1:, 0] != s[:, :-1, 0]) | (s[:, 1:, 1] != s[:, :-1, 1] + 1)
    across_rows = (s[1:, :, 0] != s[:-1, :, 0] + 1) | (s[1:, :, 1] != s[:-1, :, 1])
    if labels is not None:
        lab = np.asarray(labels)
        if lab.shape != src.shape[:2]:
            raise InvalidInput("labels", f"shape {lab.shape} does not match the sources {src.shape[:2]}")
        across_cols &= lab[:, 1:] != lab[:, :-1]
        across_rows &= lab[1:, :] != lab[:-1, :]
    return Seams(across_cols=across_cols, across_rows=across_rows)


def _pieces(seams: Seams) -> np.ndarray:
    """Label of the piece each pixel lies in: 4-connected pixels not separated by a seam edge."""
    h, w = seams.shape
    idx = np.arange(h * w).reshape(h, w)
    a = np.concatenate([idx[:, :-1][~seams.across_cols], idx[:-1, :][~seams.across_rows]])
    b = np.concatenate([idx[:, 1:][~seams.across_cols], idx[1:, :][~seams.across_rows]])
    graph = coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(h * w, h * w))
    return connected_components(graph, directed=False)[1].reshape(h, w)


_STEPS = ((0, 1), (1, -1), (1, 0), (1, 1))  # half of the 8-neighbourhood: each pair once


def seam_crossings(mask: np.ndarray, seams: Seams) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """Where features cross seams: one pair ``(a, b)`` of 8-neighbouring feature pixels per crossing.

    ``a`` and ``b`` lie in different pieces (:class:`Seams` cut the image into pieces); pairs that
    touch (8-connected pixels) belong to one crossing, represented by its first pair in raster order.

    Examples
    --------
    >>> import numpy as np
    >>> m = np.zeros((5, 8), dtype=bool); m[2, :] = True          # a line across ...
    >>> lab = np.zeros((5, 8), int); lab[:, 4:] = 1                # ... a vertical seam
    >>> seam_crossings(m, seams_from_labels(lab))
    [((2, 3), (2, 4))]
    """
    m = np.asarray(mask)
    if m.ndim != 2 or m.dtype != bool or m.shape != seams.shape:
        raise InvalidInput(
            "mask", f"must be a boolean feature mask of shape {seams.shape}, got {m.dtype} {m.shape}"
        )
    piece = _pieces(seams)
    h, w = m.shape
    pairs: list[tuple[tuple[int, int], tuple[int, int]]] = []
    touched = np.zeros(m.shape, dtype=bool)
    for dr, dc in _STEPS:
        r0, r1 = 0, h - dr
        c0, c1 = max(0, -dc), w - max(0, dc)
        a = m[r0:r1, c0:c1] & m[r0 + dr : r1 + dr, c0 + dc : c1 + dc]
        a &= piece[r0:r1, c0:c1] != piece[r0 + dr : r1 + dr, c0 + dc : c1 + dc]
        for r, c in np.argwhere(a):
            pa, pb = (int(r + r0), int(c + c0)), (int(r + r0 + dr), int(c + c0 + dc))
            pairs.append((pa, pb))
            touched[pa] = touched[pb] = True
    if not pairs:
        return []
    groups, _ = ndi.label(touched, structure=np.ones((3, 3), dtype=bool))
    first: dict[int, tuple[tuple[int, int], tuple[int, int]]] = {}
    for pa, pb in sorted(pairs):
        first.setdefault(int(groups[pa]), (pa, pb))
    return [first[g] for g in sorted(first, key=lambda g: first[g])]


def _side(mask: np.ndarray, piece: np.ndarray, start: tuple[int, int], reach: int) -> np.ndarray:
    """Feature pixels reached from ``start`` within ``reach`` 8-steps along the mask, inside its piece."""
    h, w = mask.shape
    own = piece[start]
    seen = {start}
    frontier = [start]
    for _ in range(reach):
        nxt = []
        for r, c in frontier:
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    q = (r + dr, c + dc)
                    if 0 <= q[0] < h and 0 <= q[1] < w and q not in seen and mask[q] and piece[q] == own:
                        seen.add(q)
                        nxt.append(q)
        frontier = nxt
    return np.array(sorted(seen), dtype=np.float64)


def _direction(points: np.ndarray) -> np.ndarray:
    """Principal direction (unit vector) of a set of pixel centres."""
    centred = points - points.mean(axis=0)
    _, vecs = np.linalg.eigh(centred.T @ centred)
    return vecs[:, -1]


def count_kinks(
    mask: np.ndarray,
    seams: Seams,
    *,
    angle: float = KINK_ANGLE,
    reach: int = KINK_REACH,
    region: np.ndarray | None = None,
) -> tuple[int, int]:
    """Crossings of features over seams, and how many of them are kinks (module docstring).

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
        One-pixel-wide features.
    seams : Seams
    angle : float
        Largest turn (radians) of a feature that continues smoothly across a seam.
    reach : int
        Pixels followed along the feature on each side; a side with fewer than ``reach`` pixels
        beyond the crossing pixel does not continue (its end, if near the seam, is an endpoint).
    region : ndarray of bool, shape (H, W), optional
        Count only crossings whose first pixel lies here (e.g. away from the image's frame).

    Returns
    -------
    (crossings, kinks) : (int, int)
        Crossings where the feature continues on both sides, and those of them that turn by more
        than ``angle``.

    Examples
    --------
    >>> import numpy as np
    >>> lab = np.zeros((9, 12), int); lab[:, 6:] = 1
    >>> m = np.zeros((9, 12), dtype=bool); m[4, :6] = True
    >>> m[[3, 2, 1, 0], [6, 7, 8, 9]] = True                       # turns 45 degrees at the seam
    >>> count_kinks(m, seams_from_labels(lab))
    (1, 1)
    """
    m = np.asarray(mask)
    if not (isinstance(angle, int | float) and 0 <= angle <= np.pi / 2):
        raise InvalidParameter("angle", angle, "must be in [0, pi/2] radians")
    if not (isinstance(reach, int) and reach >= 1):
        raise InvalidParameter("reach", reach, "must be an integer >= 1")
    crossings = seam_crossings(m, seams)
    piece = _pieces(seams)
    n_cross = n_kink = 0
    cos_limit = np.cos(angle)
    for a, b in crossings:
        if region is not None and not region[a]:
            continue
        side_a = _side(m, piece, a, reach)
        side_b = _side(m, piece, b, reach)
        if len(side_a) < reach + 1 or len(side_b) < reach + 1:
            continue
        n_cross += 1
        if abs(float(_direction(side_a) @ _direction(side_b))) < cos_limit - 1e-12:
            n_kink += 1
    return n_cross, n_kink


def feature_endpoints(mask: np.ndarray) -> np.ndarray:
    """Feature pixels with at most one 8-neighbour on the mask: free ends and isolated pixels.

    Examples
    --------
    >>> import numpy as np
    >>> m = np.zeros((5, 7), dtype=bool); m[2, 1:6] = True; m[0, 0] = True
    >>> np.argwhere(feature_endpoints(m)).tolist()
    [[0, 0], [2, 1], [2, 5]]
    """
    m = np.asarray(mask)
    if m.ndim != 2 or m.dtype != bool:
        raise InvalidInput("mask", f"must be a boolean (H, W) feature mask, got {m.dtype} {m.shape}")
    neighbours = ndi.convolve(m.astype(np.int64), _EIGHT, mode="constant", cval=0)
    return m & (neighbours <= 1)


def _interior(shape: tuple[int, int], margin: int) -> np.ndarray:
    inner = np.zeros(shape, dtype=bool)
    if shape[0] > 2 * margin and shape[1] > 2 * margin:
        inner[margin : shape[0] - margin, margin : shape[1] - margin] = True
    return inner


def broken_features_from_masks(
    output_mask: np.ndarray,
    exemplar_mask: np.ndarray,
    seams: Seams,
    *,
    radius: float = SEAM_RADIUS,
) -> dict[str, float]:
    """The broken-feature measure (module docstring) from feature masks already computed.

    Parameters
    ----------
    output_mask : ndarray of bool, shape (H, W)
        One-pixel-wide features of the output.
    exemplar_mask : ndarray of bool, shape (h, w)
        Those of the exemplar (same detector and options).
    seams : Seams
        The output's patch boundaries, shape (H, W).
    radius : float
        Endpoints whose centre lies within this many pixels of a seam edge count as broken there.

    Returns
    -------
    dict
        ``ratio`` (band endpoints and seam kinks over the number the exemplar's end and kink rates
        predict; NaN when nothing is expected), ``end_ratio``, ``kink_ratio``, ``density_ratio``
        (band endpoint density per pixel / the exemplar's), ``seam_kinks``, ``seam_crossings``,
        ``band_features``, ``exemplar_end_rate`` (endpoints per feature pixel),
        ``exemplar_kink_rate`` (kinks per crossing of the virtual seams), ``per_length``,
        ``expected_per_length``, ``interior_ratio``, ``seam_endpoints``, ``seam_length``,
        ``band_pixels``, ``exemplar_density`` (endpoints per pixel).
    """
    if not (isinstance(radius, int | float) and np.isfinite(radius) and radius >= 0.5):
        raise InvalidParameter("radius", radius, "must be a finite number of pixels >= 0.5")
    out = np.asarray(output_mask)
    if out.shape != seams.shape:
        raise InvalidInput("seams", f"shape {seams.shape} does not match the output {out.shape}")
    margin = int(np.ceil(radius)) + 1
    out_inner = _interior(out.shape, margin)
    ex = np.asarray(exemplar_mask)
    ex_inner = _interior(ex.shape, margin)
    if not ex_inner.any():
        raise InvalidInput("exemplar", f"is too small ({ex.shape}) for a border margin of {margin} px")
    ex_ends = feature_endpoints(ex) & ex_inner
    rho_ex = float(ex_ends.sum()) / float(ex_inner.sum())
    ex_features = int((ex & ex_inner).sum())
    end_rate_ex = float(ex_ends.sum()) / ex_features if ex_features else float("nan")
    rows, cols = np.mgrid[0 : ex.shape[0], 0 : ex.shape[1]]
    ex_cross = ex_kinks = 0
    for shift in range(0, VIRTUAL_BLOCK, VIRTUAL_BLOCK // 4):  # four grids, for more crossings
        blocks = (rows + shift) // VIRTUAL_BLOCK * (ex.shape[1] + 1) + (cols + shift) // VIRTUAL_BLOCK
        crossed, kinked = count_kinks(ex, seams_from_labels(blocks), region=ex_inner)
        ex_cross, ex_kinks = ex_cross + crossed, ex_kinks + kinked
    kink_rate_ex = ex_kinks / ex_cross if ex_cross else float("nan")

    seam_px = seams.pixels()
    if seam_px.any():
        band = ndi.distance_transform_edt(~seam_px) <= radius - 0.5
    else:
        band = np.zeros(out.shape, dtype=bool)
    band &= out_inner
    rest = out_inner & ~band
    ends = feature_endpoints(out)
    # seam length: cut edges whose two pixels are both inside the counted area
    length = float((seams.across_cols & out_inner[:, 1:] & out_inner[:, :-1]).sum()) + float(
        (seams.across_rows & out_inner[1:, :] & out_inner[:-1, :]).sum()
    )
    n_band = int(band.sum())
    e_band = int((ends & band).sum())
    f_band = int((out & band).sum())
    crossings, kinks = count_kinks(out, seams, region=out_inner)
    density_band = e_band / n_band if n_band else float("nan")
    density_rest = float((ends & rest).sum()) / float(rest.sum()) if rest.any() else float("nan")
    nan = float("nan")
    end_ratio = (e_band / f_band) / end_rate_ex if f_band and end_rate_ex > 0 else nan
    kink_ratio = (kinks / crossings) / kink_rate_ex if crossings and kink_rate_ex > 0 else nan
    expected = f_band * end_rate_ex + crossings * (kink_rate_ex if np.isfinite(kink_rate_ex) else 0.0)
    return {
        "ratio": (e_band + kinks) / expected if expected > 0 else nan,
        "end_ratio": end_ratio,
        "kink_ratio": kink_ratio,
        "density_ratio": density_band / rho_ex if rho_ex > 0 and n_band else nan,
        "seam_kinks": float(kinks),
        "seam_crossings": float(crossings),
        "band_features": float(f_band),
        "exemplar_end_rate": end_rate_ex,
        "exemplar_kink_rate": kink_rate_ex,
        "per_length": e_band / length if length else nan,
        "expected_per_length": rho_ex * n_band / length if length else nan,
        "interior_ratio": density_rest / rho_ex if rho_ex > 0 else nan,
        "seam_endpoints": float(e_band),
        "seam_length": length,
        "band_pixels": float(n_band),
        "exemplar_density": rho_ex,
    }


def broken_features(
    output: np.ndarray,
    exemplar: np.ndarray,
    seams: Seams,
    *,
    radius: float = SEAM_RADIUS,
    **feature_options: Any,
) -> dict[str, float]:
    """Broken features at patch boundaries: endpoints near seams against the exemplar's endpoint density.

    Parameters
    ----------
    output : ndarray, shape (H, W) or (H, W, 3)
        A patch method's output, in [0, 1].
    exemplar : ndarray, shape (h, w) or (h, w, 3)
        Its exemplar.
    seams : Seams
        The output's patch boundaries (:func:`seams_from_labels`, :func:`seams_from_sources`).
    radius : float
        Endpoints within this many pixels of a seam count (default :data:`SEAM_RADIUS` = 2).
    **feature_options
        Options of :func:`texsynth.synth.analysis.features.feature_map` (``features``, ``polarity``,
        ``presmooth``, ...), the same for both images.

    Returns
    -------
    dict
        See :func:`broken_features_from_masks`.
    """
    out_map = feature_map(output, **feature_options)
    ex_map = feature_map(exemplar, **feature_options)
    return broken_features_from_masks(out_map.mask, ex_map.mask, seams, radius=radius)
