"""What each headline measure means, its target, which way is better, and the verdict against it.

One place for the words beside the numbers: the job page, ``texsynth evaluate`` and the docs read it.
A target is what the project's issues and docs state for a faithful result (grey-level KL < 0.05,
orientation KL < 0.10, S2 error < 0.10) or, where none was stated, a value docs/evaluation.md
("Targets and verdicts") explains from measurements on the bundled examples. ``direction`` says how a
value is held against it: ``lower`` (value < target), ``abs-lower`` (a signed difference: |value| <
target), ``near-1`` (|value - 1| < target), ``higher`` (value > target). The verdict is ``meets``
inside the target, ``near`` within :data:`NEAR_FACTOR` times it, ``misses`` beyond.

Fringe statistics are shown only for an exemplar that has lattice fringes (:func:`fringes_shown`, by
the measures of :mod:`texsynth.synth.analysis.lattice`): elsewhere the fringes that the extraction finds are
mortar joints or blades of grass, and their KS distances mislead.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = [
    "FRINGE_MIN_DENSITY",
    "FRINGE_MIN_PEAK",
    "GLOSSARY",
    "NEAR_FACTOR",
    "Measure",
    "fringes_shown",
    "glossary",
    "headline",
    "verdict",
]

#: A value within this factor of the target (beyond it) is ``near``.
NEAR_FACTOR = 1.5
#: An exemplar has fringes when the extraction finds at least this many per 10 000 pixels ...
FRINGE_MIN_DENSITY = 8.0
#: ... and its spectrum has a peak at a fringe period at least this many times its power-law background.
FRINGE_MIN_PEAK = 5.0


@dataclass(frozen=True)
class Measure:
    """A headline measure: its label, one-line meaning, direction and target."""

    label: str
    meaning: str
    direction: str  # "lower" | "abs-lower" | "near-1" | "higher"
    target: float | None = None
    unit: str = ""

    @property
    def better(self) -> str:
        """The direction in words (the first page's field)."""
        return {
            "lower": "lower",
            "abs-lower": "closer to 0",
            "near-1": "closer to 1",
            "higher": "higher",
        }[self.direction]

    @property
    def good_below(self) -> float | None:
        """The target as the first page read it (a bound on the absolute value, or on |value - 1|)."""
        return self.target


GLOSSARY: dict[str, Measure] = {
    "grey_kl": Measure(
        "grey-level KL",
        "how different the grey-level histograms are (Kullback-Leibler divergence, 64 bins)",
        "lower",
        0.05,
    ),
    "std_difference": Measure(
        "std difference",
        "output's grey-level standard deviation minus the exemplar's (contrast; 0 = the same)",
        "abs-lower",
        0.02,
    ),
    "skewness_difference": Measure(
        "skewness difference",
        "output's grey-level skewness minus the exemplar's (asymmetry; 0 = the same)",
        "abs-lower",
        0.3,
    ),
    "orientation_kl": Measure(
        "orientation KL",
        "how different the distributions of structure orientation are (structure tensor, 36 bins)",
        "lower",
        0.10,
    ),
    "log_euclidean": Measure(
        "log-Euclidean distance",
        "distance between the mean structure tensors (anisotropy and direction together)",
        "lower",
        0.25,
    ),
    "grain_ratio": Measure(
        "grain ratio",
        "output's share of grey-level variance finer than a 1-px blur over the exemplar's (1 = as grainy; "
        "speckle raises it, blur lowers it)",
        "near-1",
        0.3,
    ),
    "fringe_ks_length": Measure(
        "fringe length KS",
        "Kolmogorov-Smirnov distance between the fringe-length distributions (HRTEM lattice fringes)",
        "lower",
        0.25,
    ),
    "fringe_ks_tortuosity": Measure(
        "fringe tortuosity KS",
        "Kolmogorov-Smirnov distance between the fringe-tortuosity distributions",
        "lower",
        0.25,
    ),
    "s2_relative_error": Measure(
        "two-point correlation error",
        "relative L1 error of S2(r) up to the exemplar's correlation length (volumes, per axis)",
        "lower",
        0.10,
    ),
    "copy_share": Measure(
        "verbatim-copy share",
        "share of output pixels whose patch is a near-exact copy of an exemplar patch",
        "lower",
        0.5,
    ),
    "seam_visibility": Measure(
        "seam visibility",
        "gradient energy across patch boundaries over the interior's (1 = invisible seams)",
        "near-1",
        0.25,
    ),
}


def _gap(direction: str, value: float, target: float) -> float:
    """How far ``value`` is from meeting ``target``, as a multiple of it (<= 1 meets)."""
    if direction == "lower":
        return value / target
    if direction == "abs-lower":
        return abs(value) / target
    if direction == "near-1":
        return abs(value - 1.0) / target
    if direction == "higher":
        return target / value if value > 0 else float("inf")
    raise ValueError(f"unknown direction {direction!r}")


def verdict(name: str, value: float | None) -> str | None:
    """``'meets'``, ``'near'`` or ``'misses'`` against the measure's target; ``None`` without one."""
    measure = GLOSSARY.get(name)
    if measure is None or measure.target is None or value is None or not np.isfinite(value):
        return None
    gap = _gap(measure.direction, float(value), measure.target)
    return "meets" if gap <= 1.0 else "near" if gap <= NEAR_FACTOR else "misses"


def headline(summary: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """``{name: {value, target, direction, verdict, label}}`` for every glossary measure in ``summary``
    (a metrics ``summary``: the headline numbers), in the glossary's order."""
    out = {}
    for name, measure in GLOSSARY.items():
        value = summary.get(name)
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        out[name] = {
            "value": float(value),
            "target": measure.target,
            "direction": measure.direction,
            "verdict": verdict(name, value),
            "label": measure.label,
        }
    return out


def fringes_shown(image: np.ndarray) -> tuple[bool, str, dict[str, Any]]:
    """Whether an exemplar's fringe statistics mean something: ``(shown, reason, measures)``.

    Shown when :func:`texsynth.synth.analysis.lattice.fringe_presence` finds at least
    :data:`FRINGE_MIN_DENSITY` fringes per 10 000 px and a spectral peak at a fringe period at least
    :data:`FRINGE_MIN_PEAK` times the background (module docstring of :mod:`texsynth.synth.analysis.lattice`).
    """
    from texsynth.synth.analysis.lattice import fringe_presence  # deferred: only where fringes are judged
    from texsynth.synth.colour import to_grey

    grey = np.asarray(image, dtype=np.float32)
    if grey.ndim == 3:
        grey = to_grey(grey)
    m = fringe_presence(grey)
    density, peak = float(m["density_per_10k_px"]), float(m["peak_ratio"])
    if density < FRINGE_MIN_DENSITY:
        return (
            False,
            (
                f"the exemplar shows too few fringe-like lines ({density:.1f} per 10 000 px, fewer than "
                f"{FRINGE_MIN_DENSITY:g}) for fringe statistics to mean something"
            ),
            m,
        )
    if peak < FRINGE_MIN_PEAK:
        return (
            False,
            (
                f"the exemplar's lines are not a lattice: no regular spacing (spectral peak {peak:.1f} times "
                f"the background, below {FRINGE_MIN_PEAK:g})"
            ),
            m,
        )
    period = m["peak_period_px"]
    return True, f"lattice fringes about {period:.1f} px apart ({density:.1f} per 10 000 px)", m


def glossary() -> dict[str, dict[str, Any]]:
    """The glossary as JSON-ready dicts (``GET /api/metrics``): label, meaning, direction, target, unit,
    and, as the first page read them, ``better`` and ``good_below``."""
    return {
        name: {**asdict(m), "better": m.better, "good_below": m.good_below} for name, m in GLOSSARY.items()
    }
