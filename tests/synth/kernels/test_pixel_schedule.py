"""The parallel form of a pixel pass (issue 25): levels of positions that never touch each other's data
(:func:`texsynth.synth.kernels.pixel_search.schedule_levels`) against their plain reference, a raster pass
in tiles (:func:`texsynth.synth.kernels.pixel_search.tile_schedule`), the properties that make them safe,
and the pass run by levels giving the sequential pass's bytes."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from tests.synth.search_cases import _rng_image
from texsynth.synth.grid.neighbourhood import neighbourhood_offsets
from texsynth.synth.kernels.pixel_search import (
    _block_edge,
    _offset_runs,
    _unit_levels_kernel,
    _unit_levels_reference,
    conflict_offsets,
    schedule_levels,
    schedule_levels_reference,
    synthesize_chunk,
    synthesize_levels,
    tile_schedule,
    tile_units,
)
from texsynth.synth.pixel.synthesis import SearchSettings, synthesize_source_map

_CAND = np.vstack([[0, 0], neighbourhood_offsets(3, "square")])


def _cases() -> list[tuple[tuple[int, int], np.ndarray, np.ndarray]]:
    square = neighbourhood_offsets(5, "square")
    out = []
    for shape in [(9, 11), (16, 16), (5, 23)]:
        rand = np.random.default_rng(shape[0]).permutation(shape[0] * shape[1])
        out.append((shape, rand, conflict_offsets(square, _CAND)))
    return out


def _levels_of(schedule, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each position's level and unit."""
    level, unit = np.full(n, -1, np.int64), np.full(n, -1, np.int64)
    for lv in range(len(schedule.starts) - 1):
        for u in range(schedule.starts[lv], schedule.starts[lv + 1]):
            at = schedule.sched[schedule.units[u] : schedule.units[u + 1]]
            level[at], unit[at] = lv, u
    return level, unit


@pytest.mark.parametrize(("shape", "order", "offsets"), _cases())
def test_levels_match_the_reference_and_never_hold_two_neighbours(
    shape: tuple[int, int], order: np.ndarray, offsets: np.ndarray
) -> None:
    got = schedule_levels(order, shape, offsets, tag0=7)
    ref = schedule_levels_reference(order, shape, offsets, tag0=7)
    np.testing.assert_array_equal(got.sched, ref.sched)
    np.testing.assert_array_equal(got.starts, ref.starts)
    np.testing.assert_array_equal(got.units, np.arange(len(order) + 1))  # a unit is one position
    assert got.tag0 == 7
    assert sorted(got.sched.tolist()) == list(range(shape[0] * shape[1]))  # every position once
    H, W = shape
    rank = np.empty(H * W, np.int64)
    rank[order] = np.arange(len(order))
    level, _ = _levels_of(got, H * W)
    for p in range(H * W):
        y, x = divmod(p, W)
        for dy, dx in offsets:
            q = ((y + dy) % H) * W + (x + dx) % W
            if q != p:  # neighbours keep the pass's order, so never share a level
                assert (level[q] < level[p]) == (rank[q] < rank[p])
                assert level[q] != level[p]


@pytest.mark.parametrize(("shape", "side"), [((9, 11), 7), ((24, 40), 9), ((5, 23), 5), ((26, 13), 7)])
def test_tiles_keep_the_raster_order_and_never_share_data_within_a_level(
    shape: tuple[int, int], side: int
) -> None:
    """Two positions of different tiles of one level never touch each other's data; every causal entry
    that does not cross the border comes first, as in a raster scan; a tile is one unit in raster order."""
    causal = neighbourhood_offsets(side, "causal")
    causal_cand = _CAND[(_CAND[:, 0] < 0) | ((_CAND[:, 0] == 0) & (_CAND[:, 1] <= 0))]
    offsets = conflict_offsets(causal, causal_cand)
    H, W = shape
    got = tile_schedule(shape, offsets, tile=(3, 8), tag0=3)
    unit_of = tile_units(shape, offsets, (3, 8))
    levels = _unit_levels_reference(unit_of, shape, offsets)  # the plain version of the levels
    np.testing.assert_array_equal(
        _unit_levels_kernel(unit_of, shape[0], shape[1], _offset_runs(offsets), len(levels)), levels
    )
    assert len(got.starts) - 1 == levels.max() + 1
    assert got.tag0 == 3
    assert sorted(got.sched.tolist()) == list(range(H * W))
    rank = np.empty(H * W, np.int64)
    rank[got.sched] = np.arange(H * W)
    level, unit = _levels_of(got, H * W)
    for u in range(len(got.units) - 1):  # a unit: a rectangle in raster order
        at = got.sched[got.units[u] : got.units[u + 1]]
        assert np.all(np.diff(at) > 0)
    for p in range(H * W):
        y, x = divmod(p, W)
        for dy, dx in offsets:
            q = ((y + dy) % H) * W + (x + dx) % W
            if q != p and unit[q] != unit[p]:
                assert level[q] != level[p]
                assert (level[q] < level[p]) == (rank[q] < rank[p])
        for dy, dx in causal:
            if y + dy >= 0 and 0 <= x + dx < W:  # not across the border
                assert rank[(y + dy) * W + x + dx] < rank[p]


@pytest.mark.parametrize("seed", range(6))
def test_unit_levels_by_row_segments_match_the_reference_on_any_units_and_offsets(seed: int) -> None:
    """The kernel's row-segment form against the per-position reference: scattered offsets (gaps inside a
    row, reaches wider than the output: wrapped more than once) and units that are not tiles (several
    segments of one unit in a row)."""
    rng = np.random.default_rng(seed)
    shape = (int(rng.integers(3, 20)), int(rng.integers(3, 20)))
    offsets = conflict_offsets(rng.integers(-25, 26, size=(int(rng.integers(1, 12)), 2)))
    if len(offsets) == 0:
        offsets = np.array([[0, 1], [0, -1]], dtype=np.int64)
    blocks = rng.integers(0, 7, size=(shape[0], (shape[1] + 2) // 3))
    unit_of = np.unique(np.repeat(blocks, 3, axis=1)[:, : shape[1]].ravel(), return_inverse=True)[1]
    levels = _unit_levels_reference(unit_of, shape, offsets)
    got = _unit_levels_kernel(
        unit_of.astype(np.int64), shape[0], shape[1], _offset_runs(offsets), len(levels)
    )
    np.testing.assert_array_equal(got, levels)


def test_tiles_make_few_levels_of_much_work() -> None:
    """A 512^2 pass: fewer than 300 levels (one barrier each) of more than 800 positions on average (a
    skewed wavefront had about 3000 of 90); a raster scan across the wrap, by levels, is one chain."""
    causal = neighbourhood_offsets(9, "causal")
    offsets = conflict_offsets(causal, _CAND[:5])
    tiles = tile_schedule((512, 512), offsets)  # TILE: 4 rows by 24
    assert len(tiles.starts) - 1 < 300
    assert 512 * 512 / (len(tiles.starts) - 1) > 800
    raster = schedule_levels(np.arange(64 * 64), (64, 64), offsets).starts
    assert len(raster) - 1 == 64 * 64


@pytest.mark.parametrize("shape", ["causal", "square"])
def test_a_pass_by_levels_gives_the_sequential_pass_bytes(
    shape: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without histogram matching the levels change nothing: the same bytes as one position after another
    (every level on the thread pool, however small)."""
    import texsynth.synth.kernels.pixel_search as search

    monkeypatch.setattr(search, "PARALLEL_MIN_LEVEL", 0)
    ex = _rng_image((24, 24, 1), seed=4)
    settings = SearchSettings(size=5, shape=shape, levels=1, iterations=2, k=3, refine_square=True)  # type: ignore[arg-type]
    states = []
    synthesize_source_map(
        [ex], [(20, 20)], settings, seed=2, on_level_done=lambda level, state: states.append(state)
    )
    state = states[0]
    order = np.random.default_rng(0).permutation(400)
    sched = schedule_levels(order, (20, 20), conflict_offsets(state.cur.offsets, state.cands.cand_offs))
    assert len(sched.starts) - 1 < 400
    one, two = copy.deepcopy(state), copy.deepcopy(state)
    one.run = one.run._replace(order=order)
    synthesize_chunk(one, 0, 400)
    synthesize_levels(two, sched, 0, len(sched.starts) - 1)
    np.testing.assert_array_equal(one.cands.src, two.cands.src)
    np.testing.assert_array_equal(one.cur.out, two.cur.out)
    np.testing.assert_array_equal(one.run.best_out, two.run.best_out)


def test_histogram_counts_follow_every_change() -> None:
    """Counts frozen during a level are brought up to date after it: they stay the output's counts."""
    ex = _rng_image((24, 24, 1), seed=5)
    settings = replace(SearchSettings(size=5, levels=1, iterations=2, k=3), histogram_weight=3.0)
    states = []
    synthesize_source_map(
        [ex], [(20, 20)], settings, seed=2, on_level_done=lambda level, state: states.append(state)
    )
    s = states[0]
    src = s.cands.src
    expect = np.bincount(s.hist.labels[(src[..., 0] * 24 + src[..., 1]).ravel()], minlength=len(s.hist.count))
    np.testing.assert_array_equal(s.hist.count, expect)


def _block_edge_reference(units: np.ndarray, a: int, z: int, target: int) -> int:
    """The boundary ``a..z`` whose position count is nearest to ``target``, the later one on a tie."""
    gaps = [abs(int(units[i]) - target) for i in range(a, z + 1)]
    return a + max(i for i, g in enumerate(gaps) if g == min(gaps))


@pytest.mark.parametrize("seed", range(6))
def test_block_edges_split_a_level_as_evenly_as_whole_units_allow(seed: int) -> None:
    rng = np.random.default_rng(seed)
    units = np.concatenate([[0], np.cumsum(rng.integers(1, 120, size=40))]).astype(np.int64)
    for a, z in [(0, 40), (3, 4), (5, 17), (10, 40)]:
        first, total = int(units[a]), int(units[z] - units[a])
        for nb in (1, 2, 3, 4):
            edges = [int(_block_edge(units, a, z, first + (b * total) // nb)) for b in range(nb + 1)]
            want = [_block_edge_reference(units, a, z, first + (b * total) // nb) for b in range(nb + 1)]
            assert edges == want
            assert edges[0] == a and edges[-1] == z and edges == sorted(edges)
            if nb == 2:  # the best split of whole units into two contiguous blocks
                best = min(max(int(units[i] - first), int(units[z] - units[i])) for i in range(a, z + 1))
                assert max(int(units[edges[1]] - first), int(units[z] - units[edges[1]])) == best
