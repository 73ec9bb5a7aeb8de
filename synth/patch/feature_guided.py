"""Feature-guided patch synthesis (Wu & Yu 2004, section 3): match on features and colour, bend, cut.

The engine behind the ``feature-guided`` method (:mod:`texsynth.synth.methods.feature_guided`), composed of
the project's pieces: (1) the exemplar's feature map (section 2.3,
:func:`texsynth.synth.analysis.features.feature_map`) and, with ``rotations``, its seven rotated/reflected
copies (:func:`variants`); (2) per patch of the raster layout
(:class:`texsynth.synth.patch.layout.PatchLayout`), the colour SSD of the overlap against every exemplar patch
by FFT (:class:`texsynth.synth.patch.search.PatchSearcher`), the ``candidates`` best kept; (3) the feature
matching cost (eq 2, eq 1's ``gdist``, ``tau = 0.1``, ``beta = 0.3``;
:func:`texsynth.synth.analysis.feature_matching.matching_costs`), plus ``reverse_weight`` times the reverse
term; (4) total cost ``w_f F / mean(F) + (1 - w_f) S / mean(S)`` (``w_f = 0.5``, section 3), drawn among
those within ``1 + tolerance`` of the least; (5) with ``deform``, the warp (section 2.2): gated
correspondences (eq 1, ``tau = 10``), thinned to spaced controls, a thin-plate spline confined to the
overlap and a band (:mod:`texsynth.synth.analysis.warp`); (6) the graph-cut seam (Kwatra et al. 2003).

Choices where the paper is silent, and departures (reasons and figures: docs/feature-guided.md and
docs/design.md, "the feature-guided engine"):
- each cost divided by its mean over the candidates, so ``w_f = 0.5`` means equal importance;
- candidates from the colour SSD, re-ranked by the feature cost (the paper: both at every translation);
- the output's feature map is the synthesized one; the reverse chamfer term (``reverse_weight``);
- correspondences beyond ``max_shift`` dropped; folding warps not applied;
- the warp: tangent gate, normal component, spaced median controls, a band, cubic resampling from the
  exemplar copy around the patch.

References
----------
Q. Wu, Y. Yu, "Feature matching and deformation for texture synthesis", ACM TOG 23(3), 2004, pp. 364-367.
V. Kwatra et al., "Graphcut textures: image and video synthesis using graph cuts", ACM TOG 22(3), 2003.
A. A. Efros, W. T. Freeman, "Image quilting for texture synthesis and transfer", SIGGRAPH 2001.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
from scipy import ndimage as ndi

from texsynth.synth.analysis.feature_matching import (
    BETA,
    MATCH_TAU,
    REVERSE_WEIGHT,
    WARP_TAU,
    FeatureIndex,
    build_feature_index,
    context_features,
    feature_correspondences,
    matching_costs,
    thin_correspondences,
)
from texsynth.synth.analysis.features import FeatureMap
from texsynth.synth.analysis.tensor import wrap_angle
from texsynth.synth.analysis.warp import band_falloff, resample, warp_coordinates
from texsynth.synth.colour import to_grey
from texsynth.synth.evaluate.breaks import Seams
from texsynth.synth.patch.graphcut import graph_cut_mask
from texsynth.synth.patch.layout import PatchLayout, Strips, patch_rng, patch_workers
from texsynth.synth.patch.search import PatchSearcher, k_nearest
from texsynth.synth.patch.usage import UsagePenalty

__all__ = [
    "FeatureGuidedOutput",
    "FeatureGuidedSettings",
    "Variant",
    "combined_cost",
    "seam_overlay",
    "synthesize_feature_guided",
    "variants",
]


@dataclass(frozen=True)
class Variant:
    """One copy of the exemplar (the exemplar itself, or a rotated/reflected copy) with its features.

    Attributes
    ----------
    name : str
        ``'identity'``, ``'rot90'``, ``'rot180'``, ``'rot270'``, and ``'flip'`` + those (a left-right
        mirror, then the rotation).
    image : ndarray of float64, shape (h, w, C)
    mask : ndarray of bool, shape (h, w)
        Feature pixels.
    tangent : ndarray of float64, shape (h, w)
        Tangent orientations (y up, ``(-pi/2, pi/2]``), NaN off the features.
    """

    name: str
    image: np.ndarray = field(repr=False)
    mask: np.ndarray = field(repr=False)
    tangent: np.ndarray = field(repr=False)


def variants(image: np.ndarray, fmap: FeatureMap, rotations: bool) -> list[Variant]:
    """The exemplar and, with ``rotations``, its 7 other rotated (90-degree steps) and reflected copies.

    The feature maps move with the pixels; tangents turn with them: a counter-clockwise quarter turn
    (:func:`numpy.rot90`) adds ``pi/2``, a left-right mirror negates the angle (y up).
    """
    img = np.asarray(image, dtype=np.float64)
    img = img[..., None] if img.ndim == 2 else img
    out = [Variant("identity", img, fmap.mask, fmap.tangent)]
    if not rotations:
        return out
    for flip in (False, True):
        base_img = img[:, ::-1] if flip else img
        base_mask = fmap.mask[:, ::-1] if flip else fmap.mask
        base_tan = -fmap.tangent[:, ::-1] if flip else fmap.tangent
        for k in range(4):
            if k == 0 and not flip:
                continue
            name = ("flip-" if flip else "") + ("identity" if k == 0 else f"rot{90 * k}")
            tan = np.rot90(base_tan, k)
            tan = np.where(np.isfinite(tan), wrap_angle(tan + k * np.pi / 2), np.nan)
            out.append(
                Variant(
                    name,
                    np.ascontiguousarray(np.rot90(base_img, k, axes=(0, 1))),
                    np.ascontiguousarray(np.rot90(base_mask, k)),
                    np.ascontiguousarray(tan),
                )
            )
    return out


def combined_cost(feature: np.ndarray, colour: np.ndarray, weight: float) -> np.ndarray:
    """``weight F / mean(F) + (1 - weight) S / mean(S)``: each term scaled by its mean over the candidates.

    A term whose mean is 0 contributes 0 (module docstring, "Normalisation").

    Examples
    --------
    >>> import numpy as np
    >>> combined_cost(np.array([1.0, 3.0]), np.array([0.02, 0.02]), 0.5).tolist()
    [0.75, 1.25]
    """
    f = np.asarray(feature, dtype=np.float64)
    s = np.asarray(colour, dtype=np.float64)
    mf, ms = float(f.mean()), float(s.mean())
    fn = f / mf if mf > 0 else np.zeros_like(f)
    sn = s / ms if ms > 0 else np.zeros_like(s)
    return weight * fn + (1.0 - weight) * sn


@dataclass(frozen=True)
class FeatureGuidedSettings:
    """What the engine needs, already validated (the method's parameter model builds it)."""

    patch_size: int
    overlap: int
    candidates: int = 20
    tolerance: float = 0.1
    feature_weight: float = 0.5
    tau: float = MATCH_TAU
    beta: float = BETA
    #: weight of the reverse chamfer term (candidate features -> context features); 0: the paper's eq 2
    reverse_weight: float = REVERSE_WEIGHT
    warp_tau: float = WARP_TAU
    deform: bool = True
    max_shift: float = 4.0
    rotations: bool = False
    #: pairs whose tangents differ by more than this (radians) are not pulled together
    max_angle: float | None = float(np.radians(30.0))
    #: keep only the displacement across the context feature (its normal component)
    normal_only: bool = True
    #: control points at least this far apart (px), each with the median displacement around it
    warp_spacing: float = 3.0
    #: regularisation of the spline at the feature constraints (0: exact, the paper)
    warp_smoothing: float = 0.0
    #: the displacement decays to 0 over this many px beyond the overlap (None: the paper's whole patch)
    warp_band: float | None = 4.0
    #: warps that move no pixel by this much (px) are not applied (resampling would only blur)
    min_shift: float = 0.5
    #: resampling of warped patches: 1 bilinear, 3 cubic (clipped to the four neighbours)
    warp_order: int = 3
    #: a torus of the output's size (a tileable output; :class:`texsynth.synth.patch.layout.PatchLayout`)
    periodic: bool = False
    #: warp the wrapped patches of a periodic layout too (known on both sides of an axis); False: paste
    #: them unwarped
    warp_two_sided: bool = True
    #: colour error of the candidates: "ssd" (the paper) or "normalised" (SSD over the overlap's plus the
    #: candidate's variance, :meth:`texsynth.synth.patch.search.PatchSearcher.normalised_ssd`)
    error: str = "ssd"
    #: gain of the penalty on over-used exemplar regions (:class:`texsynth.synth.patch.usage.UsagePenalty`,
    # one per
    #: copy of the exemplar); 0: off (the paper)
    usage_weight: float = 0.0


@dataclass(frozen=True)
class FeatureGuidedOutput:
    """The synthesized image (cropped), its synthesized feature map, patch labels and run statistics.

    ``sources`` (int64, ``(H, W, 2)``) is where each pixel came from, encoded so that two neighbours
    are continuous exactly when they are a verbatim copy of neighbouring pixels of one exemplar copy:
    ``(row + ROW_CODE * copy, col)`` for pixels copied as they are (unwarped patches, and the
    pixels a warp leaves in place), and ``(row + WARPED_CODE * (label + 1), col)`` (the patch's own
    frame) for pixels a warp moved, which continue nothing outside their patch.
    :func:`texsynth.synth.evaluate.breaks.seams_from_sources` of it with ``labels`` gives the seams by the
    same rule as quilting's ``source_map``: a seam is where two patches meet and the pixels are not
    a verbatim continuation.
    """

    image: np.ndarray
    mask: np.ndarray
    tangent: np.ndarray
    labels: np.ndarray
    sources: np.ndarray
    layout: PatchLayout
    stats: dict[str, Any]


#: Row offsets that keep the sources of different exemplar copies, and of warped patches, apart.
ROW_CODE = 1 << 20
WARPED_CODE = 1 << 32


def _folds(coords: np.ndarray) -> bool:
    """Whether a backward map ``(2, h, w)`` has a non-positive Jacobian determinant somewhere."""
    gr, gc = coords
    if min(gr.shape) < 2:
        return False
    dr_dr, dr_dc = np.gradient(gr)
    dc_dr, dc_dc = np.gradient(gc)
    return bool((dr_dr * dc_dc - dr_dc * dc_dr).min() <= 0.0)


def _sample(
    variant: Variant, coords: np.ndarray, y: int, x: int, order: int, coefficients: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The variant's colour (``order``) and features (nearest) at the backward map ``coords`` + ``(y, x)``.

    Pixels the map leaves in place are copied exactly.
    """
    h, w = variant.mask.shape
    pos = coords + np.array([y, x], dtype=np.float64)[:, None, None]
    colour = resample(variant.image, pos, order=order, coefficients=coefficients)  # type: ignore[arg-type]
    r = np.clip(np.rint(pos[0]).astype(np.intp), 0, h - 1)
    c = np.clip(np.rint(pos[1]).astype(np.intp), 0, w - 1)
    still = (pos[0] == r) & (pos[1] == c)
    colour[still] = variant.image[r[still], c[still]]
    return colour, variant.mask[r, c], variant.tangent[r, c]


def seam_overlay(
    image: np.ndarray, seams: Seams, colour: tuple[float, float, float] = (1.0, 0.1, 0.1)
) -> np.ndarray:
    """RGB float image: the output in grey, the pixels before each seam edge (left/above it) in ``colour``."""
    img = np.asarray(image, dtype=np.float64)
    grey = img if img.ndim == 2 else to_grey(img, np.float64)
    rgb = np.repeat(np.clip(grey, 0.0, 1.0)[..., None], 3, axis=2)
    on = np.zeros(seams.shape, dtype=bool)
    on[:, :-1] |= seams.across_cols
    on[:-1, :] |= seams.across_rows
    rgb[on] = colour
    return rgb.astype(np.float32)


def synthesize_feature_guided(
    exemplar: np.ndarray,
    fmap: FeatureMap,
    size: tuple[int, int],
    settings: FeatureGuidedSettings,
    rng: np.random.Generator,
    report: Callable[[str, float], None],
) -> FeatureGuidedOutput:
    """Feature-guided patch synthesis (module docstring, steps 1-6).

    Parameters
    ----------
    exemplar : ndarray, shape (h, w) or (h, w, C)
        Float image in [0, 1]; the patch must fit in it (checked by the caller).
    fmap : FeatureMap
        The exemplar's feature map (:func:`texsynth.synth.analysis.features.feature_map`).
    size : (int, int)
        Output shape ``(H, W)``.
    settings : FeatureGuidedSettings
    rng : numpy.random.Generator
        The only source of randomness.
    report : callable ``(stage, fraction)``
        Progress; it may raise :class:`texsynth.synth.errors.Cancelled`.

    Returns
    -------
    FeatureGuidedOutput
    """
    s = settings
    w, ov = s.patch_size, s.overlap
    copies = variants(exemplar, fmap, s.rotations)
    searchers = [PatchSearcher(v.image, w) for v in copies]
    indices: list[FeatureIndex] = [build_feature_index(v.mask, v.tangent) for v in copies]
    sizes = np.array([int(np.prod(sr.positions_shape)) for sr in searchers])
    starts = np.concatenate([[0], np.cumsum(sizes)])
    channels = copies[0].image.shape[2]

    layout = PatchLayout((int(size[0]), int(size[1])), w, ov, periodic=s.periodic)
    gh, gw = layout.grown_shape
    out = np.zeros((gh, gw, channels), dtype=np.float64)
    out_mask = np.zeros((gh, gw), dtype=bool)
    out_tan = np.full((gh, gw), np.nan)
    labels = np.full((gh, gw), -1, dtype=np.int32)
    sources = np.zeros((gh, gw, 2), dtype=np.int64)
    grid = np.stack(np.mgrid[0:w, 0:w], axis=-1).astype(np.int64)
    falloffs: dict[Strips, np.ndarray | None] = {}
    coefficients = [
        np.stack(
            [ndi.spline_filter(v.image[..., c], order=3, mode="nearest") for c in range(channels)], axis=-1
        )
        if s.deform and s.warp_order == 3
        else None
        for v in copies
    ]
    warps = {"tps": 0, "shepard": 0, "identity": 0, "folded": 0, "small": 0}
    shifts: list[float] = []
    pairs: list[int] = []
    feature_costs: list[float] = []
    colour_costs: list[float] = []
    reranked = 0
    usages = [UsagePenalty(v.image.shape, w, s.usage_weight) for v in copies]

    patches = layout.patches()

    def search(n: int, factors: list[np.ndarray] | None) -> tuple | None:
        """Patch ``n``'s candidates: flat positions, the costs' near-best set, feature and colour costs,
        the overlap SSD (``None`` for the first patch, drawn among all)."""
        i, j, y, x, kind = patches[n]
        if kind == "none":
            return None
        at = layout.index(y, x)
        region, region_mask, region_tan = out[at], out_mask[at], out_tan[at]
        mask = layout.strips(i, j).mask(w)
        normalised = s.error == "normalised"
        got = [
            sr.errors(region, mask, normalised, None if factors is None else factors[v])
            for v, sr in enumerate(searchers)
        ]
        ssd = np.concatenate([d.ravel() for _, d in got])
        if normalised or s.usage_weight > 0:
            err = np.concatenate([e.ravel() for e, _ in got])
            pool = k_nearest(err, s.candidates)
            colour = err[pool]
        else:
            pool = k_nearest(ssd, s.candidates)
            colour = ssd[pool] / (mask.sum() * channels)
        context = context_features(region_mask, region_tan, mask)
        feature = np.zeros(len(pool))
        which = np.searchsorted(starts, pool, side="right") - 1
        for v in np.unique(which):
            sel = which == v
            local = pool[sel] - starts[v]
            offsets = np.stack(np.unravel_index(local, searchers[v].positions_shape), axis=1)
            feature[sel] = matching_costs(
                context,
                indices[v],
                offsets.astype(np.int64),
                tau=s.tau,
                beta=s.beta,
                reverse_weight=s.reverse_weight,
            )
        total = combined_cost(feature, colour, s.feature_weight)
        best = float(total.min())
        ok = np.flatnonzero(total <= best * (1.0 + s.tolerance) + 1e-12)
        return pool, ok, feature, colour, ssd

    def stitch(n: int, flat: int) -> tuple[int, int, int, np.ndarray, int | None, str | None, float]:
        """Warp, cut and paste the exemplar patch ``flat`` at patch ``n``'s place (writes only its own
        region); returns its source, variant, cut mask and warp figures (correspondences, kind, shift)."""
        i, j, y, x, kind = patches[n]
        at = layout.index(y, x)  # wraps around the torus when periodic
        region = out[at]
        region_mask, region_tan = out_mask[at], out_tan[at]
        strips = layout.strips(i, j)
        mask = None if kind == "none" else strips.mask(w)
        v = int(np.searchsorted(starts, flat, side="right") - 1)
        py, px = (int(t) for t in np.unravel_index(flat - int(starts[v]), searchers[v].positions_shape))
        variant = copies[v]
        patch = variant.image[py : py + w, px : px + w]
        p_mask = variant.mask[py : py + w, px : px + w]
        p_tan = variant.tangent[py : py + w, px : px + w]
        src = grid + np.array([py + ROW_CODE * v, px], dtype=np.int64)
        count, warp, shift = None, None, 0.0
        if mask is not None and s.deform and (s.warp_two_sided or not strips.two_sided):
            corr = feature_correspondences(
                region_mask,
                region_tan,
                p_mask,
                p_tan,
                mask,
                tau=s.warp_tau,
                max_distance=s.max_shift,
                max_angle=s.max_angle,
                normal_only=s.normal_only,
            )
            corr = thin_correspondences(corr, s.warp_spacing)
            count = corr.count
            coords, used, _ = warp_coordinates(
                (w, w),
                np.clip(corr.sources, 0.0, w - 1.0),  # a projected source may fall just outside
                corr.targets,
                # the free borders stay in place (the paper: bottom and right; a wrapped patch's known
                # right / bottom strip is free to move like its left / top ones)
                fixed=tuple(side for side in ("bottom", "right") if getattr(strips, side) == 0),
                smoothing=s.warp_smoothing,
                falloff=falloffs[strips],
            )
            shift = float(np.abs(coords - grid.transpose(2, 0, 1)).max())
            if used != "identity" and _folds(coords):
                warp = "folded"
            elif used != "identity" and shift < s.min_shift:
                warp = "small"
            else:
                warp = used
                if used != "identity":
                    patch, p_mask, p_tan = _sample(variant, coords, py, px, s.warp_order, coefficients[v])
                    moved = (coords != grid.transpose(2, 0, 1)).any(axis=0)
                    src[moved] = (grid + np.array([WARPED_CODE * (n + 1), 0], dtype=np.int64))[moved]
        new = (
            np.ones((w, w), dtype=bool)
            if mask is None
            else graph_cut_mask(region, patch, mask, layout.sealed(i, j))
        )
        region[new] = patch[new]
        region_mask[new] = p_mask[new]
        region_tan[new] = np.where(p_mask, p_tan, np.nan)[new]
        region_labels, region_sources = labels[at], sources[at]
        region_labels[new] = n
        region_sources[new] = src[new]
        out[at], out_mask[at], out_tan[at], labels[at], sources[at] = (
            region,
            region_mask,
            region_tan,
            region_labels,
            region_sources,
        )
        return py, px, v, new, count, warp, shift

    for i, j, _, _, kind in patches:  # the warp's band falloff of every kind of known region, once
        strips = layout.strips(i, j)
        if kind != "none" and strips not in falloffs:
            falloffs[strips] = None if s.warp_band is None else band_falloff(strips.mask(w), s.warp_band)

    def place(n: int, factors: list[np.ndarray] | None) -> tuple[tuple | None, tuple]:
        """Search, draw (patch ``n``'s own random stream), warp, cut and paste patch ``n`` (reads and writes
        only its own region): the choice's figures (reranked, feature cost, overlap error) and
        :func:`stitch`'s."""
        got = search(n, factors)
        draw = patch_rng(base, n)
        if got is None:
            return None, stitch(n, int(draw.integers(int(starts[-1]))))
        pool, ok, feature, colour, ssd = got
        pick = int(ok[draw.integers(len(ok))])
        flat = int(pool[pick])
        known = layout.strips(*patches[n][:2]).mask(w).sum()
        figures = (
            pick != int(np.argmin(colour)),
            float(feature[pick]),
            float(ssd[flat]) / (known * channels),
        )
        return figures, stitch(n, flat)

    # The patches of a wave do not overlap: each is searched, drawn from its own random stream
    # (patch_rng), warped, cut and pasted, with the usage counts as they were when the wave began; then
    # the wave's patches are counted and their figures kept, in raster order. A patch's steps are mostly
    # Python holding the GIL, so the wave runs on the calling thread (gil_bound: a second thread made it
    # slower, docs/patch.md); the bytes are those of any thread count.
    base = int(rng.integers(2**63))
    by_patch: dict[int, list[int]] = {}
    with patch_workers(gil_bound=True) as run_wave:
        for wave in layout.waves():
            factors = [u.factors() for u in usages] if s.usage_weight > 0 else None
            placed = run_wave(partial(place, factors=factors), wave)
            for n, (figures, (py, px, v, new, count, warp, shift)) in zip(wave, placed, strict=True):
                if figures is not None:
                    reranked += int(figures[0])
                    feature_costs.append(figures[1])
                    colour_costs.append(figures[2])
                usages[v].add(py, px, new)
                by_patch[n] = [py, px, v]
                if count is not None:
                    pairs.append(count)
                if warp is not None:
                    warps[warp] += 1
                    if warp not in ("folded", "small", "identity"):
                        shifts.append(shift)
            report("feature-guided", len(by_patch) / len(layout))
    used_sources = [by_patch[n] for n in range(len(patches))]

    h, wd = layout.size
    stats: dict[str, Any] = {
        "variants": [c.name for c in copies],
        "exemplar_features": int(fmap.count),
        "reranked_share": reranked / max(1, len(layout) - 1),
        "mean_feature_cost": float(np.mean(feature_costs)) if feature_costs else 0.0,
        "mean_overlap_error": float(np.mean(colour_costs)) if colour_costs else 0.0,
        "patch_sources": used_sources,
    }
    if s.deform:
        stats["warps"] = warps
        stats["mean_correspondences"] = float(np.mean(pairs)) if pairs else 0.0
        stats["mean_warp_shift"] = float(np.mean(shifts)) if shifts else 0.0
    return FeatureGuidedOutput(
        image=out[:h, :wd],
        mask=out_mask[:h, :wd],
        tangent=out_tan[:h, :wd],
        labels=labels[:h, :wd],
        sources=sources[:h, :wd],
        layout=layout,
        stats=stats,
    )
