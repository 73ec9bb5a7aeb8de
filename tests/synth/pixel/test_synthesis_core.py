"""The shared synthesis machinery: kernel = reference, option semantics, reproducibility."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.synth.search_cases import (
    _rng_image,
    _run_both,
    _striped_window,
    _tiled_window,
    synthesize_with_reference,
)
from texsynth.synth import Cancelled, InvalidParameter
from texsynth.synth.analysis.tensor import structure_tensor
from texsynth.synth.api import synthesize
from texsynth.synth.grid.neighbourhood import neighbourhood_offsets, parent_offsets
from texsynth.synth.grid.scan import scan_order
from texsynth.synth.kernels.pixel_search import (
    METRIC_SSD,
    Candidates,
    ClassWindow,
    Histogram,
    Part,
    Pass,
    SearchState,
    synthesize_chunk,
)
from texsynth.synth.pixel.synthesis import (
    Guidance,
    SearchSettings,
    entry_weights,
    sets_ahead,
    synthesize_source_map,
    tensor_features,
)

# ---------------------------------------------------------------- option semantics


def test_causal_first_pass_never_reads_unsynthesized_pixels() -> None:
    """Unsynthesized output pixels are NaN: reading one would poison a distance and the argmin."""
    ex = _rng_image((16, 16, 1))
    offs = neighbourhood_offsets(5, "causal")
    src = np.full((10, 10, 2), 8, dtype=np.int64)
    empty = np.zeros((1, 1, 1), np.float32)
    state = SearchState(
        cur=Part(np.full((10, 10, 1), np.nan, np.float32), ex, offs, METRIC_SSD, 1.0),
        par=Part(empty, empty, parent_offsets(3), METRIC_SSD, 0.0),
        gui=Part(
            np.zeros((1, 1, 3), np.float32),
            np.zeros((1, 1, 3), np.float32),
            np.zeros((0, 2), np.int32),
            METRIC_SSD,
            0.0,
        ),
        alpha=0.5,
        cands=Candidates(
            src=src,
            hint=src,
            use_hint=False,
            valid=np.array([2, 14, 2, 14]),
            mask=np.ones((16, 16), np.uint8),
            kset=np.full((1, 1, 0, 2), -1, np.int64),
            cand_offs=np.zeros((1, 2), np.int32),
            exact=True,
            n_random=0,
            capacity=4,
        ),
        hist=Histogram(np.zeros(256, np.int64), np.array([100], np.int64), np.array([100.0]), 0.0),
        win=ClassWindow(np.zeros(1, np.int64), np.zeros((1, 1), np.int64), 1, -1),
        run=Pass(
            order=scan_order((10, 10), "lexicographic"),
            first_pass=True,
            done=np.zeros((10, 10), np.uint8),
            seed_key=np.uint64(1),
            stamp=np.zeros(256, np.int64),
            counter=np.zeros(1, np.int64),
            best_out=np.zeros((10, 10), np.float32),
        ),
    )
    synthesize_chunk(state, 0, 100)
    assert np.isfinite(state.run.best_out).all()
    assert np.isfinite(state.cur.out).all()
    assert (state.cands.src >= 2).all() and (state.cands.src < 14).all()


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
def test_masked_exemplar_positions_are_never_copied(search: str) -> None:
    ex = _rng_image((24, 24, 1), seed=9)
    mask = np.zeros((24, 24), np.uint8)
    mask[:, 12:] = 1
    settings = SearchSettings(size=3, levels=1, iterations=2, search=search, k=3)
    srcs, _ = synthesize_source_map([ex], [(16, 16)], settings, seed=1, ex_masks=[mask])
    assert (srcs[0][..., 1] >= 12).all()
    ref, _ = synthesize_with_reference(
        ex_levels=[ex], out_shapes=[(16, 16)], settings=settings, seed=1, ex_masks=[mask]
    )
    np.testing.assert_array_equal(srcs[0], ref[0])


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
def test_periodic_exemplar_gives_periodic_output(search: str) -> None:
    tile = _rng_image((8, 8), seed=11)
    ex = np.tile(tile, (5, 5))
    r = synthesize(
        "wei-levoy",
        ex,
        size=(32, 24),
        seed=3,
        params={"levels": 1, "neighbourhood_size": 5, "search": search, "iterations": 1},
    )
    np.testing.assert_array_equal(r.image, np.roll(r.image, 8, axis=0))
    np.testing.assert_array_equal(r.image, np.roll(r.image, 8, axis=1))


@pytest.mark.parametrize("method", ["wei-levoy", "tensor-constrained"])
def test_same_seed_same_bytes_other_seed_other_output(method: str) -> None:
    ex = _rng_image((40, 40))
    params = {"neighbourhood_size": 7, "parent_size": 3}
    if method == "tensor-constrained":
        params |= {"structure_levels": 2}
    a = synthesize(method, ex, size=(32, 32), params=params, seed=7)
    b = synthesize(method, ex, size=(32, 32), params=params, seed=7)
    c = synthesize(method, ex, size=(32, 32), params=params, seed=8)
    assert a.image.tobytes() == b.image.tobytes()
    assert a.image.tobytes() != c.image.tobytes()


def test_every_tensor_metric_is_selectable_and_matters() -> None:
    ex = _rng_image((40, 40), seed=2)
    fields = {}
    for metric in ("ED", "SO", "FN", "LE"):
        r = synthesize(
            "tensor-constrained",
            ex,
            size=(24, 24),
            seed=1,
            params={"metric": metric, "neighbourhood_size": 5, "structure_levels": 2, "parent_size": 3},
        )
        assert r.params["metric"] == metric
        assert r.tensor_field is not None and r.tensor_field.shape == (24, 24, 3)
        fields[metric] = r.tensor_field
    assert len({f.tobytes() for f in fields.values()}) > 1


def test_output_copies_exemplar_values() -> None:
    ex = _rng_image((30, 30, 3))
    r = synthesize(
        "wei-levoy", ex, size=(20, 20), params={"neighbourhood_size": 5, "levels": 2, "parent_size": 3}
    )
    src = r.extras["source_map"]
    np.testing.assert_array_equal(r.image, ex[src[..., 0], src[..., 1]])
    assert r.image.shape == (20, 20, 3) and r.image.dtype == np.float32


# ---------------------------------------------------------------- parameters, progress, errors


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"neighbourhood_size": 8}, "neighbourhood_size"),
        ({"neighbourhood_size": 1}, "neighbourhood_size"),
        ({"iterations": 0}, "iterations"),
        ({"neighbourhod": "causal"}, "neighbourhod"),
        ({"scan": "spiral"}, "scan"),
        ({"search": "tsvq"}, "search"),
    ],
)
def test_invalid_parameters_fail_before_work_naming_the_field(params: dict, field: str) -> None:
    with pytest.raises(InvalidParameter, match=field):
        synthesize("wei-levoy", _rng_image((20, 20)), size=(16, 16), params=params)


def test_unknown_metric_and_out_of_range_p_are_named() -> None:
    with pytest.raises(InvalidParameter, match="metric"):
        synthesize("tensor-constrained", _rng_image((20, 20)), params={"metric": "XX"})
    with pytest.raises(InvalidParameter, match="'p'"):
        synthesize("tensor-constrained", _rng_image((20, 20)), params={"p": 1.5})


def test_neighbourhood_larger_than_the_exemplar_is_a_clear_error() -> None:
    with pytest.raises(InvalidParameter, match="no neighbourhood fits inside the exemplar"):
        synthesize(
            "wei-levoy", _rng_image((16, 16)), size=(16, 16), params={"neighbourhood_size": 21, "levels": 1}
        )


def test_unknown_method_and_bad_size_and_seed() -> None:
    with pytest.raises(InvalidParameter, match="unknown method"):
        synthesize("nope", _rng_image((16, 16)))
    with pytest.raises(InvalidParameter, match="size"):
        synthesize("wei-levoy", _rng_image((16, 16)), size=(4, 4))
    with pytest.raises(InvalidParameter, match="seed"):
        synthesize("wei-levoy", _rng_image((16, 16)), seed=-1)


def test_progress_reaches_one_often_and_in_order() -> None:
    seen: list[tuple[str, float]] = []
    synthesize(
        "tensor-constrained",
        _rng_image((32, 32)),
        size=(32, 32),
        params={"neighbourhood_size": 5, "structure_levels": 2, "parent_size": 3},
        progress=lambda stage, f: seen.append((stage, f)),
    )
    fractions = [f for _, f in seen]
    assert fractions == sorted(fractions)
    assert fractions[-1] == 1.0
    assert max(np.diff([0.0, *fractions])) <= 0.02
    assert any(s.startswith("structure") for s, _ in seen) and any(s.startswith("texture") for s, _ in seen)


def test_a_progress_callback_that_raises_cancelled_stops_the_run() -> None:
    def stop(stage: str, fraction: float) -> None:
        if fraction > 0.1:
            raise Cancelled("job cancelled")

    with pytest.raises(Cancelled, match="job cancelled"):
        synthesize(
            "wei-levoy", _rng_image((32, 32)), size=(32, 32), params={"neighbourhood_size": 5}, progress=stop
        )


def test_a_bug_in_a_progress_callback_is_not_mistaken_for_a_cancel() -> None:
    def broken(stage: str, fraction: float) -> None:
        raise KeyError("a bug in the caller")

    with pytest.raises(KeyError, match="a bug in the caller"):
        synthesize(
            "wei-levoy",
            _rng_image((32, 32)),
            size=(32, 32),
            params={"neighbourhood_size": 5},
            progress=broken,
        )


def test_structure_neighbourhood_changes_only_the_structure_stage() -> None:
    ex = _rng_image((40, 40), seed=4)
    base = {"neighbourhood_size": 5, "structure_levels": 2, "parent_size": 3}
    causal = synthesize("tensor-constrained", ex, size=(24, 24), seed=1, params=base)
    square = synthesize(
        "tensor-constrained", ex, size=(24, 24), seed=1, params=base | {"structure_neighbourhood": "square"}
    )
    assert square.params["structure_neighbourhood"] == "square" and square.params["neighbourhood"] == "causal"
    assert causal.tensor_field.tobytes() != square.tensor_field.tobytes()
    with pytest.raises(InvalidParameter, match="structure_neighbourhood"):
        synthesize("tensor-constrained", ex, params={"structure_neighbourhood": "round"})


# ---------------------------------------------------------------- histogram matching


def _usage(src: np.ndarray, shape: tuple[int, int], border: int) -> np.ndarray:
    """How often each copyable exemplar position is copied."""
    counts = np.bincount((src[..., 0] * shape[1] + src[..., 1]).ravel(), minlength=shape[0] * shape[1])
    return counts.reshape(shape)[border:-border, border:-border]


def test_position_histogram_spreads_the_use_of_exemplar_positions() -> None:
    """Chen & Wang's position histogram: no exemplar position is copied far more than its share."""
    ex = _rng_image((20, 20, 1), seed=13)
    plain = SearchSettings(size=3, levels=1, iterations=2, search="exact")
    runs = {
        w: synthesize_source_map([ex], [(36, 36)], replace(plain, histogram_weight=w), seed=2)[0][0]
        for w in (0.0, 20.0)
    }
    share = 36 * 36 / (18 * 18)  # output pixels per copyable position
    plain_use, matched_use = (_usage(runs[w], (20, 20), 1) for w in (0.0, 20.0))
    assert plain_use.sum() == matched_use.sum() == 36 * 36
    assert plain_use.std() > 10 * share  # smooth noise: plain search copies a few positions over and over
    assert matched_use.std() < share / 2
    assert (matched_use == 0).mean() < 0.1


def test_labelled_histogram_pulls_the_output_toward_the_target_fractions() -> None:
    """Labels = dark/bright exemplar pixels, target 50/50 although the exemplar is 80% dark."""
    rng = np.random.default_rng(3)
    ex = (np.where(rng.random((24, 24)) < 0.8, 0.0, 0.6) + 0.4 * rng.random((24, 24))).astype(np.float32)
    ex = ex[..., None]
    labels = (ex[..., 0] > 0.5).astype(np.int64)
    settings = SearchSettings(size=3, levels=1, iterations=2, search="exact", histogram_weight=50.0)
    bright = {}
    for name, s in {"plain": replace(settings, histogram_weight=0.0), "matched": settings}.items():
        src = synthesize_source_map([ex], [(32, 32)], s, seed=1, histogram=[(labels, np.array([0.5, 0.5]))])[
            0
        ][0]
        bright[name] = float(labels[src[..., 0], src[..., 1]].mean())
    assert bright["plain"] < 0.3
    assert 0.4 < bright["matched"] < 0.6


def test_structure_histogram_option_selects_the_matching() -> None:
    ex = _rng_image((40, 40), seed=4)
    base = {"neighbourhood_size": 5, "structure_levels": 2, "parent_size": 3}
    fields = {
        h: synthesize(
            "tensor-constrained", ex, size=(24, 24), seed=1, params=base | {"structure_histogram": h}
        )
        for h in ("none", "position", "orientation")
    }
    assert fields["orientation"].params["structure_histogram_weight"] == 10.0
    assert len({r.tensor_field.tobytes() for r in fields.values()}) == 3
    unweighted = synthesize(
        "tensor-constrained", ex, size=(24, 24), seed=1, params=base | {"structure_histogram_weight": 0.0}
    )
    assert unweighted.tensor_field.tobytes() == fields["none"].tensor_field.tobytes()
    with pytest.raises(InvalidParameter, match="structure_histogram"):
        synthesize("tensor-constrained", ex, params={"structure_histogram": "colour"})


def test_orientation_labels_bin_the_field_and_sum_to_one() -> None:
    from texsynth.synth.io.patterns import grating
    from texsynth.synth.methods.tensor_constrained import orientation_labels

    tensors = structure_tensor(grating((32, 32), period=8, angle=np.pi / 4))
    labels, fractions = orientation_labels(tensors, bins=36)
    assert labels.shape == (32, 32) and fractions.sum() == pytest.approx(1.0)
    assert np.argmax(fractions) in (26, 27)  # gradient at 45 degrees + 90 = 135/5 = bin 27 (edge: 26)


# ---------------------------------------------------------------- per-position candidate window


def test_candidate_window_restricts_every_copied_position() -> None:
    ex = _rng_image((22, 22, 1), seed=15)
    window = _striped_window((22, 22), (12, 10), 0)
    settings = SearchSettings(size=3, levels=1, iterations=2, search="exact")
    src = synthesize_source_map([ex], [(12, 10)], settings, seed=1, window=window)[0][0]
    got = window.ex_levels[0][src[..., 0], src[..., 1]]
    np.testing.assert_array_equal(got, window.out_levels[0])


@pytest.mark.parametrize("side", [12, 16, 24, 40])
def test_the_neighbourhood_precheck_fails_exactly_when_the_run_would(side: int) -> None:
    """``check_neighbourhoods_fit`` (shapes only, used before queueing) says what the driver would say."""
    from texsynth.synth.errors import SynthError
    from texsynth.synth.pixel.synthesis import check_neighbourhoods_fit

    ex = np.random.default_rng(0).random((side, side)).astype(np.float32)
    params = {"levels": 4, "neighbourhood_size": 5, "parent_size": 3}
    try:
        check_neighbourhoods_fit(ex.shape, 4, 5, 3)
        before = None
    except SynthError as exc:
        before = str(exc)
    try:
        synthesize("wei-levoy", ex, size=(16, 16), params=params, seed=0)
        during = None
    except SynthError as exc:
        during = str(exc)
    assert before == during


# ---------------------------------------------------------------- transfer between classes


def test_class_transfer_continues_coherent_copying_across_classes() -> None:
    """Every output row wants another copy of the same tile: without the transfer the neighbours'
    coherent proposals (from the row above, another copy) are dropped; with it they are moved into the
    wanted copy, so the output copies the tile coherently in the tile's own frame, and every copied
    position lies in its wanted class."""
    tile = _rng_image((24, 24, 1), seed=17)
    shares = {}
    for transfer in (False, True):
        ex, window = _tiled_window(tile, 4, (16, 16), 4)
        if not transfer:
            window = replace(window, transfer_levels=None)
        settings = SearchSettings(size=5, levels=1, iterations=2, k=0, random_candidates=2)
        src = synthesize_source_map([ex], [(16, 16)], settings, seed=3, window=window)[0][0]
        in_class = window.ex_levels[0][src[..., 0], src[..., 1]] == window.out_levels[0]
        # without the transfer, a position whose every proposal was dropped keeps its initial source
        assert in_class.all() if transfer else in_class.mean() > 0.95
        own = src.copy()
        own[..., 1] %= 24  # the tile's own frame
        shares[transfer] = float(np.mean(np.all(own[1:] - own[:-1] == [1, 0], axis=-1)))
    assert shares[True] > 0.5 > shares[False] + 0.3, shares


# ---------------------------------------------------------------- falloff and square refinement


def test_entry_weights_are_a_gaussian_of_the_side_with_mean_one() -> None:
    offs = neighbourhood_offsets(13, "causal")
    assert entry_weights(offs, 13, 0.0).shape == (0,)  # flat: every entry weighs 1
    w = entry_weights(offs, 13, 1 / 6.4)
    assert w.mean() == pytest.approx(1.0)
    sigma = 13 / 6.4
    r2 = (offs.astype(float) ** 2).sum(axis=1)
    np.testing.assert_allclose(w / w.max(), np.exp(-(r2 - r2.min()) / (2 * sigma**2)), rtol=1e-12)
    assert w[np.argmin(r2)] > 5 * w[np.argmax(r2)]  # the nearest entries dominate the farthest


def test_falloff_makes_the_nearest_neighbours_decide() -> None:
    """A causal 5 x 5 neighbourhood whose near entries agree with one candidate and far ones with another:
    flat weights pick the far-agreeing one, a steep falloff the near-agreeing one."""
    ex = np.zeros((12, 12, 1), np.float32)
    ex[:, 6:, 0] = 1.0  # region A: 0, region B: 1
    out = np.full((9, 9, 1), np.nan, np.float32)
    offs = neighbourhood_offsets(5, "causal")
    near = (np.abs(offs) <= 1).all(axis=1)
    # the output: near entries 0 (as region A), far entries 1 (as region B), which outnumber them
    for (dy, dx), is_near in zip(offs, near, strict=True):
        out[4 + dy, 4 + dx, 0] = 0.0 if is_near else 1.0
    done = np.zeros((9, 9), np.uint8)
    done[~np.isnan(out[..., 0])] = 1
    picks = {}
    for falloff in (0.0, 0.1):
        state = SearchState(
            cur=Part(out.copy(), ex, offs, METRIC_SSD, 1.0, entry_weights(offs, 5, falloff)),
            par=Part(
                np.zeros((1, 1, 1), np.float32), np.zeros((1, 1, 1), np.float32), parent_offsets(3), 0, 0.0
            ),
            gui=Part(
                np.zeros((1, 1, 3), np.float32),
                np.zeros((1, 1, 3), np.float32),
                np.zeros((0, 2), np.int32),
                0,
                0.0,
            ),
            alpha=0.5,
            cands=Candidates(
                src=np.zeros((9, 9, 2), np.int64),
                hint=np.zeros((9, 9, 2), np.int64),
                use_hint=False,
                valid=np.array([2, 10, 2, 10], np.int64),
                mask=np.ones((12, 12), np.uint8),
                kset=np.full((1, 1, 0, 2), -1, np.int64),
                cand_offs=np.zeros((1, 2), np.int32),
                exact=True,
                n_random=0,
                capacity=4,
            ),
            hist=Histogram(np.zeros(144, np.int64), np.array([144], np.int64), np.array([144.0]), 0.0),
            win=ClassWindow(np.zeros(1, np.int64), np.zeros((1, 1), np.int64), 1, -1),
            run=Pass(
                np.array([4 * 9 + 4], np.int64),
                True,
                done.copy(),
                np.uint64(1),
                np.zeros(144, np.int64),
                np.zeros(1, np.int64),
                np.zeros((9, 9), np.float32),
            ),
        )
        synthesize_chunk(state, 0, 1)
        picks[falloff] = float(ex[state.cands.src[4, 4, 0], state.cands.src[4, 4, 1], 0])
    assert picks == {0.0: 1.0, 0.1: 0.0}


@pytest.mark.parametrize(
    ("refine", "size", "side"), [(False, 0, None), (True, 0, 7), (True, 5, 5), (True, 9, 7)]
)
def test_refinement_passes_compare_the_square_of_refine_size(
    refine: bool, size: int, side: int | None
) -> None:
    """The refinement passes compare the full square of ``refine_size`` (at most the neighbourhood's side),
    every neighbour proposing candidates; without ``refine_square`` they keep the causal L-shape."""
    ex = _rng_image((24, 24, 1), seed=3)
    settings = SearchSettings(size=7, levels=1, iterations=2, refine_square=refine, refine_size=size)
    seen = {}
    synthesize_source_map(
        [ex], [(16, 16)], settings, seed=1, on_level_done=lambda level, state: seen.update(state=state)
    )
    state = seen["state"]
    if side is None:
        np.testing.assert_array_equal(state.cur.offsets, neighbourhood_offsets(7, "causal"))
        assert len(state.cands.cand_offs) == 5  # the pixel and its 4 causal neighbours
    else:
        np.testing.assert_array_equal(state.cur.offsets, neighbourhood_offsets(side, "square"))
        assert len(state.cands.cand_offs) == 9  # the pixel and its 8 neighbours
        assert len(state.gui.offsets) == 0 or len(state.gui.offsets) == side * side


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"falloff": -0.1}, "falloff"),
        ({"refinement": "round"}, "refinement"),
        ({"refinement": "square", "refinement_size": 8}, "refinement_size"),
    ],
)
def test_falloff_and_refinement_parameters_are_checked(params: dict, field: str) -> None:
    for method in ("wei-levoy", "tensor-constrained"):
        with pytest.raises(InvalidParameter, match=field):
            synthesize(method, _rng_image((20, 20)), size=(16, 16), params=params)


def test_texture_histogram_weight_is_checked_and_matters() -> None:
    with pytest.raises(InvalidParameter, match="texture_histogram_weight"):
        synthesize("tensor-constrained", _rng_image((20, 20)), params={"texture_histogram_weight": -1})
    ex = _rng_image((32, 32), seed=8)
    runs = [
        synthesize(
            "tensor-constrained",
            ex,
            size=(40, 40),
            seed=2,
            params={"neighbourhood_size": 5, "structure_levels": 2, "texture_histogram_weight": w},
        ).extras["source_map"]
        for w in (0.0, 20.0)
    ]
    use = [np.bincount((s[..., 0] * 32 + s[..., 1]).ravel(), minlength=32 * 32) for s in runs]
    assert use[1].max() < use[0].max()  # matched: no position copied as often as the plain search's most used


@pytest.mark.parametrize(
    ("params", "field"), [({"kset_size": 8}, "kset_size"), ({"kset_dims": 0}, "kset_dims")]
)
def test_kset_parameters_are_checked(params: dict, field: str) -> None:
    with pytest.raises(InvalidParameter, match=field):
        synthesize("wei-levoy", _rng_image((20, 20)), size=(16, 16), params=params)


def test_kset_parameters_reach_the_k_coherence_sets(monkeypatch: pytest.MonkeyPatch) -> None:
    import texsynth.synth.pixel.synthesis as core

    seen: list[tuple[int, int]] = []
    real = core.k_coherence_sets

    def spy(*args, **kwargs):  # type: ignore[no-untyped-def]
        seen.append((args[5], args[6]))
        return real(*args, **kwargs)

    monkeypatch.setattr(core, "k_coherence_sets", spy)
    params = {"kset_size": 5, "kset_dims": 3, "neighbourhood_size": 7, "levels": 1}
    synthesize("wei-levoy", _rng_image((24, 24)), size=(16, 16), params=params)
    assert seen == [(5, 3)]


def test_issue13_defaults_and_the_earlier_settings_differ() -> None:
    """The issue-13 defaults are departures; the earlier settings stay reachable by parameters."""
    from texsynth.synth.methods.tensor_constrained import TensorConstrainedParams
    from texsynth.synth.methods.wei_levoy import WeiLevoyParams

    wl, tc = WeiLevoyParams(), TensorConstrainedParams()
    assert (wl.levels, wl.falloff, wl.refinement, wl.kset_size, wl.kset_dims) == (2, 0.156, "square", 7, 8)
    # falloff None: 0.156 (issue 13's value) unless the exemplar is crossed and oriented (brick-stubs work).
    assert (tc.k, tc.p, tc.falloff, tc.refinement, tc.refinement_size, tc.texture_histogram_weight) == (
        2,
        0.8,
        None,
        "square",
        None,
        3.0,
    )
    ex = _rng_image((32, 32), seed=9)
    old = {"levels": 3, "falloff": 0.0, "refinement": "same", "kset_size": 9, "kset_dims": 16}
    a = synthesize("wei-levoy", ex, size=(24, 24), seed=1, params={**old, "neighbourhood_size": 7})
    b = synthesize("wei-levoy", ex, size=(24, 24), seed=1, params={"neighbourhood_size": 7})
    assert a.image.tobytes() != b.image.tobytes()


def test_periodic_wei_levoy_gets_a_third_pass_unless_told() -> None:
    from texsynth.synth.methods.wei_levoy import WeiLevoyParams

    assert WeiLevoyParams().iterations == 2
    assert WeiLevoyParams(periodic=True).iterations == 3
    assert WeiLevoyParams(periodic=True, iterations=2).iterations == 2


def test_tensor_constrained_refinement_size_follows_the_exemplars_orientation() -> None:
    """``refinement_size=None``: the whole neighbourhood for strongly oriented exemplars, 7 for weak ones,
    and the run records the side it used; an explicit side is kept."""
    from texsynth.synth.analysis.tensor import structure_tensor
    from texsynth.synth.methods.tensor_constrained import TensorConstrainedParams, refinement_size_for

    y, x = np.mgrid[0:48, 0:48]
    stripes = (0.5 + 0.5 * np.sin(2 * np.pi * (x + 0.3 * y) / 6.0)).astype(np.float32)
    noise = _rng_image((48, 48), seed=4)
    params = TensorConstrainedParams(neighbourhood_size=9)
    assert refinement_size_for(structure_tensor(stripes), params) == 9
    assert refinement_size_for(structure_tensor(noise), params) == 7
    common = {"neighbourhood_size": 9, "structure_levels": 2, "texture_levels": 1}
    ran = synthesize("tensor-constrained", stripes, size=(32, 32), seed=1, params=common)
    assert ran.params["refinement_size"] == 9
    ran = synthesize("tensor-constrained", noise, size=(32, 32), seed=1, params=common)
    assert ran.params["refinement_size"] == 7
    kept = synthesize(
        "tensor-constrained", noise, size=(32, 32), seed=1, params={**common, "refinement_size": 5}
    )
    assert kept.params["refinement_size"] == 5


def test_tensor_constrained_falloff_is_flat_only_for_crossed_oriented_exemplars() -> None:
    """``falloff=None``: flat for an oriented exemplar with structures in two directions (brick's joints),
    0.156 for one-directional stripes and for weakly oriented noise; the run records the value it used and
    an explicit falloff is kept."""
    from texsynth.synth.analysis.tensor import cross_orientation_fraction, structure_tensor
    from texsynth.synth.methods.tensor_constrained import DEFAULT_FALLOFF, falloff_for

    y, x = np.mgrid[0:48, 0:48]
    stripes = (0.5 + 0.5 * np.sin(2 * np.pi * (x + 0.3 * y) / 6.0)).astype(np.float32)
    from skimage import data as skdata

    bricks = skdata.brick()[:128, :128].astype(np.float32) / 255.0  # bench_quality's brick crop
    noise = _rng_image((48, 48), seed=4)
    assert cross_orientation_fraction(structure_tensor(stripes)) < 0.01
    assert cross_orientation_fraction(structure_tensor(bricks)) > 0.1
    assert falloff_for(structure_tensor(bricks)) == 0.0
    assert falloff_for(structure_tensor(stripes)) == DEFAULT_FALLOFF
    assert falloff_for(structure_tensor(noise)) == DEFAULT_FALLOFF
    common = {"neighbourhood_size": 9, "structure_levels": 2, "texture_levels": 1}
    assert (
        synthesize("tensor-constrained", stripes, size=(32, 32), seed=1, params=common).params["falloff"]
        == DEFAULT_FALLOFF
    )
    kept = synthesize("tensor-constrained", noise, size=(32, 32), seed=1, params={**common, "falloff": 0.3})
    assert kept.params["falloff"] == 0.3


def test_brick_seam_defaults_and_the_earlier_settings_differ() -> None:
    """The brick-seam defaults (LE metric, pixel-only refinement passes, texture histogram weight 3) are
    departures; ``metric='SO', refinement_p=None, texture_histogram_weight=10`` restore the earlier run."""
    from texsynth.synth.methods.tensor_constrained import TensorConstrainedParams

    tc = TensorConstrainedParams()
    assert (tc.metric, tc.refinement_p, tc.texture_histogram_weight) == ("LE", 1.0, 3.0)
    ex = _rng_image((40, 40), seed=3)
    common = {"neighbourhood_size": 7, "structure_levels": 2, "parent_size": 3}
    old = {**common, "metric": "SO", "refinement_p": None, "texture_histogram_weight": 10.0}
    a = synthesize("tensor-constrained", ex, size=(32, 32), seed=1, params=old)
    b = synthesize("tensor-constrained", ex, size=(32, 32), seed=1, params=common)
    assert a.image.tobytes() != b.image.tobytes()


@pytest.mark.parametrize("value", [-0.1, 1.5])
def test_refinement_p_is_checked(value: float) -> None:
    with pytest.raises(InvalidParameter, match="refinement_p"):
        synthesize("tensor-constrained", _rng_image((40, 40)), size=(24, 24), params={"refinement_p": value})


@pytest.mark.parametrize("search", ["exact", "kcoherence"])
def test_kernel_matches_reference_with_pixel_only_refinement(search: str) -> None:
    """``refine_p=1``: the square refinement passes drop the guidance part (weight 0); kernel and
    reference agree, and the run differs from one whose refinement keeps eq 13's weights."""
    ex = _rng_image((24, 24), seed=5)
    feats, code = tensor_features(structure_tensor(ex), "LE")
    out_tensors = structure_tensor(_rng_image((12, 12), seed=6), mode="wrap")
    guidance = Guidance(
        out_levels=[tensor_features(out_tensors, "LE")[0]], ex_levels=[feats], metric=code, weight=0.4, size=3
    )
    base = {"size": 5, "levels": 1, "iterations": 2, "search": search, "k": 2, "refine_square": True}
    kwargs = {"ex_levels": [ex[..., None]], "out_shapes": [(12, 12)], "p": 0.6, "guidance": guidance}
    kwargs["seed"] = 2
    _run_both(settings=SearchSettings(**base, refine_p=1.0), **kwargs)  # type: ignore[arg-type]
    same = synthesize_source_map(settings=SearchSettings(**base), **kwargs)[0][0]  # type: ignore[arg-type]
    # refine_p equal to p weighs the refinement as refine_p=None does: the same bytes
    alike = synthesize_source_map(settings=SearchSettings(**base, refine_p=0.6), **kwargs)[0][0]  # type: ignore[arg-type]
    pixels = synthesize_source_map(settings=SearchSettings(**base, refine_p=1.0), **kwargs)[0][0]  # type: ignore[arg-type]
    np.testing.assert_array_equal(same, alike)
    assert same.tobytes() != pixels.tobytes()


def test_initial_source_map_starts_the_synthesis_and_every_pass_refines() -> None:
    """``initial``: the output starts from the given sources and every pass compares the square in a
    random order; started from the exemplar itself (each neighbourhood matches its own), the interior
    (away from the output's wrapped borders) stays the exemplar, kernel and reference alike; without
    ``initial`` it does not."""
    ex = np.random.default_rng(0).random((24, 24, 1)).astype(np.float32)
    ident = np.stack(np.mgrid[0:24, 0:24], axis=-1).astype(np.int64)
    settings = SearchSettings(size=5, shape="square", scan="random", iterations=1, k=2, refine_square=True)
    inner = (slice(4, 20), slice(4, 20))
    kept = []
    for run in (synthesize_source_map, synthesize_with_reference):
        srcs, _ = run(ex_levels=[ex], out_shapes=[(24, 24)], settings=settings, seed=1, initial=[ident])
        kept.append(srcs[0])
        assert (srcs[0][inner] == ident[inner]).all(axis=-1).mean() > 0.95
    np.testing.assert_array_equal(kept[0], kept[1])
    srcs, _ = synthesize_source_map([ex], [(24, 24)], settings, seed=1)
    assert (srcs[0][inner] == ident[inner]).all(axis=-1).mean() < 0.1


@pytest.mark.parametrize("metric", ["ED", "FN", "LE", "SO"])
def test_tensor_features_in_bands_on_threads_give_the_bytes_of_one_call(metric: str) -> None:
    """A large field is computed in bands of rows on the job's threads: the same bytes with 1, 2 and 4."""
    from texsynth.synth.threads import max_threads, use_threads

    field = structure_tensor(_rng_image((300, 77), seed=3))
    got = []
    for threads in (1, 2, 4):
        with use_threads(min(threads, max_threads())):
            feats, code = tensor_features(field, metric)  # type: ignore[arg-type]
        assert feats.shape == (300, 77, 4 if metric == "SO" else 3) and feats.flags.c_contiguous
        got.append((feats.tobytes(), code))
    assert got[0] == got[1] == got[2]


def test_k_coherence_sets_are_the_exact_nearest_neighbours() -> None:
    """The k-d tree answers what a brute-force search answers: each
    position's k nearest other positions of the projected neighbourhoods, nearest first."""
    from texsynth.synth.pixel.synthesis import k_coherence_sets, kset_points

    feats = _rng_image((40, 44), seed=5)[..., None].astype(np.float32)
    valid = np.array([3, 37, 3, 41], dtype=np.int64)
    mask = np.ones(feats.shape[:2], dtype=np.uint8)
    mask[10:14, 20:30] = 0
    embeds = [(feats, 0.25)]
    k = 6
    kset = k_coherence_sets(embeds, 7, valid, k, mask, kset_size=7, kset_dims=5)
    points = kset_points(embeds, 7, valid, mask, kset_size=7, kset_dims=5)
    yy, xx = np.nonzero(mask[3:37, 3:41])
    d = ((points[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    np.fill_diagonal(d, np.inf)
    near = np.argsort(d, axis=1, kind="stable")[:, :k]
    assert np.array_equal(kset[3 + yy, 3 + xx, :, 0], 3 + yy[near])
    assert np.array_equal(kset[3 + yy, 3 + xx, :, 1], 3 + xx[near])
    assert np.all(kset[10:14, 20:30] == -1)  # masked positions have no set


@pytest.mark.parametrize("data", ["smooth", "duplicates", "grid"])
def test_nearest_points_fast_path_is_the_default_trees_answer(data: str) -> None:
    """The large-leaf tree with the tied rows searched again gives SciPy's default tree's indices, row
    for row and in the same order, also where many distances are equal (duplicated points, points on
    an integer grid, each once: many neighbours at the same distance, where the trees order ties
    differently)."""
    from scipy.spatial import cKDTree

    from texsynth.synth.pixel import synthesis as core

    rng = np.random.default_rng(11)
    if data == "smooth":
        points = rng.normal(size=(3000, 8))
    elif data == "duplicates":
        points = np.repeat(rng.normal(size=(300, 8)), rng.integers(1, 20, size=300), axis=0)
    else:
        points = rng.permutation(np.indices((7, 7, 7, 7)).reshape(4, -1).T).astype(np.float64)
    for kk in (3, 11):
        want = cKDTree(points).query(points, k=kk)[1]
        fast = cKDTree(points, leafsize=core._KSET_LEAF).query(points, k=kk)[1]
        got = core._nearest_points(points, kk)
        assert np.array_equal(got, want)
        if data != "smooth":  # the case the second search is for: the larger leaves order ties otherwise
            assert not np.array_equal(fast, want)


@pytest.mark.parametrize("holes", [False, True])
def test_kset_points_are_the_plain_weighted_neighbourhoods_bit_for_bit(holes: bool) -> None:
    """kset_points writes each embedding's square neighbourhoods, times the square root of its weight, into
    one array: the same float64 values, bit for bit, as weighing, joining and selecting them one copy after
    the other (the sets, and so the bytes of every output, depend on them)."""
    from texsynth.synth.pixel import synthesis as core

    pixels = _rng_image((40, 44), seed=2)[..., None].astype(np.float32)
    tensors = np.random.default_rng(3).normal(size=(40, 44, 3)).astype(np.float32)
    embeds = [(pixels, 0.2391258691254927), (tensors, 0.00142571254244501)]
    valid = np.array([3, 37, 3, 41], dtype=np.int64)
    mask = np.ones(pixels.shape[:2], dtype=np.uint8)
    if holes:
        mask[10:14, 20:30] = 0
    inside = mask[3:37, 3:41].ravel() != 0
    plain = np.concatenate([np.sqrt(w) * core._square_vectors(e, 7, valid) for e, w in embeds], axis=1)
    plain = plain[inside].astype(np.float64)
    plain -= plain.mean(axis=0)
    sample = plain[:: max(1, len(plain) // core._PCA_SAMPLE)]
    want = plain @ np.linalg.eigh(sample.T @ sample)[1][:, ::-1][:, :8]
    got = core.kset_points(embeds, 9, valid, mask, kset_size=7, kset_dims=8)
    assert got.dtype == np.float64 and np.array_equal(got, want)


@pytest.mark.parametrize("guided", [False, True])
def test_sets_made_ahead_are_the_sets_the_run_makes(guided: bool) -> None:
    """:func:`sets_ahead` on its own thread gives the coarsest level's k-coherence sets bit for bit, and a
    run handed them gives the same source maps as one that makes them itself."""
    rng = np.random.default_rng(3)
    ex = [rng.random((32, 32, 1), dtype=np.float32), rng.random((16, 16, 1), dtype=np.float32)]
    settings = SearchSettings(size=5, levels=2, iterations=2, k=3)
    guidance = None
    if guided:
        tens = [rng.random((32, 32, 3), dtype=np.float32), rng.random((16, 16, 3), dtype=np.float32)]
        guidance = Guidance(out_levels=(), ex_levels=tens, metric=METRIC_SSD, weight=0.4, size=5)
    kept: dict[int, np.ndarray] = {}
    out = [rng.random((24, 24, 3), dtype=np.float32), rng.random((12, 12, 3), dtype=np.float32)]
    guide = replace(guidance, out_levels=out) if guidance is not None else None

    def run(sets=None):
        return synthesize_source_map(
            ex,
            [(24, 24), (12, 12)],
            settings,
            p=0.6,
            guidance=guide,
            seed=9,
            coarsest_sets=sets,
            on_level_done=lambda level, state: kept.setdefault(level, state.cands.kset.copy()),
        )[0]

    plain = run()
    made = kept.pop(1)
    kept.clear()
    ahead = sets_ahead(ex, settings, p=0.6, guidance=guidance, seed=9)
    sets = ahead()
    assert sets.dtype == made.dtype and np.array_equal(sets, made)
    assert (sets >= 0).any()
    handed = run(lambda: sets)
    assert all(np.array_equal(a, b) for a, b in zip(plain, handed, strict=True))


def test_an_error_while_making_sets_ahead_is_raised_by_the_wait() -> None:
    ex = [np.zeros((6, 6, 1), dtype=np.float32)]  # no 9 x 9 neighbourhood fits
    wait = sets_ahead(ex, SearchSettings(size=9, levels=1), seed=1)
    with pytest.raises(InvalidParameter, match="neighbourhood_size"):
        wait()
