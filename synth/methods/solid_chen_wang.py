"""Solid texture synthesis with position and index histogram matching (Chen & Wang 2010).

A volume ``(D, H, W)`` whose slices along two or three axes look like the 2D exemplar(s), by texture
optimisation (Kwatra et al. 2005; Kopf et al. 2007) with a k-coherence search (Tong et al. 2002), a
discrete solver (Han et al. 2006) and two histograms. It minimises Kopf's eq 1,
``E = sum_v sum_p ||s_{v,p} - e_{v,p}||^r``, ``r = 0.8``, over the constrained planes ``p``, alternating
a **search** pass (each ``e_{v,p}``: the best k-coherent candidate, its distance times the **index
histogram** factor ``1 + w_idx max(0, H_idx / T_idx - 1)``) and a **discrete solver** pass (each voxel
copies the candidate exemplar pixel of least ``fit + consensus * (e - mu)^2`` times the **position
histogram** factor; every voxel is an exemplar pixel). Coarse to fine
(:func:`texsynth.synth.pixel.solid.run_levels`);
:mod:`texsynth.synth.kernels.solid_kcoherence` has the formulas. One exemplar per plane for anisotropic
materials; ``planes=('xz', 'yz')`` for laminae (ALGORITHMS.md, section 4).

References: J. Chen, B. Wang, The Visual Computer 26(4):253-262, 2010. J. Kopf et al., SIGGRAPH 2007. X.
Tong et al., SIGGRAPH 2002 (k-coherence). J. Han, K. Zhou, L.-Y. Wei et al., Vis. Comput. 22, 2006 (solver).

Departures (why and the measurements: docs/solid.md, "Departures from the papers"):
- Kopf's form of histogram re-weighting for both histograms (the paper's formulas are not available);
- the solver adds a ``consensus`` term (the fit alone is speckled) and Kopf's grey-level histogram; fewer
  candidates (``solve_radius`` 0, ``kset_window`` 1); a level starts from the first plane's matches; parallel
  passes (Jacobi search, index histogram frozen per call; solve in blocks); every voxel searched;
- a final rank remap onto the exemplars' grey levels (``grey_remap``, as Kopf): the solver loses the tails;
- the last step blends in the matches' average until the slices are no grainier than the exemplar
  (``final_step``, :mod:`texsynth.synth.analysis.grain`): the discrete copies speckle on smooth exemplars;
- 3 iterations per level (the study: 10); laminae 10, orientation re-weighting, 60 coarse ones, radius 1;
- structured starts (``structure``, :mod:`texsynth.synth.pixel.laminar`), matched by the tree search on the
  levels that keep the period: curved sheets for one isotropic laminar exemplar (short fringes: solid-kopf's
  pilot decides; or shells around random centres, ``shells``, spaced by the fringes' curvature), solid-kopf's
  crumpled stack (``'oriented'``) for crumpled anisotropic exemplars (one, or per plane).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, field_validator
from scipy import ndimage as ndi

from texsynth.synth.analysis.grain import match_grain
from texsynth.synth.analysis.orientation_histogram import (
    OrientationLabels,
    orientation_excess,
    orientation_labels,
    usage_factors,
)
from texsynth.synth.api import PLANES, MethodSpec, Progress, Result, register
from texsynth.synth.errors import InvalidInput
from texsynth.synth.grid.scan import ScanOrder, scan_order
from texsynth.synth.kernels.solid_kcoherence import (
    ExemplarBank,
    SliceGeometry,
    SolidState,
    SolverWeights,
    new_scratch,
    search_pass,
    solve_pass,
)
from texsynth.synth.methods.common import (
    ShellKind,
    ShellParams,
    checked_progress,
    precheck_structured_start,
    shells_field,
    structure_fields,
)
from texsynth.synth.methods.solid_kopf import ORIENTED_LENGTH, laminar_pilot
from texsynth.synth.params import ui
from texsynth.synth.pixel.laminar import (
    centre_phase,
    choose_shells,
    domain_phase,
    dominant_period,
    fitted_structure_length,
    laminar_volume,
    level_phase,
    oriented_phase,
    plane_orientation,
    resolved_length,
    sheet_normal,
    sheets,
    stack_period,
    start_kind,
    structure_levels,
)
from texsynth.synth.pixel.solid import (
    PLANE_AXES,
    LevelStep,
    ProgressMeter,
    SolidPlan,
    SolidRun,
    exemplar_offsets,
    gather_plane,
    is_laminar,
    match_histogram,
    plan_levels,
    plane_offsets,
    run_levels,
    structure_schedule,
)
from texsynth.synth.pixel.synthesis import k_coherence_sets

__all__ = [
    "SolidChenWangParams",
    "chen_wang_structure_length",
    "run_solid_chen_wang",
    "synthesize_solid_chen_wang",
]

#: Radius (in slice pixels) of the window of voxels whose matches propose k-coherent candidates.
_CANDIDATE_RADIUS = 1
#: Principal components of the neighbourhoods that build the k-coherence sets.
_KSET_DIMS = 8
_CANDIDATE_WINDOW = "cross"
#: Principal components that rank the candidates before the best few are compared in full.
_RANK_DIMS = 8
#: Grey-level histogram bins (Kopf et al. 2007 use 16 per channel; 8-bit grey exemplars fill 32 evenly).
_GREY_BINS = 32
#: Relative cost of a search pass against an optimisation pass (for progress).
_SEARCH_COST = 4.0
#: The orientation re-weighting's gain for laminar exemplars (``orientation_gain=None``; docs/solid.md).
LAMINAR_ORIENTATION_GAIN = 32.0
#: The solver's candidate radius for laminar exemplars (``solve_radius=None``; docs/solid.md).
LAMINAR_SOLVE_RADIUS = 1
#: Iterations per level above the finest for laminar exemplars (``coarse_iterations=None``; docs/solid.md).
LAMINAR_COARSE_ITERATIONS = 60
#: After the oriented start (``adapt_to_structure``): iterations at the finest level (at least) and above it
#: (``coarse_iterations=None``); more straighten the fitted crumples and cost time (docs/solid.md).
ORIENTED_ITERATIONS = 5
ORIENTED_COARSE_ITERATIONS = 10
#: 'auto' takes the oriented start when the exemplar's fringes keep their orientation at most this many
#: periods (:func:`orientation_length`: the turbostratic stack 1.0, bent laminae 2.0-4.8; docs/solid.md).
ORIENTED_MAX_LENGTH = 1.5
#: The range of the fitted sheet length (periods; ``structure_length`` empty): shorter sheets break this
#: method's shells into worms, longer ones (the real crops' fit, 4.4-4.7) lose their orientations
#: (docs/solid.md, "The sheets' length for solid-chen-wang").
MIN_STRUCTURE_LENGTH = 3.0
MAX_STRUCTURE_LENGTH = 4.0


def chen_wang_structure_length(images: list[np.ndarray]) -> float:
    """The laminar start's sheet length (periods) when ``structure_length`` is empty: solid-kopf's fit to the
    exemplars (:func:`texsynth.synth.pixel.laminar.fitted_structure_length`) kept within
    :data:`MIN_STRUCTURE_LENGTH` - :data:`MAX_STRUCTURE_LENGTH`: the laminar truth's small onions 3 (fit
    2.1), the real onion crops 4 (fit 4.4-4.7), the tests' three onions in 64 px 3.3."""
    fit = fitted_structure_length(images)
    return float(np.clip(fit, MIN_STRUCTURE_LENGTH, MAX_STRUCTURE_LENGTH))


class SolidChenWangParams(ShellParams):
    """Parameters of Chen & Wang's solid synthesis (defaults: the paper's and the study's settings)."""

    levels: int = Field(
        5,
        ge=1,
        le=8,
        description="Largest number of pyramid levels, coarse to fine (fewer when exemplar or volume is "
        "small).",
        json_schema_extra=ui(
            basic=True, details=("Pyramid levels (at most; fewer when the exemplar or volume is small).")
        ),
    )
    adapt_to_structure: bool = Field(
        True,
        description="Adapt the schedule to the exemplar: layered ones get more passes per level.",
        json_schema_extra=ui(
            details=(
                "Laminae get at least 10 iterations per level, 5 after the oriented start (off: iterations "
                "literally)."
            )
        ),
    )
    iterations: int = Field(
        3,
        ge=1,
        le=20,
        description="Search-and-update passes over the volume at each level.",
        json_schema_extra=ui(basic=True, details=("Search + optimisation iterations per level.")),
    )
    coarse_iterations: int | None = Field(
        None,
        ge=1,
        le=200,
        description="Passes at every level but the finest; automatic: chosen from the exemplar.",
        json_schema_extra=ui(
            details=(
                "Iterations at every level but the finest. None, when adapt_to_structure is on: "
                f"{ORIENTED_COARSE_ITERATIONS} after the oriented start, {LAMINAR_COARSE_ITERATIONS} for "
                "other laminar exemplars; else as the finest level's."
            )
        ),
    )
    structure_length: float | None
    structure: Literal["auto", "none", "laminar", "oriented"]
    structure, structure_length = structure_fields(
        (
            "'laminar': start from a volume of curved sheets at the exemplar's period, on the "
            "levels that keep the period (the structure first, Akl 2014 in 3D); 'oriented': from a "
            "crumpled stack whose mean normal and spread fit the exemplars' fringe orientations (as "
            "solid-kopf); 'none': the paper's random start; 'auto' (with adapt_to_structure): "
            "'laminar' for one isotropic exemplar on the three planes that is fringed (mean coherence "
            ">= 0.6) or chosen by a small pilot (0.45-0.6), or for fringed isotropic per-plane "
            "exemplars; 'oriented' for fringed anisotropic exemplars on the three planes (one, or per "
            "plane) whose fringes turn within 1.5 periods (a crumpled stack; bent laminae measured "
            "better from noise); else 'none'."
        ),
        (
            "Curvature length of the laminar start, in periods (0-64]; empty or 'auto': solid-kopf's "
            f"fit to the exemplars kept within {MIN_STRUCTURE_LENGTH:g}-{MAX_STRUCTURE_LENGTH:g} "
            "periods (shorter sheets break this method's shells into worms, longer ones lose the "
            "fringes' orientations)."
        ),
    )
    shells: ShellKind = shells_field(
        "auto",
        "Default 'auto': the centres measured better on the onion truth (sessions cw6-cw8) and the onion "
        "crop (session 17), the domains on the crops of short fringes (sessions 19-20; docs/solid.md).",
    )
    oriented_length: float = Field(
        ORIENTED_LENGTH,
        gt=0.0,
        le=64.0,
        description="How far the oriented start's crumples stay straight, in fringe periods.",
        json_schema_extra=ui(
            unit="periods", details=("Correlation length of the oriented start's crumples, in periods.")
        ),
    )
    k: int = Field(
        15,
        ge=0,
        le=32,
        description="How many similar exemplar places are listed per pixel (k).",
        json_schema_extra=ui(details=("k-coherence: similar exemplar positions per pixel.")),
    )
    # Not given by the paper; measured (docs/solid.md, "Departures from the papers").
    position_weight: float = Field(
        5.0,
        ge=0.0,
        le=100.0,
        description="How strongly over-used exemplar places are avoided; 0 is off (position histogram).",
        json_schema_extra=ui(
            basic=True, details=("Position-histogram weight: 0 = off; larger = more uniform use.")
        ),
    )
    index_weight: float = Field(
        1.0,
        ge=0.0,
        le=100.0,
        description="How strongly often-chosen matches are avoided; 0 is off (index histogram).",
        json_schema_extra=ui(details=("Index-histogram weight: 0 = off; larger = more uniform matches.")),
    )
    exponent: float = Field(
        0.8,
        gt=0.0,
        le=2.0,
        description="Robustness of the matching energy: below 2, bad matches weigh less (r, Kopf's "
        "exponent).",
        json_schema_extra=ui(details=("IRLS exponent r of the energy (Kopf: 0.8).")),
    )
    scan: ScanOrder = Field(
        "hilbert",
        description="Order in which voxels are visited.",
        json_schema_extra=ui(details=("Voxel visiting order of both phases.")),
    )
    random_candidates: int = Field(
        0,
        ge=0,
        le=16,
        description="Random exemplar places tried per voxel besides the listed ones (0: the paper).",
        json_schema_extra=ui(
            details=("Random exemplar positions added to the k-coherent candidates (0: paper).")
        ),
    )
    # Measured on soot, laminae and the known answer (docs/solid.md, "Departures from the papers").
    grey_weight: float = Field(
        20.0,
        ge=0.0,
        le=1000.0,
        description="How strongly the grey-level histogram is kept close to the exemplar's; 0 is off.",
        json_schema_extra=ui(details=("Grey-level histogram weight (Kopf's histogram matching): 0 = off.")),
    )
    consensus: float = Field(
        0.5,
        ge=0.0,
        le=100.0,
        description="How strongly a voxel follows what most of its neighbours propose.",
        json_schema_extra=ui(details=("Solver: weight of the proposals' consensus.")),
    )
    final_step: Literal["auto", "discrete", "average"] = Field(
        "auto",
        description="How voxels get their final values: exemplar pixels (the paper), their matches' average, "
        "or 'auto': no grainier than the exemplar.",
        json_schema_extra=ui(
            details=(
                "The finest level's last step: 'discrete' (the paper: every voxel copies one exemplar pixel, "
                "which can speckle), 'average' (Kopf's weighted average of the last matches), 'auto': the "
                "least blend of the two whose slices are no grainier than the exemplar (none if not)."
            )
        ),
    )
    grey_remap: bool = Field(
        True,
        description="Remap the finished volume onto the exemplars' grey levels, rank for rank (off: paper).",
        json_schema_extra=ui(details=("Off: every voxel keeps its exemplar pixel's value (the paper).")),
    )
    sigma: float = Field(
        0.0,
        ge=0.0,
        le=10.0,
        description="Gaussian weighting of the window when voxels are updated; 0 weighs all equally (σ).",
        json_schema_extra=ui(details=("Gaussian entry weighting of the solver (0: flat).")),
    )
    kset_window: int = Field(
        1,
        ge=0,
        le=9,
        description="How many nearby voxels' lists of similar places are searched (the voxel first).",
        json_schema_extra=ui(
            unit="voxels",
            details=("Search: window voxels (the voxel first) whose k-coherence sets are candidates."),
        ),
    )
    solve_radius: int | None = Field(
        None,
        ge=0,
        le=7,
        description="Updates use matches centred within this distance of the voxel; automatic: chosen "
        "from the exemplar.",
        json_schema_extra=ui(
            unit="voxels",
            details=(
                "Solver candidates: matches centred within this many voxels of the voxel. None: "
                f"{LAMINAR_SOLVE_RADIUS} for laminar exemplars when adapt_to_structure is on, else 0 (the "
                f"voxel's "
                "own matches)."
            ),
        ),
    )
    orientation_gain: float | None = Field(
        None,
        ge=0.0,
        le=64.0,
        description="How strongly slices are pulled toward the exemplar's spread of orientations; 0 is "
        "off; automatic by exemplar.",
        json_schema_extra=ui(
            details=(
                "Pull each plane's matches toward its exemplar's orientation histogram (Kopf's eq 4 on "
                f"orientations; 0 = off, the paper). None: {LAMINAR_ORIENTATION_GAIN:g} for laminar "
                f"exemplars "
                "when adapt_to_structure is on, else off."
            )
        ),
    )

    @field_validator("structure_length", mode="before")
    @classmethod
    def _auto_length(cls, value: object) -> object:
        """``'auto'`` is the empty value: the length fitted to the exemplars."""
        return None if value == "auto" else value


# ------------------------------------------------------------------------------------------------ levels


def _bank(plan: SolidPlan, level: int, k: int) -> ExemplarBank:
    """The three planes' exemplars at ``level`` in one buffer (shared when planes share an image), with
    their k-coherence sets and principal-subspace features."""
    size = plan.sizes[level]
    r = size // 2
    nbhs = plan.neighbourhoods(level)
    n_dims = min(_RANK_DIMS, max(nb.basis.shape[1] for nb in nbhs))
    layout = np.zeros((3, 3), dtype=np.int64)
    valid = np.zeros((3, 4), dtype=np.int64)
    mean = np.zeros((3, size * size), dtype=np.float32)
    basis = np.zeros((3, size * size, n_dims), dtype=np.float32)
    parts: list[np.ndarray] = []
    ksets: list[np.ndarray] = []
    feats: list[np.ndarray] = []
    total = 0
    for p, nb in enumerate(nbhs):
        img = nb.image
        h, w = img.shape
        valid[p] = (r, h - r, r, w - r)
        mean[p] = nb.mean
        kept = min(n_dims, nb.basis.shape[1])
        basis[p, :, :kept] = nb.basis[:, :kept]
        shared = next((q for q in range(p) if nbhs[q] is nb), None)
        if shared is not None:
            layout[p] = layout[shared]
            continue
        layout[p] = (total, h, w)
        parts.append(img.ravel())
        local = k_coherence_sets(
            [(img[..., None], 1.0)], size, valid[p], k, np.ones((h, w), np.uint8), size, _KSET_DIMS
        )
        glob = np.where(local[..., 0] >= 0, total + local[..., 0] * w + local[..., 1], -1)
        ksets.append(glob.reshape(h * w, k))
        feat = np.zeros((h * w, n_dims), dtype=np.float32)
        feat[nb.centres, :kept] = (nb.vectors - nb.mean) @ nb.basis[:, :kept]
        feats.append(feat)
        total += h * w
    values = np.ascontiguousarray(np.concatenate(parts), dtype=np.float32)
    return ExemplarBank(
        values=values,
        layout=layout,
        valid=valid,
        kset=np.ascontiguousarray(np.concatenate(ksets), dtype=np.int32),
        features=np.ascontiguousarray(np.concatenate(feats), dtype=np.float32),
        mean=mean,
        basis=basis,
        grey_bin=np.clip((values * _GREY_BINS).astype(np.int64), 0, _GREY_BINS - 1),
    )


def _geometry(
    size: int, layout: np.ndarray, periodic: bool, planes: tuple[str, ...] = PLANES, sigma: float = 0.0
) -> SliceGeometry:
    """Slice neighbourhoods (centre included) and candidate windows of the three planes; ``planes`` are
    the constrained ones."""
    offsets = np.stack([plane_offsets(p, size) for p in PLANES]).astype(np.int64)
    lin = np.stack([exemplar_offsets(size, int(layout[p, 2])) for p in range(3)])
    cw = 2 * _CANDIDATE_RADIUS + 1
    cand = np.stack([plane_offsets(p, cw) for p in PLANES]).astype(np.int64)
    centre = (cw * cw) // 2  # the voxel's own match first
    order = np.r_[centre, np.delete(np.arange(cw * cw), centre)]
    if _CANDIDATE_WINDOW == "cross":  # the voxel and its four neighbours in the slice
        order = order[[0, *[i for i in range(1, len(order)) if np.count_nonzero(cand[0, order[i]]) == 1]]]
    cand = np.ascontiguousarray(cand[:, order])
    rc = np.stack([cand[p][:, list(PLANE_AXES[name])] for p, name in enumerate(PLANES)])
    active = np.array([p in planes for p in PLANES], dtype=np.bool_)
    r2 = np.sum(offsets.astype(np.float64) ** 2, axis=2)
    entry_weight = np.exp(-0.5 * r2 / sigma**2) if sigma > 0 else np.ones_like(r2)
    return SliceGeometry(offsets, lin, cand, np.ascontiguousarray(rc), bool(periodic), active, entry_weight)


def _bank_orientations(plan: SolidPlan, level: int, bank: ExemplarBank) -> list[OrientationLabels]:
    """Per plane, the orientation labels of its exemplar at ``level`` indexed by the bank's global
    positions (:func:`texsynth.synth.analysis.orientation_histogram.orientation_labels`)."""
    n = len(bank.values)
    lower = np.zeros(n, dtype=np.int64)
    fraction = np.zeros(n, dtype=np.float64)
    out: list[OrientationLabels] = []
    known: dict[int, OrientationLabels] = {}
    for p, nb in enumerate(plan.neighbourhoods(level)):
        if id(nb.image) not in known:
            known[id(nb.image)] = orientation_labels(nb.image)
            off, h, w = (int(t) for t in bank.layout[p])
            lower[off : off + h * w] = known[id(nb.image)].lower
            fraction[off : off + h * w] = known[id(nb.image)].fraction
        out.append(OrientationLabels(lower, fraction, known[id(nb.image)].shares))
    return out


def _update_orientation_factor(
    state: SolidState, labels: list[OrientationLabels], active: np.ndarray, gain: float
) -> None:
    """Each constrained plane's search factors from the over-use of orientations by its current matches
    (each counted with its IRLS weight), frozen for the next search pass."""
    everywhere = np.arange(state.orientation_factor.shape[1])
    for p in np.flatnonzero(active):
        excess = orientation_excess(labels[p], state.match[p].ravel(), state.weight[p].ravel())
        state.orientation_factor[p] = usage_factors(labels[p], excess, everywhere, gain)


def _random_matches(bank: ExemplarBank, shape: tuple[int, int, int], rng: np.random.Generator) -> np.ndarray:
    match = np.empty((3, *shape), dtype=np.int32)
    for p in range(3):
        off, _, w = (int(t) for t in bank.layout[p])
        y0, y1, x0, x1 = (int(t) for t in bank.valid[p])
        ys = rng.integers(y0, y1, size=shape)
        xs = rng.integers(x0, x1, size=shape)
        match[p] = off + ys * w + xs
    return match


def _tree_matches(
    plan: SolidPlan, level: int, bank: ExemplarBank, volume: np.ndarray, periodic: bool
) -> np.ndarray:
    """Each plane's best exemplar match of every voxel's slice neighbourhood in ``volume`` (PCA + k-d
    tree, :meth:`texsynth.synth.pixel.solid.ExemplarNeighbourhoods.search`), as global bank indices."""
    shape = volume.shape
    vol = np.ascontiguousarray(volume, dtype=np.float32)
    centres = np.stack(np.meshgrid(*[np.arange(s) for s in shape], indexing="ij"), axis=-1).reshape(-1, 3)
    match = np.empty((3, *shape), dtype=np.int32)
    chunk = 1 << 16
    for p, (name, nb) in enumerate(zip(PLANES, plan.neighbourhoods(level), strict=True)):
        flat = match[p].reshape(-1)
        for a in range(0, len(centres), chunk):
            queries = gather_plane(vol, centres[a : a + chunk], name, plan.sizes[level], periodic)
            pos, _ = nb.search(queries)
            flat[a : a + chunk] = bank.layout[p, 0] + pos
    return match


def _upsampled_matches(
    coarse: np.ndarray, coarse_bank: ExemplarBank, bank: ExemplarBank, shape: tuple[int, int, int]
) -> np.ndarray:
    """Each fine voxel's match: its parent's, doubled, plus the voxel's parity along the plane's axes."""
    coords = np.ogrid[0 : shape[0], 0 : shape[1], 0 : shape[2]]
    match = np.empty((3, *shape), dtype=np.int32)
    for p, name in enumerate(PLANES):
        parent = coarse[p][coords[0] // 2, coords[1] // 2, coords[2] // 2].astype(np.int64)
        my, mx = np.divmod(parent - coarse_bank.layout[p, 0], coarse_bank.layout[p, 2])
        ra, ca = PLANE_AXES[name]
        y0, y1, x0, x1 = (int(t) for t in bank.valid[p])
        fy = np.clip(2 * my + coords[ra] % 2, y0, y1 - 1)
        fx = np.clip(2 * mx + coords[ca] % 2, x0, x1 - 1)
        match[p] = bank.layout[p, 0] + fy * bank.layout[p, 2] + fx
    return match


def _targets(
    bank: ExemplarBank, n_vox: int, active: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Uniform-use targets over each constrained plane's valid positions: the index histogram's (slices
    matched per neighbourhood: ``n_vox`` per constrained plane using the exemplar) and the position
    histogram's (voxels copying each pixel: ``n_vox / n_planes`` per constrained plane using it)."""
    n = len(bank.values)
    act = np.ones(3, dtype=bool) if active is None else np.asarray(active, dtype=bool)
    index_target = np.ones(n)
    position_target = np.ones(n)
    for p in np.flatnonzero(act):
        off = int(bank.layout[p, 0])
        sharing = int(np.sum((bank.layout[:, 0] == off) & act))
        y0, y1, x0, x1 = (int(t) for t in bank.valid[p])
        n_valid = (y1 - y0) * (x1 - x0)
        w = int(bank.layout[p, 2])
        rows = off + np.arange(y0, y1)[:, None] * w + np.arange(x0, x1)[None, :]
        index_target[rows] = n_vox * sharing / n_valid
        position_target[rows] = n_vox * sharing / (float(act.sum()) * n_valid)
    return index_target, position_target


def _grey_target(bank: ExemplarBank, n_vox: int, active: np.ndarray) -> np.ndarray:
    """Voxels per grey-level bin if the volume had the constrained planes' exemplars' histogram (pooled,
    each plane counting for an equal share of the voxels)."""
    target = np.zeros(_GREY_BINS)
    for p in np.flatnonzero(active):
        off, h, w = (int(t) for t in bank.layout[p])
        counts = np.bincount(bank.grey_bin[off : off + h * w], minlength=_GREY_BINS).astype(np.float64)
        target += counts / counts.sum() * n_vox / int(np.sum(active))
    return np.maximum(target, 0.5)


def _usage_spread(origin: np.ndarray, bank: ExemplarBank, active: np.ndarray) -> float:
    """Coefficient of variation of how often each valid exemplar pixel is copied (0 = perfectly uniform)."""
    counts = np.bincount(origin.ravel(), minlength=len(bank.values)).astype(np.float64)
    keep = np.zeros(len(bank.values), dtype=bool)
    for p in np.flatnonzero(active):
        off, w = int(bank.layout[p, 0]), int(bank.layout[p, 2])
        y0, y1, x0, x1 = (int(t) for t in bank.valid[p])
        keep[off + np.arange(y0, y1)[:, None] * w + np.arange(x0, x1)[None, :]] = True
    used = counts[keep]
    return float(used.std() / max(used.mean(), 1e-12))


# ------------------------------------------------------------------------------------------------ driver


def orientation_length(image: np.ndarray) -> float:
    """How far the fringes keep their orientation, in fringe periods.

    The structure tensor's doubled-angle orientation ``(J_rr - J_cc + 2i J_rc) / |...|`` (Gaussian
    derivatives of 1 px, integration 2 px), less its mean, is autocorrelated (periodic FFT); the answer is
    the first radius at which the radial mean of the normalised autocorrelation falls below 0.5, divided
    by :func:`texsynth.synth.pixel.laminar.dominant_period`. Crumpled stacks: about 1; bent laminae 2-5.
    """
    img = np.asarray(image, dtype=np.float64)
    gr = ndi.gaussian_filter(img, 1.0, order=(1, 0), mode="reflect")
    gc = ndi.gaussian_filter(img, 1.0, order=(0, 1), mode="reflect")
    j_rr, j_cc, j_rc = (ndi.gaussian_filter(g, 2.0, mode="reflect") for g in (gr * gr, gc * gc, gr * gc))
    z = (j_rr - j_cc) + 2j * j_rc
    z = z / np.maximum(np.abs(z), 1e-12)
    z = z - z.mean()
    spectrum = np.fft.fft2(z)
    ac = np.fft.ifft2(spectrum * np.conj(spectrum)).real
    ac = ac / max(float(ac[0, 0]), 1e-12)
    h, w = ac.shape
    rows, cols = np.meshgrid(np.fft.fftfreq(h) * h, np.fft.fftfreq(w) * w, indexing="ij")
    radius = np.hypot(rows, cols).astype(np.int64).ravel()
    profile = np.bincount(radius, ac.ravel()) / np.maximum(np.bincount(radius), 1)
    below = np.flatnonzero(profile < 0.5)
    lag = int(below[0]) if below.size else len(profile)
    return lag / max(dominant_period(img), 1e-6)


def _crumpled_stack(exemplars: Mapping[str, np.ndarray], planes: tuple[str, ...]) -> bool:
    """Whether 'auto' takes the oriented start: laminar exemplars (:func:`is_laminar`) on the three planes
    whose fringes turn within :data:`ORIENTED_MAX_LENGTH` periods (:func:`orientation_length`), as the
    stack's crumples do.

    One exemplar for every plane is measured once; per-plane exemplars by their lengths' mean weighted by
    each plane's anisotropy (:func:`texsynth.synth.pixel.laminar.plane_orientation`, as solid-kopf's
    :func:`texsynth.synth.pixel.laminar.exemplar_bend`: a plane nearly parallel to the sheets shows contour
    bands, not fringes). Per-plane bent sheets (2.2 periods) keep the random start (docs/solid.md).
    """
    images = [np.asarray(exemplars[p]) for p in planes]
    if len(images) != 3:  # two views: not measured with the oriented start but on bent laminae (worse)
        return False
    if all(im is images[0] or np.array_equal(im, images[0]) for im in images[1:]):
        return is_laminar(images[:1]) and orientation_length(images[0]) <= ORIENTED_MAX_LENGTH
    if not is_laminar(images):
        return False
    weights = [max(plane_orientation(im)[1], 1e-3) for im in images]
    length = float(np.average([orientation_length(im) for im in images], weights=weights))
    return length <= ORIENTED_MAX_LENGTH


@dataclass(frozen=True)
class _Schedule:
    """The run's automatic choices, resolved once from the parameters and the constrained exemplars."""

    iterations: int
    coarse_iterations: int
    orientation_gain: float
    solve_radius: int
    start: str = "none"
    period: float = 0.0
    stack_period: float = 0.0
    #: The start's length (periods): the sheets' (laminar) or the crumples' (oriented); 0 without a start.
    length: float = 0.0
    #: The laminar start's sheets: 'surfaces', 'centres' or 'domains' (``shells``); None without it.
    shells: str | None = None
    #: The exemplars' centres of curvature: their concentration and the fitted spacing (periods); None
    #: without the laminar start.
    concentration: float | None = None
    centre_spacing: float | None = None
    #: How much one centre per exemplar explains their orientations (``concentric_fit``); None without
    #: the laminar start.
    concentric: float | None = None
    #: How far the exemplars' fringes keep their orientation (periods, ``bend_length``); None when the
    #: choice of the sheets did not need it.
    bend: float | None = None

    @property
    def laminar_start(self) -> bool:
        """Whether the coarsest level starts from sheets (laminar or oriented) rather than noise."""
        return self.start != "none"

    @classmethod
    def resolve(cls, params: SolidChenWangParams, exemplars: Mapping[str, np.ndarray]) -> _Schedule:
        """Laminae (``adapt_to_structure``, :func:`texsynth.synth.pixel.solid.is_laminar`) get at least 10
        iterations per level and the laminar settings of the parameters left ``None``; fewer levels hurt this
        method, so they stay."""
        iterations = params.iterations
        orientation_gain = params.orientation_gain or 0.0
        solve_radius = params.solve_radius or 0
        coarse_iterations = params.coarse_iterations
        start = start_kind(
            params.structure, exemplars, params.planes, params.adapt_to_structure, laminar_pilot
        )
        if (
            params.structure == "auto"
            and start == "oriented"
            and not _crumpled_stack(exemplars, params.planes)
        ):
            start = "none"  # bent laminae: worse than from noise (docs/solid.md); grains: not laminae
        if params.adapt_to_structure:
            constrained = [exemplars[name] for name in params.planes]
            _, iterations = structure_schedule(constrained, 1, iterations)
            laminar = is_laminar(constrained)
            if params.orientation_gain is None and laminar:
                orientation_gain = LAMINAR_ORIENTATION_GAIN
            if params.solve_radius is None and laminar:
                solve_radius = LAMINAR_SOLVE_RADIUS
            if start == "oriented":  # the stack is there from the start: nothing to grow or anneal
                iterations = max(params.iterations, ORIENTED_ITERATIONS)
                if coarse_iterations is None:
                    coarse_iterations = ORIENTED_COARSE_ITERATIONS
            if coarse_iterations is None and laminar:
                coarse_iterations = LAMINAR_COARSE_ITERATIONS
        if coarse_iterations is None:
            coarse_iterations = iterations
        period = stack = length = 0.0
        shells = concentration = spacing = concentric = bend = None
        if start != "none":
            period = float(np.mean([dominant_period(np.asarray(exemplars[p])) for p in params.planes]))
        if start == "oriented":  # the sheets' spacing behind the planes' apparent periods (as solid-kopf)
            views = {p: np.asarray(exemplars[p]) for p in params.planes}
            stack = stack_period(views, sheet_normal({p: plane_orientation(im) for p, im in views.items()}))
            length = params.oriented_length
        elif start == "laminar":
            images = [np.asarray(exemplars[p]) for p in params.planes]
            length = resolved_length(params.structure_length, lambda: chen_wang_structure_length(images))
            chosen = choose_shells(params.shells, params.centre_spacing, images)
            shells, concentration = chosen.kind, chosen.concentration
            spacing, concentric, bend = chosen.spacing, chosen.concentric, chosen.bend
        return cls(
            iterations,
            coarse_iterations,
            orientation_gain,
            solve_radius,
            start,
            period,
            stack,
            length,
            shells,
            concentration,
            spacing,
            concentric,
            bend,
        )

    def levels(self, levels: int) -> int:
        """At most ``levels``; with the laminar start, those that keep a 3 px period."""
        return structure_levels(self.period, levels) if self.laminar_start else levels

    def per_level(self, levels: int) -> list[int]:
        """Iterations of each pyramid level (0 the finest)."""
        return [self.iterations if level == 0 else self.coarse_iterations for level in range(levels)]


class _ChenWangLoop:
    """Search and discrete-solver passes at each level (:func:`texsynth.synth.pixel.solid.run_levels`)."""

    def __init__(
        self, params: SolidChenWangParams, plan: SolidPlan, run: SolidRun, schedule: _Schedule
    ) -> None:
        self.params, self.plan, self.run, self.schedule = params, plan, run, schedule
        self.weights0 = SolverWeights(
            index_weight=params.index_weight,
            position_weight=params.position_weight,
            exponent=params.exponent,
            n_random=params.random_candidates,
            solve_radius=schedule.solve_radius,
            kset_window=params.kset_window,
            consensus=params.consensus,
            grey_weight=params.grey_weight,
        )
        total = sum(
            (1 + iterations * (1 + _SEARCH_COST)) * int(np.prod(s))
            for iterations, s in zip(schedule.per_level(plan.levels), plan.shapes, strict=True)
        )
        self.meter = ProgressMeter(run.report, total)
        self.stats: dict = {
            "levels": plan.levels,
            "iterations": schedule.iterations,
            "coarse_iterations": schedule.coarse_iterations,
            "orientation_gain": schedule.orientation_gain,
            "solve_radius": schedule.solve_radius,
            "sizes": list(plan.sizes),
            "laminar_start": schedule.laminar_start,
            "start": schedule.start,
            # The sheets' spacing: the planes' mean period, or the stack's behind it (oriented start).
            "period": (schedule.stack_period if schedule.start == "oriented" else schedule.period)
            if schedule.laminar_start
            else None,
            # The start's length in periods (the sheets' fitted or given; the crumples'), None without one.
            "start_length": schedule.length if schedule.laminar_start else None,
            # The laminar start's sheets ('surfaces', 'centres' or 'domains'), None without it.
            "shells": schedule.shells,
            # The exemplars' centres of curvature (share gathered) and the centres' spacing (periods).
            "centre_concentration": schedule.concentration,
            "centre_spacing": schedule.centre_spacing,
            # How much one centre explains the exemplars' orientations (a particle seen whole).
            "concentric_explained": schedule.concentric,
            # How far the exemplars' fringes keep their orientation (periods: short ones get domains).
            "fringe_bend": schedule.bend,
            "mean_match_distance": {},
            "mean_candidates": {},
            "level_seconds": {},
        }
        self.match: np.ndarray | None = None
        self.prev_bank: ExemplarBank | None = None

    def start_level(self, step: LevelStep) -> None:
        """The level's bank and geometry, its matches (upsampled, or random at the coarsest), its first
        voxels and histograms, and the solve pass that precedes the first search."""
        params, plan, rng = self.params, self.plan, self.run.rng
        self.t0 = time.perf_counter()
        shape, n_vox = step.shape, step.voxels
        bank = self.bank = _bank(plan, step.level, params.k)
        geometry = self.geometry = _geometry(
            step.size, bank.layout, params.periodic, params.planes, params.sigma
        )
        start_volume = None
        if (self.match is None or self.prev_bank is None) and self.schedule.laminar_start:
            scale = 2.0**step.level
            values = np.concatenate(
                [plan.exemplars[PLANES.index(p)][step.level].ravel() for p in params.planes]
            )
            if self.schedule.start == "oriented":  # solid-kopf's crumpled stack, at the finest shape
                views = {p: plan.exemplars[PLANES.index(p)][0] for p in params.planes}
                stack = self.schedule.stack_period
                phi = oriented_phase(
                    plan.shapes[0],
                    views,
                    stack,
                    self.schedule.length * stack,
                    rng,
                    periodic=params.periodic,
                )
                start_volume = sheets(level_phase(phi, step.level), stack / scale, values)
            elif self.schedule.shells in ("centres", "domains"):  # onions, or straight stacks in cells
                spacing = float(self.schedule.centre_spacing or 0.0) * self.schedule.period / scale
                drawn = centre_phase if self.schedule.shells == "centres" else domain_phase
                phase = drawn(shape, spacing, rng, periodic=params.periodic)
                start_volume = sheets(phase, self.schedule.period / scale, values)
            else:
                start_volume = laminar_volume(
                    shape,
                    self.schedule.period / scale,
                    self.schedule.length * self.schedule.period / scale,
                    values,
                    rng,
                    periodic=params.periodic,
                )
            match = _tree_matches(plan, step.level, bank, start_volume, params.periodic)
        elif self.match is None or self.prev_bank is None:
            match = _random_matches(bank, shape, rng)
        else:
            match = _upsampled_matches(self.match, self.prev_bank, bank, shape)
        index_target, position_target = _targets(bank, n_vox, geometry.active)
        # The first voxels: the pixels the first constrained plane's matches are centred on (coherent
        # 2 x 2 blocks of the coarser solution, or random pixels at the coarsest level).
        # A copy: a view would alias the plane's matches, and every solve would overwrite them.
        origin = np.array(match[int(np.flatnonzero(geometry.active)[0])], dtype=np.int32)
        self.state = SolidState(
            volume=np.ascontiguousarray(bank.values[origin] if start_volume is None else start_volume),
            match=np.ascontiguousarray(match),
            weight=np.ones((3, *shape), dtype=np.float32),
            origin=origin,
            index_count=np.bincount(match[geometry.active].ravel(), minlength=len(bank.values)).astype(
                np.int64
            ),
            index_target=index_target,
            position_count=np.bincount(origin.ravel(), minlength=len(bank.values)).astype(np.int64),
            position_target=position_target,
            grey_count=np.bincount(bank.grey_bin[origin].ravel(), minlength=_GREY_BINS).astype(np.int64),
            grey_target=_grey_target(bank, n_vox, geometry.active),
            orientation_factor=np.ones((3, len(bank.values)), dtype=np.float64),
        )
        gain = self.schedule.orientation_gain
        self.orientations = _bank_orientations(plan, step.level, bank) if gain > 0 else None
        self.scratch = new_scratch(bank, self.state)
        self.fixed_order = None if params.scan == "random" else scan_order(shape, params.scan)
        self.label = f"level {step.levels - step.level}/{step.levels}"
        self._phase(solve_pass, 1.0, f"{self.label}: initial voxels", self.weights0)

    def iterate(self, step: LevelStep, it: int) -> bool:
        """A search pass (index and orientation histograms frozen per call), then a solve pass."""
        weights = SolverWeights(
            **{**self.weights0.__dict__, "seed_key": int(self.run.rng.integers(0, 2**63))}
        )
        acc = self.scratch["acc"]
        acc[:] = 0.0
        if self.orientations is not None:
            gain = self.schedule.orientation_gain
            _update_orientation_factor(self.state, self.orientations, self.geometry.active, gain)
        self._phase(search_pass, _SEARCH_COST, f"{self.label}, iteration {it + 1}: search", weights)
        key = f"level {step.levels - step.level} iteration {it + 1}"
        self.stats["mean_match_distance"][key] = float(acc[0] / max(acc[1], 1.0))
        self.stats["mean_candidates"][key] = float(acc[2] / max(acc[1], 1.0))
        self._phase(solve_pass, 1.0, f"{self.label}, iteration {it + 1}: optimisation", weights)
        return True

    def end_level(self, step: LevelStep) -> None:
        self.match = self.state.match
        self.prev_bank = self.bank
        self.stats["level_seconds"][f"level {step.levels - step.level}"] = time.perf_counter() - self.t0

    def _phase(self, fn: Callable[..., None], cost: float, stage: str, weights: SolverWeights) -> None:
        """One pass of ``fn`` (search or solve) over the level's scan order, in progress-sized chunks."""
        shape = self.state.volume.shape
        order = (
            self.fixed_order if self.fixed_order is not None else scan_order(shape, "random", self.run.rng)
        )
        for start, stop in self.meter.chunks(len(order), cost, stage):
            fn(self.bank, self.geometry, self.state, weights, order, start, stop, self.scratch)

    def _final_volume(self) -> np.ndarray:
        """The discrete volume blended with the last matches' least-squares average (``final_step``): by
        the weight given, or ('auto') the least one whose slices' grain (:mod:`texsynth.synth.analysis.grain`)
        is at most the exemplars' mean."""
        params, volume = self.params, self.state.volume
        average = self.scratch.get("consensus")  # the last solve pass's mu: Kopf's voxel of those matches
        if params.final_step == "discrete" or average is None:
            self.stats["final_blend"] = 0.0
            return volume
        images = [self.plan.exemplars[PLANES.index(p)][0] for p in params.planes]
        axes = [PLANES.index(p) for p in params.planes]
        given = 1.0 if params.final_step == "average" else None
        volume, blend, ratios = match_grain(volume, average, images, axes, params.periodic, given)
        # the slices' grain over the exemplars': the discrete volume's, then the one returned
        self.stats["grain_ratio"] = ratios
        self.stats["final_blend"] = blend
        return volume

    def finish(self) -> tuple[np.ndarray, dict]:
        """The finest level's volume (remapped onto the exemplars' grey levels with ``grey_remap``)."""
        self.stats["usage_spread"] = _usage_spread(self.state.origin, self.bank, self.geometry.active)
        volume = np.clip(self._final_volume(), 0.0, 1.0).astype(np.float32)
        pooled = np.concatenate(
            [self.plan.exemplars[PLANES.index(p)][0].ravel() for p in self.params.planes]
        ).astype(np.float32)
        self.stats["contrast_before_remap"] = float(volume.std() / max(float(pooled.std()), 1e-12))
        if self.params.grey_remap:  # Kopf's final rank remap (docs/solid.md, "Departures from the papers")
            volume = match_histogram(volume, pooled)
        return volume, self.stats


def synthesize_solid_chen_wang(
    exemplars: Mapping[str, np.ndarray],
    size: tuple[int, int, int],
    params: SolidChenWangParams,
    *,
    seed: int = 0,
    progress: Progress | None = None,
) -> tuple[np.ndarray, dict]:
    """The volume ``size = (D, H, W)`` and the run's statistics.

    Parameters
    ----------
    exemplars : mapping ``{'xy', 'xz', 'yz'} -> ndarray (h, w) float32``
        One grey exemplar per plane (the same array three times for an isotropic material).
    size : (D, H, W)
    params : SolidChenWangParams
    seed : int
        Every random choice comes from ``numpy.random.default_rng(seed)``.
    progress : callable ``(stage, fraction)``, optional
        Called at least every 2% of the work; whatever it raises stops the run.

    Returns
    -------
    volume : ndarray (D, H, W) float32
        Every voxel is an exemplar pixel of the finest level.
    stats : dict
        ``levels``, ``sizes``, ``mean_match_distance`` and ``mean_candidates`` (per level and iteration of
        the search), ``usage_spread``
        (coefficient of variation of the exemplar pixels' use at the finest level) and ``level_seconds``.
    """
    for plane in PLANES:
        if not np.all(np.isfinite(np.asarray(exemplars[plane]))):
            raise InvalidInput(f"exemplar_{plane}", "contains NaN or infinite values")
    schedule = _Schedule.resolve(params, exemplars)
    levels = schedule.levels(params.levels)
    plan = plan_levels(exemplars, tuple(int(s) for s in size), levels, params.neighbourhood_size)
    run = SolidRun.start(None, exemplars, params.planes, seed, progress or (lambda stage, fraction: None))
    loop = _ChenWangLoop(params, plan, run, schedule)
    run_levels(plan, schedule.per_level(plan.levels), loop)
    return loop.finish()


def run_solid_chen_wang(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int, int],
    params: SolidChenWangParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
    exemplars: Mapping[str, np.ndarray] | None = None,
) -> Result:
    """The registered runner (see :class:`texsynth.synth.api.MethodSpec`)."""
    start = time.perf_counter()
    report = checked_progress(progress)
    planes = dict(exemplars) if exemplars is not None else dict.fromkeys(PLANES, exemplar)
    volume, stats = synthesize_solid_chen_wang(planes, size, params, seed=seed, progress=report)
    report("done", 1.0)
    return Result(
        method="solid-chen-wang",
        image=volume,
        params=params.model_dump(),
        seed=seed,
        timings={"synthesis": time.perf_counter() - start},
        stats=stats,
    )


SPEC = register(
    MethodSpec(
        name="solid-chen-wang",
        summary="Solid texture from 2D exemplars: k-coherence search, discrete solver, position and index "
        "histogram matching (Chen & Wang 2010).",
        params_model=SolidChenWangParams,
        run=run_solid_chen_wang,
        precheck=precheck_structured_start,
        output_ndim=3,
        plane_exemplars=True,
        paper="Chen & Wang, The Visual Computer 26(4), 2010",
        seconds_per_element=1.8e-5,  # 128^3 from 128^2 soot: 38.5 s (docs/benchmarks.md)
    )
)
