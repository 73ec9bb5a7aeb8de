"""Measures of patch-based outputs: seam visibility and verbatim copies.

- **Seam visibility** (:func:`seam_visibility`): the mean squared grey-level difference across the patch
  boundaries (vertical differences in the horizontal overlap strips, horizontal differences in the
  vertical ones, the strip and the pixel pair just before it), divided by the same mean over the pixel pairs
  outside the strips. 1 = boundaries look like the interior; a visible seam raises it. The boundaries come
  from the layout a patch method reports in ``Result.stats['layout']``
  (:meth:`texsynth.synth.patch.layout.PatchLayout.describe`).
- **Verbatim copies** (:func:`copy_map`): for each output pixel, the RMS grey-level distance (per pixel,
  [0, 1] units) from the ``p x p`` patch around it to the nearest exemplar patch; :func:`copy_share` is the
  share of pixels below a small threshold (:data:`COPY_THRESHOLD`). The nearest patch is found in the
  first :data:`PCA_DIMS` principal components of the exemplar's patches with a k-d tree
  (:class:`scipy.spatial.cKDTree`, :data:`CANDIDATES` candidates), then its exact distance is computed: an
  exact copy (distance 0) is always found, and any other distance is an upper bound of the true one. Large
  outputs are measured on a grid of stride ``s`` (at most :data:`MAX_QUERIES` patches) and each pixel takes
  its nearest grid value. Colour images are measured on their grey (BT.601) levels.
- **Seam contrast** (:func:`seam_contrast`): for any method that knows where each pixel came from (the
  pixel methods' and quilting's source maps, :func:`texsynth.synth.evaluate.breaks.seams_from_sources`), the
  mean squared grey-level difference across the seam edges (neighbours whose sources are not neighbours the
  same way) over the mean across the other edges, and the share of coherent edges. A patchwork of copied
  regions whose borders show raises the ratio above 1; the exemplar's own, cut anywhere, is 1.
- **Tile seam** (:func:`tile_seam`): whether an output tiles. Laid 2 x 2, the image meets itself where its
  last row touches its first and its last column its first; the squared grey-level differences across
  those wrap-around pairs, each over the mean of the same direction's differences inside the image. 1 =
  the tile borders look like the interior (a tileable output); a visible seam raises it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.spatial import cKDTree

from texsynth.synth.colour import to_grey
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.threads import current_threads, thread_map

__all__ = [
    "CANDIDATES",
    "COPY_PATCH",
    "COPY_THRESHOLD",
    "MAX_QUERIES",
    "PCA_DIMS",
    "copy_map",
    "copy_share",
    "seam_contrast",
    "seam_visibility",
    "tile_seam",
]

#: Side of the patches compared by :func:`copy_map`, pixels.
COPY_PATCH = 7
#: RMS distance below which a pixel's patch counts as a verbatim copy (about 2.5 grey levels of 255).
COPY_THRESHOLD = 0.01
#: Principal components of the k-d tree search.
PCA_DIMS = 8
#: Candidates per query whose exact distance is computed.
CANDIDATES = 2
#: Distance in the PCA space within which :func:`copy_map` first looks for a verbatim copy (the rounding
#: of an exact copy's projection is about 1e-15).
_COPY_RADIUS = 1e-3
#: At most this many output patches are compared (a stride is chosen above it).
MAX_QUERIES = 128 * 128


def _grey(image: np.ndarray, role: str) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] == 3:
        arr = to_grey(arr, np.float64)
    if arr.ndim != 2:
        raise InvalidInput(role, f"expected a grey (H, W) or RGB (H, W, 3) image, got shape {arr.shape}")
    return arr.astype(np.float64, copy=False)


def seam_visibility(image: np.ndarray, layout: dict[str, Any]) -> dict[str, float]:
    """Gradient energy across patch boundaries over the interior's.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        A patch method's output.
    layout : dict
        ``Result.stats['layout']``: ``overlap``, ``seam_rows``, ``seam_cols``.

    Returns
    -------
    dict
        ``ratio`` (boundary / interior), ``boundary`` and ``interior`` mean squared differences.
    """
    grey = _grey(image, "image")
    overlap = int(layout["overlap"])
    dy = np.diff(grey, axis=0) ** 2  # dy[r] = pair (r, r + 1)
    dx = np.diff(grey, axis=1) ** 2
    in_y = np.zeros(dy.shape[0], dtype=bool)
    for r in layout["seam_rows"]:
        in_y[max(0, r - 1) : min(dy.shape[0], r + max(overlap, 1))] = True
    in_x = np.zeros(dx.shape[1], dtype=bool)
    for c in layout["seam_cols"]:
        in_x[max(0, c - 1) : min(dx.shape[1], c + max(overlap, 1))] = True
    boundary = np.concatenate([dy[in_y].ravel(), dx[:, in_x].ravel()])
    interior = np.concatenate([dy[~in_y].ravel(), dx[:, ~in_x].ravel()])
    b = float(boundary.mean()) if boundary.size else float("nan")
    i = float(interior.mean()) if interior.size else float("nan")
    return {"ratio": b / i if i > 0 else float("nan"), "boundary": b, "interior": i}


def copy_map(
    output: np.ndarray,
    exemplar: np.ndarray,
    patch: int = COPY_PATCH,
    max_queries: int = MAX_QUERIES,
) -> np.ndarray:
    """RMS distance from the patch around each output pixel to its nearest exemplar patch.

    Parameters
    ----------
    output, exemplar : ndarray, shape (H, W) or (H, W, 3)
        Images in [0, 1] (colour is compared on grey levels).
    patch : int
        Side of the compared patches.
    max_queries : int
        At most this many output patches are compared; a stride is used beyond it.

    Returns
    -------
    ndarray, float32, shape (H, W)
        0 where the output copies the exemplar verbatim; larger is further from any exemplar patch.
    """
    out, ex = _grey(output, "output"), _grey(exemplar, "exemplar")
    if patch < 1 or patch > min(*ex.shape, *out.shape):
        raise InvalidParameter(
            "patch", patch, f"must be between 1 and the images' smallest side ({ex.shape})"
        )
    ex_patches = sliding_window_view(ex, (patch, patch)).reshape(-1, patch * patch)
    mean = ex_patches.mean(axis=0)
    centred = ex_patches - mean
    dims = min(PCA_DIMS, patch * patch, len(ex_patches))
    _, vecs = np.linalg.eigh(centred.T @ centred)  # principal axes, ascending eigenvalues
    basis = np.ascontiguousarray(vecs[:, ::-1][:, :dims])
    tree = cKDTree(centred @ basis)
    valid = (out.shape[0] - patch + 1, out.shape[1] - patch + 1)
    stride = max(1, int(np.ceil(np.sqrt(valid[0] * valid[1] / max_queries))))
    ys, xs = np.arange(0, valid[0], stride), np.arange(0, valid[1], stride)
    # a strided view (the same windows as [ys][:, xs], without the copy of every row's windows that
    # the row indexing made first: 51 MB at 1024^2)
    windows = sliding_window_view(out, (patch, patch))[::stride, ::stride].reshape(-1, patch * patch)
    k = min(CANDIDATES, len(ex_patches))
    dist = np.empty(len(windows))

    def nearest(start: int) -> None:  # one block of queries: writes only its own slots
        q = windows[start : start + 2048]
        proj = (q - mean) @ basis
        block = dist[start : start + len(q)]
        # Verbatim copies first: a search within a hair of the query finds them at once, and their distance
        # is 0 whatever the other candidates are; the unbounded search around a copy spends most of its
        # time proving its second neighbour far (a quilted output is mostly copies).
        _, near = tree.query(proj, k=1, distance_upper_bound=_COPY_RADIUS)
        found = np.flatnonzero(near < tree.n)
        copies = found[((ex_patches[near[found]] - q[found]) ** 2).mean(axis=1) == 0]
        block[copies] = 0.0
        rest = np.setdiff1d(np.arange(len(q)), copies)
        if rest.size:
            _, idx = tree.query(proj[rest], k=k)
            idx = idx.reshape(len(rest), k)
            d = ((ex_patches[idx] - q[rest][:, None, :]) ** 2).mean(axis=2)
            block[rest] = np.sqrt(d.min(axis=1))

    # Blocks on the job's threads (the tree query and NumPy release the GIL): the same bytes on any count.
    blocks = range(0, len(windows), 2048)
    thread_map(nearest, blocks, current_threads())
    grid = dist.reshape(len(ys), len(xs))
    half = patch // 2
    iy = np.clip(np.rint((np.arange(out.shape[0]) - half) / stride).astype(int), 0, len(ys) - 1)
    ix = np.clip(np.rint((np.arange(out.shape[1]) - half) / stride).astype(int), 0, len(xs) - 1)
    return grid[np.ix_(iy, ix)].astype(np.float32)


def copy_share(distances: np.ndarray, threshold: float = COPY_THRESHOLD) -> float:
    """Share of pixels of a :func:`copy_map` closer than ``threshold`` to an exemplar patch."""
    return float(np.mean(np.asarray(distances) < threshold))


def seam_contrast(image: np.ndarray, seams: Any) -> dict[str, float]:
    """Gradient energy across the seams of a source map over the energy across coherent edges.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
    seams : :class:`texsynth.synth.evaluate.breaks.Seams`
        The cut 4-neighbour pairs (e.g. ``seams_from_sources(result.extras['source_map'])``).

    Returns
    -------
    dict
        ``ratio`` (seam / coherent mean squared difference; ``nan`` without seams or coherent edges),
        ``seam`` and ``coherent`` means, and ``coherent_share``, the share of 4-neighbour pairs that are
        not seams (1 = one verbatim copy, about 0 = every pixel from elsewhere).

    Examples
    --------
    >>> import numpy as np
    >>> from texsynth.synth.evaluate.breaks import seams_from_labels
    >>> img = np.tile(np.array([0.0, 0.1, 0.2, 0.9, 1.0, 1.1]), (4, 1))  # a jump between columns 2 and 3
    >>> out = seam_contrast(img, seams_from_labels(np.tile([0, 0, 0, 1, 1, 1], (4, 1))))
    >>> round(out["ratio"], 1), round(out["coherent_share"], 3)
    (104.1, 0.895)
    """
    grey = _grey(image, "image")
    if seams.shape != grey.shape:
        raise InvalidInput("seams", f"are for a {seams.shape} image, not {grey.shape}")
    dx = np.diff(grey, axis=1) ** 2
    dy = np.diff(grey, axis=0) ** 2
    cut = np.concatenate([dx[seams.across_cols], dy[seams.across_rows]])
    kept = np.concatenate([dx[~seams.across_cols], dy[~seams.across_rows]])
    seam = float(cut.mean()) if cut.size else float("nan")
    coherent = float(kept.mean()) if kept.size else float("nan")
    ratio = seam / coherent if cut.size and kept.size and coherent > 0 else float("nan")
    share = kept.size / max(cut.size + kept.size, 1)
    return {"ratio": ratio, "seam": seam, "coherent": coherent, "coherent_share": float(share)}


def tile_seam(image: np.ndarray) -> dict[str, float]:
    """Gradient energy across the borders of a 2 x 2 tiling over the interior's.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        An output meant to tile (``periodic=True``).

    Returns
    -------
    dict
        ``ratio``: the wrap-around pairs' squared differences, each over the mean squared difference of
        the pairs inside the image in the same direction, averaged over all ``H + W`` wrap pairs (1 = no
        seam; ``nan`` for a flat image); ``rows`` and ``cols``: the same for the horizontal border (last
        row against first) and the vertical one (last column against first) alone; ``rows_rank`` and
        ``cols_rank``: the share of the image's own lines of pairs (each row pair, each column pair) whose
        mean squared difference is below the border's. One line of pairs is a noisy sample (a periodic
        128 x 128 texture gives ratios of 0.6-1.4), so the ranks say whether the border stands out of the
        interior's own spread: about 0.5 for a seamless tiling, 1 for a seam stronger than any line inside.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.arange(16)
    >>> tri = np.abs(x - 8.0)  # a triangle wave: every step, the wrap included, is 1
    >>> round(tile_seam(tri[None, :] + tri[::2, None])["ratio"], 6)
    1.0
    >>> tile_seam(np.tile(x / 15.0, (8, 1)))["cols"] > 100  # a ramp jumps back at the border
    True
    """
    grey = _grey(image, "image")
    if min(grey.shape) < 2:
        raise InvalidInput("image", f"needs at least 2 x 2 pixels to tile, got {grey.shape}")
    line_y = np.mean(np.diff(grey, axis=0) ** 2, axis=1)  # one value per row pair
    line_x = np.mean(np.diff(grey, axis=1) ** 2, axis=0)  # one value per column pair
    inner_y, inner_x = float(line_y.mean()), float(line_x.mean())
    wrap_y = (grey[0] - grey[-1]) ** 2
    wrap_x = (grey[:, 0] - grey[:, -1]) ** 2
    rows = float(wrap_y.mean()) / inner_y if inner_y > 0 else float("nan")
    cols = float(wrap_x.mean()) / inner_x if inner_x > 0 else float("nan")
    ranks = {
        "rows_rank": float(np.mean(line_y < wrap_y.mean())),
        "cols_rank": float(np.mean(line_x < wrap_x.mean())),
    }
    if not (inner_y > 0 and inner_x > 0):
        return {"ratio": float("nan"), "rows": rows, "cols": cols, **ranks}
    ratio = (wrap_y.sum() / inner_y + wrap_x.sum() / inner_x) / (wrap_y.size + wrap_x.size)
    return {"ratio": float(ratio), "rows": rows, "cols": cols, **ranks}
