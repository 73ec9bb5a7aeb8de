"""Patch layout and the masked FFT search against a direct SSD."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.errors import InvalidParameter
from texsynth.synth.patch.layout import PatchLayout, check_periodic_size, overlap_mask, periodic_positions
from texsynth.synth.patch.search import PatchSearcher, candidates_within, k_nearest


def test_layout_covers_size_and_kinds():
    layout = PatchLayout((50, 37), 10, 3)
    gh, gw = layout.grown_shape
    assert gh >= 50 and gw >= 37 and gh - layout.step < 50
    kinds = {(i, j): k for i, j, _, _, k in layout.patches()}
    assert kinds[(0, 0)] == "none" and kinds[(0, 1)] == "left"
    assert kinds[(1, 0)] == "top" and kinds[(1, 1)] == "L"
    desc = layout.describe()
    assert desc["seam_rows"] == [7, 14, 21, 28, 35, 42] and desc["step"] == 7


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("kind", ["left", "top", "L"])
def test_masked_ssd_matches_direct(channels, kind):
    rng = np.random.default_rng(0)
    ex = rng.random((19, 23, channels))
    template = rng.random((6, 6, channels))
    mask = overlap_mask(6, 2, kind)
    got = PatchSearcher(ex, 6).ssd(template, mask)
    want = np.array(
        [
            [np.sum(mask[..., None] * (ex[y : y + 6, x : x + 6] - template) ** 2) for x in range(18)]
            for y in range(14)
        ]
    )
    np.testing.assert_allclose(got, want, atol=1e-10)


def test_grey_search_finds_the_patch_itself():
    rng = np.random.default_rng(1)
    ex = rng.random((30, 30))
    searcher = PatchSearcher(ex, 8)
    d = searcher.ssd(ex[11:19, 4:12], overlap_mask(8, 3, "L"))
    assert k_nearest(d, 3)[0] == np.ravel_multi_index((11, 4), searcher.positions_shape)
    assert np.allclose(searcher.patches(k_nearest(d, 1))[0][..., 0], ex[11:19, 4:12])


def test_candidates_within_tolerance():
    d = np.array([[1.0, 1.05, 1.2], [3.0, 1.09, 0.99999]])
    assert set(candidates_within(d, 0.1)) == {0, 1, 4, 5}
    assert list(k_nearest(d, 2)) == [5, 0]


@pytest.mark.parametrize(
    ("size", "w", "overlap"), [((96, 96), 16, 4), ((100, 77), 16, 4), ((128, 128), 30, 7)]
)
def test_periodic_layout_covers_the_torus_and_knows_what_is_written(size, w, overlap):
    """Painting the patches in raster order on the torus: every pixel is covered, each patch's strips are
    exactly the pixels already written under it, and the last column / row have right / bottom strips."""
    check_periodic_size(size, w, overlap)
    layout = PatchLayout(size, w, overlap, periodic=True)
    assert layout.grown_shape == size
    written = np.zeros(size, dtype=bool)
    for i, j, y, x, kind in layout.patches():
        at = layout.index(y, x)
        np.testing.assert_array_equal(written[at], layout.mask(i, j), err_msg=f"patch {(i, j)} ({kind})")
        written[at] = True
        strips = layout.strips(i, j)
        assert (strips.right > 0) == (j == layout.cols - 1)
        assert (strips.bottom > 0) == (i == layout.rows - 1)
        widths = [s for s in (strips.top, strips.left, strips.right, strips.bottom) if s]
        assert (min(widths) >= overlap) if (i or j) else (kind == "none" and not widths)
    assert written.all()
    last = layout.mask(layout.rows - 1, layout.cols - 1)
    assert last[:, -1].all() and last[-1, :].all() and last[:, 0].all() and last[0, :].all()
    assert not last.all()  # the last patch keeps pixels of its own
    assert layout.kind(0, layout.cols - 1) == "left+right" and layout.kind(layout.rows - 1, 0) == "top+bottom"
    assert layout.kind(layout.rows - 1, layout.cols - 1) == "L+right+bottom"


def test_periodic_positions_spread_the_steps_evenly():
    assert periodic_positions(96, 12) == list(range(0, 96, 12))  # a multiple: the step itself
    pos = periodic_positions(100, 12)  # 9 patches, steps of 11 or 12 (never longer than the step)
    steps = np.diff([*pos, 100])
    assert len(pos) == 9 and set(steps) <= {11, 12}
    desc = PatchLayout((100, 96), 16, 4, periodic=True).describe()
    assert desc["periodic"] and desc["seam_rows"][0] == 0 and desc["overlap"] == 16 - 11
    assert PatchLayout((50, 37), 10, 3).describe()["periodic"] is False


def test_periodic_index_wraps_reads_and_writes():
    layout = PatchLayout((20, 20), 8, 2, periodic=True)
    out = np.zeros((20, 20))
    at = layout.index(15, 17)
    out[at] = 1.0
    assert out.sum() == 64 and out[15:20, 17:20].all() and out[0:3, 0:5].all() and out[15:, :5].all()


@pytest.mark.parametrize(
    ("size", "field", "match"),
    [
        ((23, 96), "height", "at least two patch steps.*2 x \\(16 - 4\\) = 24 px"),
        ((96, 23), "width", "at least two patch steps"),
    ],
)
def test_periodic_size_errors_name_the_side(size, field, match):
    with pytest.raises(InvalidParameter, match=match) as err:
        check_periodic_size(size, 16, 4)
    assert err.value.name == field


def test_periodic_size_error_when_the_last_patch_keeps_nothing():
    # overlap 12 of 32 (step 20), 41 px: 3 patches 13-14 px apart, the last one's two strips meet
    with pytest.raises(InvalidParameter, match="no pixel of its own") as err:
        check_periodic_size((41, 64), 32, 12)
    assert err.value.name == "height"


def _regions_meet(layout: PatchLayout, a: tuple, b: tuple) -> bool:
    """Whether the w x w regions of patches ``a`` and ``b`` (``patches()`` rows) share a pixel."""
    ha, hb = np.zeros(layout.grown_shape, bool), np.zeros(layout.grown_shape, bool)
    ha[layout.index(a[2], a[3])] = True
    hb[layout.index(b[2], b[3])] = True
    return bool((ha & hb).any())


@pytest.mark.parametrize(
    ("size", "w", "overlap", "periodic"),
    [((100, 90), 16, 3, False), ((64, 80), 16, 8, False), ((60, 60), 12, 7, False), ((96, 80), 16, 4, True)],
)
def test_waves_keep_every_overlapping_pair_in_raster_order(size, w, overlap, periodic):
    """Patches of one wave never meet; a patch meeting an earlier one comes in a later wave (issue 25)."""
    layout = PatchLayout(size, w, overlap, periodic=periodic)
    patches = layout.patches()
    waves = layout.waves()
    assert sorted(n for wave in waves for n in wave) == list(range(len(layout)))
    wave_of = {n: k for k, wave in enumerate(waves) for n in wave}
    for a in range(len(patches)):
        for b in range(a + 1, len(patches)):
            if _regions_meet(layout, patches[a], patches[b]):
                assert wave_of[a] < wave_of[b], (patches[a][:2], patches[b][:2])
    if not periodic and 2 * overlap < w:  # the diagonals j + 2 i
        assert all(
            wave_of[i * layout.cols + j] == j + 2 * i for i in range(layout.rows) for j in range(layout.cols)
        )
    if periodic:  # the last column meets the next row's first patch: one patch a wave
        assert all(len(wave) == 1 for wave in waves)


def test_patch_streams_depend_on_the_patch_only():
    from texsynth.synth.patch.layout import patch_rng

    assert patch_rng(7, 3).integers(1 << 30) == patch_rng(7, 3).integers(1 << 30)
    assert patch_rng(7, 3).integers(1 << 30) != patch_rng(7, 4).integers(1 << 30)
    assert patch_rng(7, 3).integers(1 << 30) != patch_rng(8, 3).integers(1 << 30)


def test_patch_workers_run_every_patch_and_keep_the_order():
    from texsynth.synth.patch.layout import patch_workers
    from texsynth.synth.threads import use_threads

    for threads in (1, 2):
        for gil_bound in (False, True):
            with use_threads(threads), patch_workers(gil_bound) as run:
                assert run(lambda n: n * n, [3, 1, 2]) == [9, 1, 4]
                assert run(lambda n: -n, [5]) == [-5]


def test_gil_bound_patch_workers_place_a_wave_on_the_calling_thread():
    import threading
    import time

    from texsynth.synth.patch.layout import patch_workers
    from texsynth.synth.threads import use_threads

    def where(n: int) -> int:
        time.sleep(0.002)  # long enough for a helper thread to take items, were there one
        return threading.get_ident()

    with use_threads(2), patch_workers(gil_bound=True) as run:
        assert set(run(where, list(range(8)))) == {threading.get_ident()}
