"""The patch methods' kernels against their plain NumPy references: the same bits."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from texsynth.synth.kernels import patch_search as kernels
from texsynth.synth.patch.cut import error_surface, error_surface_reference, raster_cut_reference
from texsynth.synth.patch.layout import Strips
from texsynth.synth.patch.search import PatchSearcher, candidates_within
from texsynth.synth.patch.usage import UsagePenalty


@pytest.mark.parametrize("n", [1, 7, 8, 9, 127, 128, 129, 300, 1024, 3072, 9409, 70000])
def test_pairwise_sum_is_numpys(n):
    a = np.random.default_rng(n).random(n) * 3 - 1
    assert kernels.pairwise_sum(a) == np.sum(a)


def _case(seed: int, channels: int, shape=(40, 52), w=12):
    rng = np.random.default_rng(seed)
    return PatchSearcher(rng.random((*shape, channels)), w), rng


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("kind", ["left", "top", "L", "weights"])
def test_errors_are_the_numpy_errors(channels, kind):
    searcher, rng = _case(channels, channels)
    w = searcher.w
    mask = rng.random((w, w, channels)) if kind == "weights" else Strips.of_kind(3, kind).mask(w)
    template = rng.random((w, w, channels))
    factors = 1 + rng.random(searcher.positions_shape)
    ssd = searcher.ssd_reference(template, mask)
    norm = searcher.normalised_ssd(template, mask, ssd)
    for normalised, f in ((False, None), (True, None), (True, factors), (False, factors)):
        err, got = searcher.errors(template, mask, normalised, f)
        want = norm if normalised else ssd
        want = want * f if f is not None else want
        assert np.array_equal(got, ssd) and np.array_equal(err, want)
    assert np.array_equal(searcher.ssd(template, mask), ssd)


@pytest.mark.parametrize("channels", [1, 3])
def test_search_many_is_one_template_at_a_time(channels):
    searcher, rng = _case(10 + channels, channels)
    w = searcher.w
    masks = [Strips.of_kind(4, k).mask(w) for k in ("L", "left", "top", "L", "L")]
    templates = rng.random((len(masks), w, w, channels))
    factors = 1 + rng.random(searcher.positions_shape)
    for normalised in (False, True):
        for threads in (1, 2):  # 1: the serial kernel, 2: the parallel one
            got = searcher.search_many(templates, masks, normalised, factors, 0.3, threads)
            err, ssd, pools, counts = got
            for b, mask in enumerate(masks):
                e, d = searcher.errors(templates[b], mask, normalised, factors)
                assert np.array_equal(err[b], e) and np.array_equal(ssd[b], d)
                pool = candidates_within(e, 0.3)
                assert np.array_equal(pools[b, : counts[b]], pool)
                assert np.array_equal(kernels.candidates_within(e, 0.3), pool)


def test_candidates_of_an_exact_match():
    e = np.array([[0.5, 0.0], [0.0, 2.0]])
    assert kernels.candidates_within(e, 0.1).tolist() == candidates_within(e, 0.1).tolist() == [1, 2]


@pytest.mark.parametrize("channels", [1, 3])
def test_error_surface_kernel(channels):
    rng = np.random.default_rng(channels)
    old, new = rng.random((2, 9, 9, channels))
    assert np.array_equal(error_surface(old, new), error_surface_reference(old, new))


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize(("top", "left"), [(0, 0), (0, 4), (3, 0), (4, 4), (2, 5)])
def test_raster_cut_is_the_reference(seed, top, left):
    e = np.random.default_rng(seed).random((16, 16))
    e[:, 2] *= 0.1  # a valley the cuts follow
    assert np.array_equal(kernels.raster_cut(e, top, left), raster_cut_reference(e, top, left))


@pytest.mark.parametrize("stitch", [kernels.stitch_many, kernels.stitch_many_serial])
def test_gather_paste_and_stitch_many(stitch):
    rng = np.random.default_rng(5)
    w, channels = 8, 2
    image = rng.random((30, 30, channels))
    ex = rng.random((20, 20, channels))
    rows = np.array([np.arange(0, w), np.arange(12, 12 + w), np.arange(26, 26 + w) % 30])  # disjoint
    cols = np.array([np.arange(6, 6 + w), np.arange(0, w), (np.arange(25, 25 + w)) % 30])
    regions = kernels.gather_many(image, rows, cols)
    for b in range(3):
        assert np.array_equal(regions[b], image[np.ix_(rows[b], cols[b])])
    pys, pxs = np.array([0, 5, 12]), np.array([3, 12, 0])
    tops, lefts = np.array([0, 3, 2]), np.array([3, 0, 2])
    want, want_src = image.copy(), np.zeros((30, 30, 2), dtype=np.int32)
    masks = []
    for b in range(3):
        patch = ex[pys[b] : pys[b] + w, pxs[b] : pxs[b] + w]
        m = raster_cut_reference(error_surface_reference(regions[b], patch), int(tops[b]), int(lefts[b]))
        at = np.ix_(rows[b], cols[b])
        region = want[at]
        region[m] = patch[m]
        want[at] = region
        src = want_src[at]
        offsets = np.stack(np.mgrid[0:w, 0:w], axis=-1)
        src[m] = (offsets + np.array([pys[b], pxs[b]]))[m]
        want_src[at] = src
        masks.append(m)
    source = np.zeros((30, 30, 2), dtype=np.int32)
    got = stitch((image, source), (rows, cols, regions), ex, (pys, pxs, tops, lefts))
    assert np.array_equal(got, np.array(masks))
    assert np.array_equal(image, want) and np.array_equal(source, want_src)


def test_usage_factors_are_the_numpy_ones():
    rng = np.random.default_rng(0)
    u = UsagePenalty((40, 50), 10, 1.5)
    for k in range(12):
        share = 1.0 / (1 + k % 5)  # the Gaussian models count fractions of a use
        u.add(int(rng.integers(31)), int(rng.integers(41)), np.full((10, 10), share))
        assert np.array_equal(u.factors(), u.factors_reference())


NOGIL = (
    "template_terms finish_errors candidates_within gather error_surface raster_cut paste usage_factors"
    " gather_many template_terms_many search_many_serial stitch_many_serial"
)


@pytest.mark.skipif(numba.config.DISABLE_JIT, reason="no compiled kernels without the JIT")
def test_serial_copies_are_compiled_apart():
    """One body, two option sets: the serial copies have their own names (numba's cache keys by name)."""
    for name in ("search_many", "stitch_many"):
        parallel, serial = getattr(kernels, name), getattr(kernels, name + "_serial")
        assert parallel.targetoptions.get("parallel") is True and "parallel" not in serial.targetoptions
        assert serial.py_func.__name__ != parallel.py_func.__name__


@pytest.mark.parametrize("name", NOGIL.split())
@pytest.mark.skipif(numba.config.DISABLE_JIT, reason="no compiled kernels without the JIT")
def test_per_patch_kernels_release_the_gil(name):
    """The patches of a wave run on Python threads: a kernel that kept the GIL would serialise them."""
    assert getattr(kernels, name).targetoptions.get("nogil") is True
