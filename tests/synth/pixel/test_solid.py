"""Solid machinery (texsynth.synth.pixel.solid) and its kernels (texsynth.synth.kernels.solid_search) against
references."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.errors import Cancelled, InvalidInput
from texsynth.synth.grid.scan import scan_order
from texsynth.synth.kernels.solid_search import (
    HistogramState,
    MatchField,
    PackedExemplars,
    best_vote,
    best_vote_reference,
    candidate_differences,
    candidate_differences_reference,
    gather_slices,
    gather_slices_reference,
    irls_update,
    irls_update_reference,
    kcoherence_search_reference,
    merge_remap,
    merge_remap_reference,
    nearest_exact,
    nearest_exact_reference,
    rerank,
    rerank_reference,
)
from texsynth.synth.pixel.solid import (
    PLANE_AXES,
    PLANES,
    LevelStep,
    ProgressMeter,
    dense_sources,
    exemplar_neighbourhoods,
    exemplar_offsets,
    gather_plane,
    match_histogram,
    plan_levels,
    plane_centres,
    plane_offsets,
    run_levels,
    slice_geometry,
    upsample_sources,
    upsample_volume,
)


def _exemplar(shape=(20, 22), seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.random(shape, dtype=np.float32)


@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("plane", PLANES)
def test_gather_slices_equals_reference(periodic: bool, plane: str) -> None:
    rng = np.random.default_rng(1)
    vol = rng.random((6, 7, 9), dtype=np.float32)
    centres = np.stack([rng.integers(0, s, 40) for s in vol.shape], axis=1).astype(np.int64)
    offs = plane_offsets(plane, 5)
    np.testing.assert_array_equal(
        gather_slices(vol, centres, offs, periodic), gather_slices_reference(vol, centres, offs, periodic)
    )


@pytest.mark.parametrize("plane", PLANES)
def test_slice_neighbourhoods_are_exemplar_neighbourhoods(plane: str) -> None:
    """A volume made of one exemplar along a plane gives that exemplar's vectors, entry for entry."""
    ex = _exemplar((12, 12))
    a, b = PLANE_AXES[plane]
    other = ({0, 1, 2} - {a, b}).pop()
    vol = np.ascontiguousarray(np.expand_dims(ex, other).repeat(5, axis=other))
    nb = exemplar_neighbourhoods(ex, 3)
    rows, cols = np.divmod(nb.centres, 12)
    centres = np.zeros((len(rows), 3), dtype=np.int64)
    centres[:, a], centres[:, b], centres[:, other] = rows, cols, 2
    np.testing.assert_array_equal(gather_plane(vol, centres, plane, 3, False), nb.vectors)
    offs = exemplar_offsets(3, 12, centre=False)
    np.testing.assert_array_equal(
        gather_plane(vol, centres, plane, 3, True, centre=False), ex.ravel()[nb.centres[:, None] + offs[None]]
    )


def test_nearest_exact_and_rerank_equal_references() -> None:
    rng = np.random.default_rng(2)
    vectors = rng.random((300, 25), dtype=np.float32)
    queries = rng.random((50, 25), dtype=np.float32)
    queries[:5] = vectors[[3, 7, 7, 299, 0]]  # exact hits
    i1, d1 = nearest_exact(queries, vectors)
    i2, d2 = nearest_exact_reference(queries, vectors)
    np.testing.assert_array_equal(i1, i2)
    np.testing.assert_array_equal(d1, d2)
    assert list(i1[:5]) == [3, 7, 7, 299, 0] and np.all(d1[:5] == 0)
    cands = rng.integers(-1, 301, (50, 6))  # -1 and 300 are padding
    r1, e1 = rerank(queries, vectors, cands)
    r2, e2 = rerank_reference(queries, vectors, cands)
    np.testing.assert_array_equal(r1, r2)
    np.testing.assert_array_equal(e1, e2)


@pytest.mark.parametrize("periodic", [True, False])
def test_kcoherence_search_equals_reference(periodic: bool) -> None:
    ex = _exemplar((16, 18), seed=3)
    nb = exemplar_neighbourhoods(ex, 5)
    shape = (6, 7, 8)
    rng = np.random.default_rng(4)
    vol = rng.random(shape, dtype=np.float32)
    src = nb.centres[rng.integers(0, len(nb.centres), int(np.prod(shape)))]
    for plane in PLANES:
        centres = plane_centres(shape, plane, 2, (1, 0))
        queries = gather_plane(vol, centres, plane, 5, periodic)
        geometry = slice_geometry(shape, plane, periodic)
        scratch = (np.zeros(ex.size, dtype=np.int64), np.zeros(1, dtype=np.int64))
        pos, d2 = nb.search_coherent(
            queries, centres, geometry, src, n_random=3, seed_key=99, index0=7, scratch=scratch
        )
        ref_pos, ref_d2 = kcoherence_search_reference(queries, centres, geometry, src, nb.sets, 3, 99, 7)
        np.testing.assert_array_equal(pos, ref_pos)
        np.testing.assert_array_equal(d2, ref_d2)
        assert np.all(nb.sets.valid[pos] == 1)


def _field(shape, n, ex_widths, stride, rng) -> MatchField:
    N = int(np.prod(shape))
    phase = rng.integers(0, stride, (3, 2)).astype(np.int64)
    match = np.full((3, N), -1, dtype=np.int64)
    for p, plane in enumerate(PLANES):
        c = plane_centres(shape, plane, stride, tuple(phase[p]))
        flat = np.ravel_multi_index(tuple(c.T), shape)
        r = n // 2
        w = ex_widths[p]
        match[p, flat] = (rng.integers(r, w - r, len(flat)) * w + rng.integers(r, w - r, len(flat))).astype(
            np.int64
        )
    return MatchField(
        match=match,
        weight=rng.random((3, N), dtype=np.float32) + 0.1,
        offsets=np.stack([plane_offsets(p, n) for p in PLANES]).astype(np.int32),
        ex_offsets=np.stack([exemplar_offsets(n, w) for w in ex_widths]),
        axes=np.array([PLANE_AXES[p] for p in PLANES], dtype=np.int64),
        phase=phase,
        stride=stride,
    )


@pytest.mark.parametrize(("periodic", "gain", "stride"), [(True, 0.0, 1), (True, 50.0, 2), (False, 5.0, 2)])
def test_irls_update_equals_reference(periodic: bool, gain: float, stride: int) -> None:
    rng = np.random.default_rng(5)
    shape = (5, 6, 7)
    images = [_exemplar((10, 10), 1), _exemplar((9, 12), 2), _exemplar((11, 10), 3)]
    field = _field(shape, 3, [im.shape[1] for im in images], stride, rng)
    packed = PackedExemplars.pack(images)
    vol = rng.random(shape, dtype=np.float32)
    pooled = np.concatenate([im.ravel() for im in images])
    order = scan_order(shape, "random", rng)
    a, b = vol.copy(), vol.copy()
    ha = HistogramState.start(a, pooled, 8, gain)
    hb = HistogramState.start(b, pooled, 8, gain)
    irls_update(a, order, 0, 64, field, packed, ha, periodic, block=32)  # split on a block boundary
    irls_update(a, order, 64, len(order), field, packed, ha, periodic, block=32)
    irls_update_reference(b, order, 0, len(order), field, packed, hb, periodic, block=32)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ha.count, hb.count)
    assert not np.array_equal(a, vol)
    if gain > 0:  # the running histogram is the volume's
        np.testing.assert_array_equal(
            ha.count, np.bincount(np.clip((a.ravel().astype(np.float64) * 8).astype(int), 0, 7), minlength=8)
        )


def test_irls_update_is_a_weighted_average_of_proposals() -> None:
    """One matched neighbourhood of constant value c covering a voxel: the voxel becomes c."""
    shape = (4, 4, 4)
    ex = np.full((5, 5), 0.25, dtype=np.float32)
    rng = np.random.default_rng(0)
    field = _field(shape, 3, [5, 5, 5], 1, rng)
    vol = rng.random(shape, dtype=np.float32)
    hist = HistogramState.start(vol, ex, 4, 0.0)
    irls_update(vol, np.arange(vol.size), 0, vol.size, field, PackedExemplars.pack([ex] * 3), hist, True)
    np.testing.assert_allclose(vol, 0.25, atol=1e-7)


def test_match_histogram_takes_the_exemplar_values_in_rank_order() -> None:
    rng = np.random.default_rng(6)
    vol = rng.random((6, 6, 6), dtype=np.float32)
    values = rng.beta(0.5, 0.5, 6**3).astype(np.float32)
    out = match_histogram(vol, values)
    np.testing.assert_array_equal(np.sort(out.ravel()), np.sort(values))
    assert np.all(np.argsort(out.ravel(), kind="stable") == np.argsort(vol.ravel(), kind="stable"))


def test_plane_centres_cover_every_voxel_and_dense_sources_follow_them() -> None:
    shape = (5, 6, 7)
    ex_shape = (30, 30)
    for plane in PLANES:
        a, b = PLANE_AXES[plane]
        c = plane_centres(shape, plane, 2, (1, 0))
        assert np.all(c[:, a] % 2 == 1) and np.all(c[:, b] % 2 == 0)
        assert len(c) == np.prod(shape) // shape[a] // shape[b] * len(range(1, shape[a], 2)) * len(
            range(0, shape[b], 2)
        )
        match = np.full(int(np.prod(shape)), -1, dtype=np.int64)
        flat = np.ravel_multi_index(tuple(c.T), shape)
        match[flat] = 15 * 30 + 15
        src = dense_sources(match, shape, plane, 2, (1, 0), ex_shape)
        np.testing.assert_array_equal(src[flat], match[flat])
        rows, cols = np.divmod(src, 30)
        assert np.all(np.abs(rows - 15) <= 1) and np.all(np.abs(cols - 15) <= 1)
        up = upsample_sources(src, shape, (10, 12, 14), plane, (60, 60), ex_shape)
        r2, c2 = np.divmod(up, 60)
        assert np.all(np.abs(r2 - 30) <= 3) and np.all(np.abs(c2 - 30) <= 3)


def test_upsample_volume_keeps_constants_and_doubles_sizes() -> None:
    vol = np.full((3, 4, 5), 0.3, dtype=np.float32)
    for periodic in (True, False):
        up = upsample_volume(vol, (6, 8, 9), periodic)
        assert up.shape == (6, 8, 9) and up.dtype == np.float32
        np.testing.assert_allclose(up, 0.3, atol=1e-6)


def test_plan_levels_shrinks_levels_and_names_small_exemplars() -> None:
    ex = _exemplar((32, 32))
    plan = plan_levels(dict.fromkeys(PLANES, ex), (16, 16, 16), 5, 7)
    assert plan.levels == 3 and plan.sizes[0] == 7 and all(s % 2 == 1 for s in plan.sizes)
    assert plan.shapes == [(16, 16, 16), (8, 8, 8), (4, 4, 4)]
    with pytest.raises(InvalidInput, match=r"exemplar: 5x5 pixels is smaller than the 7x7 neighbourhood"):
        plan_levels(dict.fromkeys(PLANES, _exemplar((5, 5))), (16, 16, 16), 3, 7)
    planes = {"xy": ex, "xz": _exemplar((6, 20)), "yz": ex}
    with pytest.raises(InvalidInput, match=r"exemplar_xz: 6x20 pixels is smaller than the 7x7"):
        plan_levels(planes, (16, 16, 16), 3, 7)


def test_tree_search_is_as_good_as_exact_search() -> None:
    """The PCA + tree search's best matches are within 5% of the exhaustive search's (mean distance)."""
    ex = _exemplar((40, 40), seed=7)
    from scipy.ndimage import gaussian_filter

    ex = gaussian_filter(ex, 1.0, mode="wrap").astype(np.float32)
    nb = exemplar_neighbourhoods(ex, 7)
    other = exemplar_neighbourhoods(np.ascontiguousarray(ex.T[::-1]), 7)  # realistic, unseen queries
    queries = other.vectors[:: max(1, len(other.vectors) // 500)]
    _, d_fast = nb.search(queries)
    _, d_exact = nb.search(queries, exact=True)
    assert np.all(d_fast >= d_exact - 1e-12)
    assert d_fast.mean() <= 1.05 * d_exact.mean()


def test_upsample_volume_of_a_linear_function_has_no_shift_or_transpose() -> None:
    """Coarse voxel ``j`` covers fine voxels ``2j, 2j + 1`` (skimage's pyramid): a ramp ``a z + b y + c x``
    sampled at the coarse centres comes back, inside the volume, as the same ramp at the fine centres."""
    coeff = (0.01, 0.02, 0.05)  # distinct per axis: a transpose would show
    coarse = np.fromfunction(
        lambda z, y, x: coeff[0] * (2 * z + 0.5) + coeff[1] * (2 * y + 0.5) + coeff[2] * (2 * x + 0.5),
        (4, 5, 6),
    ).astype(np.float32)
    up = upsample_volume(coarse, (8, 10, 12), periodic=False)
    want = np.fromfunction(lambda z, y, x: coeff[0] * z + coeff[1] * y + coeff[2] * x, (8, 10, 12))
    inner = (slice(1, -1),) * 3
    np.testing.assert_allclose(up[inner], want[inner], atol=1e-5)


def test_every_voxel_gets_every_covering_neighbourhood_of_every_plane() -> None:
    """Weights 1, every proposal of plane p worth 10^p: a voxel's sum of weights is the number of grid
    centres covering it, and its value tells how many came from each plane (all planes, every window)."""
    shape, n, stride = (6, 7, 8), 3, 2
    ex = np.zeros((9, 9), dtype=np.float32)
    rng = np.random.default_rng(1)
    field = _field(shape, n, [9, 9, 9], stride, rng)
    field.weight[:] = 1.0
    images = [ex + 10.0**p for p in range(3)]
    vol = np.zeros(shape, dtype=np.float32)
    hist = HistogramState.start(vol, ex, 4, 0.0)
    irls_update(vol, np.arange(vol.size), 0, vol.size, field, PackedExemplars.pack(images), hist, True)
    # expected: per plane, centres of the plane's grid within the voxel's n x n window (periodic)
    r = n // 2
    for v in rng.integers(0, vol.size, 40):
        z, y, x = np.unravel_index(v, shape)
        counts = []
        for p, plane in enumerate(PLANES):
            a, b = PLANE_AXES[plane]
            pos = (z, y, x)
            ca = [(pos[a] + d) % shape[a] for d in range(-r, r + 1)]
            cb = [(pos[b] + d) % shape[b] for d in range(-r, r + 1)]
            counts.append(
                sum((i - field.phase[p, 0]) % stride == 0 for i in ca)
                * sum((j - field.phase[p, 1]) % stride == 0 for j in cb)
            )
        want = sum(c * 10.0**p for p, c in enumerate(counts)) / sum(counts)
        assert vol[z, y, x] == pytest.approx(want, rel=1e-6)


def test_irls_update_skips_inactive_planes() -> None:
    shape = (5, 6, 7)
    rng = np.random.default_rng(2)
    images = [np.full((9, 9), 0.1 * (p + 1), dtype=np.float32) for p in range(3)]
    field = _field(shape, 3, [9, 9, 9], 1, rng)
    field.active = np.array([0, 1, 1], dtype=np.uint8)
    vol = np.zeros(shape, dtype=np.float32)
    hist = HistogramState.start(vol, images[0], 4, 0.0)
    irls_update(vol, np.arange(vol.size), 0, vol.size, field, PackedExemplars.pack(images), hist, True)
    assert vol.min() > 0.2 - 1e-6 and vol.max() < 0.3 + 1e-6  # only the xz (0.2) and yz (0.3) proposals


def test_kcoherence_search_with_fewer_set_entries_equals_reference() -> None:
    ex = _exemplar((16, 18), seed=3)
    nb = exemplar_neighbourhoods(ex, 5)
    shape = (6, 7, 8)
    rng = np.random.default_rng(4)
    vol = rng.random(shape, dtype=np.float32)
    src = nb.centres[rng.integers(0, len(nb.centres), int(np.prod(shape)))]
    centres = plane_centres(shape, "xz", 1)
    queries = gather_plane(vol, centres, "xz", 5, True)
    geometry = slice_geometry(shape, "xz", True)
    scratch = (np.zeros((3, ex.size), dtype=np.int64), np.zeros(1, dtype=np.int64))
    pos, d2 = nb.search_coherent(
        queries, centres, geometry, src, n_random=1, seed_key=5, index0=0, scratch=scratch, k=3
    )
    ref_pos, ref_d2 = kcoherence_search_reference(queries, centres, geometry, src, nb.sets, 1, 5, 0, k=3)
    np.testing.assert_array_equal(pos, ref_pos)
    np.testing.assert_array_equal(d2, ref_d2)


# ---------------------------------------------------------------- the driver


class _Recorder:
    """A level loop that records the driver's calls and stops a level after ``stop_after`` iterations."""

    def __init__(self, stop_after: int) -> None:
        self.calls: list[tuple] = []
        self.stop_after = stop_after

    def start_level(self, step: LevelStep) -> None:
        self.calls.append(("start", step.level, step.shape, step.size, step.iterations, step.coarsest))

    def iterate(self, step: LevelStep, it: int) -> bool:
        self.calls.append(("iterate", step.level, it))
        return it + 1 < self.stop_after

    def end_level(self, step: LevelStep) -> None:
        self.calls.append(("end", step.level))


def test_run_levels_goes_coarse_to_fine_with_per_level_iterations_and_early_stops() -> None:
    ex = np.random.default_rng(0).random((32, 32)).astype(np.float32)
    plan = plan_levels(dict.fromkeys(PLANES, ex), (16, 16, 16), 2, 7)
    loop = _Recorder(stop_after=2)
    run_levels(plan, [1, 3], loop)  # level 0 (finest) 1 iteration, level 1 (coarsest) 3, stopped at 2
    assert loop.calls == [
        ("start", 1, plan.shapes[1], plan.sizes[1], 3, True),
        ("iterate", 1, 0),
        ("iterate", 1, 1),
        ("end", 1),
        ("start", 0, plan.shapes[0], plan.sizes[0], 1, False),
        ("iterate", 0, 0),
        ("end", 0),
    ]


def test_progress_chunks_cover_the_items_and_report_after_each_chunk() -> None:
    seen: list[tuple[str, float]] = []
    meter = ProgressMeter(lambda stage, fraction: seen.append((stage, fraction)), total=200.0)
    done = []
    for a, b in meter.chunks(10, 20.0, "stage"):  # 1% of 200 units = 2 units: one item per chunk
        assert len(seen) == len(done)  # reported after the caller's work on the chunk, not before
        done.append((a, b))
    assert done == [(i, i + 1) for i in range(10)]
    assert seen[-1] == ("stage", 1.0)
    assert [(a, b) for a, b in ProgressMeter(lambda s, f: None, 1.0).chunks(5, 1.0, "s", step=2)] == [
        (0, 2),
        (2, 4),
        (4, 5),
    ]


def test_progress_chunks_stop_when_the_report_cancels() -> None:
    def cancel(stage: str, fraction: float) -> None:
        if fraction >= 0.3:
            raise Cancelled("stop")

    done = []
    with pytest.raises(Cancelled):
        for a, b in ProgressMeter(cancel, total=10.0).chunks(10, 1.0, "stage", step=1):
            done.append((a, b))
    assert done == [(0, 1), (1, 2), (2, 3)]


@pytest.mark.parametrize(("periodic", "stride"), [(True, 1), (True, 2), (False, 2)])
def test_best_vote_equals_reference(periodic: bool, stride: int) -> None:
    rng = np.random.default_rng(8)
    shape = (5, 6, 7)
    images = [_exemplar((10, 10), 1), _exemplar((9, 12), 2), _exemplar((11, 10), 3)]
    field = _field(shape, 3, [im.shape[1] for im in images], stride, rng)
    field.match[1, ::5] = -1  # some centres without a match
    packed = PackedExemplars.pack(images)
    vol = rng.random(shape, dtype=np.float32)
    before = vol.copy()
    out = best_vote(vol, field, packed, periodic)
    np.testing.assert_array_equal(out, best_vote_reference(vol, field, packed, periodic))
    np.testing.assert_array_equal(vol, before)  # a new volume
    assert np.isin(out, packed.values).mean() > 0.9  # exemplar pixels, not averages


def test_best_vote_copies_the_heaviest_proposal() -> None:
    """Two planes propose constant exemplars 0.2 and 0.7; the heavier plane wins every voxel."""
    shape = (4, 4, 4)
    rng = np.random.default_rng(0)
    field = _field(shape, 3, [5, 5, 5], 1, rng)
    field.active[:] = (1, 1, 0)
    field.weight[0] = 1.0
    field.weight[1] = 2.0
    images = [np.full((5, 5), v, np.float32) for v in (0.2, 0.7, 0.0)]
    out = best_vote(rng.random(shape, dtype=np.float32), field, PackedExemplars.pack(images), True)
    np.testing.assert_array_equal(out, np.float32(0.7))


def test_exemplar_tables_are_kept_by_content() -> None:
    """The same image content (another array), size and centre give the same tables back; a changed
    pixel, size or centre does not, and changing the caller's array afterwards leaves the tables alone."""
    img = _exemplar((24, 26), seed=5)
    first = exemplar_neighbourhoods(img, 5)
    assert exemplar_neighbourhoods(img.copy(), 5) is first
    assert exemplar_neighbourhoods(img, 3) is not first
    assert exemplar_neighbourhoods(img, 5, centre=False) is not first
    before = first.image.copy()
    img[3, 4] += 0.25
    changed = exemplar_neighbourhoods(img, 5)
    assert changed is not first and changed.image[3, 4] == img[3, 4]
    np.testing.assert_array_equal(first.image, before)
    with pytest.raises(InvalidInput, match="exemplar_xz"):
        exemplar_neighbourhoods(img, 31, role="exemplar_xz")


@pytest.mark.parametrize("threads", [1, 2])
def test_candidate_differences_equal_reference(monkeypatch, threads: int) -> None:
    """The k-coherence sets' differences (every row on the pool), "no neighbour" (P) read as the last row."""
    import texsynth.synth.kernels.solid_search as kernels
    from texsynth.synth.threads import use_threads

    rng = np.random.default_rng(8)
    vectors = rng.random((300, 25), dtype=np.float32)
    candidates = rng.integers(0, 301, size=(280, 9))  # 300 = no neighbour
    monkeypatch.setattr(kernels, "PARALLEL_MIN_ITEMS", 0)
    with use_threads(threads):
        got = candidate_differences(vectors, candidates)
    want = candidate_differences_reference(vectors, candidates)
    assert got.dtype == np.float32 and got.shape == (280, 9, 25)
    assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("half", [0, 1, 37, 90, 100])
def test_merge_remap_of_two_sorted_halves_equals_one_stable_sort(half: int) -> None:
    rng = np.random.default_rng(9)
    values = (np.round(rng.random(100) * 8) / 8).astype(np.float32)  # many ties
    values[[5, 60]] = np.nan
    ref = np.sort(rng.random(37).astype(np.float32))
    out = np.empty_like(values)
    left = np.argsort(values[:half], kind="stable")
    right = np.argsort(values[half:], kind="stable")
    merge_remap(values, left, right, ref, out)
    assert out.tobytes() == merge_remap_reference(values, ref).tobytes()


def _tables_equal(a, b) -> None:
    for name in ("centres", "vectors", "mean", "basis"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_array_equal(a.sets.kset, b.sets.kset)
    np.testing.assert_array_equal(a.sets.valid, b.sets.valid)


def test_prefetched_tables_are_the_direct_builds_and_handed_out_once() -> None:
    """A finer level's tables built on the helper thread (``SolidPlan.prefetch``, 2 threads) are the
    tables a direct build gives, array for array; the level's own request waits for the build in flight
    and gets that object; with one thread nothing is prefetched."""
    import texsynth.synth.pixel.solid as solid
    from texsynth.synth.threads import use_threads

    ex = _exemplar((40, 44), seed=5)
    plan = plan_levels(dict.fromkeys(PLANES, ex), (16, 16, 16), 2, 5)
    solid._BUILT.clear()
    direct = solid._build_neighbourhoods(plan.exemplars[0][0], plan.sizes[0], True)
    with use_threads(1):
        assert plan.prefetch(0) is None
    with use_threads(2):
        future = plan.prefetch(0)
        assert future is not None
        got = plan.neighbourhoods(0)  # may wait for the build in flight
        future.result()
        assert all(nb is got[0] for nb in got)  # one table for the three planes, built once
        assert plan.neighbourhoods(0)[0] is got[0]
        assert plan.prefetch(5) is None  # no such level
    _tables_equal(got[0], direct)
    assert not solid._BUILDING


def test_a_failed_prefetch_is_raised_by_the_level_that_needs_it() -> None:
    """A build that fails on the helper thread leaves no table and no build in flight: the caller's own
    request builds it again and raises there (here the neighbourhood is wider than the exemplar)."""
    import dataclasses

    import texsynth.synth.pixel.solid as solid
    from texsynth.synth.threads import use_threads

    ex = _exemplar((20, 22), seed=6)
    plan = dataclasses.replace(plan_levels(dict.fromkeys(PLANES, ex), (8, 8, 8), 1, 5), sizes=[30])
    solid._BUILT.clear()
    with use_threads(2):
        future = plan.prefetch(0)
        assert future is not None
        future.result()  # the helper swallowed the error ...
        assert not solid._BUILDING and not solid._BUILT
        with pytest.raises(InvalidInput, match="30x30"):  # ... which the level's own request raises
            plan.neighbourhoods(0)
