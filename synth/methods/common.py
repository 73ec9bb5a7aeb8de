"""Parameters and helpers shared by the pixel-based methods (one definition each)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np
from pydantic import Field, ValidationInfo, field_validator, model_validator

from texsynth.synth.api import PLANES, Progress
from texsynth.synth.errors import InvalidInput
from texsynth.synth.grid.neighbourhood import Shape
from texsynth.synth.grid.scan import ScanOrder
from texsynth.synth.params import MethodParams, ui
from texsynth.synth.pixel.laminar import (
    CENTRE_SPACINGS,
    CENTRED_MIN_CONCENTRATION,
    CONCENTRIC_MIN_EXPLAINED,
    DOMAIN_MAX_BEND,
    DOMAIN_SPACING,
    DOMAIN_SPACING_RANGE,
    MIN_PERIOD_SIDE,
)

if TYPE_CHECKING:  # the pixel driver, imported by the pixel methods that use it (not by the patch methods)
    from texsynth.synth.pixel.synthesis import SearchSettings

__all__ = [
    "NeighbourhoodParams",
    "PatchParams",
    "ShellKind",
    "ShellParams",
    "SolidParams",
    "as_features",
    "checked_progress",
    "precheck_structured_start",
    "shells_field",
    "structure_fields",
]


class PatchParams(MethodParams):
    """The overlap rule every patch method shares (below the patch size, by default a fraction of it) and
    the tileable option ``periodic`` (:class:`texsynth.synth.patch.layout.PatchLayout`).

    Subclasses declare their own ``patch_size`` and ``overlap`` fields (defaults and bounds are each
    paper's) and set :attr:`OVERLAP_DIVISOR` / :attr:`MIN_OVERLAP` for the default overlap.
    """

    #: The default overlap is ``max(MIN_OVERLAP, patch_size // OVERLAP_DIVISOR)``.
    OVERLAP_DIVISOR: ClassVar[int] = 4
    MIN_OVERLAP: ClassVar[int] = 1

    periodic: bool = Field(
        False,
        description="Make the output tile seamlessly: patches wrap around its borders (each side needs "
        "two patch steps).",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Tileable output: the patches are laid on a torus of the output's size, the last column's "
                "patches overlapping the first column and the last row the first row, so a 2 x 2 tiling "
                "shows no seam. Each output side must hold at least two patch steps (patch_size - "
                "overlap)."
            ),
        ),
    )

    @field_validator("overlap", check_fields=False)
    @classmethod
    def _overlap_below_patch(cls, overlap: int | None, info: ValidationInfo) -> int | None:
        patch = info.data.get("patch_size")
        if overlap is not None and patch is not None and overlap >= patch:
            raise ValueError(f"must be smaller than patch_size ({patch})")
        return overlap

    def resolved_overlap(self) -> int:
        """The overlap in pixels: the given one, or the method's default fraction of the patch."""
        overlap = getattr(self, "overlap", None)
        if overlap is not None:
            return int(overlap)
        return max(self.MIN_OVERLAP, int(self.patch_size) // self.OVERLAP_DIVISOR)


class NeighbourhoodParams(MethodParams):
    """Neighbourhood, scan and search options common to the Wei-Levoy family."""

    neighbourhood_size: int = Field(
        13,
        ge=3,
        le=41,
        description="Side of the square window of pixels compared when matching (N).",
        json_schema_extra=ui(
            basic=True, unit="px", odd=True, details=("Side of the square/L neighbourhood (odd).")
        ),
    )
    neighbourhood: Shape = Field(
        "causal",
        description="Shape of that window: 'causal' uses only the pixels already made, 'square' the "
        "pixels all around.",
        json_schema_extra=ui(
            details=("'causal' L-shape (with a lexicographic scan) or 'square' non-causal (random walk).")
        ),
    )
    scan: ScanOrder | None = Field(
        None,
        description="Order in which pixels are visited; automatic: row by row for 'causal', random for "
        "'square'.",
        json_schema_extra=ui(
            details=("Scan order; default lexicographic for a causal neighbourhood, random for a square one.")
        ),
    )
    parent_size: int = Field(
        5,
        ge=3,
        le=15,
        description="Side of the window also compared on the next coarser pyramid level.",
        json_schema_extra=ui(
            unit="px", odd=True, details=("Side of the parent-level square neighbourhood (odd).")
        ),
    )
    search: Literal["kcoherence", "exact"] = Field(
        "kcoherence",
        description="How candidates are found: 'kcoherence' tries a few likely exemplar places (fast), "
        "'exact' tries them all (slow).",
        json_schema_extra=ui(
            details=(
                "'exact' compares every exemplar position (slow, the definition); 'kcoherence' compares "
                "k-coherent candidates (fast; measured as good in docs/benchmarks.md)."
            )
        ),
    )
    k: int = Field(
        5,
        ge=0,
        le=32,
        description="How many similar exemplar places each neighbour proposes (k of the k-coherence search).",
        json_schema_extra=ui(details=("k-coherence: similar exemplar positions proposed per candidate.")),
    )
    random_candidates: int = Field(
        2,
        ge=0,
        le=64,
        description="Random exemplar places tried per pixel besides the proposed ones.",
        json_schema_extra=ui(details=("k-coherence: random candidates added per pixel.")),
    )
    falloff: float = Field(
        0.0,
        ge=0.0,
        le=2.0,
        description="How fast the window's pixels weigh less away from its centre; 0 weighs all equally "
        "(Gaussian σ = falloff × side).",
        json_schema_extra=ui(
            details=(
                "Gaussian weighting of the neighbourhood (Efros & Leung 1999): sigma = falloff x its side "
                "(Efros & Leung: 1 / 6.4); 0 = every entry weighs the same (Wei & Levoy)."
            )
        ),
    )
    refinement: Literal["same", "square"] = Field(
        "same",
        description="Window of the later passes: 'same' as the first pass, or 'square': all around each "
        "pixel.",
        json_schema_extra=ui(
            details=(
                "Neighbourhood of the refinement passes (2, 3, ...): 'same' as the first pass (Wei & "
                "Levoy), or 'square': the full square around each pixel in a random order, every "
                "neighbour proposing candidates, so that a pixel is matched against the pixels after it "
                "too."
            )
        ),
    )
    refinement_size: int | None = Field(
        None,
        ge=3,
        le=41,
        description="Side of the square window of the later passes; automatic: the neighbourhood size.",
        json_schema_extra=ui(
            unit="px",
            odd=True,
            details=(
                "Side of the square refinement neighbourhood (odd; capped at each level's neighbourhood "
                "side; default neighbourhood_size)."
            ),
        ),
    )
    periodic: bool = Field(
        False,
        description="Make the output tile seamlessly: it wraps around its borders.",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Toroidal output: the output tiles seamlessly (every stage wraps around its borders). A "
                "causal neighbourhood then needs 2 or more passes: its refinement passes compare the full "
                "square in random order, which closes the tile borders."
            ),
        ),
    )

    @model_validator(mode="after")
    def _odd_sizes(self) -> NeighbourhoodParams:
        for name in ("neighbourhood_size", "parent_size", "refinement_size", "kset_size"):
            value = getattr(self, name, None)
            if value is not None and value % 2 == 0:
                raise ValueError(f"{name} must be odd")
        return self

    @model_validator(mode="after")
    def _periodic_refines(self) -> NeighbourhoodParams:
        if self.periodic:
            for passes, shape in self.periodic_stages():
                if shape == "causal" and getattr(self, passes) < 2:
                    raise ValueError(
                        f"periodic=True with a causal neighbourhood needs {passes} >= 2: the first pass "
                        "cannot close the tile borders, a refinement pass does"
                    )
        return self

    def periodic_stages(self) -> list[tuple[str, Shape]]:
        """Each synthesis stage's passes field and neighbourhood shape (the periodic check)."""
        return [("iterations", self.neighbourhood)] if "iterations" in type(self).model_fields else []

    def resolved_scan(self) -> ScanOrder:
        return self.scan or ("lexicographic" if self.neighbourhood == "causal" else "random")

    def search_settings(
        self, *, size: int, levels: int, iterations: int, alpha: float = 0.5, **search: float | None
    ) -> SearchSettings:
        """The driver's settings from these parameters; ``search`` overrides internal knobs (k-set size)."""
        from texsynth.synth.pixel.synthesis import SearchSettings

        return SearchSettings(
            size=size,
            shape=self.neighbourhood,
            scan=self.resolved_scan(),
            levels=levels,
            parent_size=self.parent_size,
            iterations=iterations,
            search=self.search,
            k=self.k,
            random_candidates=self.random_candidates,
            alpha=alpha,
            periodic=self.periodic,
            falloff=self.falloff,
            refine_square=self.refinement == "square",
            refine_size=self.refinement_size or 0,
            **search,
        )


class SolidParams(MethodParams):
    """Parameters every solid method shares: slice neighbourhoods, a tileable volume, the matched planes."""

    neighbourhood_size: int = Field(
        7,
        ge=3,
        le=15,
        description="Side of the square window compared in each slice (N).",
        json_schema_extra=ui(
            basic=True, unit="voxels", odd=True, details=("Side of the square slice neighbourhoods (odd).")
        ),
    )
    periodic: bool = Field(
        True,
        description="Make the volume tile seamlessly in 3D: it wraps around its faces.",
        json_schema_extra=ui(basic=True, details=("Toroidal volume: the output tiles seamlessly.")),
    )
    planes: tuple[Literal["xy", "xz", "yz"], ...] = Field(
        PLANES,
        description="Slice planes that must look like the exemplar: all three for an even material, two "
        "(e.g. xz, yz) for layers.",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Slice planes whose neighbourhoods are matched: all three (isotropic material), or two, "
                "e.g. ('xz', 'yz') for laminae (the study's front and side views), leaving the xy slices "
                "free."
            ),
        ),
    )

    @field_validator("planes", mode="before")
    @classmethod
    def _planes(cls, value: object) -> tuple[str, ...]:
        from texsynth.synth.pixel.solid import checked_planes  # deferred: 2D methods need no solid driver

        return checked_planes(value)  # type: ignore[arg-type]

    @field_validator("neighbourhood_size")
    @classmethod
    def _odd(cls, value: int) -> int:
        if value % 2 == 0:
            raise ValueError("neighbourhood_size must be odd")
        return value


#: ``centre_spacing`` bounds (periods): the calibrated table's ends (:data:`CENTRE_SPACINGS`), down to the
#: smallest domains measured (2 periods, below :data:`DOMAIN_SPACING`).
CENTRE_SPACING_RANGE = (min(2.0, DOMAIN_SPACING, CENTRE_SPACINGS[0]), CENTRE_SPACINGS[-1])


#: The laminar start's sheets (:func:`shells_field`).
ShellKind = Literal["auto", "sheets", "surfaces", "centres", "domains"]


def shells_field(default: str, measured: str) -> Any:
    """The solids' ``shells`` field: one description for both methods, each its own default and what it
    measured (``measured``, appended to the details): ``shells: ShellKind = shells_field(...)``."""
    return Field(
        default,
        description="Starting sheets: surfaces of a random field, shells around centres (onions) or "
        "straight stacks in domains; sheets, auto: chosen from the exemplars' fringes.",
        json_schema_extra=ui(
            details=(
                "'surfaces': sheets at the period around the zero level of a random field of the sheets' "
                "length; 'centres': spherical shells around random centres centre_spacing periods apart "
                "(closed onion shells); 'domains': straight stacks, each with its own random normal, in "
                "random cells centre_spacing periods apart (turbostratic crystallites: short straight "
                f"fringes; {DOMAIN_SPACING:g} when empty, measured on real crops; chosen by 'sheets' or "
                f"'auto', {DOMAIN_SPACING_RANGE[0]:g}-{DOMAIN_SPACING_RANGE[1]:g} by how far the fringes "
                f"keep their orientation); 'sheets': 'domains' "
                f"when the fringes keep their orientation less than {DOMAIN_MAX_BEND:g} periods and their "
                "centres of curvature do not gather (isotropic exemplars of short straight pieces: "
                "disordered cores, soot), else 'surfaces'; 'auto': 'centres' when at least "
                f"{CENTRED_MIN_CONCENTRATION:g} of the fringes' centres of curvature gather (many small "
                "onions), else 'domains' as 'sheets', else 'centres' when one centre explains at least "
                f"{CONCENTRIC_MIN_EXPLAINED:g} of their orientations' departure from straight (a particle "
                "seen whole, long fringes), else 'surfaces'. Only with the laminar start. " + measured
            )
        ),
    )


class ShellParams(SolidParams):
    """The solids with a laminar start: how far apart the centres of its shells are (with ``shells``,
    :func:`shells_field`, each method's default; :func:`texsynth.synth.pixel.laminar.choose_shells`)."""

    centre_spacing: float | None = Field(
        None,
        ge=CENTRE_SPACING_RANGE[0],
        le=CENTRE_SPACING_RANGE[1],
        description="Distance between the onions' centres (shells='centres') or the domains' (shells="
        f"'domains'), in fringe periods; empty: fitted, or {DOMAIN_SPACING:g} for domains.",
        json_schema_extra=ui(
            details=(
                "One centre per cube of this side (periods, "
                f"{CENTRE_SPACING_RANGE[0]:g}-{CENTRE_SPACING_RANGE[1]:g}). Empty or 'auto': the spacing "
                "whose shells' slices have the exemplars' median radius of curvature (the onion truth's "
                "4.8-4.9 periods, its centres are 5.0 apart)."
            )
        ),
    )

    @field_validator("centre_spacing", mode="before")
    @classmethod
    def _auto_spacing(cls, value: object) -> object:
        """``'auto'`` is the empty value: the spacing fitted to the exemplars."""
        return None if value == "auto" else value


def precheck_structured_start(params: Any, shapes: Mapping[str, tuple[int, ...]]) -> None:
    """:attr:`MethodSpec.precheck` of the solids: a structured start asked for (``structure`` 'laminar' or
    'oriented') measures each exemplar's fringe period, which needs :data:`MIN_PERIOD_SIDE` px a side; a
    smaller exemplar is named before the job is queued ('auto' takes no structured start there)."""
    structure = getattr(params, "structure", "none")
    if structure not in ("laminar", "oriented"):
        return
    for role, shape in shapes.items():
        if role.startswith("exemplar") and min(shape[:2]) < MIN_PERIOD_SIDE:
            raise InvalidInput(
                role,
                f"{shape[1]} x {shape[0]} px is too small to measure its fringe period (structure="
                f"{structure!r} needs at least {MIN_PERIOD_SIDE} px on each side); use structure='none' or "
                "'auto'",
            )


def structure_fields(structure_details: str, length_details: str) -> tuple[Any, Any]:
    """The solids' ``structure`` and ``structure_length`` fields: one default, bounds and description for both
    methods, each method's ``details`` (how its 'auto' decides): ``structure, structure_length =
    structure_fields(...)`` in a parameter model."""
    structure = Field(
        "auto",
        description="The volume's start: curved sheets, a crumpled stack fitted to the fringes, or noise "
        "(the paper); 'auto' picks by the exemplars.",
        json_schema_extra=ui(details=structure_details),
    )
    length = Field(
        None,
        gt=0.0,
        le=64.0,
        description="How far the starting sheets run before they bend, in fringe periods; empty (or "
        "'auto'): fitted to the exemplars.",
        json_schema_extra=ui(unit="periods", details=length_details),
    )
    return structure, length


def as_features(image: np.ndarray) -> np.ndarray:
    """An image as kernel features: ``(H, W, C)`` C-contiguous float32."""
    img = image[..., None] if image.ndim == 2 else image
    return np.ascontiguousarray(img, dtype=np.float32)


def checked_progress(progress: Progress):
    """Wrap a progress callback so that the fractions it sees lie in [0, 1].

    The protocol (:class:`texsynth.synth.api.Progress`): a callback stops the work by raising
    :class:`Cancelled`, which passes through unchanged. Anything else it raises is a bug in the
    caller and propagates as it is, so that a broken callback fails loudly instead of looking like
    a cancelled job.
    """

    def report(stage: str, fraction: float) -> None:
        progress(stage, min(1.0, max(0.0, fraction)))

    return report
