"""Exemplar diagnostics: how stationary an exemplar is, and a plain warning when it is not.

Exemplar-based synthesis assumes a stationary exemplar: every region a sample of one process. A crop
that mixes an ordered shell with a disordered core (as real HRTEM micrographs do) breaks that, and the
methods then copy one region or average the two (issue 24). The exemplar is cut into a grid of windows
about :data:`PERIODS` fringe periods wide (the period from the power spectrum,
:func:`texsynth.synth.analysis.spectrum.dominant_period`; between :data:`MIN_WINDOW` px and a third of the
shorter side, half-overlapping), and four local statistics are compared across them:

- ``mean``: the standard deviation of the windows' mean grey, over the image's grey standard deviation
  (shading, a bright region);
- ``contrast``: the coefficient of variation of the windows' grey standard deviations;
- ``coherence``: the standard deviation of the windows' mean structure-tensor coherence (sigma_d 1,
  sigma_w 2: the study's 7x7 window), order against disorder;
- ``orientation``: the standard deviation of the windows' orientation spread, ``1 - |sum T| / tr(sum T)``
  of the window's summed tensor (rotation-invariant: fringes that turn, as onions' do, keep a low
  spread; a disordered region has a high one).

Each is divided by its :data:`SCALES` entry, the largest value measured on stationary textures (soot
crops, brick, grass, gravel, laminae, rings, gratings, onion and turbostratic slices, wood, cells) with
a margin; the ``score`` is the largest ratio, and above :data:`THRESHOLD` (1) the report carries a
warning with the suggestion to crop. Calibration figures: docs/evaluation.md, "Exemplar stationarity".
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from texsynth.synth.analysis.spectrum import dominant_period
from texsynth.synth.analysis.tensor import coherence, structure_tensor
from texsynth.synth.colour import to_grey
from texsynth.synth.errors import InvalidInput

__all__ = [
    "MIN_WINDOW",
    "PERIODS",
    "SCALES",
    "THRESHOLD",
    "Stationarity",
    "exemplar_diagnostics",
    "stationarity",
]

#: Window side in fringe periods.
PERIODS = 8.0
#: Smallest window side, pixels (also used when no period is found).
MIN_WINDOW = 24
#: Per component, the value above which a texture is not stationary (calibrated; module docstring).
SCALES: dict[str, float] = {"mean": 0.30, "contrast": 0.20, "coherence": 0.085, "orientation": 0.30}
#: Score above which the exemplar is reported as not stationary.
THRESHOLD = 1.0
_NAMES = {
    "mean": "mean grey",
    "contrast": "contrast",
    "coherence": "order (coherence)",
    "orientation": "orientation spread",
}


@dataclass(frozen=True)
class Stationarity:
    """The stationarity diagnostics of one exemplar (:func:`stationarity`)."""

    score: float
    components: dict[str, float]
    window: int
    period: float | None
    windows: int
    #: ``(row, col, side)`` of the window that differs most from the others in the leading component.
    odd_window: tuple[int, int, int]
    warning: str | None = None
    threshold: float = THRESHOLD
    scales: dict[str, float] = field(default_factory=lambda: dict(SCALES))

    @property
    def stationary(self) -> bool:
        return self.score <= self.threshold

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON types, as metrics.json and the manifest record it."""
        return {
            "score": round(self.score, 4),
            "stationary": self.stationary,
            "threshold": self.threshold,
            "components": {k: round(v, 4) for k, v in self.components.items()},
            "scales": dict(self.scales),
            "window": self.window,
            "period": None if self.period is None else round(self.period, 3),
            "windows": self.windows,
            "odd_window": {"row": self.odd_window[0], "col": self.odd_window[1], "side": self.odd_window[2]},
            "warning": self.warning,
        }


def _grey(image: np.ndarray) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] in (3, 4):
        arr = to_grey(arr[..., :3].astype(np.float32))
    if arr.ndim != 2:
        raise InvalidInput("exemplar", f"expected a grey or RGB image, got shape {np.shape(image)}")
    arr = arr.astype(np.float32)
    if not np.all(np.isfinite(arr)):
        raise InvalidInput("exemplar", "contains NaN or infinite values")
    return arr


def _window(grey: np.ndarray) -> tuple[int, float | None]:
    try:
        period: float | None = dominant_period(grey)
    except InvalidInput:
        period = None
    side = min(grey.shape)
    wanted = MIN_WINDOW if period is None else round(PERIODS * period)
    return int(max(8, min(max(MIN_WINDOW, wanted), side // 3))), period


def stationarity(image: np.ndarray, *, window: int | None = None) -> Stationarity:
    """How much local grey and tensor statistics vary across ``image`` (0: not at all; > 1: not stationary).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        The exemplar, values in [0, 1]; every side at least 24 px (three windows of 8 px).
    window : int, optional
        Window side in pixels; by default :data:`PERIODS` fringe periods within [:data:`MIN_WINDOW`,
        a third of the shorter side].

    Returns
    -------
    Stationarity
        ``score`` (the largest component over its scale), the four ``components``, the window, the
        period, the number of windows, the most different window and, when ``score > 1``, a warning.

    Examples
    --------
    >>> from texsynth.synth.io.patterns import grating
    >>> stationarity(grating((96, 96), 0.3, period=6.0, noise=0.2)).stationary
    True
    """
    grey = _grey(image)
    if min(grey.shape) < 24:
        raise InvalidInput(
            "exemplar", f"too small to judge its stationarity ({grey.shape}; needs 24 px a side)"
        )
    period: float | None
    if window is None:
        win, period = _window(grey)
    else:
        if (
            isinstance(window, bool)
            or not isinstance(window, int | np.integer)
            or not 8 <= window <= min(grey.shape) // 2
        ):
            raise InvalidInput("window", f"must be an integer in [8, {min(grey.shape) // 2}], got {window!r}")
        win, period = int(window), None
    tensors = structure_tensor(grey, 1.0, 2.0)
    coh = coherence(tensors)
    step = max(1, win // 2)
    h, w = grey.shape
    rows = list(range(0, h - win + 1, step))
    cols = list(range(0, w - win + 1, step))
    corners = [(r, c) for r in rows for c in cols]
    local = np.empty((len(corners), 4))
    for i, (r, c) in enumerate(corners):
        sl = (slice(r, r + win), slice(c, c + win))
        patch = grey[sl]
        jxx, jxy, jyy = (float(tensors[(*sl, k)].sum(dtype=np.float64)) for k in range(3))
        trace = jxx + jyy
        concentration = np.sqrt((jxx - jyy) ** 2 + 4 * jxy**2) / trace if trace > 0 else 0.0
        local[i] = (
            patch.mean(dtype=np.float64),
            patch.std(dtype=np.float64),
            coh[sl].mean(),
            1.0 - concentration,
        )
    spread = float(grey.std(dtype=np.float64))
    contrast_mean = float(local[:, 1].mean())
    components = {
        "mean": float(local[:, 0].std()) / spread if spread > 0 else 0.0,
        "contrast": float(local[:, 1].std()) / contrast_mean if contrast_mean > 0 else 0.0,
        "coherence": float(local[:, 2].std()),
        "orientation": float(local[:, 3].std()),
    }
    ratios = {k: v / SCALES[k] for k, v in components.items()}
    lead = max(ratios, key=lambda k: ratios[k])
    column = list(SCALES).index(lead)
    odd = int(np.argmax(np.abs(local[:, column] - np.median(local[:, column]))))
    score = ratios[lead]
    warning = None
    if score > THRESHOLD:
        r, c = corners[odd]
        warning = (
            f"The exemplar is not stationary: its {_NAMES[lead]} varies across it "
            f"(score {score:.2f} > {THRESHOLD:g}); the region at rows {r}-{r + win}, columns {c}-{c + win} "
            "differs most from the rest. Synthesis assumes one texture everywhere and will copy or average "
            "the regions: crop the exemplar to one kind of texture."
        )
    return Stationarity(score, components, win, period, len(corners), (*corners[odd], win), warning)


def exemplar_diagnostics(images: Mapping[str, np.ndarray]) -> dict[str, Any]:
    """The diagnostics of every exemplar of a run, by input role (``exemplar``, ``exemplar_xy``, ...).

    Returns
    -------
    dict
        ``{"stationarity": {role: Stationarity.to_dict() or {"score": None, "note": why}},
        "warnings": ["role: warning", ...]}``; an exemplar too small to judge gets a note, not an error.
    """
    reports: dict[str, Any] = {}
    warnings: list[str] = []
    seen: dict[int, dict[str, Any]] = {}
    for role, image in images.items():
        if id(image) in seen:  # one exemplar given for several planes is judged once
            reports[role] = seen[id(image)]
            continue
        try:
            found = stationarity(image)
        except InvalidInput as exc:
            reports[role] = {"score": None, "stationary": None, "warning": None, "note": exc.problem}
        else:
            reports[role] = found.to_dict()
            if found.warning:
                warnings.append(f"{role}: {found.warning}")
        seen[id(image)] = reports[role]
    return {"stationarity": reports, "warnings": warnings}
