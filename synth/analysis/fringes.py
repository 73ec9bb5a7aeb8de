"""HRTEM lattice-fringe morphology: extract fringes, measure their length and tortuosity.

The fringe analysis materials scientists run on HRTEM images of soot and dense carbons
(Yehliu et al. 2011; Botero et al. 2016, 2019), and the morphological part of the benchmark of the
volumetric-synthesis study (Urs et al. 2012, section 3.2, Fig. 10):

1. **band-pass**: a Gaussian low-pass (``sigma``), then a morphological bottom-hat with a disk of
   radius ``background`` (Botero's choice) or a difference of Gaussians; fringes are dark lines
   (``polarity='dark'``);
2. **threshold** at Otsu's level times ``threshold_factor`` (Botero's ``bw_fac``), or a fixed value;
3. **skeletonise**; 4. **prune** branches shorter than ``min_length``; 5. **break junctions**, so every
   piece is a simple path (a *fringe*) or a closed loop;
6. **measure**: length along the skeleton (axial steps 1, diagonal sqrt(2)), tortuosity = length /
   end-to-end distance; 7. **drop** fringes shorter than ``min_length``.

The skeleton is read as a graph whose diagonal links count only where no pixel bridges them, so "more
than two neighbours" means a real junction and a drawn straight line has exactly its drawn length
(docs/design.md, "fringes": the rule and its reasons).

Departures: no histogram equalisation and branch pruning instead of Botero's T/Y/H repair; closed
loops counted (``n_loops``) and left out of the distributions; fringes cut by the border kept;
digitised oblique lines measure a tortuosity slightly above 1 (docs/design.md, docs/evaluation.md).

References
----------
R. D. Urs et al., "Non-parametric synthesis of laminar volumetric textures from a 2D sample", BMVC 2012.
M. L. Botero et al., "HRTEM evaluation of soot particles produced by the non-premixed combustion of
liquid fuels", Carbon 96 (2016) 459-473; "Internal structure of soot particles in a diffusion flame",
Carbon 141 (2019) 635-642. K. Yehliu, R. L. Vander Wal, A. L. Boehman, "Development of an HRTEM image
analysis method to quantify carbon nanostructure", Combust. Flame 158(9) (2011) 1837-1851.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from skimage.filters import threshold_otsu
from skimage.morphology import black_tophat, disk, skeletonize, white_tophat

from texsynth.synth.analysis.split import gaussian_filter
from texsynth.synth.analysis.tensor import wrap_angle
from texsynth.synth.errors import InvalidInput, InvalidParameter

__all__ = [
    "MIN_LENGTH",
    "TORTUOUS",
    "Fringes",
    "extract_fringes",
    "extract_fringes_stack",
    "fringe_band_pass",
    "fringe_summary",
    "measure_skeleton",
]

#: Tortuosity above which a fringe counts as highly tortuous (Botero et al. 2016, "FT > 1.5").
TORTUOUS = 1.5
#: Default minimum fringe (and branch) length, pixels: 0.5 nm at 18 px/nm, close to the usual
#: 0.483 nm cut-off of Yehliu et al. (2011), the size of two aromatic rings.
MIN_LENGTH = 9.0

FilterName = Literal["bottom-hat", "dog"]
Polarity = Literal["dark", "bright"]

_SQRT2 = float(np.sqrt(2.0))
#: Branch pruning stops after this many rounds (each round removes the branches that are short
#: *now*; a second round catches branches that appear when a junction dissolves).
_PRUNE_ROUNDS = 4  # texsynth.synth.kernels.fringe_graph.PRUNE_ROUNDS (a test holds them equal)


@dataclass(frozen=True)
class Fringes:
    """The fringes of one image: per-fringe measures and the images to draw them.

    Attributes
    ----------
    lengths : ndarray, shape (n,)
        Path length of each fringe along its skeleton, in pixels.
    end_to_end : ndarray, shape (n,)
        Euclidean distance between the centres of the fringe's two end pixels, in pixels.
    tortuosity : ndarray, shape (n,)
        ``lengths / end_to_end`` (>= 1).
    orientation : ndarray, shape (n,)
        Direction of the end-to-end chord, radians counter-clockwise from +x with ``y`` up,
        wrapped to ``(-pi/2, pi/2]`` (the fringe direction, not the gradient's).
    endpoints : ndarray, shape (n, 2, 2)
        ``(row, col)`` of the two end pixels of each fringe.
    labels : ndarray of int32, shape (H, W)
        Skeleton pixels of fringe ``i`` hold ``i + 1``; 0 elsewhere (for overlays).
    binary : ndarray of bool, shape (H, W)
        The thresholded band-pass response, before skeletonisation.
    n_loops : int
        Closed skeleton loops left out of the measures.
    pixel_size : float or None
        Nanometres per pixel, when known.
    """

    lengths: np.ndarray
    end_to_end: np.ndarray
    tortuosity: np.ndarray
    orientation: np.ndarray
    endpoints: np.ndarray
    labels: np.ndarray = field(repr=False)
    binary: np.ndarray = field(repr=False)
    n_loops: int = 0
    pixel_size: float | None = None

    @property
    def count(self) -> int:
        """Number of fringes measured."""
        return len(self.lengths)

    @property
    def skeleton(self) -> np.ndarray:
        """Boolean image of the measured fringes' skeleton pixels."""
        return self.labels > 0

    @property
    def lengths_nm(self) -> np.ndarray | None:
        """Fringe lengths in nanometres, or ``None`` without a pixel size."""
        return None if self.pixel_size is None else self.lengths * self.pixel_size

    def summary(self) -> dict[str, float | int | None]:
        """Count, mean/median length, median tortuosity and share above :data:`TORTUOUS`.

        Lengths are in pixels, and also in nm (``*_nm`` keys) when the pixel size is known; values
        that do not exist (no fringe) are ``None``.
        """
        return fringe_summary(self.lengths, self.tortuosity, self.pixel_size)


def fringe_summary(
    lengths: np.ndarray, tortuosity: np.ndarray, pixel_size: float | None = None
) -> dict[str, float | int | None]:
    """Summary statistics of a set of fringes (see :meth:`Fringes.summary`)."""
    n = len(lengths)
    out: dict[str, float | int | None] = {
        "count": int(n),
        "mean_length": float(np.mean(lengths)) if n else None,
        "median_length": float(np.median(lengths)) if n else None,
        "mean_tortuosity": float(np.mean(tortuosity)) if n else None,
        "median_tortuosity": float(np.median(tortuosity)) if n else None,
        "share_tortuous": float(np.mean(tortuosity > TORTUOUS)) if n else None,
    }
    if pixel_size is not None:
        for key in ("mean_length", "median_length"):
            value = out[key]
            out[f"{key}_nm"] = None if value is None else float(value) * pixel_size
    return out


def _check_positive(name: str, value: float) -> float:
    if not (np.isfinite(value) and value > 0):
        raise InvalidParameter(name, value, "must be a positive, finite number")
    return float(value)


def fringe_band_pass(
    image: np.ndarray,
    *,
    filter: FilterName = "bottom-hat",
    sigma: float = 1.0,
    background: float = 3.0,
    polarity: Polarity = "dark",
) -> np.ndarray:
    """Band-pass response of a grey image in which fringes of the chosen polarity are high.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (N, H, W)
        Grey image, or a stack of them (each filtered alone, bit for bit as on its own).
    filter : {'bottom-hat', 'dog'}
        ``'bottom-hat'``: Gaussian low-pass of scale ``sigma``, then a bottom-hat (closing minus
        image) with a disk of radius ``background`` pixels (a top-hat for bright fringes);
        ``'dog'``: ``G(sigma) - G(background)``, negated for dark fringes.
    sigma : float
        Scale of the low-pass Gaussian, in pixels (removes noise finer than the fringes).
    background : float
        Disk radius (bottom-hat) or Gaussian scale (DoG) of the background, in pixels: larger
        than half the fringe width, about half the fringe spacing.
    polarity : {'dark', 'bright'}
        Whether fringes are darker (HRTEM lattice fringes) or brighter than their surroundings.

    Returns
    -------
    ndarray of float64, the shape of ``image``
        High on fringes.
    """
    img = np.asarray(image, dtype=np.float64)
    _check_positive("sigma", sigma)
    _check_positive("background", background)
    if polarity not in ("dark", "bright"):
        raise InvalidParameter("polarity", polarity, "must be 'dark' or 'bright'")
    # a stack (N, H, W) is filtered image by image: along its last two axes only
    planes = (-2, -1)
    low = gaussian_filter(img, sigma, mode="reflect", axes=planes)
    if filter == "bottom-hat":
        footprint = disk(max(1, round(background)))
        tophat = black_tophat if polarity == "dark" else white_tophat
        return tophat(low, footprint if img.ndim == 2 else footprint[None])
    if filter == "dog":
        dog = low - gaussian_filter(img, background, mode="reflect", axes=planes)
        return -dog if polarity == "dark" else dog
    raise InvalidParameter("filter", filter, "must be 'bottom-hat' or 'dog'")


def _shifted(mask: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """``out[r, c] = mask[r + dy, c + dx]``, False outside the image."""
    h, w = mask.shape
    out = np.zeros_like(mask)
    out[max(0, -dy) : h - max(0, dy), max(0, -dx) : w - max(0, dx)] = mask[
        max(0, dy) : h - max(0, -dy), max(0, dx) : w - max(0, -dx)
    ]
    return out


def _skeleton_edges(
    skel: np.ndarray, index: np.ndarray, *, thin: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edges ``(i, j, weight)`` between skeleton pixels, each pair once.

    With ``thin=True`` a diagonal pair is linked only when neither of the two pixels that would
    bridge it through 4-neighbour steps is on the skeleton (module docstring).
    """
    src, dst, wts = [], [], []
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        pair = skel & _shifted(skel, dy, dx)
        if dy and dx and thin:
            # bridges of (r, c)-(r+1, c+dx): (r, c+dx) and (r+1, c)
            pair &= ~_shifted(skel, 0, dx) & ~_shifted(skel, 1, 0)
        rows, cols = np.nonzero(pair)
        src.append(index[rows, cols])
        dst.append(index[rows + dy, cols + dx])
        wts.append(np.full(len(rows), _SQRT2 if dy and dx else 1.0))
    return np.concatenate(src), np.concatenate(dst), np.concatenate(wts)


def _degrees(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    return np.bincount(src, minlength=n) + np.bincount(dst, minlength=n)


def _components(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _index(skel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows, cols = np.nonzero(skel)
    index = np.full(skel.shape, -1, dtype=np.int64)
    index[rows, cols] = np.arange(len(rows))
    return rows, cols, index


def _prune_branches(skel: np.ndarray, min_length: float) -> np.ndarray:
    """Remove branches (free end to junction) shorter than ``min_length``; returns a new skeleton.

    The plain reference of :func:`texsynth.synth.kernels.fringe_graph.skeleton_paths`'s pruning (tests).
    """
    skel = skel.copy()
    for _ in range(_PRUNE_ROUNDS):
        rows, cols, index = _index(skel)
        n = len(rows)
        src, dst, wts = _skeleton_edges(skel, index, thin=True)
        degree = _degrees(n, src, dst)
        junction = degree > 2
        if not junction.any():
            break
        inner = ~junction[src] & ~junction[dst]
        seg = _components(n, src[inner], dst[inner])
        n_seg = int(seg.max()) + 1 if n else 0
        # a segment's length counts its own steps plus the step onto the junction
        # (astype: with no inner step at all, bincount gives integers and the += below would raise)
        seg_len = np.bincount(seg[src[inner]], weights=wts[inner], minlength=n_seg).astype(np.float64)
        cross = junction[src] ^ junction[dst]
        outer = np.where(junction[src[cross]], dst[cross], src[cross])
        seg_len += np.bincount(seg[outer], weights=wts[cross], minlength=n_seg)
        touches = np.bincount(seg[outer], minlength=n_seg) > 0
        free = np.bincount(seg[(degree <= 1) & ~junction], minlength=n_seg) > 0
        spur = touches & free & (seg_len < min_length)
        doomed = spur[seg] & ~junction
        if not doomed.any():
            break
        skel[rows[doomed], cols[doomed]] = False
    return skel


def _measure(skel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Break junctions and measure the pieces (the plain reference of the kernel's measure; tests).

    Returns ``(labels_per_pixel, rows, cols, lengths, endpoint_pairs, n_loops)`` where
    ``labels_per_pixel`` gives each remaining skeleton pixel its path's id (-1 for removed or loop
    pixels) and ``endpoint_pairs`` has shape (n, 2) (pixel indices).
    """
    rows, cols, index = _index(skel)
    n = len(rows)
    src, dst, _ = _skeleton_edges(skel, index, thin=True)
    junction = _degrees(n, src, dst) > 2
    keep = ~junction[src] & ~junction[dst]
    src, dst = src[keep], dst[keep]
    comp = _components(n, src, dst)
    comp[junction] = -1
    degree = _degrees(n, src, dst)

    # end pixels of each path: degree <= 1 (degree 0 is a one-pixel piece, both its ends)
    ends = np.flatnonzero((degree <= 1) & ~junction)
    order = ends[np.argsort(comp[ends], kind="stable")]
    path_ids, first = np.unique(comp[order], return_index=True)
    last = len(order) - 1 - np.unique(comp[order][::-1], return_index=True)[1]
    pairs = np.stack([order[first], order[last]], axis=1)
    n_pieces = len(np.unique(comp[comp >= 0]))
    n_loops = n_pieces - len(path_ids)

    # path length: shortest path between the two ends on the full 8-neighbourhood graph of the piece
    fsrc, fdst, fwts = _skeleton_edges(skel, index, thin=False)
    same = (comp[fsrc] == comp[fdst]) & (comp[fsrc] >= 0)
    graph = coo_matrix((fwts[same], (fsrc[same], fdst[same])), shape=(n, n)).tocsr()
    if len(pairs):
        dist = dijkstra(graph, directed=False, indices=pairs[:, 0], min_only=True)
        lengths = dist[pairs[:, 1]]
    else:
        lengths = np.zeros(0)
    # pixels of loops get -1 too: only paths are fringes
    is_path = np.zeros(int(comp.max()) + 1 if n else 0, dtype=bool)
    is_path[path_ids] = True
    pixel_path = np.where((comp >= 0) & is_path[np.maximum(comp, 0)], comp, -1)
    remap = np.full(len(is_path), -1, dtype=np.int64)
    remap[path_ids] = np.arange(len(path_ids))
    pixel_path = np.where(pixel_path >= 0, remap[np.maximum(pixel_path, 0)], -1)
    return pixel_path, rows, cols, lengths, pairs, n_loops


#: Above this many pixels a skeleton is measured by the numba kernel even when numba is not yet loaded
#: (its first use in a process costs about 0.3 s; a 64^2 skeleton costs 2 ms in NumPy, 0.1 ms in the kernel).
_KERNEL_PIXELS = 1 << 18


def _skeleton_paths(
    skel: np.ndarray, min_length: float, prune: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Prune and measure: :func:`texsynth.synth.kernels.fringe_graph.skeleton_paths` (nogil, one call), or
    its plain reference (:func:`_prune_branches`, :func:`_measure`) where numba is not loaded yet and the
    image is small. The two give the same results (tested), so the choice never changes a metric."""
    prune = bool(prune and min_length > 0)
    if "numba" in sys.modules or skel.size >= _KERNEL_PIXELS:
        from texsynth.synth.kernels.fringe_graph import skeleton_paths

        return skeleton_paths(np.ascontiguousarray(skel), float(min_length), prune)
    if prune:
        skel = _prune_branches(skel, min_length)
    return (skel, *_measure(skel))


def extract_fringes(
    image: np.ndarray,
    *,
    filter: FilterName = "bottom-hat",
    sigma: float = 1.0,
    background: float = 3.0,
    polarity: Polarity = "dark",
    threshold: Literal["otsu"] | float = "otsu",
    threshold_factor: float = 1.0,
    min_length: float = MIN_LENGTH,
    pixel_size: float | None = None,
) -> Fringes:
    """Extract the lattice fringes of a grey HRTEM image and measure their length and tortuosity.

    Parameters
    ----------
    image : ndarray, shape (H, W)
        Grey image in [0, 1] (convert RGB to grey first).
    filter : {'bottom-hat', 'dog'}
        Band-pass filter, see :func:`fringe_band_pass`.
    sigma : float
        Low-pass Gaussian scale, pixels. The default 1 suits fringes ~6-7 px apart (graphitic
        0.34-0.4 nm spacing at 18 px/nm).
    background : float
        Bottom-hat disk radius or DoG background scale, pixels (about half the fringe spacing).
    polarity : {'dark', 'bright'}
        Fringe polarity; lattice fringes are dark in these HRTEM images.
    threshold : 'otsu' or float
        ``'otsu'``: Otsu's threshold of the filter response; a number: that response value.
    threshold_factor : float
        Multiplies the threshold (Botero's ``bw_fac``: above 1 keeps only the strongest fringes).
    min_length : float
        Branches and fringes shorter than this (pixels) are removed; default :data:`MIN_LENGTH`.
    pixel_size : float, optional
        Nanometres per pixel, to report lengths in nm.

    Returns
    -------
    Fringes
        Per-fringe lengths, end-to-end distances, tortuosities, chord orientations, and the label
        image; fringes are numbered in raster order of their first pixel.

    Notes
    -----
    Length ``L`` is the 8-connected path length between the end pixels (axial step 1, diagonal step
    ``sqrt(2)``) and tortuosity is ``L / |e1 - e2|`` (Botero et al. 2016; Urs et al. 2012,
    section 3.2). See the module docstring for the steps and the skeleton graph.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.ones((32, 32))
    >>> img[16, 4:28] = 0.0                         # one dark line, 24 pixels: 23 px centre to centre
    >>> f = extract_fringes(img)
    >>> f.count, float(f.lengths[0]), float(f.tortuosity[0])
    (1, 23.0, 1.0)
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise InvalidInput("image", f"fringe analysis needs a grey (H, W) image, got shape {img.shape}")
    return extract_fringes_stack(
        img[None],
        filter=filter,
        sigma=sigma,
        background=background,
        polarity=polarity,
        threshold=threshold,
        threshold_factor=threshold_factor,
        min_length=min_length,
        pixel_size=pixel_size,
    )[0]


def extract_fringes_stack(
    images: np.ndarray,
    *,
    filter: FilterName = "bottom-hat",
    sigma: float = 1.0,
    background: float = 3.0,
    polarity: Polarity = "dark",
    threshold: Literal["otsu"] | float = "otsu",
    threshold_factor: float = 1.0,
    min_length: float = MIN_LENGTH,
    pixel_size: float | None = None,
) -> list[Fringes]:
    """:func:`extract_fringes` of each image of a stack ``(N, H, W)`` (the same options, the same results).

    The band-pass runs on the whole stack in a few long filter calls (each image filtered alone, bit for
    bit); the threshold, skeleton and measures follow image by image. A volume's evaluation extracts the
    fringes of a run of slices this way, with fewer of the short calls that hold the GIL.
    """
    img = np.asarray(images)
    if img.ndim != 3:
        raise InvalidInput("image", f"fringe analysis needs grey (H, W) images, got shape {img.shape[1:]}")
    if img.size == 0 or not np.isfinite(img).all():
        raise InvalidInput("image", "is empty or holds NaN/inf values")
    if not (np.isfinite(min_length) and min_length >= 0):
        raise InvalidParameter("min_length", min_length, "must be a finite number of pixels >= 0")
    _check_positive("threshold_factor", threshold_factor)
    if pixel_size is not None:
        _check_positive("pixel_size", pixel_size)

    responses = fringe_band_pass(img, filter=filter, sigma=sigma, background=background, polarity=polarity)
    if isinstance(threshold, str) and threshold != "otsu":
        raise InvalidParameter("threshold", threshold, "must be 'otsu' or a number")
    out = []
    for response in responses:
        if isinstance(threshold, str):
            level = threshold_otsu(response) if np.ptp(response) > 0 else np.inf
        else:
            level = float(threshold)
        binary = response > level * threshold_factor
        fringes = measure_skeleton(skeletonize(binary), min_length=min_length, pixel_size=pixel_size)
        out.append(replace(fringes, binary=binary))
    return out


def measure_skeleton(
    skeleton: np.ndarray,
    *,
    min_length: float = MIN_LENGTH,
    prune: bool = True,
    pixel_size: float | None = None,
) -> Fringes:
    """Measure the fringes of a one-pixel-wide skeleton (steps 4-7 of the module docstring).

    Parameters
    ----------
    skeleton : ndarray of bool, shape (H, W)
        A thin (skeletonised) binary image, e.g. lines drawn with :func:`skimage.draw.line`.
    min_length : float
        Branches (when ``prune``) and fringes shorter than this many pixels are removed.
    prune : bool
        Remove branches shorter than ``min_length`` before breaking junctions.
    pixel_size : float, optional
        Nanometres per pixel.

    Returns
    -------
    Fringes
        With ``binary`` set to the skeleton itself.

    Notes
    -----
    A straight line of ``N`` pixels measures ``N - 1`` (horizontal or vertical) or
    ``(N - 1) sqrt(2)`` (diagonal): lengths run from the centre of one end pixel to the centre of the
    other, and its tortuosity is 1.

    Examples
    --------
    >>> import numpy as np
    >>> from skimage.draw import line
    >>> skel = np.zeros((40, 40), bool)
    >>> skel[line(5, 5, 25, 25)] = True            # 21 pixels on a diagonal
    >>> f = measure_skeleton(skel)
    >>> round(float(f.lengths[0]), 6) == round(20 * 2 ** 0.5, 6), float(f.tortuosity[0])
    (True, 1.0)
    """
    skel = np.asarray(skeleton, dtype=bool)
    if skel.ndim != 2:
        raise InvalidInput("skeleton", f"must be a 2-D boolean image, got shape {skel.shape}")
    if not (np.isfinite(min_length) and min_length >= 0):
        raise InvalidParameter("min_length", min_length, "must be a finite number of pixels >= 0")
    if pixel_size is not None:
        _check_positive("pixel_size", pixel_size)
    skel, pixel_path, rows, cols, lengths, pairs, n_loops = _skeleton_paths(skel, min_length, prune)

    # a one-pixel piece has length 0 and is never a fringe
    keep = (lengths >= min_length) & (lengths > 0)
    new_id = np.zeros(len(lengths), dtype=np.int32)
    new_id[keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    labels = np.zeros(skel.shape, dtype=np.int32)
    on = pixel_path >= 0
    labels[rows[on], cols[on]] = new_id[pixel_path[on]]

    pairs = pairs[keep]
    # summing sqrt(2) steps drifts by ulps: round lengths and chords alike to 1e-9 px so that a
    # straight diagonal has a tortuosity of exactly 1
    lengths = np.round(lengths[keep].astype(np.float64), 9)
    ends = np.zeros((len(pairs), 2, 2), dtype=np.int64)
    for k in (0, 1):
        ends[:, k, 0] = rows[pairs[:, k]]
        ends[:, k, 1] = cols[pairs[:, k]]
    drow = (ends[:, 1, 0] - ends[:, 0, 0]).astype(np.float64)
    dcol = (ends[:, 1, 1] - ends[:, 0, 1]).astype(np.float64)
    chord = np.round(np.hypot(drow, dcol), 9)
    # y is up (dy = -drow); a chord has an orientation, not a direction: wrap to (-pi/2, pi/2]
    theta = wrap_angle(np.arctan2(-drow, dcol))
    tortuosity = lengths / chord
    return Fringes(
        lengths=lengths,
        end_to_end=chord,
        tortuosity=tortuosity,
        orientation=theta,
        endpoints=ends,
        labels=labels,
        binary=skel,
        n_loops=int(n_loops),
        pixel_size=None if pixel_size is None else float(pixel_size),
    )
