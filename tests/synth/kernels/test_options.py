"""The kernels' numba options: one body compiled with two option sets keeps two cache entries."""

from __future__ import annotations

import importlib
import pkgutil
from collections import defaultdict

import numba
import numpy as np
import pytest
from numba.core.registry import CPUDispatcher

import texsynth.synth.kernels as kernels_package
from texsynth.synth.kernels.options import kernel
from texsynth.synth.kernels.pixel_search import _levels_parallel, _levels_serial

# With the JIT off (the kernels' Python bodies run) there is nothing compiled, so nothing cached.
pytestmark = pytest.mark.skipif(numba.config.DISABLE_JIT, reason="NUMBA_DISABLE_JIT: no compiled kernels")


def _body(x):
    return x + 1.0


def _index_name(dispatcher: CPUDispatcher) -> str:
    return dispatcher._cache._cache_file._index_name


def test_a_second_option_set_of_one_body_gets_its_own_cache_entry() -> None:
    serial = kernel(_body)
    parallel = kernel(parallel=True)(_body)
    again = kernel(_body)
    # numba names the cache file after the function and keys it by signature only (numba issue #6845):
    # without the copy the parallel compile would load the serial one's code from disk
    assert _index_name(serial) != _index_name(parallel)
    assert "parallel_True" in parallel.py_func.__qualname__
    assert _index_name(again) == _index_name(serial)
    x = np.arange(4.0)
    assert np.array_equal(parallel(x), serial(x)) and np.array_equal(serial(x), x + 1.0)
    assert parallel.py_func.__doc__ == _body.__doc__ and parallel.py_func.__module__ == _body.__module__


def test_the_pixel_passes_serial_and_parallel_kernels_do_not_share_a_cache_file() -> None:
    assert _levels_parallel.targetoptions.get("parallel") and not _levels_serial.targetoptions.get("parallel")
    assert _index_name(_levels_parallel) != _index_name(_levels_serial)


def test_no_two_kernels_with_different_options_share_a_cache_file() -> None:
    seen: dict[str, list[tuple[str, dict]]] = defaultdict(list)
    for info in pkgutil.iter_modules(kernels_package.__path__):
        module = importlib.import_module(f"{kernels_package.__name__}.{info.name}")
        for name, value in vars(module).items():
            if (
                isinstance(value, CPUDispatcher)
                and value._cache is not None
                and hasattr(value._cache, "_cache_file")
            ):
                seen[_index_name(value)].append((name, dict(value.targetoptions)))
    assert seen, "no cached kernel found"
    for index, entries in seen.items():
        options = {repr(sorted(o.items())) for _, o in entries}
        assert len(options) == 1, (index, entries)
