"""The solid driver's memory at big volumes (issue 25): the same answers with smaller working sets.

Each test compares a memory-saving form with the plain definition it replaced (whole-volume arrays),
and pins what a 512^3 run relies on: int32 per-voxel positions, slab-wise temporaries, serial transforms.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from texsynth.synth.errors import InvalidInput
from texsynth.synth.pixel import laminar, solid
from texsynth.synth.pixel.solid import (
    PLANE_AXES,
    PLANES,
    SOURCE_DTYPE,
    initial_sources,
    match_histogram,
    plan_levels,
    plane_centres,
    upsample_plane_sources,
)
from texsynth.synth.threads import use_threads


def _match_histogram_definition(vol: np.ndarray, values: np.ndarray) -> np.ndarray:
    flat = vol.ravel()
    ranks = np.argsort(flat, kind="stable")
    ref = np.sort(np.asarray(values, dtype=np.float32).ravel())
    out = np.empty_like(flat)
    out[ranks] = ref[(np.arange(flat.size, dtype=np.int64) * ref.size) // flat.size]
    return out.reshape(vol.shape)


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("split", [0, 1 << 30])
def test_match_histogram_in_halves_is_the_whole_volume_remap(monkeypatch, threads: int, split: int) -> None:
    """Sorted in two halves and merged (split 0) or in one sort: the bytes of one stable argsort."""
    rng = np.random.default_rng(11)
    vol = np.round(rng.random((9, 10, 11), dtype=np.float32) * 20) / 20  # ties: the stable order decides
    vol.ravel()[[3, 500, 501, 900]] = [np.nan, np.nan, -0.0, 0.0]  # NumPy's order: NaN last, -0 == 0
    values = rng.beta(0.5, 0.5, 777).astype(np.float32)
    monkeypatch.setattr(solid, "SPLIT_SORT", split)
    with use_threads(threads):
        got = match_histogram(vol, values)
    np.testing.assert_array_equal(got, _match_histogram_definition(vol, values))
    assert got.tobytes() == _match_histogram_definition(vol, values).tobytes()
    vol64 = vol.astype(np.float64)  # solid-chen-wang's volume may be float64: kept as it is
    with use_threads(threads):
        assert match_histogram(vol64, values).dtype == np.float64


def test_match_histogram_holds_no_whole_volume_index_arrays() -> None:
    """Traced peak of the remap of a 2^21-voxel volume sorted in two halves: their ranks (8 bytes a voxel)
    and the output (4), 12.x bytes a voxel; the whole-volume quantile indices made it 24."""
    vol = np.random.default_rng(0).random((128, 128, 128), dtype=np.float32)
    values = np.linspace(0, 1, 5000, dtype=np.float32)
    match_histogram(vol[:8], values)  # the merge kernel loaded before tracing
    tracemalloc.start()
    try:
        with use_threads(2):
            match_histogram(vol, values)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 13 * vol.size, peak / vol.size


@pytest.mark.parametrize("plane", PLANES)
@pytest.mark.parametrize("stride", [1, 2, 3])
def test_plane_centres_are_the_meshgrid_of_the_grid(plane: str, stride: int) -> None:
    shape = (5, 6, 7)
    a, b = PLANE_AXES[plane]
    for phase in ((0, 0), (1, 0), (2, 1)):
        ranges = [np.arange(s, dtype=np.int64) for s in shape]
        ranges[a] = ranges[a][phase[0] % stride :: stride]
        ranges[b] = ranges[b][phase[1] % stride :: stride]
        want = np.stack([g.ravel() for g in np.meshgrid(*ranges, indexing="ij")], axis=1)
        got = plane_centres(shape, plane, stride, phase)
        assert got.dtype == np.int64 and got.flags.c_contiguous
        np.testing.assert_array_equal(got, want)


def test_the_per_voxel_positions_are_int32_with_the_same_values() -> None:
    ex = np.random.default_rng(3).random((40, 36), dtype=np.float32)
    plan = plan_levels(dict.fromkeys(PLANES, ex), (12, 14, 16), 2, 5)
    nbhs = plan.neighbourhoods(1)
    src = initial_sources(nbhs, int(np.prod(plan.shapes[1])), np.random.default_rng(5))
    rng = np.random.default_rng(5)  # the int64 definition draws the same numbers in the same order
    want = np.stack([nbhs[p].centres[rng.integers(0, len(nbhs[p].centres), src.shape[1])] for p in range(3)])
    assert src.dtype == SOURCE_DTYPE == np.int32
    np.testing.assert_array_equal(src, want)
    up = upsample_plane_sources(src, plan, 0)
    up64 = upsample_plane_sources(src.astype(np.int64), plan, 0)
    assert up.dtype == np.int32 and up.shape == (3, int(np.prod(plan.shapes[0])))
    np.testing.assert_array_equal(up, up64)


def test_an_exemplar_too_large_for_int32_positions_is_refused_naming_it(monkeypatch) -> None:
    assert solid.MAX_EXEMPLAR_PIXELS == 2**31 - 1
    monkeypatch.setattr(solid, "MAX_EXEMPLAR_PIXELS", 64 * 64 - 1)  # as a 46341^2 exemplar against 2^31 - 1
    ex = np.zeros((64, 64), dtype=np.float32)
    with pytest.raises(InvalidInput) as info:
        plan_levels({"xy": ex, "xz": ex, "yz": ex}, (16, 16, 16), 1, 5)
    assert info.value.source == "exemplar" and "at most 4095" in str(info.value)


def test_the_signed_distance_is_the_same_serial_and_on_two_threads(monkeypatch) -> None:
    inside = laminar._smooth_field((20, 22, 24), 3.0, np.random.default_rng(2)) > 0
    with use_threads(2):
        parallel = laminar._signed_distance(inside)
        monkeypatch.setattr(laminar, "PARALLEL_EDT_VOXELS", 0)
        serial = laminar._signed_distance(inside)
    assert parallel.dtype == serial.dtype == np.float64
    np.testing.assert_array_equal(serial, parallel)


def test_the_smooth_field_is_the_meshgrid_definition() -> None:
    shape, sigma = (12, 10, 14), 2.5
    noise = np.random.default_rng(9).standard_normal(shape)
    freqs = np.meshgrid(*[np.fft.fftfreq(s) for s in shape[:2]], np.fft.rfftfreq(shape[2]), indexing="ij")
    low_pass = np.exp(-2.0 * (np.pi * sigma) ** 2 * sum(f**2 for f in freqs))
    field = np.fft.irfftn(np.fft.rfftn(noise) * low_pass, s=shape, axes=(0, 1, 2))
    want = field / max(float(field.std()), 1e-12)
    np.testing.assert_array_equal(laminar._smooth_field(shape, sigma, np.random.default_rng(9)), want)
