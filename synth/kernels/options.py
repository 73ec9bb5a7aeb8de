"""The numba options of every kernel, written once.

``cache=True``: compiled kernels are kept on disk (``NUMBA_CACHE_DIR``), so a worker pays the
compilation once. ``error_model='numpy'``: division by zero gives ``inf``/``nan`` as in NumPy instead
of raising, which keeps the inner loops free of exception checks. ``fastmath`` stays off: it would
let LLVM reorder sums, and the same seed must give the same bytes on every run.

One body compiled with two option sets (a kernel on the calling thread and the same body on numba's
pool) needs two names: numba's cache file is named after the function and keys its entries by signature
alone, not by options (numba issue #6845), so the second compile would load the first one's code from
disk: a parallel kernel that runs on one thread. :func:`kernel` gives a later option set of one body a
copy of the function named after those options.
"""

from __future__ import annotations

import re
import types
from collections.abc import Callable
from typing import Any

from numba import njit

__all__ = ["NUMBA_OPTIONS", "cache_distinct", "kernel"]

NUMBA_OPTIONS: dict[str, Any] = {"cache": True, "error_model": "numpy"}


#: Each compiled body (its code object) and the options it was first compiled with.
_FIRST_OPTIONS: dict[types.CodeType, dict[str, Any]] = {}


def cache_distinct(function: Callable, options: dict[str, Any]) -> Callable:
    """``function`` itself the first time its body is compiled, or with the same options again; for other
    options, a copy whose name ends with them (``_body__parallel_True``), so that numba's cache keeps the
    two compiles apart (see the module docstring)."""
    code = function.__code__
    first = _FIRST_OPTIONS.setdefault(code, dict(options))
    if first == options:
        return function
    words = [f"{k}_{v}" for k, v in sorted(options.items()) if first.get(k, None) != v]
    words += [f"no_{k}" for k in sorted(first) if k not in options]
    suffix = "__" + re.sub(r"\W", "_", "_".join(words))
    copy = types.FunctionType(
        code, function.__globals__, function.__name__ + suffix, function.__defaults__, function.__closure__
    )
    copy.__qualname__ = function.__qualname__ + suffix
    copy.__module__ = function.__module__
    copy.__doc__ = function.__doc__
    copy.__kwdefaults__ = function.__kwdefaults__
    return copy


def kernel(function: Callable | None = None, **overrides: Any):
    """``@kernel`` or ``@kernel(inline='always')``: :func:`numba.njit` with :data:`NUMBA_OPTIONS`."""
    options = {**NUMBA_OPTIONS, **overrides}
    if function is not None:
        return njit(**options)(cache_distinct(function, options))
    return lambda f: njit(**options)(cache_distinct(f, options))
