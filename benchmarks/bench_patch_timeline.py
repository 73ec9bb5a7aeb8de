"""Where a patch method's synthesis spends its time, per thread (issue 25; docs/benchmarks.md, "Threads").

Run ``python -m benchmarks.bench_patch_timeline --method quilting --size 1024 --threads 1,2 --runs 3``. Each
run is a fresh process, as a ``texsynth synthesize`` command's synthesis is: the method's modules imported
first (the command imports them before it reads the exemplar), then one :func:`texsynth.synth.api.synthesize`
on the HRTEM soot crop. The child wraps the ``thread_map`` that runs a wave's tasks (quilting's runs of
patches, the other methods' patches) and the copy map's query blocks, and records every task's thread,
wall and thread CPU, and the process CPU at each wave's start and end. Printed per run: process CPU
before the first wave (numba's first kernel load, the searcher, the layout), in the waves, between the
waves and the copy map, in its queries and after; the task CPU of each thread; and the sum over waves of
the gap between the first and the last thread to finish its tasks (waiting at the wave barrier); the
critical path: the process CPU with each ``thread_map`` call's CPU replaced by its busiest thread's (what
a quiet machine's wall would be if no thread waited for the GIL or a core); the scheduled path: the same
with each call's tasks dealt in order to the least busy of ``threads`` workers (what it would be if a
thread that cannot get a core under load did not leave its tasks to the others). CPU
figures hold under load; wall figures only on a quiet machine (the 1-minute load is printed). ``--warm``
times a second synthesis in each process (a service worker after its first job).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

_CHILD = """
import json, sys, threading, time
from texsynth.synth.threads import single_threaded_blas
single_threaded_blas()
import importlib
import texsynth.synth.evaluate.patches as copy_maps
import texsynth.synth.patch.layout as layout
from benchmarks._report import DATA
from texsynth.synth.api import synthesize
from texsynth.synth.io import load_image

method, size, threads, warm = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4] == "warm"
module = importlib.import_module("texsynth.synth.methods." + method.replace("-", "_"))
tasks, calls = [], []

def instrument(mod, kind):
    inner = mod.thread_map
    def wrapped(fn, items, count):
        def task(x):
            a, c = time.perf_counter(), time.thread_time()
            try:
                return fn(x)
            finally:
                tasks.append((kind, threading.get_ident(), a, time.perf_counter(), time.thread_time() - c))
        a, c = time.perf_counter(), time.process_time()
        try:
            return inner(task, items, count)
        finally:
            calls.append((kind, a, time.perf_counter(), c, time.process_time()))
    mod.thread_map = wrapped

# quilting's waves call thread_map itself; the others' through layout.patch_workers
instrument(module if method == "quilting" else layout, "wave")
instrument(copy_maps, "copy")
exemplar = load_image(DATA / "hrtem-soot-128.png")
if warm:  # a service worker's later job: numba's kernels loaded, the heap grown
    synthesize(method, exemplar, size=(size, size), seed=2, threads=threads)
    tasks.clear(), calls.clear()
c0, t0 = time.process_time(), time.perf_counter()
synthesize(method, exemplar, size=(size, size), seed=1, threads=threads)
c1, t1 = time.process_time(), time.perf_counter()
waves = [c for c in calls if c[0] == "wave"]
copies = [c for c in calls if c[0] == "copy"]
per_thread = {}
for kind, tid, a, b, cpu in tasks:
    per_thread.setdefault(kind, {}).setdefault(str(tid), 0.0)
    per_thread[kind][str(tid)] += cpu
barrier, path, scheduled = 0.0, 0.0, 0.0
for call_kind, a, b, ca, cb in calls:
    ends, spent, workers = {}, {}, [0.0] * threads
    for kind, tid, x, y, cpu in sorted(tasks, key=lambda t: t[2]):
        if kind == call_kind and a <= x <= b:
            ends[tid] = max(ends.get(tid, 0.0), y)
            spent[tid] = spent.get(tid, 0.0) + cpu
            workers[workers.index(min(workers))] += cpu  # list scheduling, in the tasks' order
    if call_kind == "wave" and len(ends) > 1:
        barrier += max(ends.values()) - min(ends.values())
    path += max(spent.values(), default=0.0) - (cb - ca)  # the call's busiest thread instead of its CPU
    scheduled += max(workers) - (cb - ca)
out = {
    "wall": t1 - t0,
    "cpu": c1 - c0,
    "before_waves": waves[0][3] - c0,
    "waves": sum(w[4] - w[3] for w in waves),
    "between_waves": (waves[-1][4] - waves[0][3]) - sum(w[4] - w[3] for w in waves),
    "to_copy": (copies[0][3] - waves[-1][4]) if copies else 0.0,
    "copy": (copies[0][4] - copies[0][3]) if copies else 0.0,
    "after": c1 - (copies[0][4] if copies else waves[-1][4]),
    "wave_tasks": sorted(per_thread.get("wave", {}).values(), reverse=True),
    "copy_tasks": sorted(per_thread.get("copy", {}).values(), reverse=True),
    "barrier_wait": barrier,
    "critical_path": c1 - c0 + path,
    "scheduled_path": c1 - c0 + scheduled,
    "wave_calls": len(waves),
}
print("TIMELINE " + json.dumps(out))
"""

FIELDS = (
    "cpu",
    "before_waves",
    "waves",
    "between_waves",
    "to_copy",
    "copy",
    "after",
    "critical_path",
    "scheduled_path",
    "barrier_wait",
    "wall",
)


def run(method: str, size: int, threads: int, warm: bool = False) -> dict[str, object]:
    """One fresh child process; its timeline (see the module docstring); ``warm``: of its second synthesis."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, method, str(size), str(threads), "warm" if warm else "fresh"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    line = next(x for x in done.stdout.splitlines() if x.startswith("TIMELINE "))
    got = json.loads(line.removeprefix("TIMELINE "))
    got["load"] = os.getloadavg()[0]
    return got


def _nth(values: object, k: int) -> float:
    """The ``k``-th largest per-thread CPU (0 when fewer threads took a task)."""
    return float(values[k]) if isinstance(values, list) and k < len(values) else 0.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    methods = ["quilting", "gaussian-patch", "feature-guided"]
    parser.add_argument("--method", default="quilting", choices=methods)
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--threads", default="1,2", help="comma-separated counts, alternated")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--warm", action="store_true", help="time each process's second synthesis")
    args = parser.parse_args(argv)
    counts = [int(t) for t in args.threads.split(",")]
    run(args.method, 64, counts[0])  # numba's cache on disk, as after any earlier run
    results: dict[int, list[dict[str, object]]] = {t: [] for t in counts}
    for _ in range(args.runs):
        for t in counts:
            results[t].append(run(args.method, args.size, t, args.warm))
    state = "a warm process's second synthesis" if args.warm else "fresh processes"
    print(f"{args.method} {args.size}^2, {state}, medians of {args.runs} (process CPU, s):")
    extra = " | wave-task CPU per thread | copy-map CPU per thread | load |"
    print("| threads | " + " | ".join(FIELDS) + extra)
    print("|---" * (len(FIELDS) + 4) + "|")
    for t, rows in results.items():
        med = [statistics.median(float(r[f]) for r in rows) for f in FIELDS]
        tasks = [statistics.median(_nth(r["wave_tasks"], k) for r in rows) for k in range(t)]
        copies = [statistics.median(_nth(r["copy_tasks"], k) for r in rows) for k in range(t)]
        loads = sorted(float(r["load"]) for r in rows)  # type: ignore[arg-type]
        cells = " | ".join(f"{v:.3f}" for v in med)
        task_text = " / ".join(f"{v:.3f}" for v in tasks)
        copy_text = " / ".join(f"{v:.3f}" for v in copies)
        print(f"| {t} | {cells} | {task_text} | {copy_text} | {loads[0]:.1f}-{loads[-1]:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
