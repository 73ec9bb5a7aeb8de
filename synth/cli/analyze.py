"""``texsynth analyze IMAGE --out DIR``: the structure-tensor analysis of one image, as files.

Writes into ``DIR``:

- ``coherence.png``: coherence, grey (0 black, 1 white), with its legend;
- ``orientation.png``: the **fringe** direction in the cyclic hue palette, with its legend;
- ``composite.png``: HSV, hue = fringe direction, saturation = coherence, value = the image;
- ``tensor.json``: mean coherence, the dominant orientation in degrees (gradient and fringe
  direction), energy-weighted orientation histograms of both with their bin edges in degrees, the
  image's shape and the two scales, and the image's stationarity as an exemplar
  (:func:`texsynth.synth.analysis.stationarity.stationarity`; a warning is printed when it is not stationary).

Angles follow ALGORITHMS.md: degrees counter-clockwise from +x with ``y`` up on screen, wrapped to
``(-90, 90]``. The gradient direction is across the fringes; the fringe direction, 90 degrees away,
is what the images show and what a person reads.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from texsynth.synth.errors import InvalidParameter

if TYPE_CHECKING:  # numpy, scipy and the renderers load when the command runs, not for ``--help``
    import numpy as np

__all__ = ["TensorAnalysis", "analyze_image", "register", "run"]

_MAX_BINS = 3600
_HISTOGRAM_WEIGHTING = "tensor trace l1 + l2 (gradient energy); flat regions do not vote"
_DESCRIPTION = """\
Structure-tensor analysis of one image (Akl et al. 2014, eqs 1-5). Writes into DIR:

  coherence.png    coherence, grey: 0 black (no orientation), 1 white (perfect fringes)
  orientation.png  fringe direction, cyclic hue palette (legend: strip and half-disc)
  composite.png    hue = fringe direction, saturation = coherence, brightness = image
  tensor.json      mean coherence, dominant orientation (gradient and fringe), histograms,
                   stationarity (score <= 1: one texture throughout; else a warning: crop it)

Angles: degrees counter-clockwise from +x, y up on screen, wrapped to (-90, 90].
The gradient direction runs across fringes; the fringe direction is 90 degrees away.
"""
_CONVENTIONS = (
    "degrees counter-clockwise from +x (x right, y up on screen), wrapped to (-90, 90]; "
    "gradient = across the fringes (eigenvector of the largest eigenvalue), fringe = gradient + 90"
)


@dataclass(frozen=True)
class TensorAnalysis:
    """What ``analyze`` measures on one image.

    Attributes
    ----------
    tensors : ndarray, shape (H, W, 3)
        The structure tensor field ``(S_xx, S_xy, S_yy)``.
    coherence : ndarray, shape (H, W)
        Coherence in [0, 1].
    fringe_direction : ndarray, shape (H, W)
        Fringe (structure) direction in radians, ``(-pi/2, pi/2]``.
    summary : dict
        The JSON-ready report (see :func:`analyze_image`).
    """

    tensors: np.ndarray
    coherence: np.ndarray
    fringe_direction: np.ndarray
    summary: dict[str, Any]


def _degrees(angle: float) -> float:
    from texsynth.synth.analysis import tensor

    return round(math.degrees(float(tensor.wrap_angle(angle))), 6)


def _check_scale(name: str, value: float, largest_side: int | None = None) -> None:
    if not (math.isfinite(value) and value > 0):
        raise InvalidParameter(name, value, "must be a positive, finite number of pixels")
    if largest_side is not None and value > largest_side:
        raise InvalidParameter(name, value, f"must be at most the image's largest side ({largest_side} px)")


def _check_parameters(sigma_d: float, sigma_w: float, bins: int) -> None:
    _check_scale("sigma_d", sigma_d)
    _check_scale("sigma_w", sigma_w)
    if not 1 <= bins <= _MAX_BINS:
        raise InvalidParameter("bins", bins, f"must lie in [1, {_MAX_BINS}]")


def analyze_image(
    image: np.ndarray, *, sigma_d: float = 1.0, sigma_w: float = 3.0, bins: int = 36
) -> TensorAnalysis:
    """Structure-tensor analysis of a grey or RGB image (Akl 2014, eqs 1-5).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        float image in [0, 1] (:func:`texsynth.synth.io.load_image`); RGB channels are combined by Di Zenzo.
    sigma_d, sigma_w : float
        Derivative and window scales in pixels, each positive and at most the image's largest side.
    bins : int
        Number of orientation histogram bins over 180 degrees, in ``[1, 3600]``.

    Returns
    -------
    TensorAnalysis
        Fields and a summary with ``shape``, ``sigma_d``, ``sigma_w``, ``mean_coherence``,
        ``dominant_orientation_deg`` (``gradient``, ``fringe``; the orientation of the mean tensor)
        and ``orientation_histogram`` (``bin_edges_deg``, ``gradient``, ``fringe``, each summing to 1).
    """
    import numpy as np

    from texsynth.synth.analysis import tensor

    _check_parameters(sigma_d, sigma_w, bins)
    largest = int(max(image.shape[:2]))
    _check_scale("sigma_d", sigma_d, largest)
    _check_scale("sigma_w", sigma_w, largest)
    S = tensor.structure_tensor(image, sigma_d, sigma_w)
    coh = tensor.coherence(S)
    dominant = tensor.dominant_orientation(S)
    # Uniform bins over (-90, 90]; the edges are written from their definition, not from the float32
    # radians the histogram used (which would print as -90.000003).
    grad_hist, _ = tensor.orientation_histogram(S, bins=bins)
    # Rotating every tensor by +90 degrees turns gradient orientations into fringe directions and
    # keeps the eigenvalues, hence the energy weights: the fringe histogram on the same bin edges.
    fringe_hist, _ = tensor.orientation_histogram(tensor.rotate_tensors(S, np.pi / 2), bins=bins)
    summary: dict[str, Any] = {
        "shape": [int(s) for s in image.shape],
        "sigma_d": float(sigma_d),
        "sigma_w": float(sigma_w),
        "conventions": _CONVENTIONS,
        "mean_coherence": round(float(coh.mean(dtype=np.float64)), 6),
        "dominant_orientation_deg": {
            "gradient": _degrees(dominant),
            "fringe": _degrees(dominant + np.pi / 2),
        },
        "orientation_histogram": {
            "bins": int(bins),
            "weighting": _HISTOGRAM_WEIGHTING,
            "bin_edges_deg": [round(float(e), 6) for e in np.linspace(-90.0, 90.0, bins + 1)],
            "gradient": [float(h) for h in grad_hist],
            "fringe": [float(h) for h in fringe_hist],
        },
    }
    from texsynth.synth.analysis.stationarity import exemplar_diagnostics

    summary["stationarity"] = exemplar_diagnostics({"image": image})["stationarity"]["image"]
    return TensorAnalysis(S, coh, tensor.structure_direction(S), summary)


def _as_float(rendering: np.ndarray) -> np.ndarray:
    """uint8 rendering -> float32 in [0, 1] for :func:`texsynth.synth.io.save_image` (exact at 8 bits)."""
    import numpy as np

    return rendering.astype(np.float32) / np.float32(255)


def run(args: argparse.Namespace) -> int:
    """Run ``texsynth analyze``: validate, load, analyse, write four files, print one line."""
    from texsynth.synth.io import (  # deferred: ``--help`` needs no image codecs
        atomic_write_json,
        load_image,
        save_image,
    )
    from texsynth.synth.output import render

    _check_parameters(args.sigma_d, args.sigma_w, args.bins)
    image = load_image(args.image)
    analysis = analyze_image(image, sigma_d=args.sigma_d, sigma_w=args.sigma_w, bins=args.bins)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidParameter("out", str(out), f"cannot create the directory ({exc.strerror})") from None
    renderings = {
        "coherence.png": render.coherence_image(analysis.coherence, legend=True),
        "orientation.png": render.orientation_image(analysis.fringe_direction, legend=True),
        "composite.png": render.composite_image(
            analysis.fringe_direction, analysis.coherence, image, legend=True
        ),
    }
    summary = {"source": str(args.image), **analysis.summary, "files": [*renderings, "tensor.json"]}
    try:
        for name, rendering in renderings.items():
            save_image(out / name, _as_float(rendering))
        atomic_write_json(out / "tensor.json", summary)
    except OSError as exc:
        raise InvalidParameter("out", str(out), f"cannot write there ({exc.strerror or exc})") from None
    dominant = summary["dominant_orientation_deg"]
    found = summary["stationarity"]
    stationary = "" if found.get("score") is None else f", stationarity {found['score']:.2f}"
    print(
        f"{out}: coherence.png, orientation.png, composite.png, tensor.json "
        f"(mean coherence {summary['mean_coherence']:.3f}, fringe direction {dominant['fringe']:.1f} deg, "
        f"gradient {dominant['gradient']:.1f} deg{stationary})"
    )
    if found.get("warning"):
        print(f"  warning: {found['warning']}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``analyze`` to the ``texsynth`` command line."""
    parser = subparsers.add_parser(
        "analyze",
        help="structure-tensor analysis of an image: coherence, orientation, composite, tensor.json",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("image", metavar="IMAGE", help="image file (PNG, TIFF, JPEG; grey or RGB)")
    parser.add_argument("--out", required=True, metavar="DIR", help="directory to write the four files into")
    parser.add_argument(
        "--sigma-d", type=float, default=1.0, metavar="PX", help="derivative scale in pixels (default 1.0)"
    )
    parser.add_argument(
        "--sigma-w",
        type=float,
        default=3.0,
        metavar="PX",
        help="window (integration) scale in pixels (default 3.0)",
    )
    parser.add_argument(
        "--bins",
        type=int,
        default=36,
        metavar="N",
        help="orientation histogram bins over 180 degrees (default 36)",
    )
    parser.set_defaults(func=run)
