"""The one place that sets thread counts: numba's per job (the ``threads`` knob), OpenBLAS's to one.

**numba.** A job runs its parallel kernels (``prange``) on ``threads`` threads: ``--threads N`` on
``texsynth synthesize``/``evaluate``, ``threads=`` in :func:`texsynth.synth.api.synthesize` and the evaluation
entry points, ``TEXSYNTH_THREADS`` in the service. The default is every core this process may use
(CLI, API); the service divides the cores between its worker processes (:func:`service_threads`).
The bytes never depend on the count (DESIGN.md, "Parallel and deterministic"): parallel loops write
only their own slots, draw random numbers from counter-based hashes
(:func:`texsynth.synth.kernels.common.splitmix`) and reduce in a fixed order; ``tests/synth/test_threads.py``
checks every method with 1, 2 and 4. numba's count is per calling thread and capped by its pool
(``NUMBA_NUM_THREADS``, cores by default), so :func:`use_threads` is entered in the thread that runs the work.

**OpenBLAS.** The engine's matrix work is small (the k-coherence PCA of a few thousand neighbourhoods
of at most a few hundred values), where OpenBLAS's threads cost more than they give and, on a shared
2-core machine, spin against the other work (docs/benchmarks.md, "The whole command"). The entry
points call :func:`single_threaded_blas` before NumPy loads OpenBLAS: the ``texsynth`` command (and so
the workers ``texsynth serve`` starts), ``python -m worker`` and the benchmarks that time the engine.
A value already in the environment wins. This module imports nothing heavy (numba when first used).
"""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

from texsynth.synth.errors import InvalidParameter

__all__ = [
    "BLAS_THREADS",
    "OMP_WAIT",
    "THREADS_ENV",
    "available_cores",
    "check_threads",
    "current_threads",
    "max_threads",
    "service_threads",
    "single_threaded_blas",
    "thread_map",
    "use_threads",
]

T = TypeVar("T")
R = TypeVar("R")

#: The environment variable OpenBLAS reads its thread count from, once, when NumPy loads it.
BLAS_THREADS = "OPENBLAS_NUM_THREADS"

_NESTED = threading.local()  # how many use_threads blocks the calling thread is inside
_IN_TASK = threading.local()  # whether the calling thread is running a task of thread_map

#: The service's knob: threads of one job (default: the cores divided between the worker processes).
THREADS_ENV = "TEXSYNTH_THREADS"


#: How OpenMP's idle threads wait (numba's ``omp`` threading layer): ``passive`` sleeps instead of spinning.
OMP_WAIT = "OMP_WAIT_POLICY"


def single_threaded_blas() -> None:
    """Ask for one OpenBLAS thread, and OpenMP threads that sleep while they wait, unless the
    environment already says; call before importing NumPy.

    Spinning threads burn a core the other jobs of a shared machine need: solid-chen-wang 64^3 with 2
    threads under load 5 took 7.5-8.7 s of CPU and 11.6-13.1 s wall spinning, 5.4-5.5 s and 8.5 s
    passive (docs/benchmarks.md, "Threads"). Same bytes either way.
    """
    os.environ.setdefault(BLAS_THREADS, "1")
    os.environ.setdefault(OMP_WAIT, "passive")


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system tells, else the CPU count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def max_threads() -> int:
    """The most threads a job can have in this process: numba's pool (``NUMBA_NUM_THREADS``)."""
    import numba

    return int(numba.config.NUMBA_NUM_THREADS)


def current_threads() -> int:
    """The thread count of the work running now (numba's, as :func:`use_threads` set it): what other
    parallel libraries take (SciPy's ``cKDTree.query(workers=...)``), so that the knob holds for them too."""
    import numba

    return int(numba.get_num_threads())


_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()


def _forget_pools() -> None:
    """In a forked child: the parent's helper threads do not exist there, so their pools are dropped."""
    global _POOLS_LOCK
    _POOLS.clear()
    _POOLS_LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pools)


def _helpers(count: int) -> ThreadPoolExecutor:
    """This process's pool of ``count`` helper threads, started at first use and kept (one per count)."""
    with _POOLS_LOCK:
        pool = _POOLS.get(count)
        if pool is None:
            pool = _POOLS[count] = ThreadPoolExecutor(count, thread_name_prefix=f"texsynth-{count}")
        return pool


def thread_map(fn: Callable[[T], R], items: Sequence[T], threads: int) -> list[R]:
    """``[fn(x) for x in items]`` on ``threads`` Python threads: the calling thread and ``threads - 1``
    helpers take the items one at a time, so work outside numba that releases the GIL (NumPy, SciPy's
    FFT and k-d tree: the patch methods' waves, the copy map) runs on the job's cores.

    The helpers are started at their first use and kept: a job does not pay for starting threads, and
    their CPU time stays in Linux's per-thread counters (the benchmarks' busiest thread). The results
    are in ``items``' order whichever thread computed them. A call made inside a task of another runs its
    items in line (a helper waiting on its own pool would wait for ever). The first exception of ``fn`` is
    raised here (the other threads stop taking items).
    """
    n = len(items)
    helpers = min(int(threads), n) - 1
    if helpers <= 0 or getattr(_IN_TASK, "on", False):
        return [fn(x) for x in items]
    out: list[Any] = [None] * n
    errors: list[BaseException] = []
    ticket = itertools.count()  # next() on a count is atomic under the GIL

    def work() -> None:
        _IN_TASK.on = True
        try:
            while not errors and (k := next(ticket)) < n:
                try:
                    out[k] = fn(items[k])
                except BaseException as err:  # raised again in the calling thread
                    errors.append(err)
        finally:
            _IN_TASK.on = False

    pool = _helpers(int(threads) - 1)
    futures = [pool.submit(work) for _ in range(helpers)]
    work()
    for f in futures:
        f.result()
    if errors:
        raise errors[0]
    return out


def check_threads(value: Any, name: str = "threads") -> int | None:
    """``value`` as a thread count (``None`` stays ``None``: the default), or :class:`InvalidParameter`.

    A count is a whole number from 1 to :func:`max_threads`; ``name`` is the field the message names.
    """
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int):
        try:
            if isinstance(value, bool) or float(value) != int(value):
                raise ValueError
            value = int(value)
        except (TypeError, ValueError, OverflowError):
            raise InvalidParameter(name, value, "must be a whole number of threads, 1 or more") from None
    top = max_threads()
    if not 1 <= value <= top:
        raise InvalidParameter(
            name,
            value,
            f"must be from 1 to {top} (NUMBA_NUM_THREADS; this machine has {available_cores()} cores)",
        )
    return int(value)


@contextmanager
def use_threads(threads: int | None) -> Iterator[int]:
    """Run the enclosed work with ``threads`` numba threads (``None``: the default).

    The default is every thread of the pool, except inside another :func:`use_threads` block of the
    same thread, whose count it keeps (``synthesize_to_folder(threads=1)`` calls ``synthesize()``).
    Validated as :func:`check_threads`; the previous count is restored on exit. Yields the count.
    """
    import numba

    count = check_threads(threads)
    depth = getattr(_NESTED, "depth", 0)
    before = numba.get_num_threads()
    if count is None:
        count = before if depth else max_threads()
    numba.set_num_threads(count)
    _NESTED.depth = depth + 1
    try:
        yield count
    finally:
        _NESTED.depth = depth
        numba.set_num_threads(before)


def service_threads(concurrency: int, threads: int | str | None = None) -> int:
    """Threads of one service job: ``threads`` (``TEXSYNTH_THREADS``) when set, else the cores divided
    between the ``concurrency`` worker processes (at least one each), so that processes x threads <= cores.

    A value that is not a whole number from 1 to numba's pool (``NUMBA_NUM_THREADS``, else the CPU
    count) raises :class:`InvalidParameter` naming ``TEXSYNTH_THREADS``: the service stops at start.
    """
    if threads is None or (isinstance(threads, str) and not threads.strip()):
        return max(1, available_cores() // max(1, int(concurrency)))
    raw = os.environ.get("NUMBA_NUM_THREADS", "").strip()
    pool = int(raw) if raw.isdigit() and int(raw) > 0 else max(1, os.cpu_count() or 1)
    try:
        value = int(str(threads).strip())
    except ValueError:
        value = 0
    if not 1 <= value <= pool:
        raise InvalidParameter(
            THREADS_ENV, threads, f"must be a whole number from 1 to {pool} (NUMBA_NUM_THREADS, else CPUs)"
        )
    return value
