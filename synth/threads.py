"""The one place that sets the BLAS thread count: OpenBLAS single-threaded in every texsynth process.

The engine's matrix work is small (the k-coherence PCA of a few thousand neighbourhoods of at most a
few hundred values), where OpenBLAS's threads cost more than they give and, on a shared 2-core
machine, spin against the other work (docs/benchmarks.md, "The whole command"). The bytes are the
same whatever the count (``tests/synth/cli/test_cli_synthesize.py``). The entry points call
:func:`single_threaded_blas` before NumPy loads OpenBLAS: the ``texsynth`` command (and so the
workers ``texsynth serve`` starts), ``python -m worker`` and the benchmarks that time the engine. A
value already in the environment wins. This module imports nothing heavy.
"""

from __future__ import annotations

import os

__all__ = ["BLAS_THREADS", "single_threaded_blas"]

#: The environment variable OpenBLAS reads its thread count from, once, when NumPy loads it.
BLAS_THREADS = "OPENBLAS_NUM_THREADS"


def single_threaded_blas() -> None:
    """Ask for one OpenBLAS thread unless the environment already says; call before importing NumPy."""
    os.environ.setdefault(BLAS_THREADS, "1")
