"""Tileable outputs of the pixel synthesis (``SearchSettings.periodic``): the kernel against its reference."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from synth.analysis.tensor import structure_tensor
from synth.grid.pyramid import gaussian_pyramid, level_shapes
from synth.pixel.synthesis import Guidance, SearchSettings, tensor_features

from .test_synthesis_core import _run_both


def _noise(shape: tuple[int, int] = (96, 96)) -> np.ndarray:
    """Smooth isotropic noise (an HRTEM-like granular texture without the shared data)."""
    z = gaussian_filter(np.random.default_rng(0).random(shape), 1.5, mode="wrap")
    return ((z - z.min()) / np.ptp(z)).astype(np.float32)


# ---------------------------------------------------------------- the kernel against its reference


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
@pytest.mark.parametrize("shape", ["causal", "square"])
def test_kernel_matches_reference_periodic(search: str, shape: str) -> None:
    ex = _noise((22, 20))[..., None]
    levels = 2
    settings = SearchSettings(
        size=5,
        shape=shape,  # type: ignore[arg-type]
        scan="lexicographic" if shape == "causal" else "random",
        levels=levels,
        parent_size=3,
        iterations=3,
        search=search,  # type: ignore[arg-type]
        k=3,
        random_candidates=2,
        histogram_weight=2.0,
        periodic=True,
    )
    _run_both(
        ex_levels=gaussian_pyramid(ex, levels),
        out_shapes=level_shapes((14, 12), levels),
        settings=settings,
        seed=3,
    )


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
def test_kernel_matches_reference_periodic_with_tensor_guidance(search: str) -> None:
    ex = _noise((24, 24))
    feats, code = tensor_features(structure_tensor(ex), "SO")
    out_tensors = structure_tensor(_noise((12, 12)), mode="wrap")
    guidance = Guidance(
        out_levels=[tensor_features(out_tensors, "SO")[0]],
        ex_levels=[feats],
        metric=code,
        weight=0.4,
        size=3,
        hint_levels=[np.random.default_rng(1).integers(2, 20, (12, 12, 2))],
    )
    settings = SearchSettings(
        size=5, levels=1, iterations=2, search=search, k=2, random_candidates=1, periodic=True
    )
    _run_both(
        ex_levels=[ex[..., None]], out_shapes=[(12, 12)], settings=settings, p=0.6, guidance=guidance, seed=2
    )
