"""The bundled example exemplars of the browser page's gallery and of ``GET /api/examples``.

Six small images, each credited with its licence in ``README.md`` beside them (CC0 or MIT, or made by
texsynth's own generators): a real HRTEM micrograph of soot fringes, brick, grass and gravel from
scikit-image's data (CC0), a generated laminar exemplar (:mod:`texsynth.synth.io.laminar`) and a generated
constraint image for ``arbitrary-shape`` (:mod:`texsynth.synth.io.patterns`). ``python -m
texsynth.app.examples.build`` makes the PNGs again from those sources (same bytes). Whether an example shows
lattice fringes is not written down here but measured by the engine's own rule
(:func:`texsynth.synth.evaluate.glossary.fringes_shown`), the one the job's metrics use.
"""

from __future__ import annotations

import io
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

__all__ = ["EXAMPLES", "FOLDER", "THUMBNAIL_SIDE", "Example", "catalogue", "has_fringes", "thumbnail_png"]

FOLDER = Path(__file__).resolve().parent
#: The longest side of a gallery thumbnail, pixels.
THUMBNAIL_SIDE = 96


@dataclass(frozen=True)
class Example:
    """One bundled image: its file stem, what it is, where it comes from, the method that suits it."""

    name: str
    title: str
    kind: str  # "2d": an exemplar; "constraint": a constraint image
    credit: str
    licence: str
    suggested_method: str

    @property
    def path(self) -> Path:
        return FOLDER / f"{self.name}.png"


EXAMPLES: dict[str, Example] = {
    e.name: e
    for e in (
        Example(
            "soot-fringes",
            "Soot particle, HRTEM lattice fringes (128 px, about 18 px/nm)",
            "2d",
            "HRTEMFringeMapping, Botero et al., Carbon 2016; (C) 2020 M. Kraft and the Computational "
            "Modelling Group, Cambridge",
            "MIT",
            "tensor-constrained",
        ),
        Example(
            "brick",
            "Brick wall (scikit-image data, 128 px)",
            "2d",
            "scikit-image data.brick(), from CC0Textures Bricks25",
            "CC0-1.0",
            "quilting",
        ),
        Example(
            "grass",
            "Grass (scikit-image data, 128 px)",
            "2d",
            "scikit-image data.grass(), from DeviantArt linolafett Grass-01",
            "CC0-1.0",
            "wei-levoy",
        ),
        Example(
            "gravel",
            "Gravel (scikit-image data, 128 px)",
            "2d",
            "scikit-image data.gravel(), from CC0Textures Gravel04",
            "CC0-1.0",
            "quilting",
        ),
        Example(
            "laminar",
            "Generated laminar carbon: a slice of crumpled sheets 6 px apart (texsynth.synth.io.laminar)",
            "2d",
            "made by texsynth (texsynth.synth.io.laminar.turbostratic_volume, seed 27)",
            "MIT",
            "solid-kopf",
        ),
        Example(
            "constraint-waves",
            "Generated constraint: waves for arbitrary-shape synthesis (texsynth.synth.io.patterns)",
            "constraint",
            "made by texsynth (texsynth.synth.io.patterns.waves)",
            "MIT",
            "arbitrary-shape",
        ),
    )
}


@lru_cache(maxsize=len(EXAMPLES))
def has_fringes(name: str) -> bool:
    """Whether example ``name`` shows lattice fringes, by the rule the job metrics use."""
    from texsynth.synth.evaluate.glossary import fringes_shown
    from texsynth.synth.io import load_image

    example = EXAMPLES[name]
    if example.kind != "2d":
        return False
    return fringes_shown(load_image(example.path))[0]


def catalogue() -> list[dict[str, Any]]:
    """``GET /api/examples``: every example with its URLs and whether it has fringes."""
    return [
        {
            **asdict(e),
            "url": f"/api/examples/{e.name}",
            "thumbnail": f"/api/examples/{e.name}/thumbnail",
            "has_fringes": has_fringes(e.name),
        }
        for e in EXAMPLES.values()
    ]


@lru_cache(maxsize=len(EXAMPLES))
def thumbnail_png(name: str) -> bytes:
    """A small PNG of example ``name`` (its longest side :data:`THUMBNAIL_SIDE`, never enlarged)."""
    with Image.open(EXAMPLES[name].path) as image:
        image.thumbnail((THUMBNAIL_SIDE, THUMBNAIL_SIDE), Image.Resampling.LANCZOS)
        buf = io.BytesIO()
        image.save(buf, "PNG", optimize=True)
    return buf.getvalue()


def _as_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.round(np.asarray(image, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)
