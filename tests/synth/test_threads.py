"""The threads knob (:mod:`texsynth.synth.threads`): its meaning, its bad values, and the same bytes with 1, 2
and 4 threads for every method (issue 25)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numba
import numpy as np
import pytest

from texsynth.synth.api import synthesize
from texsynth.synth.cli import main
from texsynth.synth.errors import InvalidParameter
from texsynth.synth.io import save_image
from texsynth.synth.io.patterns import undulating_laminae
from texsynth.synth.threads import (
    THREADS_ENV,
    available_cores,
    check_threads,
    max_threads,
    service_threads,
    use_threads,
)

# Every method at a small size, with 1, 2 and 4 threads in one process whose numba pool has 4 threads
# (NUMBA_NUM_THREADS=4, more than this machine's cores, so that 4 threads really run), every solid
# kernel and every pixel pass forced onto the pool however small its input: a digest per method and count.
_EVERY_METHOD = """
import hashlib, json
import numpy as np
import texsynth.synth.kernels.solid_search as k
import texsynth.synth.kernels.pixel_search as pixel
from texsynth.synth.api import available_methods, synthesize
from texsynth.synth.io.patterns import undulating_laminae

k.PARALLEL_MIN_ITEMS = 0
pixel.PARALLEL_MIN_LEVEL = 0
ex = undulating_laminae((40, 40), period=6.0, amplitude=4.0, wavelength=32.0, noise=0.1, seed=0)
yy, xx = np.mgrid[0:48, 0:48].astype(np.float32)
con = (0.5 + 0.5 * np.sin(2 * np.pi * (xx + 6 * np.sin(2 * np.pi * yy / 48)) / 12)).astype(np.float32)
out = {}
for name, spec in sorted(available_methods().items()):
    size = (12, 12, 12) if spec.output_ndim == 3 else (48, 48)
    params = {"levels": 2} if spec.output_ndim == 3 and "levels" in spec.params_model.model_fields else {}
    digests = []
    for threads in (1, 2, 4):
        r = synthesize(name, ex, size=size, seed=5, params=params,
                       constraint=con if spec.constraint == "required" else None, threads=threads)
        h = hashlib.sha256(r.image.tobytes())
        if r.tensor_field is not None:
            h.update(np.ascontiguousarray(r.tensor_field).tobytes())
        digests.append(h.hexdigest())
    out[name] = digests
print(json.dumps(out))
"""


def test_every_method_gives_the_same_bytes_with_one_two_and_four_threads() -> None:
    env = {**os.environ, "NUMBA_NUM_THREADS": "4"}
    done = subprocess.run(
        [sys.executable, "-c", _EVERY_METHOD], env=env, capture_output=True, text=True, check=True
    )
    digests = json.loads(done.stdout.strip().splitlines()[-1])
    assert len(digests) >= 10  # every registered method ran
    differ = {name: d for name, d in digests.items() if len(set(d)) != 1}
    assert not differ, f"bytes depend on the thread count: {differ}"


def test_use_threads_sets_the_count_and_restores_it() -> None:
    before = numba.get_num_threads()
    with use_threads(1) as count:
        assert count == 1 and numba.get_num_threads() == 1
    assert numba.get_num_threads() == before
    with use_threads(None) as count:  # the default: the whole pool
        assert count == max_threads() == numba.get_num_threads()
    assert numba.get_num_threads() == before


def test_the_default_inside_a_chosen_count_keeps_it() -> None:
    """``synthesize_to_folder(threads=1)`` calls ``synthesize()`` (no count): the synthesis keeps 1."""
    with use_threads(1):
        with use_threads(None) as count:
            assert count == 1 == numba.get_num_threads()
        assert numba.get_num_threads() == 1


def test_pipeline_runs_the_synthesis_on_the_chosen_count(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import texsynth.synth.api as api
    from texsynth.synth.pipeline import synthesize_to_folder

    real, seen = api.use_threads, []

    @contextmanager
    def spy(threads: int | None) -> Iterator[int]:
        with real(threads) as count:
            seen.append(numba.get_num_threads())  # what the method's kernels run on
            yield count

    monkeypatch.setattr(api, "use_threads", spy)
    images = {"exemplar": undulating_laminae((32, 32))}
    synthesize_to_folder("random-phase", images, tmp_path / "o", size=(32, 32), plots=False, threads=1)
    assert seen == [1]


@pytest.mark.parametrize("value", [0, -1, 2.5, "two", True, max_threads() + 1])
def test_bad_thread_counts_are_named(value: object) -> None:
    with pytest.raises(InvalidParameter, match="'threads'"):
        check_threads(value)


def test_whole_numbers_pass_as_counts() -> None:
    assert check_threads(None) is None
    assert check_threads(1) == 1
    assert check_threads("1") == 1
    assert check_threads(np.int64(1)) == 1


def test_api_refuses_a_bad_count_before_any_work() -> None:
    ex = undulating_laminae((32, 32))
    with pytest.raises(InvalidParameter, match="'threads' = 0"):
        synthesize("random-phase", ex, size=(32, 32), threads=0)
    one = synthesize("random-phase", ex, size=(32, 32), threads=1)
    every = synthesize("random-phase", ex, size=(32, 32))
    assert one.image.tobytes() == every.image.tobytes()


def test_service_divides_the_cores_between_its_workers() -> None:
    cores = available_cores()
    assert service_threads(1) == cores
    assert service_threads(cores) == 1
    assert service_threads(cores + 3) == 1  # never zero
    assert service_threads(2, "1") == 1
    assert service_threads(1, None) * 1 <= cores


@pytest.mark.parametrize("raw", ["0", "-2", "abc", "1.5", "999"])
def test_a_bad_service_value_stops_at_start(raw: str) -> None:
    from texsynth.jobs.config import Settings

    with pytest.raises(InvalidParameter, match=THREADS_ENV):
        Settings.from_env({THREADS_ENV: raw, "TEXSYNTH_CONCURRENCY": "1"})


def test_service_settings_carry_the_count_to_the_workers() -> None:
    from texsynth.jobs.config import Settings

    settings = Settings.from_env({"TEXSYNTH_CONCURRENCY": "1"})
    assert settings.threads == available_cores()
    assert Settings.from_env(settings.to_env()).threads == settings.threads
    assert Settings.from_env({THREADS_ENV: "1"}).threads == 1


@pytest.mark.parametrize("command", ["synthesize", "evaluate"])
@pytest.mark.parametrize("value", ["0", "x", "1.5"])
def test_cli_bad_threads_is_one_line_and_exit_2(
    command: str, value: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    image = tmp_path / "ex.png"
    save_image(image, undulating_laminae((32, 32)))
    words = (
        ["synthesize", "random-phase", "--exemplar", str(image), "--out", str(tmp_path / "o")]
        if command == "synthesize"
        else ["evaluate", "--exemplar", str(image), "--output", str(image)]
    )
    assert main([*words, "--threads", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'--threads'" in err[0] and command in err[0]


def test_cli_threads_runs_and_gives_the_same_bytes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    image = tmp_path / "ex.png"
    save_image(image, undulating_laminae((32, 32)))
    outputs = []
    for threads in ("1", None):
        out = tmp_path / f"o{threads}"
        words = ["synthesize", "random-phase", "--exemplar", str(image), "--size", "32x32", "--no-plots"]
        assert main([*words, "--out", str(out), *(["--threads", threads] if threads else [])]) == 0
        outputs.append((out / "output.png").read_bytes())
    assert outputs[0] == outputs[1]


# The patch methods at sizes whose waves hold several patches (small patches on a 96^2 output), their
# copy maps in several blocks of queries, and a periodic layout (one patch a wave): with 1, 2 and 4
# threads in a process whose pools have 4 (issue 25). Every extra array of the result is in the digest.
_PATCH_METHODS = """
import hashlib, json
import numpy as np
from texsynth.synth.api import synthesize
from texsynth.synth.io.patterns import undulating_laminae

ex = undulating_laminae((48, 48), period=6.0, amplitude=4.0, wavelength=32.0, noise=0.1, seed=0)
cases = {
    "quilting": ("quilting", {"patch_size": 12, "overlap": 4}),
    "quilting-graph-cut": ("quilting", {"patch_size": 12, "overlap": 4, "blending": "graph-cut"}),
    "quilting-periodic": ("quilting", {"patch_size": 12, "overlap": 4, "periodic": True}),
    "gaussian-patch": ("gaussian-patch", {"patch_size": 12, "overlap": 4}),
    "feature-guided": ("feature-guided", {"patch_size": 12, "overlap": 4}),
}
out = {}
for name, (method, params) in cases.items():
    digests = []
    for threads in (1, 2, 4):
        r = synthesize(method, ex, size=(96, 96), seed=3, params=params, threads=threads)
        h = hashlib.sha256(r.image.tobytes())
        for key in sorted(r.extras):
            h.update(np.ascontiguousarray(r.extras[key]).tobytes())
        h.update(json.dumps(r.stats.get("coverage"), sort_keys=True, default=str).encode())
        digests.append(h.hexdigest())
    out[name] = digests
print(json.dumps(out))
"""


def test_patch_methods_give_the_same_bytes_with_one_two_and_four_threads() -> None:
    env = {**os.environ, "NUMBA_NUM_THREADS": "4"}
    done = subprocess.run(
        [sys.executable, "-c", _PATCH_METHODS], env=env, capture_output=True, text=True, check=True
    )
    digests = json.loads(done.stdout.strip().splitlines()[-1])
    assert len(digests) == 5
    differ = {name: d for name, d in digests.items() if len(set(d)) != 1}
    assert not differ, f"bytes depend on the thread count: {differ}"


def test_thread_map_keeps_the_order_and_raises_the_first_error() -> None:
    import threading

    from texsynth.synth.threads import thread_map

    seen: set[str] = set()

    def square(n: int) -> int:
        seen.add(threading.current_thread().name)
        return n * n

    assert thread_map(square, list(range(50)), 1) == [n * n for n in range(50)]
    assert seen == {threading.current_thread().name}  # one thread: the caller alone
    assert thread_map(square, list(range(50)), 3) == [n * n for n in range(50)]
    assert thread_map(square, [], 2) == []

    def fail(n: int) -> int:
        if n == 7:
            raise ValueError("seven")
        return n

    with pytest.raises(ValueError, match="seven"):
        thread_map(fail, list(range(20)), 2)


def test_thread_map_works_in_a_forked_child_after_the_parent_used_it() -> None:
    """The parent's helper threads do not exist in a fork: the child starts its own (no hang)."""
    import multiprocessing

    from texsynth.synth.threads import thread_map

    assert thread_map(abs, [-1, -2, -3], 2) == [1, 2, 3]  # the parent's helpers now exist
    ctx = multiprocessing.get_context("fork")
    with ctx.Pool(1) as pool:
        assert pool.apply_async(thread_map, (abs, [-4, -5, -6], 2)).get(timeout=60) == [4, 5, 6]


# solid-kopf's serial parts put on the threads (issue 25, branch kwhole25): the pilot's and the final step's
# slice coherence (stacks of slices on the threads), the final rank remap sorted in two halves (forced at
# every size), the k-coherence sets' differences; with 1, 2 and 4 threads in a process whose pools have 4.
# Branch kopf64w: the finer levels' exemplar tables prefetched on a helper thread (2 and 4 threads).
_KOPF_STARTS = """
import hashlib, json
import texsynth.synth.kernels.solid_search as k
import texsynth.synth.pixel.solid as solid
from texsynth.synth.api import synthesize
from texsynth.synth.methods.solid_kopf import pilot_ratios
from texsynth.synth.io.patterns import undulating_laminae

k.PARALLEL_MIN_ITEMS = 0
solid.SPLIT_SORT = 0
ex = undulating_laminae((40, 40), period=6.0, amplitude=4.0, wavelength=32.0, noise=0.1, seed=0)
cases = {
    "laminar-auto-final": {"structure": "laminar", "final_step": "auto", "levels": 2},
    "laminar-best": {"structure": "laminar", "final_step": "best", "levels": 2},
    # three levels: each finer level's tables built on the helper thread while the coarser one runs
    "random-3-levels": {"structure": "none", "levels": 3, "adapt_to_structure": False},
}
out = {}
for name, params in cases.items():
    digests = []
    for threads in (1, 2, 4):
        solid._BUILT.clear()  # the exemplar tables built anew at each count
        r = synthesize("solid-kopf", ex, size=(16, 16, 16), seed=2, params=params, threads=threads)
        digests.append(hashlib.sha256(r.image.tobytes() + r.stats["final_step"].encode()).hexdigest())
    out[name] = digests
from texsynth.synth.threads import use_threads
pilots = []
for threads in (1, 2, 4):
    with use_threads(threads):
        pilots.append(repr(sorted(pilot_ratios(ex, side=16).items())))
out["pilot"] = pilots
print(json.dumps(out))
"""


def test_kopf_starts_and_remap_give_the_same_bytes_with_one_two_and_four_threads() -> None:
    env = {**os.environ, "NUMBA_NUM_THREADS": "4"}
    done = subprocess.run(
        [sys.executable, "-c", _KOPF_STARTS], env=env, capture_output=True, text=True, check=True
    )
    digests = json.loads(done.stdout.strip().splitlines()[-1])
    assert len(digests) == 4
    differ = {name: d for name, d in digests.items() if len(set(d)) != 1}
    assert not differ, f"bytes depend on the thread count: {differ}"
