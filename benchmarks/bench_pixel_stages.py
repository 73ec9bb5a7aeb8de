"""Per-stage, per-thread CPU of a pixel method's synthesis (issue 25): what runs on one core.

Run ``python -m benchmarks.bench_pixel_stages --method tensor-constrained --size 512 --threads 2``
(``--runs N``, ``--exemplar FILE``; default the HRTEM soot crop, seed 1). In one process, a warm
:func:`texsynth.synth.api.synthesize` (one untimed run first: numba's first load is not a stage) is
timed with the driver's stages wrapped (:mod:`texsynth.synth.pixel.synthesis`, the method's module):
each stage's wall time and the CPU time of the calling thread and of every other thread of the process
over it, from Linux's per-thread counters (``/proc/self/task/*/schedstat``, nanoseconds). A stage inside
another counts once, in the inner one; the passes are split by stage, level size and kind (raster:
tiles in waves; random). 'others' is the CPU of every other thread: numba's pool, the k-d tree's
workers and helper threads alive at the stage's end (a thread that ended inside the stage is not
counted: the sets made ahead, :func:`texsynth.synth.pixel.synthesis.sets_ahead`, show in the total
only). With 2 threads a stage whose 'others' is near zero ran on one core; 'calling' against
'others' in the passes is their balance; 'idle' is threads x wall less both (a quiet machine's waits: at
barriers, on one thread; OpenMP's short spin, ``GOMP_SPINCOUNT``, counts as CPU); the passes' parallel
levels (one barrier each) and balance (positions per thread over the biggest block's). Prints a table.
"""

from __future__ import annotations

import argparse
import collections
import functools
import hashlib
import itertools
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchmarks._report import DATA

#: Driver functions timed as stages, by module (the passes are labelled by stage and level, below).
STAGES = {
    "texsynth.synth.pixel.synthesis": [
        "_level_setup",
        "_level_sets",
        "kset_points",
        "_nearest_points",
        "_initial_sources",
        "_histogram_state",
        "tile_schedule",
        "schedule_levels",
        "scan_order",
        "synthesize_levels",
        "_search_seam",
    ],
    "texsynth.synth.methods.tensor_constrained": [
        "structure_tensor",
        "gaussian_pyramid",
        "orientation_labels",
        "synthesize_source_map",
        "tensor_features",
        "source_map_pyramid",
        "coherence",
        "orientation",
    ],
    "texsynth.synth.methods.wei_levoy": ["gaussian_pyramid", "synthesize_source_map"],
}


def _threads_cpu() -> dict[str, int]:
    """Nanoseconds on a CPU of every thread of this process, by thread id."""
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/schedstat") as f:
                out[tid] = int(f.read().split()[0])
        except OSError:
            continue
    return out


class StageClock:
    """Wraps functions; sums each stage's wall and CPU (calling thread, other threads), exclusive."""

    def __init__(self) -> None:
        self.me = str(threading.get_native_id())
        #: wall, CPU calling thread, CPU others, calls; for the passes: parallel levels, their positions,
        #: the positions of each level's biggest block (:func:`_blocks_of`)
        self.rows: dict[str, list[float]] = collections.defaultdict(lambda: [0.0] * 7)
        self.threads = 1
        self._stack: list[list[float]] = []
        self._stage = "synthesis"

    def wrap(self, module: Any, name: str) -> None:
        fn = getattr(module, name, None)
        if fn is None or getattr(fn, "_timed", False):
            return

        @functools.wraps(fn)
        def timed(*args: Any, **kwargs: Any) -> Any:
            if str(threading.get_native_id()) != self.me:
                return fn(*args, **kwargs)
            label = self._label(name, args, kwargs)
            before, start = _threads_cpu(), time.perf_counter()
            self._stack.append([0.0, 0.0, 0.0])
            try:
                return fn(*args, **kwargs)
            finally:
                wall, after = time.perf_counter() - start, _threads_cpu()
                inner = self._stack.pop()
                mine = (after.get(self.me, 0) - before.get(self.me, 0)) / 1e9
                others = sum(v - before.get(t, 0) for t, v in after.items() if t != self.me) / 1e9
                row = self.rows[label]
                row[0] += wall - inner[0]
                row[1] += mine - inner[1]
                row[2] += others - inner[2]
                row[3] += 1
                if name == "synthesize_levels":
                    for i, v in enumerate(_blocks_of(args[1], args[2], args[3], self.threads)):
                        row[4 + i] += v
                if self._stack:
                    for i, v in enumerate((wall, mine, others)):
                        self._stack[-1][i] += v

        timed._timed = True  # type: ignore[attr-defined]
        setattr(module, name, timed)

    def _label(self, name: str, args: tuple, kwargs: dict) -> str:
        if name == "synthesize_source_map":
            self._stage = kwargs.get("stage", "synthesis")
        if name != "synthesize_levels":
            return name
        state, schedule = args[0], args[1]
        h, w = state.run.done.shape
        kind = "raster" if len(schedule.units) - 1 < h * w else "random"
        return f"passes: {self._stage} {h}x{w} {kind}"


def _blocks_of(schedule: Any, lo: int, hi: int, blocks: int) -> tuple[int, int, int]:
    """Levels ``lo:hi`` of ``schedule`` as the kernel runs them on ``blocks`` threads: the levels run in
    parallel, their positions and the sum over them of the biggest block's positions (whole units split
    at the boundary nearest each share, as ``_block_edge``; positions / blocks / that = the balance)."""
    import numpy as np

    from texsynth.synth.kernels.pixel_search import PARALLEL_MIN_LEVEL

    units, starts = schedule.units, schedule.starts
    span = int(units[starts[hi]] - units[starts[lo]])
    if blocks < 2 or span < PARALLEL_MIN_LEVEL * max(1, hi - lo):
        return 0, 0, 0
    positions = biggest = 0
    for level in range(lo, hi):
        a, z = int(starts[level]), int(starts[level + 1])
        first, total = int(units[a]), int(units[z] - units[a])
        edges = []
        for b in range(blocks + 1):
            target = first + (b * total) // blocks
            i = a + int(np.searchsorted(units[a : z + 1], target))
            if i > a and target - units[i - 1] < units[i] - target:
                i -= 1
            edges.append(int(units[i]))
        positions += total
        biggest += max(e1 - e0 for e0, e1 in itertools.pairwise(edges))
    return hi - lo, positions, biggest


def measure(method: str, size: int, threads: int, runs: int, exemplar: Path) -> tuple[str, dict, float]:
    """Per-stage rows (summed over ``runs``), the output digest and the whole synthesis' figures."""
    import importlib

    from texsynth.synth.api import synthesize
    from texsynth.synth.io import load_image

    clock = StageClock()
    clock.threads = threads
    for module_name, names in STAGES.items():
        module = importlib.import_module(module_name)
        for name in names:
            clock.wrap(module, name)
    image = load_image(exemplar)
    run: Callable[[], Any] = lambda: synthesize(method, image, size=(size, size), seed=1, threads=threads)  # noqa: E731
    run()  # numba's first load and the kernels' caches
    clock.rows.clear()
    before, start = _threads_cpu(), time.perf_counter()
    for _ in range(runs):
        result = run()
    wall, after = time.perf_counter() - start, _threads_cpu()
    total = {
        "wall": wall / runs,
        "calling": (after[clock.me] - before[clock.me]) / 1e9 / runs,
        "others": sum(v - before.get(t, 0) for t, v in after.items() if t != clock.me) / 1e9 / runs,
    }
    digest = hashlib.sha256(result.image.tobytes()).hexdigest()[:16]
    return digest, {"rows": dict(clock.rows), "total": total}, os.getloadavg()[0]


def main(argv: list[str] | None = None) -> None:
    from texsynth.synth.threads import single_threaded_blas

    single_threaded_blas()  # as the texsynth command does, before NumPy loads OpenBLAS
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="tensor-constrained")
    parser.add_argument("--size", type=int, default=512, help="output side (square)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--runs", type=int, default=3, help="timed runs (summed, shown per run)")
    parser.add_argument("--exemplar", type=Path, default=DATA / "hrtem-soot-128.png")
    args = parser.parse_args(argv)
    load0 = os.getloadavg()[0]
    digest, found, load1 = measure(args.method, args.size, args.threads, args.runs, args.exemplar)
    t = found["total"]
    print(
        f"{args.method} {args.size}^2, {args.threads} threads, {args.runs} runs,"
        f" load {load0:.1f} -> {load1:.1f}, output {digest}; per run: wall {t['wall']:.3f} s,"
        f" CPU calling thread {t['calling']:.3f} s, other threads {t['others']:.3f} s,"
        f" idle {args.threads * t['wall'] - t['calling'] - t['others']:.3f} core-s"
    )
    print(
        "| stage | calls | wall (s) | CPU calling thread (s) | CPU other threads (s) | idle (core-s)"
        " | parallel levels | balance |"
    )
    print("|---|---|---|---|---|---|---|---|")
    n = args.runs
    for label, (wall, mine, others, calls, levels, positions, biggest) in sorted(
        found["rows"].items(), key=lambda kv: -kv[1][1] - kv[1][2]
    ):
        if mine + others < 0.001 * n and wall < 0.001 * n:
            continue
        idle = args.threads * wall - mine - others
        balance = f"{positions / args.threads / biggest:.3f}" if biggest else ""
        print(
            f"| {label} | {int(calls) // n} | {wall / n:.3f} | {mine / n:.3f} | {others / n:.3f}"
            f" | {idle / n:.3f} | {int(levels) // n or ''} | {balance} |"
        )


if __name__ == "__main__":
    main()
