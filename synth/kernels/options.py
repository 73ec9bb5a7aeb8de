"""The numba options of every kernel, written once.

``cache=True``: compiled kernels are kept on disk (``NUMBA_CACHE_DIR``), so a worker pays the
compilation once. ``error_model='numpy'``: division by zero gives ``inf``/``nan`` as in NumPy instead
of raising, which keeps the inner loops free of exception checks. ``fastmath`` stays off: it would
let LLVM reorder sums, and the same seed must give the same bytes on every run.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from numba import njit

__all__ = ["NUMBA_OPTIONS", "kernel"]

NUMBA_OPTIONS: dict[str, Any] = {"cache": True, "error_model": "numpy"}


def kernel(function: Callable | None = None, **overrides: Any):
    """``@kernel`` or ``@kernel(inline='always')``: :func:`numba.njit` with :data:`NUMBA_OPTIONS`."""
    options = {**NUMBA_OPTIONS, **overrides}
    if function is not None:
        return njit(**options)(function)
    return njit(**options)
