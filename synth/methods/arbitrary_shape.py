"""Arbitrary-shape synthesis: the exemplar's texture dressed on a constraint image's structure.

Akl, Yaacoub, Donias, Da Costa, Germain (GRETSI), in three steps:

1. **Constraint field** (section 2.1, eqs 1-3): the orientation field ``O_con`` of the constraint
   ``I_con`` (eq 1) turns every tensor of the exemplar's field ``S_en`` by the angle at the same
   position, ``S_con = R S_en R^T`` (eqs 2-3, :func:`texsynth.synth.analysis.tensor.rotate_tensors`).
2. **Rotated dictionary** ``D_M`` (section 2.2, eq 4): the exemplar turned by ``2 pi m / M`` (5 deg).
3. **Synthesis** (section 3, eqs 5-6): each output neighbourhood (intensities and ``S_con``'s tensors)
   is matched in ``D_M`` with ``W SSD + (1 - W) STD`` and the best match's pixel copied: the shared
   engine (:mod:`texsynth.synth.pixel.synthesis`) on ``D_M``'s canvas, guided by ``S_con``.

Choices the paper leaves open and departures, each measured in docs/arbitrary-shape.md ("How it works"):
- ``rotation_reference='dominant'``: ``S_en`` turned by ``O_con - O_dom`` (``'absolute'``: the paper);
- a size unlike the constraint's: an exemplar-like texture synthesized first by ``tensor-constrained``;
- ``restrict_rotations`` (the paper's perspective): only the copies at the local angle are searched;
- ``transfer_candidates``: a proposal from another copy moves to the copy at the local angle;
- ``histogram_weight``: grey-level histogram matching (Kopf et al. 2007, eq 4); 0 is the paper;
- ``hint_layout='strands'``, ``initial_sources='hints'``: the exemplar's fibres laid along the
  constraint's strands (:mod:`texsynth.synth.methods.strand_hints`), chosen by the fibre grey spread;
- ``recipe='auto'``: settings by the exemplar's coherence (``'fibres'`` adds square refinement passes);
- ``W`` weighs normalised parts; default 0.1, the measured best; ``k = 0`` (k-sets over ``D_M`` are large);
- ``periodic=True``: the output tiles if the constraint does. Following it: :func:`orientation_agreement`.

References
----------
A. Akl, C. Yaacoub, M. Donias, J.-P. Da Costa, C. Germain, "Synthèse de texture contrainte par champ
de structure arbitraire", GRETSI (eqs 1-6, figures 1-4).
A. Akl et al., "Structure tensor based synthesis of directional textures ...", IEEE ICIP 2014.
"""

from __future__ import annotations

import math
import time
from typing import Literal, NamedTuple

import numpy as np
from pydantic import Field, field_validator
from scipy.spatial import cKDTree
from skimage.transform import resize

from texsynth.synth.analysis.fibre_grey import OWN_GREY_FIBRES, fibre_grey_spread
from texsynth.synth.analysis.rotation import (
    RotatedDictionary,
    build_rotated_dictionary,
    dictionary_bytes,
    rotation_candidates,
)
from texsynth.synth.analysis.tensor import (
    ORIENTED_COHERENCE,
    Metric,
    coherence,
    dominant_orientation,
    mean_coherence,
    orientation,
    rotate_tensors,
    structure_direction,
    structure_tensor,
    wrap_angle,
)
from texsynth.synth.api import MethodSpec, Progress, Result, register
from texsynth.synth.colour import to_grey
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.grid.pyramid import gaussian_pyramid, level_shapes
from texsynth.synth.methods.common import NeighbourhoodParams, as_features, checked_progress
from texsynth.synth.methods.strand_hints import StrandHints, fibre_table, strand_hints
from texsynth.synth.methods.tensor_constrained import TensorConstrainedParams, run_tensor_constrained
from texsynth.synth.params import ui
from texsynth.synth.pixel.synthesis import (
    CandidateWindow,
    Guidance,
    level_neighbourhood_size,
    source_map_pyramid,
    synthesize_source_map,
    tensor_features,
)

__all__ = [
    "DICTIONARY_MEMORY_LIMIT",
    "K_SET_MEMORY_LIMIT",
    "PAPER_HINTS",
    "STRAND_HINTS",
    "ArbitraryShapeParams",
    "Resolution",
    "constraint_field",
    "orientation_agreement",
    "rotation_window",
    "run_arbitrary_shape",
]

#: Largest estimated size (bytes) of the k-coherence set computation over ``D_M``.
K_SET_MEMORY_LIMIT = 1_500_000_000
#: Largest estimated size (bytes) of ``D_M``'s canvas, the features and pyramid made from it counted twice
#: over (the service's own estimate, TEXSYNTH_MAX_JOB_MEMORY_BYTES, refuses far less before queueing).
DICTIONARY_MEMORY_LIMIT = 8_000_000_000
#: A constraint whose largest tensor trace is below this (images in [0, 1]) has no structure at all.
FLAT_TRACE = 1e-8
#: Scale of the orientation analysis of :func:`orientation_agreement` (pixels): a window about one
#: fringe period wide (the generated constraints' period is 8 px; HRTEM fringes 3-6 px).
AGREEMENT_SIGMA_W = 4.0
#: Grey-level bins of the histogram matching (``histogram_weight``).
GREY_LABELS = 16
#: The settings each recipe gives the parameters left at their defaults (docs/arbitrary-shape.md has the
#: measurements). 'fibres' (strongly oriented exemplars): every tensor of S_con turned to the constraint
#: ('local'), the strict rotation window with proposals moved across copies (transfer_candidates, a
#: field default), intensities and tensors weighed equally (W = 0.5) and grey-level histogram matching,
#: so that strands continue along the constraint with the exemplar's grey levels; then three square
#: refinement passes in a random order (4 passes, refinement='square', the whole 13 x 13 square), which
#: mend the kinks the causal lexicographic first pass leaves where the strands turn (the waves' crests).
#: 'weak' (soot-like
#: exemplars, whose own orientations scatter): 'local', the soot's short fringes' scale (sigma_w = 2),
#: the paper's square neighbourhood with a random walk, 7 x 7, 4 passes, W = 0.2.
RECIPES: dict[str, dict[str, object]] = {
    "fibres": {
        "rotation_reference": "local",
        "window_search": "strict",
        "w": 0.5,
        "histogram_weight": 5.0,
        "iterations": 4,
        "refinement": "square",
    },
    "weak": {
        "rotation_reference": "local",
        "sigma_w": 2.0,
        "neighbourhood": "square",
        "neighbourhood_size": 7,
        "iterations": 4,
        "w": 0.2,
    },
    "paper": {},
}
#: The strand hints (:mod:`texsynth.synth.methods.strand_hints`, the output started from them) that
#: :meth:`ArbitraryShapeParams.resolved` gives the 'fibres' recipe for fibres with their own grey levels.
STRAND_HINTS: dict[str, object] = {"hint_layout": "strands", "initial_sources": "hints"}
#: The paper's route, chosen otherwise: hints from an exemplar-like texture, a random start.
PAPER_HINTS: dict[str, object] = {"hint_layout": "texture", "initial_sources": "random"}


class ArbitraryShapeParams(NeighbourhoodParams):
    """Parameters of arbitrary-shape synthesis; the fields' defaults = the GRETSI paper's settings
    (section 4), plus ``transfer_candidates``.

    ``recipe`` (default ``'auto'``) then sets the fields left at their defaults from the exemplar's mean
    coherence: :data:`RECIPES` ``'fibres'`` for strongly oriented exemplars, ``'weak'`` for weakly
    oriented ones (HRTEM soot, whose own orientations scatter widely); ``recipe='paper'`` runs the
    fields as given (docs/arbitrary-shape.md has the measurements). ``hint_layout`` and
    ``initial_sources`` left unset are chosen from the exemplar's fibre grey spread (the strand hints
    for the 'fibres' recipe on fibres with their own grey levels; :meth:`resolved`).
    """

    recipe: Literal["auto", "fibres", "weak", "paper"] = Field(
        "auto",
        description="Settings picked for the exemplar: 'fibres' for strongly oriented ones, 'weak' for "
        "soot, 'paper' as given; 'auto' decides.",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Settings chosen for the exemplar: 'fibres' for strongly oriented exemplars (strands "
                "continue along the constraint), 'weak' for weakly oriented ones (soot), 'paper' the "
                "parameters as given (their defaults: the paper's settings); 'auto' picks 'fibres' when "
                "the exemplar's mean coherence is at least 0.7, else 'weak'. A recipe sets only the "
                "parameters left at their defaults: a value you change is kept."
            ),
        ),
    )
    angular_step: float = Field(
        5.0,
        gt=0.0,
        le=180.0,
        description="Angle between the exemplar's rotated copies; must divide 360 (M = 360 / step copies).",
        json_schema_extra=ui(
            basic=True,
            unit="degrees",
            details=("Degrees between the rotated copies of D_M (M = 360 / step)."),
        ),
    )
    levels: int = Field(
        1,
        ge=1,
        le=4,
        description="Number of pyramid levels, coarse to fine (the paper: 1 or 2).",
        json_schema_extra=ui(basic=True, details=("Gaussian pyramid levels (the paper: 1 or 2).")),
    )
    iterations: int = Field(
        2,
        ge=1,
        le=10,
        description="Passes over the output at each pyramid level (the paper: 2).",
        json_schema_extra=ui(basic=True, details=("Passes per pyramid level (the paper: 2).")),
    )
    # The paper gives no value of W; 0.1 follows the constraint best at an unchanged grey-level
    # histogram on the generated constraints (docs/arbitrary-shape.md, measured for 0.5, 0.3, 0.1).
    w: float = Field(
        0.1,
        ge=0.0,
        le=1.0,
        description="How strongly the grey levels weigh against the orientation tensors when matching (W, "
        "Eq. 5).",
        json_schema_extra=ui(
            basic=True, details=("W of eq 5: weight of the intensity SSD against the tensor STD.")
        ),
    )
    metric: Metric = Field(
        "ED",
        description="How two orientation tensors are compared: Euclidean (ED, the paper), "
        "shape-orientation (SO), Frobenius (FN), log-Euclidean (LE).",
        json_schema_extra=ui(details=("Tensor dissimilarity: ED (the paper), SO, FN or LE.")),
    )
    alpha: float = Field(
        0.5,
        ge=0.0,
        le=1.0,
        description="With shape-orientation only: weight of orientation against coherence (α).",
        json_schema_extra=ui(details=("SO metric: weight of orientation against coherence.")),
    )
    rotation_reference: Literal["dominant", "absolute", "local"] = Field(
        "dominant",
        description="How the exemplar is turned to follow the constraint: by the difference to its "
        "'dominant' angle, 'absolute', or 'local'.",
        json_schema_extra=ui(
            details=(
                "'dominant': turn the exemplar's tensors by O_con minus the exemplar's dominant "
                "orientation (structures follow the constraint, keeping the exemplar's own orientation "
                "spread); 'absolute': by O_con (the paper, literally); 'local': by O_con minus each "
                "tensor's own orientation (S_con's orientation is O_con exactly; for weakly oriented "
                "exemplars)."
            )
        ),
    )
    restrict_rotations: bool = Field(
        True,
        description="Search only the rotated copies near the constraint's local angle (within the "
        "rotation window).",
        json_schema_extra=ui(
            details=("Search only the copies turned by the local constraint angle (within rotation_window).")
        ),
    )
    rotation_window: float = Field(
        2.5,
        ge=0.0,
        le=90.0,
        description="Half-width of the range of rotated copies searched around the local angle.",
        json_schema_extra=ui(
            unit="degrees",
            details=(
                "Half-width (degrees) of the window of copies searched with restrict_rotations (at least "
                "the nearest copy)."
            ),
        ),
    )
    # Measured (docs/arbitrary-shape.md): with 'local', the wanted copy jumps with the exemplar's own
    # orientation noise from pixel to pixel, and a strict window breaks coherent copying (soot: 0.37
    # against 0.24 with hints only); with 'dominant'/'absolute' the strict window follows as well or
    # better.
    window_search: Literal["strict", "hints"] | None = Field(
        None,
        description="How the rotation window restricts: 'strict' everywhere, or 'hints' that neighbours "
        "may outvote; automatic by the reference.",
        json_schema_extra=ui(
            details=(
                "How restrict_rotations restricts: 'strict' searches only the copies in the window at "
                "every position; 'hints' proposes one in-window candidate per position but lets "
                "neighbours' sources from other copies compete. Default: strict, hints with "
                "rotation_reference='local'."
            )
        ),
    )
    transfer_candidates: bool = Field(
        True,
        description="Move a neighbour's proposal from another rotated copy to the copy at the local angle "
        "instead of dropping it.",
        json_schema_extra=ui(
            details=(
                "With the strict window: a neighbour's coherent proposal from another rotated copy is "
                "moved to the same exemplar point of the copy at the local angle instead of being "
                "dropped, so strands continue where the constraint's angle crosses a copy's step (False: "
                "dropped, the previous behaviour)."
            )
        ),
    )
    histogram_weight: float = Field(
        0.0,
        ge=0.0,
        le=100.0,
        description="How strongly over-used grey levels are avoided; 0 is off (the paper).",
        json_schema_extra=ui(
            details=(
                "Grey-level histogram matching: a candidate whose grey-level bin the output already "
                "over-uses has its distance multiplied by 1 + weight * excess (0: off, the paper)."
            )
        ),
    )
    constraint_tensors: Literal["rotated-exemplar", "constraint"] = Field(
        "rotated-exemplar",
        description="Orientation field to follow: the exemplar's tensors turned to the constraint "
        "(S_con), or the constraint's own.",
        json_schema_extra=ui(
            details=(
                "'rotated-exemplar': S_con, the exemplar's tensors turned by O_con (the method); "
                "'constraint': the constraint image's own tensors (the paper's naive I_sor/O, for "
                "comparison)."
            )
        ),
    )
    hint_layout: Literal["texture", "strands"] | None = Field(
        None,
        description="Where the starting hints come from: a 'texture' made from the exemplar, or exemplar "
        "fibres laid along 'strands'.",
        json_schema_extra=ui(
            details=(
                "Where the hints (and S_en) come from: 'texture', an exemplar-like texture synthesized in "
                "the exemplar's frame (the paper's route); 'strands', exemplar fibres laid along the "
                "constraint's strands, so that each output strand is offered one fibre (one grey level) "
                "along its length (texsynth.synth.methods.strand_hints). Default: 'strands' with the "
                "'fibres' "
                "recipe when the exemplar's fibres carry their own grey levels (fibre grey spread at "
                "least 0.35, e.g. a wood grain) and restrict_rotations is on, else 'texture'."
            )
        ),
    )
    strand_hint_spacing: int = Field(
        128,
        ge=8,
        le=1024,
        description="With strand hints: length along a strand before its hinted fibre changes.",
        json_schema_extra=ui(
            unit="px",
            details=(
                "With hint_layout='strands': pixels between the cuts across the strands where a strand's "
                "hinted fibre changes (longer runs of one fibre with a larger spacing)."
            ),
        ),
    )
    initial_sources: Literal["random", "hints"] | None = Field(
        None,
        description="How the output starts: from 'random' exemplar places (the paper), or from the "
        "'hints'; automatic by the hints.",
        json_schema_extra=ui(
            details=(
                "How the output starts: 'random' sources and a first pass in the neighbourhood's scan "
                "(the paper); 'hints', every position starts from its hint (with hint_layout='strands': "
                "the exemplar's fibres laid along the constraint) and every pass, the first included, "
                "compares the square refinement neighbourhood in a random order (refinement='square'). "
                "Needs restrict_rotations (the hints). Default: 'hints' where hint_layout's default is "
                "'strands', else 'random'."
            )
        ),
    )
    sigma_d: float = Field(
        1.0,
        gt=0.0,
        le=16.0,
        description="Blur before the image gradients of the orientation field (σ_d).",
        json_schema_extra=ui(unit="px", details=("Structure tensor: derivative scale (pixels).")),
    )
    sigma_w: float = Field(
        3.0,
        gt=0.0,
        le=32.0,
        description="Size of the window over which the orientation field is averaged (σ_w).",
        json_schema_extra=ui(unit="px", details=("Structure tensor: window scale (pixels).")),
    )
    k: int = Field(
        0,
        ge=0,
        le=32,
        description="Similar places proposed per neighbour across the rotated copies; 0 uses neighbours "
        "and hints only (memory grows with it).",
        json_schema_extra=ui(
            details=(
                "k-coherence sets over D_M (memory grows with M); 0: neighbours' sources and hints only."
            )
        ),
    )

    @field_validator("angular_step")
    @classmethod
    def _whole_turn(cls, step: float) -> float:
        m = 360.0 / step
        if not math.isfinite(m) or abs(m - round(m)) > 1e-6:  # 1e-308 makes M infinite
            raise ValueError("angular_step must divide 360 degrees (5 gives the paper's 72 rotations)")
        return step

    @property
    def n_rotations(self) -> int:
        return round(360.0 / self.angular_step)

    def resolved(self, exemplar: np.ndarray) -> Resolution:
        """These parameters with the recipe and the hint choice applied, and the measured exemplar
        properties they were chosen from (:class:`Resolution`).

        'auto' picks 'fibres' when the exemplar's mean structure-tensor coherence (this ``sigma_d``,
        ``sigma_w``) is at least :data:`ORIENTED_COHERENCE`, else 'weak'. The recipe's settings replace
        only the fields left at their defaults (a field set to its default value counts as left: pass
        ``recipe='paper'`` for the defaults themselves); ``recipe`` becomes the chosen name.

        ``hint_layout`` and ``initial_sources`` left unset (None) are chosen next: the strand hints
        (:data:`STRAND_HINTS`) with the 'fibres' recipe (auto or explicit) when the exemplar's fibres
        carry their own grey levels, i.e. its fibre grey spread
        (:func:`texsynth.synth.analysis.fibre_grey.fibre_grey_spread`, these scales) is at least
        :data:`OWN_GREY_FIBRES`, and ``restrict_rotations`` is on (the hints come with the rotation
        window); else the paper's route ('texture', 'random'). Why: the strand hints keep each strand's
        grey level for a wood grain (grey along/across 0.51-0.70 -> 0.14-0.25) but close the rings of
        uniform stripes (fringes, laminae) into loops the strand measure leaves out, and streak the soot
        (docs/arbitrary-shape.md). A value given (either field) is kept. The spread is measured only
        with the 'fibres' recipe (else None).
        """
        coh = mean_coherence(exemplar, self.sigma_d, self.sigma_w)
        name = self.recipe
        if name == "auto":
            name = "fibres" if coh >= ORIENTED_COHERENCE else "weak"
        fields = type(self).model_fields
        update = {k: v for k, v in RECIPES[name].items() if getattr(self, k) == fields[k].default}
        spread = fibre_grey_spread(exemplar, self.sigma_d, self.sigma_w) if name == "fibres" else None
        own_grey = spread is not None and spread >= OWN_GREY_FIBRES
        chosen = STRAND_HINTS if own_grey and self.restrict_rotations else PAPER_HINTS
        update.update({k: v for k, v in chosen.items() if getattr(self, k) is None})
        params = self.model_copy(update={**update, "recipe": name})
        return Resolution(params, name, coh, spread, own_grey)


class Resolution(NamedTuple):
    """What :meth:`ArbitraryShapeParams.resolved` chose and the measured exemplar properties it chose from
    (recorded in the run's stats)."""

    params: ArbitraryShapeParams
    recipe: str
    coherence: float
    fibre_grey_spread: float | None
    #: the spread is at least OWN_GREY_FIBRES (the strand hints' condition, with restrict_rotations)
    own_grey_fibres: bool


def orientation_agreement(
    output: np.ndarray,
    constraint: np.ndarray,
    *,
    sigma_d: float = 1.0,
    sigma_w: float = AGREEMENT_SIGMA_W,
) -> float:
    """How well ``output``'s structures follow ``constraint``'s: weighted mean ``|sin(O_out - O_con)|``.

    Both images' structure orientations are measured (:func:`texsynth.synth.analysis.tensor.structure_tensor`,
    scales
    ``sigma_d``, ``sigma_w``); each pixel counts by the product of the two coherences, so that only
    places where both images have an orientation vote. 0 is perfect agreement; independent random
    orientations give ``2 / pi = 0.64``; perpendicular structures give 1. RGB images count by their
    luma.

    Examples
    --------
    >>> from texsynth.synth.io.patterns import grating
    >>> a = grating((64, 64), 0.3, noise=0.1)
    >>> round(orientation_agreement(a, grating((64, 64), 0.3)), 2)
    0.0
    >>> round(orientation_agreement(a, grating((64, 64), 0.3 + np.pi / 2)), 2)
    1.0
    """
    out, con = to_grey(output), to_grey(constraint)
    if out.shape != con.shape or out.ndim != 2:
        raise InvalidInput(
            "output", f"shape {output.shape} does not match the constraint's {constraint.shape}"
        )
    s_out = structure_tensor(out, sigma_d, sigma_w)
    s_con = structure_tensor(con, sigma_d, sigma_w)
    weight = coherence(s_out).astype(np.float64) * coherence(s_con)
    total = weight.sum()
    if total <= 0:
        raise InvalidInput("constraint", "no pixel where both images have an orientation")
    diff = np.abs(np.sin(orientation(s_out).astype(np.float64) - orientation(s_con)))
    return float((weight * diff).sum() / total)


def constraint_field(
    constraint: np.ndarray,
    shape: tuple[int, int],
    sigma_d: float,
    sigma_w: float,
    *,
    periodic: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """The constraint image at ``shape`` (grey) and its tensor field; a flat image is an error.

    With ``periodic`` the constraint is taken as a tile: its resampling and its tensors' filters wrap
    around its borders (``mode='wrap'``) instead of mirroring it.
    """
    mode = "wrap" if periodic else "reflect"
    con = to_grey(constraint)
    if con.ndim != 2:
        raise InvalidInput("constraint", f"shape {constraint.shape} is neither (H, W) grey nor (H, W, 3) RGB")
    if not np.isfinite(con).all():
        raise InvalidInput("constraint", "contains NaN or infinite values")
    if con.shape != tuple(shape):
        con = resize(con, shape, order=1, mode=mode, anti_aliasing=True, preserve_range=True).astype(
            np.float32
        )
    s_icon = structure_tensor(con, sigma_d, sigma_w, mode=mode)
    if float((s_icon[..., 0] + s_icon[..., 2]).max()) < FLAT_TRACE:
        raise InvalidInput(
            "constraint",
            "is featureless (flat): it has no structure orientation for the texture to follow; "
            "give an image with fringes, edges or any oriented content",
        )
    return con, s_icon


def _identity_sources(shape: tuple[int, int]) -> np.ndarray:
    return np.stack(np.mgrid[0 : shape[0], 0 : shape[1]], axis=-1).astype(np.int64)


def _base_texture(exemplar, size, params, seed, report) -> tuple[np.ndarray, np.ndarray, dict]:
    """``S_en``'s texture at the output size and, per position, the exemplar position it shows
    (synthesized, tileable, whenever the output is periodic: the exemplar itself does not tile)."""
    if tuple(exemplar.shape[:2]) == tuple(size) and not params.periodic:
        return exemplar, _identity_sources(size), {}
    sub = TensorConstrainedParams(
        neighbourhood_size=params.neighbourhood_size,
        neighbourhood=params.neighbourhood,
        scan=params.scan,
        parent_size=params.parent_size,
        search=params.search,
        sigma_d=params.sigma_d,
        sigma_w=params.sigma_w,
        periodic=params.periodic,
        # tensor-constrained's settings before issue 13's defaults (this recipe was measured with them)
        metric="SO",
        refinement_p=None,
        k=3,
        p=0.5,
        falloff=0.0,
        refinement="same",
        refinement_size=None,
        texture_histogram_weight=0.0,
    )

    def sub_progress(stage: str, fraction: float) -> None:
        report(f"exemplar-like texture, {stage}", 0.4 * fraction)

    res = run_tensor_constrained(exemplar, size=size, params=sub, seed=seed, progress=sub_progress)
    return res.image, res.extras["source_map"].astype(np.int64), res.stats


def _strand_layout(s_ex: np.ndarray, o_con: np.ndarray, params, radius: int, seed: int) -> StrandHints:
    """``hint_layout='strands'``: the exemplar's fibres laid along the constraint's strands
    (:mod:`texsynth.synth.methods.strand_hints`), fibres at least a neighbourhood's radius (+2) inside the
    exemplar so that every rotated copy holds their neighbourhoods."""
    table = fibre_table(structure_direction(s_ex), float(dominant_orientation(s_ex)) + np.pi / 2, radius + 2)
    return strand_hints(
        o_con.astype(np.float64) + np.pi / 2,
        table,
        params.strand_hint_spacing,
        np.random.default_rng([seed, 13]),
        periodic=params.periodic,
    )


def _signed_copies(delta: np.ndarray, copy_angle: np.ndarray, dictionary: RotatedDictionary) -> np.ndarray:
    """The copy nearest the local angle ``delta`` (modulo pi), or its half-turn twin, whichever is
    nearer ``copy_angle`` (modulo 2 pi): the one that carries the hinted fibre's direction onto the
    strand's, so that neighbouring hints keep the exemplar's handedness."""
    m = dictionary.n_rotations
    step = 2 * np.pi / m
    want = np.mod(np.rint(wrap_angle(delta) / step).astype(np.int64), m)
    if m % 2:
        return want
    twin = np.mod(want + m // 2, m)
    off = np.abs(np.angle(np.exp(1j * (dictionary.angles[want] - copy_angle))))
    return np.where(off <= np.pi / 2, want, twin)


def rotation_window(
    dictionary: RotatedDictionary,
    delta: np.ndarray,
    window: float,
    ex_shapes: list[tuple[int, int]],
    out_shapes: list[tuple[int, int]],
    *,
    transfer: bool = False,
) -> CandidateWindow:
    """The restriction of ``restrict_rotations``: at every output position, only the copies of
    ``D_M`` turned by the local angle ``delta`` (within ``window`` radians, at least the nearest copy;
    a copy and its half-turn twin alike) are searched.

    Classes are the copies' indices; the wanted class is the copy nearest ``delta``; the span is the
    number of angular steps the window holds. Levels subsample both maps 2:1, like the pyramids.
    With ``transfer`` a proposal from a copy outside the window is moved to the same exemplar point of
    the wanted copy (:meth:`RotatedDictionary.affine_maps`) instead of being dropped.
    """
    m = dictionary.n_rotations
    step = 2 * np.pi / m
    span = int(np.floor(max(window, step / 2) / step + 1e-9))
    want = np.mod(np.rint(wrap_angle(delta) / step).astype(np.int64), m)
    ex_levels, out_levels = [], []
    for lvl, (ex_shape, out_shape) in enumerate(zip(ex_shapes, out_shapes, strict=True)):
        f = 2**lvl
        ex_levels.append(dictionary.tile_index[::f, ::f][: ex_shape[0], : ex_shape[1]].astype(np.int64))
        out_levels.append(want[::f, ::f][: out_shape[0], : out_shape[1]])
    transfer_levels = [dictionary.affine_maps(lvl) for lvl in range(len(ex_shapes))] if transfer else None
    return CandidateWindow(
        ex_levels, out_levels, period=m // 2 if m % 2 == 0 else m, span=span, transfer_levels=transfer_levels
    )


def _nearest_allowed(hint: np.ndarray, mask: np.ndarray, copies: np.ndarray) -> np.ndarray:
    """Hints moved, where their neighbourhood does not fit in their copy (near its border), to the
    nearest position of the same copy that may be copied, so that every output position has one
    candidate inside its rotation window."""
    hint = hint.copy()
    bad = mask[hint[..., 0], hint[..., 1]] == 0
    if not bad.any():
        return hint
    copy_of = copies[hint[..., 0], hint[..., 1]]
    wanted = np.unique(copy_of[bad])
    # Each wanted copy's allowed positions in raster order (the points and order np.argwhere gave, so the
    # same trees and the same ties), from one stable sort instead of a scan of the canvas per copy.
    flat = np.flatnonzero(mask.ravel())
    cls = copies.ravel()[flat]
    by_copy = np.argsort(cls, kind="stable")
    flat, cls = flat[by_copy], cls[by_copy]
    lo = np.searchsorted(cls, wanted, side="left")
    hi = np.searchsorted(cls, wanted, side="right")
    for m, a, z in zip(wanted, lo, hi, strict=True):
        sel = bad & (copy_of == m)
        if z > a:
            allowed = np.stack(np.divmod(flat[a:z], copies.shape[1]), axis=1)
            hint[sel] = allowed[cKDTree(allowed).query(hint[sel])[1]]
    return hint


def grey_labels(levels: list[np.ndarray], exemplar: np.ndarray, bins: int = GREY_LABELS):
    """Grey-level histogram matching's labels and target: every canvas position of every pyramid
    level labelled by the bin of its grey level (luma, ``bins`` equal bins of [0, 1]), the target the
    exemplar's share of each bin (its own pixels, not the rotated copies: the copies' bicubic
    resampling smooths the histogram)."""

    def label(img: np.ndarray) -> np.ndarray:
        grey = to_grey(img[..., 0] if img.shape[-1] == 1 else img)
        return np.clip((grey * bins).astype(np.int64), 0, bins - 1)

    target = (
        np.bincount(label(as_features(exemplar)).ravel(), minlength=bins)
        / exemplar.shape[0]
        / exemplar.shape[1]
    )
    return [(label(lv), target) for lv in levels]


def _check_k_memory(params: ArbitraryShapeParams, dictionary: RotatedDictionary, channels: int) -> None:
    if params.k == 0 or params.search == "exact":
        return
    ks = min(params.neighbourhood_size, 9)
    need = int(dictionary.area.sum()) * ks * ks * (channels + 3) * 12
    if need > K_SET_MEMORY_LIMIT:
        raise InvalidParameter(
            "k",
            params.k,
            f"k-coherence sets over the {dictionary.n_rotations} rotated copies would need about "
            f"{need / 1e9:.1f} GB; use k=0, a larger angular_step or a smaller exemplar",
        )


def run_arbitrary_shape(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int],
    params: ArbitraryShapeParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
) -> Result:
    if constraint is None:
        raise InvalidInput("constraint", "arbitrary-shape synthesis needs a constraint image")
    report = checked_progress(progress)
    t0 = time.perf_counter()
    resolution = params.resolved(exemplar)
    params = resolution.params
    if params.initial_sources == "hints" and not params.restrict_rotations:
        raise InvalidParameter(
            "initial_sources",
            "hints",
            "needs restrict_rotations=True (the hints come with the rotation window)",
        )
    need = 2 * dictionary_bytes(exemplar.shape, params.n_rotations)
    if need > DICTIONARY_MEMORY_LIMIT:
        raise InvalidParameter(
            "angular_step",
            params.angular_step,
            f"{params.n_rotations} rotated copies of the {exemplar.shape[1]}x{exemplar.shape[0]} exemplar "
            f"would need about {need / 1e9:.0f} GB; use a larger angular_step (the paper's 5 degrees) or "
            "a smaller exemplar",
        )
    size = (int(size[0]), int(size[1]))
    mode = "wrap" if params.periodic else "reflect"  # filters on output-sized fields
    con, s_icon = constraint_field(constraint, size, params.sigma_d, params.sigma_w, periodic=params.periodic)
    o_con = orientation(s_icon)
    s_ex = structure_tensor(exemplar, params.sigma_d, params.sigma_w)
    o_dom = dominant_orientation(s_ex)

    # Step 1: S_con, the exemplar-like texture's tensors turned by the constraint's angle (eqs 2-3).
    radius = params.neighbourhood_size // 2
    strand = _strand_layout(s_ex, o_con, params, radius, seed) if params.hint_layout == "strands" else None
    if strand is not None:  # S_en: the exemplar's tensors at the fibres laid along the strands
        base, base_src, base_stats = None, strand.source, {"strand_hints_missed": strand.missed}
        s_en = s_ex[base_src[..., 0], base_src[..., 1]]
    else:
        base, base_src, base_stats = _base_texture(exemplar, size, params, seed, report)
        s_en = s_ex if base is exemplar else structure_tensor(base, params.sigma_d, params.sigma_w, mode=mode)
    t1 = time.perf_counter()
    reference = {"dominant": o_dom, "absolute": 0.0, "local": None}[params.rotation_reference]
    reference = orientation(s_en).astype(np.float64) if reference is None else reference
    delta = wrap_angle(o_con.astype(np.float64) - reference)
    s_con = rotate_tensors(s_en, delta).astype(np.float32)
    guide = s_con if params.constraint_tensors == "rotated-exemplar" else s_icon.astype(np.float32)

    # Step 2: the rotated dictionary D_M.
    dictionary = build_rotated_dictionary(exemplar, params.n_rotations, tensors=s_ex)
    features = as_features(dictionary.image)
    _check_k_memory(params, dictionary, features.shape[2])
    levels = params.levels
    ex_levels = gaussian_pyramid(features, levels)
    shapes = [lv.shape[:2] for lv in ex_levels]
    radii = [
        (params.neighbourhood_size if lvl == 0 else level_neighbourhood_size(params.neighbourhood_size, sh))
        // 2
        for lvl, sh in enumerate(shapes)
    ]
    parent_radii = [level_neighbourhood_size(params.parent_size, sh) // 2 for sh in shapes[1:]] + [0]
    masks = dictionary.level_masks(radii, parent_radii)
    t2 = time.perf_counter()

    # Step 3: synthesis in D_M guided by S_con (eq 5), hints into the copies at the local angle.
    rng = np.random.default_rng(seed)
    window = np.radians(params.rotation_window)
    hint = None
    candidate_window = None
    strict = False
    if params.restrict_rotations:
        m_hint = rotation_candidates(delta, params.n_rotations, window, rng)
        if strand is not None:
            m_hint = _signed_copies(delta, strand.copy_angle, dictionary)
        candidate_window = rotation_window(
            dictionary, delta, window, shapes, level_shapes(size, levels), transfer=params.transfer_candidates
        )
        strict = (
            params.window_search or ("hints" if params.rotation_reference == "local" else "strict")
        ) == "strict"
        hint = [
            _nearest_allowed(h, mask, cls)
            for h, mask, cls in zip(
                source_map_pyramid(dictionary.to_canvas(base_src, m_hint), levels),
                masks,
                candidate_window.ex_levels,
                strict=True,
            )
        ]
    gui_code = tensor_features(guide, params.metric)[1]
    guidance = Guidance(
        out_levels=[tensor_features(t, params.metric)[0] for t in gaussian_pyramid(guide, levels, mode=mode)],
        ex_levels=[
            tensor_features(t, params.metric)[0] for t in gaussian_pyramid(dictionary.tensors, levels)
        ],
        metric=gui_code,
        weight=1.0 - params.w,
        size=params.neighbourhood_size,
        hint_levels=hint,
    )
    settings = params.search_settings(
        size=params.neighbourhood_size, levels=levels, iterations=params.iterations, alpha=params.alpha
    )
    settings = type(settings)(**{**settings.__dict__, "histogram_weight": params.histogram_weight})
    if params.restrict_rotations:  # random candidates would land anywhere in D_M
        settings = type(settings)(**{**settings.__dict__, "random_candidates": 0})
    srcs, synthesis = synthesize_source_map(
        ex_levels,
        level_shapes(size, levels),
        settings,
        p=params.w,
        guidance=guidance,
        seed=seed + 2,
        progress=report,
        stage="texture",
        span=(0.4 if base is not exemplar and base is not None else 0.0, 1.0),
        ex_masks=masks,
        window=candidate_window if params.restrict_rotations and strict else None,
        histogram=grey_labels(ex_levels, exemplar) if params.histogram_weight > 0 else None,
        initial=hint if params.initial_sources == "hints" else None,
    )
    src = srcs[0]
    image = dictionary.image[src[..., 0], src[..., 1]]
    image = image[..., 0] if exemplar.ndim == 2 else image
    t3 = time.perf_counter()
    used = dictionary.angles[dictionary.tile_index[src[..., 0], src[..., 1]]]
    half = max(window, np.pi / params.n_rotations)
    in_window = np.abs(wrap_angle(used - delta)) <= half + 1e-9
    report("done", 1.0)
    return Result(
        method="arbitrary-shape",
        image=np.ascontiguousarray(image, dtype=np.float32),
        params=params.model_dump(),
        seed=seed,
        timings={"exemplar_like": t1 - t0, "dictionary": t2 - t1, "texture": t3 - t2},
        tensor_field=guide,
        extras={
            "constraint_orientation": o_con.astype(np.float32),
            "constraint_coherence": coherence(s_icon).astype(np.float32),
            "orientation": orientation(guide).astype(np.float32),
            "coherence": coherence(guide).astype(np.float32),
            "source_rotation": used.astype(np.float32),
            "source_map": src.astype(np.int32),
        },
        stats={
            "recipe": resolution.recipe,
            "exemplar_coherence": resolution.coherence,
            "fibre_grey_spread": resolution.fibre_grey_spread,
            "own_grey_fibres": resolution.own_grey_fibres,
            "n_rotations": params.n_rotations,
            "dominant_orientation": float(o_dom),
            "in_window_fraction": float(in_window.mean()),
            "orientation_agreement": orientation_agreement(image, con),
            "mean_best_distance": synthesis.mean_best_distance,
            "exemplar_like": base_stats,
        },
    )


SPEC = register(
    MethodSpec(
        name="arbitrary-shape",
        summary="The exemplar's texture following any constraint image's structure (Akl et al., GRETSI).",
        params_model=ArbitraryShapeParams,
        run=run_arbitrary_shape,
        constraint="required",
        paper="Akl, Yaacoub, Donias, Da Costa, Germain, GRETSI",
    )
)
