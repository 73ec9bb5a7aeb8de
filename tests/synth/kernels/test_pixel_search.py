"""The pixel search kernel (texsynth.synth.kernels.pixel_search) against its plain NumPy reference, through
whole source-map syntheses: pixels, tensor guidance, tensors, chunking, histograms, windows, transfers,
falloff and square refinement."""

from __future__ import annotations

import numpy as np
import pytest

from tests.synth.search_cases import _rng_image, _run_both, _striped_window, _tiled_window
from texsynth.synth.analysis.tensor import structure_tensor
from texsynth.synth.grid.pyramid import gaussian_pyramid, level_shapes
from texsynth.synth.kernels.pixel_search import METRIC_NORM, METRIC_SO, METRIC_SSD
from texsynth.synth.pixel.synthesis import Guidance, SearchSettings, synthesize_source_map, tensor_features


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
@pytest.mark.parametrize("shape", ["causal", "square"])
@pytest.mark.parametrize("channels", [1, 3])
def test_kernel_matches_reference_on_pixels(search: str, shape: str, channels: int) -> None:
    ex = _rng_image((22, 20, channels), seed=channels)
    levels = 2
    settings = SearchSettings(
        size=5,
        shape=shape,
        scan="lexicographic" if shape == "causal" else "random",
        levels=levels,
        parent_size=3,
        iterations=2,
        search=search,
        k=3,
        random_candidates=2,
    )
    _run_both(
        ex_levels=gaussian_pyramid(ex, levels),
        out_shapes=level_shapes((14, 12), levels),
        settings=settings,
        seed=3,
    )


@pytest.mark.parametrize(
    ("metric", "code"), [("ED", METRIC_SSD), ("FN", METRIC_NORM), ("LE", METRIC_NORM), ("SO", METRIC_SO)]
)
@pytest.mark.parametrize("search", ["exact", "kcoherence"])
def test_kernel_matches_reference_with_tensor_guidance(metric: str, code: int, search: str) -> None:
    ex = _rng_image((24, 24), seed=5)
    feats, got = tensor_features(structure_tensor(ex), metric)  # type: ignore[arg-type]
    assert got == code
    out_tensors = structure_tensor(_rng_image((12, 12), seed=6), mode="wrap")
    guidance = Guidance(
        out_levels=[tensor_features(out_tensors, metric)[0]],
        ex_levels=[feats],
        metric=code,
        weight=0.4,
        size=3,
        hint_levels=[np.random.default_rng(1).integers(2, 20, (12, 12, 2))],
    )
    settings = SearchSettings(
        size=5, levels=1, iterations=2, search=search, k=2, random_candidates=1, alpha=0.3
    )
    _run_both(
        ex_levels=[ex[..., None]], out_shapes=[(12, 12)], settings=settings, p=0.6, guidance=guidance, seed=2
    )


@pytest.mark.parametrize("metric", ["SO", "LE"])
def test_kernel_matches_reference_when_synthesizing_tensors(metric: str) -> None:
    feats, code = tensor_features(structure_tensor(_rng_image((20, 20), seed=8)), metric)  # type: ignore[arg-type]
    settings = SearchSettings(size=3, levels=2, parent_size=3, iterations=1, search="exact")
    _run_both(
        ex_levels=gaussian_pyramid(feats, 2),
        out_shapes=level_shapes((10, 10), 2),
        settings=settings,
        metric=code,
        seed=4,
    )


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
def test_how_a_pass_is_chunked_changes_no_byte(monkeypatch: pytest.MonkeyPatch, search: str) -> None:
    """The kernel keeps nothing between calls but the state (its scratch buffers and the flat copy of
    the exemplar features are rebuilt per call): one call per pass and one call per position give the
    same bytes, with all three parts of a distance (pixels, parent level, SO tensor guidance) and
    histogram matching on."""
    import texsynth.synth.pixel.synthesis as synthesis

    ex = _rng_image((24, 24), seed=5)
    ex_tensors = gaussian_pyramid(structure_tensor(ex), 2)
    out_field = structure_tensor(_rng_image((14, 12), seed=6), mode="wrap")
    out_tensors = gaussian_pyramid(out_field, 2, mode="wrap")
    guidance = Guidance(
        out_levels=[tensor_features(t, "SO")[0] for t in out_tensors],
        ex_levels=[tensor_features(t, "SO")[0] for t in ex_tensors],
        metric=METRIC_SO,
        weight=0.4,
        size=5,
    )
    settings = SearchSettings(
        size=5, levels=2, parent_size=3, iterations=2, search=search, k=2, histogram_weight=2.0
    )
    runs = []
    for chunks in (1, 10**9):  # one chunk per pass; one position per chunk
        monkeypatch.setattr(synthesis, "_CHUNKS_PER_PASS", chunks)
        srcs, report = synthesize_source_map(
            ex_levels=gaussian_pyramid(ex[..., None], 2),
            out_shapes=level_shapes((14, 12), 2),
            settings=settings,
            p=0.6,
            guidance=guidance,
            seed=4,
        )
        runs.append((srcs, report.mean_best_distance))
    for a, b in zip(runs[0][0], runs[1][0], strict=True):
        np.testing.assert_array_equal(a, b)
    assert runs[0][1] == runs[1][1]


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
@pytest.mark.parametrize("labelled", [False, True])
def test_kernel_matches_reference_with_histogram_matching(search: str, labelled: bool) -> None:
    ex = _rng_image((22, 20, 1), seed=12)
    levels = 2
    settings = SearchSettings(
        size=5, levels=levels, parent_size=3, iterations=2, search=search, k=2, histogram_weight=3.0
    )
    histogram = None
    if labelled:  # four grey-level bins as labels, wanting equal shares
        histogram = [
            (np.minimum((lvl[..., 0] * 4).astype(np.int64), 3), np.full(4, 0.25))
            for lvl in gaussian_pyramid(ex, levels)
        ]
    _run_both(
        ex_levels=gaussian_pyramid(ex, levels),
        out_shapes=level_shapes((14, 12), levels),
        settings=settings,
        seed=5,
        histogram=histogram,
    )


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
@pytest.mark.parametrize("span", [0, 1])
def test_kernel_matches_reference_with_a_candidate_window(search: str, span: int) -> None:
    ex = _rng_image((22, 22, 1), seed=14)
    settings = SearchSettings(size=5, levels=1, iterations=2, search=search, k=2, random_candidates=3)
    _run_both(
        ex_levels=[ex],
        out_shapes=[(12, 10)],
        settings=settings,
        seed=6,
        window=_striped_window((22, 22), (12, 10), span),
    )


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
@pytest.mark.parametrize("period", [2, 4])
def test_kernel_matches_reference_with_a_class_transfer(search: str, period: int) -> None:
    ex, window = _tiled_window(_rng_image((14, 11, 1), seed=16), 4, (12, 10), period)
    settings = SearchSettings(size=5, levels=1, iterations=2, search=search, k=2, random_candidates=3)
    _run_both(ex_levels=[ex], out_shapes=[(12, 10)], settings=settings, seed=7, window=window)


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
@pytest.mark.parametrize(
    "extra",
    [
        {"falloff": 0.156},
        {"refine_square": True, "refine_size": 3},
        {"falloff": 0.2, "refine_square": True},
    ],
)
def test_kernel_matches_reference_with_falloff_and_square_refinement(search: str, extra: dict) -> None:
    ex = _rng_image((22, 20, 1), seed=21)
    levels = 2
    settings = SearchSettings(
        size=5, levels=levels, parent_size=3, iterations=2, search=search, k=3, histogram_weight=2.0, **extra
    )
    _run_both(
        ex_levels=gaussian_pyramid(ex, levels),
        out_shapes=level_shapes((14, 12), levels),
        settings=settings,
        seed=7,
    )
