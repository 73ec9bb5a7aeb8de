"""Conditional locally Gaussian patch synthesis (Raad, Desolneux & Morel 2015): LG, CLG and RCLG.

Patches of side ``w`` are synthesized in raster order with overlap (sec. 2, Fig. 1;
:class:`texsynth.synth.patch.layout.PatchLayout`). For each new patch, the ``N`` exemplar patches nearest to
the output on the overlap (L2, eq. 1; FFT correlation, :class:`texsynth.synth.patch.search.PatchSearcher`)
give
``mu`` and ``Sigma`` (eq. 1); the patch is then a draw from ``N(mu, Sigma)`` (``model='lg'``), the
conditional mean given the overlap ``y0`` (``'clg'``, eq. 4), or the minimiser of eq. 5 (``'rclg'``,
closed form eq. 7 with ``G = Sigma + sigma^2 I``), solved in the ``N``-dimensional span of the
neighbours (:mod:`texsynth.synth.patch.gaussian`). ``blending='boundary-cut'`` stitches it along the
Efros-Freeman minimum-error cut (Fig. 3); ``'none'`` pastes it (Fig. 2).

Departures, each measured in docs/patch.md and docs/design.md ("gaussian-patch"):
- ``sigma``, ``theta`` (not in the paper): 0.05, 0.05; overlap a quarter of the patch; first patch drawn;
- ``estimate='neighbour'`` (the paper: ``'mean'``): one neighbour corrected toward the overlap (Matheron's
  rule, tapered by ``localisation``); ``'draw'``: a draw from the conditional law (sec. 3.1);
- ``contrast='restore'``: each patch keeps the neighbours' standard deviation (the mean decays);
- ``neighbours`` N = 5 (the paper: 20); ``scales > 1``: the paper's sec. 4 outlook, simplified;
- ``periodic=True``: a torus layout, two-sided patches mended at their inner edges;
- the output is clipped to [0, 1] (``stats['clipped_share']``);
- ``error='normalised'``, ``usage_weight=1``, ``blending='boundary-cut'`` (since issue 24): the neighbours
  on the variance-normalised overlap error times a penalty on over-used regions, so the output does not
  settle in the exemplar's flattest part (docs/patch.md, "Laminar HRTEM").
The paper: ``estimate='mean'``, ``contrast='none'``, ``neighbours=20``, ``error='ssd'``, ``usage_weight=0``.

References
----------
L. Raad, A. Desolneux, J.-M. Morel, "Conditional Gaussian models for texture synthesis", SSVM 2015,
LNCS 9087, pp. 474-485. L. Raad et al., "Locally Gaussian exemplar-based texture synthesis", ICIP 2014
(LG). A. A. Efros, W. T. Freeman, "Image quilting for texture synthesis and transfer", SIGGRAPH 2001.
"""

from __future__ import annotations

import time
from functools import partial
from typing import Literal

import numpy as np
from pydantic import Field
from skimage.transform import rescale, resize

from texsynth.synth.api import MethodSpec, Progress, Result, register
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.evaluate.coverage import exemplar_coverage
from texsynth.synth.evaluate.patches import copy_map, copy_share
from texsynth.synth.methods.common import PatchParams, checked_progress
from texsynth.synth.methods.quilting import check_patch_geometry
from texsynth.synth.params import ui
from texsynth.synth.patch.cut import error_surface, strips_cut_mask
from texsynth.synth.patch.gaussian import (
    GaussianPatchModel,
    lg_patch,
    localisation_taper,
    mend_inner_edges,
    rclg_draw,
    rclg_neighbour,
    rclg_patch,
    restore_contrast,
)
from texsynth.synth.patch.layout import PatchLayout, Strips, check_periodic_size, patch_rng, patch_workers
from texsynth.synth.patch.search import PatchSearcher, k_nearest
from texsynth.synth.patch.usage import UsagePenalty

__all__ = ["GaussianPatchParams", "run_gaussian_patch", "synthesize_gaussian_patches"]


class GaussianPatchParams(PatchParams):
    """Parameters of the locally Gaussian patch models (Raad, Desolneux & Morel 2015)."""

    OVERLAP_DIVISOR = 4
    MIN_OVERLAP = 1

    model: Literal["lg", "clg", "rclg"] = Field(
        "rclg",
        description="Patch model: 'rclg' follows the overlap loosely, 'clg' exactly, 'lg' ignores it (Eq. "
        "7, 4, Gaussian draw).",
        json_schema_extra=ui(
            basic=True,
            details=(
                "'lg': a draw from N(mu, Sigma), overlap ignored; 'clg': conditional mean given the "
                "overlap (eq. 4); 'rclg': regularised conditional (eq. 7), the overlap may move by about "
                "theta."
            ),
        ),
    )
    # (w, N) = (30, 20): the first example of the paper's Figs 2 and 3 (w 10-40, N 10-50 in the paper).
    patch_size: int = Field(
        30,
        ge=4,
        le=128,
        description="Side of the square patches (w).",
        json_schema_extra=ui(basic=True, unit="px", details=("Side w of the square patches, pixels.")),
    )
    overlap: int | None = Field(
        None,
        ge=1,
        le=127,
        description="How much neighbouring patches overlap; automatic: a quarter of the patch.",
        json_schema_extra=ui(
            basic=True,
            unit="px",
            details=("Overlap between neighbouring patches, pixels; default a quarter of w."),
        ),
    )
    neighbours: int = Field(
        5,
        ge=1,
        le=500,
        description="How many similar exemplar patches form each patch's model (N; the paper: 20).",
        json_schema_extra=ui(
            basic=True,
            details=("N: exemplar patches nearest on the overlap that define mu and Sigma (the paper: 20)."),
        ),
    )
    # The paper gives no value for sigma or theta: 0.05 / 0.05 are ours (docs/patch.md: sigma = 0.01 lets
    # CLG extrapolate into saturated garbage on brick; a larger theta moves the seam to the overlap's edge).
    sigma: float = Field(
        0.05,
        gt=0.0,
        le=1.0,
        description="Noise added to the model, in grey levels from 0 to 1 (σ).",
        json_schema_extra=ui(
            details=("Added noise: the model is N(mu, Sigma + sigma^2 I) (grey levels in [0, 1]).")
        ),
    )
    theta: float = Field(
        0.05,
        ge=0.0,
        le=10.0,
        description="How far a new patch may depart from the overlap's values; 0 follows it exactly (θ, "
        "Eq. 5).",
        json_schema_extra=ui(details=("RCLG: allowed deviation from the overlap's values (eq. 5); 0 = CLG.")),
    )
    blending: Literal["none", "boundary-cut"] = Field(
        "boundary-cut",
        description="How patches are joined: a minimum-error 'boundary-cut', or 'none' (pasted over the "
        "overlap).",
        json_schema_extra=ui(
            details=(
                "'boundary-cut' (default): stitch along the Efros-Freeman minimum-error cut (paper, Fig. "
                "3); 'none': paste over the overlap (paper, Fig. 2)."
            )
        ),
    )
    estimate: Literal["mean", "draw", "neighbour"] = Field(
        "neighbour",
        description="What each new patch is: a corrected 'neighbour' patch, the model's 'mean', or a "
        "random 'draw'.",
        json_schema_extra=ui(
            details=(
                "CLG/RCLG: 'neighbour' (default, not the paper) = one of the N neighbours, drawn "
                "uniformly, corrected toward the overlap by the model's gain tapered with the distance "
                "from the overlap (keeps structure the overlap does not pin, such as a brick's joints); "
                "'mean' = the most probable patch (the paper); 'draw' = a random draw from the same "
                "conditional law (the paper's suggested remedy for its smoothing; docs/patch.md: close to "
                "the mean when the overlap pins the rank-N model)."
            )
        ),
    )
    localisation: float | None = Field(
        None,
        gt=0.0,
        le=1000.0,
        description="How far from the overlap the correction of a neighbour patch fades out; automatic: "
        "the overlap.",
        json_schema_extra=ui(
            unit="px",
            details=(
                "estimate='neighbour': length (pixels) of the Gaussian taper of the correction with the "
                "distance from the overlap; default the overlap. Ignored by the other estimates."
            ),
        ),
    )
    contrast: Literal["restore", "none"] = Field(
        "restore",
        description="Keep each new patch as contrasted as its neighbours ('restore'), or let contrast "
        "fade ('none').",
        json_schema_extra=ui(
            details=(
                "CLG/RCLG: 'restore' scales each new patch's spread to its neighbours' (not the paper; "
                "without it the conditional mean blurs and contrast decays patch after patch, "
                "docs/patch.md); 'none' = the paper literally."
            )
        ),
    )
    error: Literal["normalised", "ssd"] = Field(
        "normalised",
        description="How overlaps are compared: 'normalised' does not favour flat patches; 'ssd' is the "
        "plain squared difference.",
        json_schema_extra=ui(
            details=(
                "Overlap distance of the neighbour search: 'normalised' (default, not the paper) = the "
                "SSD over the overlap's plus the candidate's own variance, so flat candidates are not "
                "preferred for being flat; 'ssd' = the paper's L2."
            )
        ),
    )
    usage_weight: float = Field(
        1.0,
        ge=0.0,
        le=100.0,
        description="How strongly over-used exemplar places are avoided; 0 is the paper (position "
        "histogram).",
        json_schema_extra=ui(
            details=(
                "Gain of the penalty on over-used exemplar regions in the neighbour search (Chen & Wang's "
                "position histogram; not the paper). 0 = the paper."
            )
        ),
    )
    scales: int = Field(
        1,
        ge=1,
        le=4,
        description="Number of scales, coarse to fine; 1 is the paper.",
        json_schema_extra=ui(
            details=(
                "1 = the paper; > 1: coarse to fine, each scale's neighbours chosen also on the coarser "
                "scale's output."
            )
        ),
    )


def _check(
    exemplar_shape: tuple[int, ...], params: GaussianPatchParams, output: tuple[int, ...] | None = None
) -> None:
    """Patch, overlap and N against the exemplar's shape at every scale, and with ``periodic`` the
    ``output`` shape (when known) against the patch step (before any work)."""
    overlap = params.resolved_overlap()
    if params.periodic and output is not None:
        check_periodic_size(output, params.patch_size, overlap)
    h, w = exemplar_shape[:2]
    for s in range(params.scales):
        shape = (round(h / 2**s), round(w / 2**s))
        role = "exemplar" if s == 0 else f"exemplar reduced {2**s} times (scale {s + 1} of {params.scales})"
        check_patch_geometry(shape, params.patch_size, overlap, role)
        count = (shape[0] - params.patch_size + 1) * (shape[1] - params.patch_size + 1)
        if params.neighbours > count:
            raise InvalidParameter(
                "neighbours",
                params.neighbours,
                f"larger than the number of {params.patch_size} x {params.patch_size} patches in the {role} "
                f"({count})",
            )


def _fits_torus(size: tuple[int, int], params: GaussianPatchParams) -> bool:
    """Whether a periodic layout of ``size`` passes :func:`check_periodic_size`."""
    try:
        check_periodic_size(size, params.patch_size, params.resolved_overlap())
    except InvalidParameter:
        return False
    return True


def synthesize_gaussian_patches(
    exemplar: np.ndarray,
    size: tuple[int, int],
    params: GaussianPatchParams,
    rng: np.random.Generator,
    report=None,
    guide: tuple[np.ndarray, np.ndarray] | None = None,
    periodic: bool = False,
    sources: list[list[int]] | None = None,
    weights_used: list[float] | None = None,
    firsts: list[bool] | None = None,
) -> tuple[np.ndarray, PatchLayout]:
    """One scale of the synthesis: ``(H, W, C)`` float64 (unclipped) and its layout.

    ``guide = (exemplar_guide, output_guide)``: images of the same shapes as the exemplar and the output
    (the coarser scale upsampled) whose whole patch joins the overlap in the neighbour search.
    ``periodic``: the layout is a torus of ``size`` (checked by the caller, :func:`check_periodic_size`).
    ``sources``, ``weights_used``: lists that receive the top-left exemplar position of every patch's
    neighbour (all ``N`` of them, weighted ``1/N``, when the patch is the model's mean or a draw, nearest
    first); ``firsts``: True for the first position of each patch.
    """
    sources = [] if sources is None else sources
    weights_used = [] if weights_used is None else weights_used
    firsts = [] if firsts is None else firsts
    w, overlap = params.patch_size, params.resolved_overlap()
    ex = exemplar[..., None] if exemplar.ndim == 2 else exemplar
    channels = ex.shape[2]
    layout = PatchLayout(size, w, overlap, periodic=periodic)
    gh, gw = layout.grown_shape
    if guide is not None:
        ex_guide, out_guide = (g[..., None] if g.ndim == 2 else g for g in guide)
        search_image = np.concatenate([ex, ex_guide], axis=2)
        out_guide = np.pad(
            out_guide, ((0, gh - out_guide.shape[0]), (0, gw - out_guide.shape[1]), (0, 0)), mode="reflect"
        )
    else:
        search_image, out_guide = ex, None
    searcher = PatchSearcher(search_image, w)
    out = np.zeros((gh, gw, channels), dtype=np.float64)
    n_pos = searcher.positions_shape[0] * searcher.positions_shape[1]
    usage = UsagePenalty(ex.shape, w, params.usage_weight)
    tapers: dict[Strips, np.ndarray] = {}
    length = params.localisation if params.localisation is not None else float(overlap)
    patches = layout.patches()
    for strips in {layout.strips(i, j) for i, j, *_ in patches}:  # the localisation tapers, once per kind
        if strips.kind != "none":
            tapers[strips] = np.repeat(
                localisation_taper(strips.mask(w), length)[..., None], channels, axis=2
            ).ravel()

    def place(n: int, factors: np.ndarray | None) -> list[tuple[int, int, float]]:
        """Build and paste patch ``n`` (writes only its own region, draws from its own random stream);
        returns the exemplar positions it was built on with their shares (the first is the nearest)."""
        i, j, y, x, kind = patches[n]
        draw = patch_rng(base, n)
        at = layout.index(y, x)  # wraps around the torus when periodic
        region = out[at]
        strips = layout.strips(i, j)
        mask = strips.mask(w)
        if out_guide is None and kind == "none":
            first = np.unravel_index(int(draw.integers(n_pos)), searcher.positions_shape)
            out[at] = searcher.patch(*first)
            return [(int(first[0]), int(first[1]), 1.0)]
        template = region
        weights = np.repeat(mask[..., None].astype(np.float64), channels, axis=2)
        if out_guide is not None:
            template = np.concatenate([region, out_guide[at]], axis=2)
            share = mask.sum() / mask.size if kind != "none" else 1.0
            weights = np.concatenate([weights, np.full((w, w, channels), share)], axis=2)
        err, _ = searcher.errors(template, weights, params.error == "normalised", factors)
        nearest = k_nearest(err, params.neighbours)
        positions = np.stack(np.unravel_index(nearest, searcher.positions_shape), axis=1)
        member = None
        model = GaussianPatchModel.from_patches(searcher.patches(nearest)[..., :channels])
        if kind == "none":
            patch = lg_patch(model, draw) if params.model == "lg" else model.mu
        elif params.model == "lg":
            patch = lg_patch(model, draw)
        else:
            known = np.repeat(mask[..., None], channels, axis=2).ravel()
            theta = params.theta if params.model == "rclg" else 0.0
            y0 = region.ravel()[known]
            if params.estimate == "draw":
                patch = rclg_draw(model, known, y0, params.sigma, theta, draw)
            elif params.estimate == "neighbour":
                member = int(draw.integers(len(nearest)))
                patch = rclg_neighbour(model, known, y0, params.sigma, theta, draw, tapers[strips], member)
            else:
                patch = rclg_patch(model, known, y0, params.sigma, theta)
            if params.contrast == "restore":
                patch = restore_contrast(model, known, patch)
            if strips.two_sided:
                patch = mend_inner_edges(patch.reshape(w, w, channels), mask)
        patch = patch.reshape(w, w, channels)
        if params.blending == "boundary-cut" and kind != "none":
            new_mask = strips_cut_mask(error_surface(region, patch), strips)
            region[new_mask] = patch[new_mask]
        else:
            region[...] = patch
        out[at] = region
        # the exemplar positions this patch was built on: its neighbour, or all N for the model's mean/draws
        chosen = positions if member is None else positions[member : member + 1]
        share = 1.0 if member is not None else 1.0 / len(positions)
        return [(int(py), int(px), share) for py, px in chosen]

    # The patches of a wave do not overlap: each is built from its own random stream (patch_rng), the usage
    # counts as they were when the wave began; then the wave's patches are counted, in raster order. A
    # patch's steps are mostly Python holding the GIL, so the wave runs on the calling thread (gil_bound: a
    # second thread made it slower, docs/patch.md); the bytes are those of any thread count.
    base = int(rng.integers(2**63))
    built: dict[int, list[tuple[int, int, float]]] = {}
    with patch_workers(gil_bound=True) as run_wave:
        for wave in layout.waves():
            factors = usage.factors() if params.usage_weight > 0 else None
            for n, used in zip(wave, run_wave(partial(place, factors=factors), wave), strict=True):
                built[n] = used
                for py, px, share in used:
                    usage.add(py, px, np.full((w, w), share))
            if report is not None:
                report("patches", len(built) / len(layout))
    for n in range(len(patches)):
        for k, (py, px, share) in enumerate(built[n]):
            sources.append([py, px])
            weights_used.append(share)
            firsts.append(k == 0)
    return out[: size[0], : size[1]], layout


def run_gaussian_patch(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int],
    params: GaussianPatchParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
) -> Result:
    size = (int(size[0]), int(size[1]))
    _check(exemplar.shape, params, size)
    report = checked_progress(progress)
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    channel_axis = 2 if exemplar.ndim == 3 else None
    guide = None
    out = None
    layout = None
    ex_prev = exemplar
    for s in range(params.scales - 1, -1, -1):
        factor = 2**s
        ex_s = (
            exemplar
            if s == 0
            else rescale(exemplar, 1 / factor, anti_aliasing=True, channel_axis=channel_axis)
        )
        size_s = (
            max(params.patch_size, round(size[0] / factor)),
            max(params.patch_size, round(size[1] / factor)),
        )
        if out is not None:
            ex_coarse = resize(ex_prev, ex_s.shape, order=1, anti_aliasing=False)
            out_coarse = resize(out, (*size_s, *out.shape[2:]), order=1, anti_aliasing=False)
            guide = (ex_coarse, out_coarse)

        def level_report(stage: str, fraction: float, s: int = s) -> None:
            done = params.scales - 1 - s
            report(f"scale {done + 1}/{params.scales}", (done + fraction) / params.scales)

        # a coarser scale only guides the search: periodic when its size allows (the finest is checked)
        periodic = params.periodic and (s == 0 or _fits_torus(size_s, params))
        sources: list[list[int]] = []
        weights_used: list[float] = []
        firsts: list[bool] = []
        out, layout = synthesize_gaussian_patches(
            ex_s, size_s, params, rng, level_report, guide, periodic, sources, weights_used, firsts
        )
        ex_prev = ex_s
    assert out is not None and layout is not None
    raw = out[..., 0] if exemplar.ndim == 2 else out
    clipped = float(np.mean((raw < 0) | (raw > 1)))
    image = np.clip(raw, 0.0, 1.0).astype(np.float32)
    t_synth = time.perf_counter() - start
    cmap = copy_map(image, exemplar)
    report("done", 1.0)
    return Result(
        method="gaussian-patch",
        image=image,
        params=params.model_dump(),
        seed=seed,
        timings={"synthesis": t_synth, "copy_map": time.perf_counter() - start - t_synth},
        extras={"copy_map": cmap},
        stats={
            "layout": layout.describe(),
            "clipped_share": clipped,
            "copy_share": copy_share(cmap),
            "patch_sources": [src for src, first in zip(sources, firsts, strict=True) if first],
            "coverage": exemplar_coverage(sources, exemplar.shape, params.patch_size, weights_used),
        },
    )


SPEC = register(
    MethodSpec(
        name="gaussian-patch",
        summary="Locally Gaussian patch synthesis, LG / conditional CLG / regularised RCLG "
        "(Raad, Desolneux & Morel 2015).",
        params_model=GaussianPatchParams,
        run=run_gaussian_patch,
        precheck=lambda params, shapes: _check(shapes["exemplar"], params, shapes.get("output")),
        paper="Raad, Desolneux & Morel, SSVM 2015",
    )
)
