"""Big images' filters and per-pixel maps on the job's threads: the values of one call, whatever the count."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage as ndi

from texsynth.synth.analysis import split
from texsynth.synth.analysis.split import gaussian_filter, per_pixel, split_rows
from texsynth.synth.analysis.tensor import coherence, orientation, structure_tensor, structure_tensor_stack
from texsynth.synth.threads import thread_map, use_threads


@pytest.fixture
def small_split(monkeypatch):
    """Split from 32^2 pixels on, so that small images take the threaded path."""
    monkeypatch.setattr(split, "SPLIT_PIXELS", 32 * 32)


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(
    ("shape", "axes", "order"),
    [
        ((67, 45), None, 0),
        ((67, 45), None, (0, 1)),
        ((45, 67), None, (1, 0)),
        ((3, 50, 41), (1, 2), (1, 0)),
        ((2, 40, 70), (-2, -1), 0),
    ],
)
@pytest.mark.parametrize("mode", ["reflect", "wrap"])
def test_gaussian_filter_is_scipys_bit_for_bit_with_any_thread_count(
    small_split, dtype, shape, axes, order, mode
):
    image = np.random.default_rng(3).random(shape).astype(dtype)
    want = ndi.gaussian_filter(image, 1.5, order=order, mode=mode, axes=axes)
    for threads in (1, 2, 3, 4):  # the pieces' count is the job's thread count
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(split, "current_threads", lambda threads=threads: threads)
            got = split.gaussian_filter(image, 1.5, order=order, mode=mode, axes=axes)
        assert _same_bits(got, want), threads


def test_gaussian_filter_splits_only_big_planes(monkeypatch):
    """Below SPLIT_PIXELS per plane (a volume's slices, a 256^2 command) one SciPy call does it all."""
    calls = []
    monkeypatch.setattr(split, "thread_map", lambda fn, items, n: calls.append(n) or [fn(x) for x in items])
    image = np.random.default_rng(0).random((64, 64))
    with use_threads(2):
        gaussian_filter(image, 1.0)
        assert calls == []
        monkeypatch.setattr(split, "SPLIT_PIXELS", 64 * 64)
        gaussian_filter(image, 1.0)
    assert calls == [2, 2]  # one split pass per axis


def test_per_pixel_and_split_rows_give_the_values_of_one_call(small_split):
    image = np.random.default_rng(1).random((70, 90)).astype(np.float32)
    tensors = structure_tensor(image)
    with use_threads(1):
        want = (coherence(tensors), orientation(tensors), structure_tensor(image))
    with use_threads(2):
        got = (coherence(tensors), orientation(tensors), structure_tensor(image))
    for g, w in zip(got, want, strict=True):
        assert _same_bits(g, w)
    stack = np.stack([image, image[::-1]]).astype(np.float64)
    with use_threads(2):
        both = structure_tensor_stack(stack)
    for i in range(2):
        with use_threads(1):
            assert _same_bits(both[i], structure_tensor(stack[i]))
    seen = np.zeros(70, dtype=int)

    def mark(a: int, b: int) -> None:
        seen[a:b] += 1

    with use_threads(2):
        split_rows(mark, image.shape)
    assert (seen == 1).all()  # every row once


def test_per_pixel_of_a_strided_field_is_one_call(small_split):
    field = np.random.default_rng(2).random((40, 40, 6))[..., ::2]  # not contiguous
    with use_threads(2):
        assert _same_bits(per_pixel(lambda t: t.sum(axis=-1), field), field.sum(axis=-1))
    contiguous = np.ascontiguousarray(field)
    with use_threads(2):
        assert _same_bits(per_pixel(lambda t: t.sum(axis=-1), contiguous), contiguous.sum(axis=-1))


def test_thread_map_inside_a_task_runs_in_line():
    """A task that maps again (a split filter inside a thread_map task) neither waits for ever on its own
    pool nor takes threads: its items run on its own thread."""
    import threading

    def inner(x: int) -> tuple[int, str]:
        return x, threading.current_thread().name

    def outer(x: int) -> list[tuple[int, str]]:
        return thread_map(inner, [x, x + 1, x + 2], 2)

    got = thread_map(outer, list(range(6)), 2)
    for x, run in enumerate(got):
        assert [v for v, _ in run] == [x, x + 1, x + 2]
        assert len({name for _, name in run}) == 1  # in line, on the task's thread
