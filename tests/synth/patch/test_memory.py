"""settle_heap: a patch method's per-wave arrays stay on malloc's heap (no fresh pages every wave)."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

from texsynth.synth.patch.memory import MAX_SETTLE, settle_heap, wave_batch, wave_bytes

# A wave's pattern: six arrays of 1.6 MB written and freed, twenty times, in a fresh process.
_CHURN = """
import resource, sys
import numpy as np
from texsynth.synth.patch.memory import settle_heap
if sys.argv[1] == "settle":
    settle_heap(16 << 20)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    arrays = [np.ones(200_000) for _ in range(6)]
    del arrays
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> int:
    done = subprocess.run(
        [sys.executable, "-c", _CHURN, mode], capture_output=True, text=True, check=True, env=dict(os.environ)
    )
    return int(done.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's malloc thresholds")
def test_settled_heap_takes_no_fresh_pages_after_the_first_wave() -> None:
    one_wave = 6 * 200_000 * 8 // 4096  # pages of one iteration
    settled, plain = _faults("settle"), _faults("plain")
    assert settled < 2 * one_wave  # the first iteration's pages, then the heap's
    assert plain > 10 * one_wave  # without: fresh pages nearly every iteration (the cause, as measured)


def test_sizes() -> None:
    assert settle_heap(1000) == 0
    assert settle_heap(3 << 20) == 3 << 20
    assert settle_heap(1 << 40) == MAX_SETTLE
    assert wave_bytes(13, (128, 128), 1) == 13 * 128 * 128 * 56
    assert wave_bytes(2, (10, 20), 3) == 2 * 200 * 88


def test_wave_batch_keeps_a_waves_searches_within_the_largest_threshold() -> None:
    one = wave_bytes(1, (160, 160), 1)  # a 128^2 exemplar's grid with 32 px patches
    assert wave_batch((160, 160), 1, 1) == MAX_SETTLE // one == 23
    assert wave_batch((160, 160), 1, 2) == 11  # two threads search at once
    assert wave_batch((160, 160), 1, 2) * 2 * one <= MAX_SETTLE
    assert wave_batch((4000, 4000), 3, 4) == 1  # never none


def test_quilting_searched_in_batches_gives_the_same_bytes(monkeypatch) -> None:
    """A wave's runs searched a patch or two at a time: the bytes of whole runs (the patches of a wave
    neither overlap nor read each other)."""
    import numpy as np

    from texsynth.synth.api import synthesize
    from texsynth.synth.methods import quilting

    rng = np.random.default_rng(5)
    exemplar = rng.random((48, 48)).astype(np.float32)
    params = {"patch_size": 12}
    whole = synthesize("quilting", exemplar, size=(150, 150), params=params, seed=3, threads=2)
    for batch in (1, 2):
        monkeypatch.setattr(quilting, "wave_batch", lambda grid, channels, threads, batch=batch: batch)
        small = synthesize("quilting", exemplar, size=(150, 150), params=params, seed=3, threads=2)
        assert small.image.tobytes() == whole.image.tobytes(), batch
        assert np.array_equal(small.extras["source_map"], whole.extras["source_map"])
