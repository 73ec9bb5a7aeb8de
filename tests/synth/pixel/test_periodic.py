"""Tileable outputs of the 2D pixel methods (``periodic=True``): a 2 x 2 tiling shows no seam.

The measure is :func:`texsynth.synth.evaluate.tile_seam`. One line of pixel pairs is a noisy sample (a
seamless border's rank is about uniform over [0, 1]), so the checks take the mean over three seeds: the ratio
and the ranks of a seamless output stay near 1 and 0.5; a causal scan's seam (the default, non-periodic
output) sits near 1.5 and 0.9.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from texsynth.synth import InvalidParameter
from texsynth.synth.analysis.tensor import structure_tensor
from texsynth.synth.api import available_methods, synthesize
from texsynth.synth.evaluate import tile_seam
from texsynth.synth.grid.pyramid import gaussian_pyramid, level_shapes
from texsynth.synth.io.patterns import grating, waves
from texsynth.synth.methods.arbitrary_shape import constraint_field
from texsynth.synth.pixel.synthesis import Guidance, SearchSettings, tensor_features

from .test_synthesis_core import _run_both

SIZE = (96, 96)
SEEDS = (1, 2, 3)
#: Mean over SEEDS of a seamless tiling: ratio below this, ...
MAX_RATIO = 1.2
#: ... and the mean of the six ranks (rows and columns) below this.
MAX_RANK = 0.8


def _noise(shape: tuple[int, int] = (96, 96)) -> np.ndarray:
    """Smooth isotropic noise (an HRTEM-like granular texture without the shared data)."""
    z = gaussian_filter(np.random.default_rng(0).random(shape), 1.5, mode="wrap")
    return ((z - z.min()) / np.ptp(z)).astype(np.float32)


def _fringes() -> np.ndarray:
    return grating((64, 64), np.radians(20), 6.0, noise=0.1, seed=0)


def _tileable_constraint(shape: tuple[int, int] = SIZE) -> np.ndarray:
    """Bent fringes with whole periods across the image (it tiles), its borders at a generic phase."""
    return np.roll(waves(shape, period=8.0, amplitude=6.0, wavelength=shape[1]), shape[1] // 8, axis=1)


#: wei-levoy with the paper's passes (causal refinement, flat neighbourhood, 3 levels): its causal scan
#: closes at the tile borders. The defaults' square refinement passes already look across them.
PAPER_WL = {"refinement": "same", "falloff": 0.0, "levels": 3, "kset_size": 9, "kset_dims": 16}


def _run(method: str, periodic: bool, seed: int, extra: dict | None = None):
    if method == "arbitrary-shape":
        return synthesize(
            method,
            _fringes(),
            size=SIZE,
            seed=seed,
            params={"periodic": periodic, **(extra or {})},
            constraint=_tileable_constraint(),
        )
    params = {"periodic": periodic, **(extra or {})}
    return synthesize(method, _noise(), size=SIZE, seed=seed, params=params)


def _mean_seam(method: str, periodic: bool, extra: dict | None = None) -> tuple[float, float]:
    """Mean ``tile_seam`` ratio and mean rank (rows and columns) over SEEDS."""
    seams = [tile_seam(_run(method, periodic, seed, extra).image) for seed in SEEDS]
    ratio = float(np.mean([s["ratio"] for s in seams]))
    rank = float(np.mean([[s["rows_rank"], s["cols_rank"]] for s in seams]))
    return ratio, rank


# ---------------------------------------------------------------- the outputs tile


@pytest.mark.parametrize("method", ["wei-levoy", "tensor-constrained", "arbitrary-shape"])
def test_periodic_output_tiles_without_a_seam(method: str) -> None:
    ratio, rank = _mean_seam(method, periodic=True)
    assert ratio < MAX_RATIO and rank < MAX_RANK, (ratio, rank)


@pytest.mark.parametrize("method", ["wei-levoy", "arbitrary-shape"])
def test_the_default_output_shows_the_seam_the_measure_catches(method: str) -> None:
    """The same check fails without ``periodic``: a causal scan closes at the tile borders.

    arbitrary-shape with the paper's settings and proposals dropped outside the rotation window (the
    configuration this test was written for). The fibres recipe's causal passes alone keep a seam too,
    less far above the interior on this case (mean ratio 1.30, rank 0.79; with transfer_candidates alone
    1.44, 0.70); its square refinement passes (the defaults since) look across the borders: 0.86, 0.30.
    wei-levoy with the paper's passes: its default square refinement already looks across the borders.
    Since raster passes run in tiles (issue 25) a seam pass searches the first columns again with the full
    square, across the left border: arbitrary-shape's rank 0.78 (ratio 2.99), below the 0.85 before."""
    paper = {"recipe": "paper", "transfer_candidates": False} if method == "arbitrary-shape" else PAPER_WL
    ratio, rank = _mean_seam(method, periodic=False, extra=paper)
    assert ratio > 1.3 and rank > 0.75, (ratio, rank)


def test_paper_passes_tile_with_periodic() -> None:
    """``periodic`` also closes the borders of the paper's causal passes (two passes suffice there)."""
    ratio, rank = _mean_seam("wei-levoy", periodic=True, extra=PAPER_WL)
    assert ratio < MAX_RATIO and rank < MAX_RANK, (ratio, rank)


# ---------------------------------------------------------------- reproducibility, invariance, parameters


@pytest.mark.parametrize("method", ["wei-levoy", "tensor-constrained", "arbitrary-shape"])
def test_periodic_same_seed_same_bytes(method: str) -> None:
    a, b = _run(method, True, seed=5), _run(method, True, seed=5)
    assert a.image.tobytes() == b.image.tobytes()
    assert a.params["periodic"] is True
    assert a.image.tobytes() != _run(method, False, seed=5).image.tobytes()


def test_a_square_neighbourhood_in_random_order_already_wraps_and_is_unchanged() -> None:
    """Its search already sees across the borders: ``periodic`` changes nothing, to the byte."""
    # (the pass count given: periodic=True alone gives wei-levoy a third pass)
    params = {"neighbourhood": "square", "neighbourhood_size": 7, "levels": 2, "iterations": 2}
    plain = synthesize("wei-levoy", _noise((48, 48)), size=(48, 48), seed=2, params=params)
    periodic = synthesize(
        "wei-levoy", _noise((48, 48)), size=(48, 48), seed=2, params=params | {"periodic": True}
    )
    assert plain.image.tobytes() == periodic.image.tobytes()


@pytest.mark.parametrize("method", ["wei-levoy", "tensor-constrained", "arbitrary-shape"])
def test_periodic_is_in_the_schema_with_a_description(method: str) -> None:
    prop = available_methods()[method].schema()["properties"]["periodic"]
    assert prop["default"] is False and prop["type"] == "boolean"
    assert "tile" in prop["description"] and "tiles" in prop["x-details"]


@pytest.mark.parametrize(
    ("method", "params", "field"),
    [
        ("wei-levoy", {"iterations": 1}, "iterations"),
        ("arbitrary-shape", {"iterations": 1}, "iterations"),
        ("tensor-constrained", {"structure_iterations": 1}, "structure_iterations"),
        ("tensor-constrained", {"texture_iterations": 1}, "texture_iterations"),
    ],
)
def test_a_causal_periodic_run_needs_a_refinement_pass(method: str, params: dict, field: str) -> None:
    with pytest.raises(InvalidParameter, match=f"periodic=True with a causal neighbourhood needs {field}"):
        synthesize(method, _noise((32, 32)), size=(32, 32), params=params | {"periodic": True})


def test_one_pass_is_allowed_with_a_square_neighbourhood() -> None:
    params = {"periodic": True, "iterations": 1, "neighbourhood": "square", "neighbourhood_size": 5}
    r = synthesize("wei-levoy", _noise((32, 32)), size=(32, 32), seed=1, params=params)
    assert r.image.shape == (32, 32)


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


# ---------------------------------------------------------------- arbitrary shape: the constraint wraps


def test_periodic_constraint_field_wraps_around_the_borders() -> None:
    con = _tileable_constraint((48, 48))
    shift = (11, 17)
    _, s = constraint_field(con, (48, 48), 1.0, 3.0, periodic=True)
    _, s_rolled = constraint_field(np.roll(con, shift, axis=(0, 1)), (48, 48), 1.0, 3.0, periodic=True)
    np.testing.assert_allclose(s_rolled, np.roll(s, shift, axis=(0, 1)), atol=1e-6)
    _, plain = constraint_field(np.roll(con, shift, axis=(0, 1)), (48, 48), 1.0, 3.0)
    assert not np.allclose(plain, np.roll(s, shift, axis=(0, 1)), atol=1e-6)  # mirrored borders differ


def test_periodic_arbitrary_shape_synthesizes_a_tileable_base_even_at_the_exemplar_size() -> None:
    ex = _fringes()
    params = {"angular_step": 15.0, "neighbourhood_size": 7, "periodic": True}
    r = synthesize(
        "arbitrary-shape", ex, size=(64, 64), seed=1, params=params, constraint=_tileable_constraint((64, 64))
    )
    assert r.stats["exemplar_like"]  # the exemplar itself does not tile: a tileable S_en was synthesized
    plain = synthesize(
        "arbitrary-shape",
        ex,
        size=(64, 64),
        seed=1,
        params=params | {"periodic": False},
        constraint=_tileable_constraint((64, 64)),
    )
    assert plain.stats["exemplar_like"] == {}
