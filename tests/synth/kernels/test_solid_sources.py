"""The per-voxel source kernels (:mod:`texsynth.synth.kernels.solid_sources`) against their NumPy versions."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.kernels.solid_sources import (
    dense_sources,
    dense_sources_reference,
    upsample_sources,
    upsample_sources_reference,
)

PLANES = ("xy", "xz", "yz")


@pytest.mark.parametrize("shape", [(5, 7, 9), (4, 5, 4), (10, 12, 14)])
@pytest.mark.parametrize("plane", PLANES)
def test_dense_sources_equal_the_reference(shape: tuple[int, int, int], plane: str) -> None:
    rng = np.random.default_rng(sum(shape))
    for stride in (1, 2, 3, 4):
        for phase in ((0, 0), (1, 0), (stride - 1, stride - 1), (0, stride - 1)):
            for ex in ((30, 30), (9, 17)):
                match = np.full(int(np.prod(shape)), -1, dtype=np.int64)
                sel = rng.random(match.size) < 0.6  # some grid centres without a match
                match[sel] = rng.integers(0, ex[0] * ex[1], int(sel.sum()))
                want = dense_sources_reference(match, shape, plane, stride, phase, ex)
                np.testing.assert_array_equal(dense_sources(match, shape, plane, stride, phase, ex), want)
                for dtype in (np.int64, np.int32):  # int32: the solid driver's per-voxel positions
                    out = np.full(match.size, 7, dtype=dtype)
                    assert dense_sources(match.astype(dtype), shape, plane, stride, phase, ex, out=out) is out
                    np.testing.assert_array_equal(out, want)
                small = match.astype(np.int32)
                assert dense_sources(small, shape, plane, stride, phase, ex).dtype == np.int32


@pytest.mark.parametrize("plane", PLANES)
def test_upsample_sources_equal_the_reference(plane: str) -> None:
    rng = np.random.default_rng(3)
    for coarse in ((5, 7, 9), (4, 4, 4)):
        for fine in (
            tuple(2 * s for s in coarse),
            tuple(2 * s + k for s, k in zip(coarse, (1, 0, 1), strict=True)),
        ):
            for ex, cex in (((60, 60), (30, 30)), ((17, 9), (9, 5))):
                src = rng.integers(0, cex[0] * cex[1], int(np.prod(coarse)))
                want = upsample_sources_reference(src, coarse, fine, plane, ex, cex)
                np.testing.assert_array_equal(upsample_sources(src, coarse, fine, plane, ex, cex), want)
                for dtype in (np.int64, np.int32):
                    out = np.empty(int(np.prod(fine)), dtype=dtype)
                    upsample_sources(src.astype(dtype), coarse, fine, plane, ex, cex, out=out)
                    np.testing.assert_array_equal(out, want)


def test_bad_outputs_are_refused() -> None:
    shape = (4, 4, 4)
    match = np.full(64, -1, dtype=np.int64)
    for bad in (
        np.empty(63, dtype=np.int64),
        np.empty(64, dtype=np.int16),
        np.empty(128, dtype=np.int64)[::2],
    ):
        with pytest.raises(ValueError, match="out must be a C-contiguous int32 or int64 array of 64 entries"):
            dense_sources(match, shape, "xy", 2, (0, 0), (10, 10), out=bad)
        with pytest.raises(ValueError, match="out must be a C-contiguous int32 or int64 array of 64 entries"):
            upsample_sources(np.zeros(8, dtype=np.int64), (2, 2, 2), shape, "xy", (10, 10), (5, 5), out=bad)
    with pytest.raises(ValueError, match="out must not share memory with match"):
        dense_sources(match, shape, "xy", 2, (0, 0), (10, 10), out=match)


def test_gather_slices_writes_into_a_given_buffer_or_names_a_bad_one() -> None:
    from texsynth.synth.kernels.solid_search import gather_slices

    vol = np.random.default_rng(0).random((6, 7, 8)).astype(np.float32)
    centres = np.array([[0, 0, 0], [5, 6, 7], [2, 3, 4]], dtype=np.int64)
    offsets = np.array([[0, -1, 0], [0, 0, 0], [0, 1, 1]], dtype=np.int32)
    want = gather_slices(vol, centres, offsets, True)
    out = np.empty((3, 3), dtype=np.float32)
    assert gather_slices(vol, centres, offsets, True, out) is out
    np.testing.assert_array_equal(out, want)
    for bad in (
        np.empty((3, 4), dtype=np.float32),
        np.empty((3, 3)),
        np.empty((3, 6), dtype=np.float32)[:, ::2],
    ):
        with pytest.raises(ValueError, match=r"out must be a C-contiguous float32 array of shape \(3, 3\)"):
            gather_slices(vol, centres, offsets, True, bad)
