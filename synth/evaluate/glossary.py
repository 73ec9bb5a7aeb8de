"""What each headline measure means, which way is better, and the thresholds the docs use.

One place for the words beside the numbers: the job page, ``texsynth evaluate`` and the docs read it.
A threshold is the target the project's issues and docs state for a faithful result (e.g. grey-level
KL < 0.05, orientation KL < 0.10); ``None`` where no target is documented.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["GLOSSARY", "Measure", "glossary", "verdict"]


@dataclass(frozen=True)
class Measure:
    """A headline measure: its label, one-line meaning, direction and documented threshold."""

    label: str
    meaning: str
    better: str  # "lower" | "higher" | "closer to 1"
    good_below: float | None = None  # the documented target (absolute value, for signed differences)
    unit: str = ""


GLOSSARY: dict[str, Measure] = {
    "grey_kl": Measure(
        "grey-level KL",
        "how different the grey-level histograms are (Kullback-Leibler divergence, 64 bins)",
        "lower",
        0.05,
    ),
    "std_difference": Measure(
        "std difference", "output's grey-level standard deviation minus the exemplar's (contrast)", "lower"
    ),
    "skewness_difference": Measure(
        "skewness difference", "output's grey-level skewness minus the exemplar's (asymmetry)", "lower"
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
    ),
    "fringe_ks_length": Measure(
        "fringe length KS",
        "Kolmogorov-Smirnov distance between the fringe-length distributions (HRTEM lattice fringes)",
        "lower",
    ),
    "fringe_ks_tortuosity": Measure(
        "fringe tortuosity KS",
        "Kolmogorov-Smirnov distance between the fringe-tortuosity distributions",
        "lower",
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
    ),
    "seam_visibility": Measure(
        "seam visibility",
        "gradient energy across patch boundaries over the interior's (1 = invisible seams)",
        "closer to 1",
    ),
}


def verdict(name: str, value: float | None) -> str | None:
    """``'good'`` or ``'off'`` against the documented threshold; ``None`` without one (or no value)."""
    measure = GLOSSARY.get(name)
    if measure is None or measure.good_below is None or value is None:
        return None
    return "good" if abs(value) < measure.good_below else "off"


def glossary() -> dict[str, dict[str, Any]]:
    """The glossary as JSON-ready dicts (``GET /api/metrics``)."""
    return {name: asdict(measure) for name, measure in GLOSSARY.items()}
