"""Speed-up from 1 to 2 threads (issue 25): whole ``texsynth synthesize`` processes and the synthesis alone.

Run ``python -m benchmarks.bench_threads`` (``--runs N``, ``--cases kopf-64,tensor-512,...``); writes the
``threads`` (volumes) and ``threads-2d`` sections of docs/benchmarks.md. Each run is a fresh ``python -m
texsynth.synth.cli synthesize METHOD --threads N`` process on the real HRTEM soot crop
(``hrtem-soot-128.png``; a generated laminae pattern when ``../shared/data`` is absent), plots off, every
other artifact written (the volume's evaluation included). The child wraps
:func:`texsynth.synth.pipeline.synthesize` to time the synthesis alone (wall and CPU of the process, the
only threads then at work being the job's); the parent times the whole process (wall from start to exit,
CPU from ``os.wait4``: all threads, user + system). One untimed run first (numba's cache on disk, as after
any earlier run of the user's), then runs with 1 and 2 threads alternated (1, 2, 2, 1, 1, 2, ...) so that
both see the same load; medians. The 1-minute load average is read before and after every run and
reported: on a machine shared with other jobs, a 2-thread run cannot get two cores, and the wall-time
speed-up is then a floor (CPU time says what the work costs; its growth from 1 to 2 threads is the
parallel overhead). The bytes of every run are compared: the same with 1 and 2 threads. The CPU time of
the synthesis' busiest thread (Linux's per-thread counters) gives a speed-up estimate that the load
inflates less (see the section's note). ``--stages N`` instead prints solid-kopf's stages per level at ``N``
threads in this process (:func:`stage_table`): which of them run on the calling thread alone.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from benchmarks._report import DATA, machine, write_section

ROOT = Path(__file__).resolve().parent.parent
#: name -> (method, size WxHxD)
CASES = {
    "kopf-64": ("solid-kopf", "64x64x64"),
    "kopf-128": ("solid-kopf", "128x128x128"),
    "chen-wang-64": ("solid-chen-wang", "64x64x64"),
    "solid-wei-levoy-64": ("solid-wei-levoy", "64x64x64"),
    # The 2D methods (their own section, threads-2d): one line a case.
    "wei-levoy-512": ("wei-levoy", "512x512"),
    "tensor-512": ("tensor-constrained", "512x512"),
    "arbitrary-shape-256": ("arbitrary-shape", "256x256"),
    # the patch methods (waves of disjoint patches on the job's threads, docs/patch.md)
    "quilting-1024": ("quilting", "1024x1024"),
    "gaussian-patch-512": ("gaussian-patch", "512x512"),
    "feature-guided-512": ("feature-guided", "512x512"),
    # random phase: FFTs of the output's size (scipy.fft on the job's threads)
    "random-phase-1024": ("random-phase", "1024x1024"),
}
#: Methods that need a constraint image: a generated one of the output's size (undulating rings).
CONSTRAINED = {"arbitrary-shape"}

_CHILD = """
import json, os, sys, time
from texsynth.synth.threads import single_threaded_blas
single_threaded_blas()  # before NumPy loads, as the texsynth command does (else OpenBLAS spins a thread)
import texsynth.synth.pipeline as pipeline
from texsynth.synth.cli import main

inner = pipeline.synthesize
spent = {}
tick = os.sysconf("SC_CLK_TCK")

def per_thread():
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            fields = open(f"/proc/self/task/{tid}/stat").read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[tid] = (int(fields[11]) + int(fields[12])) / tick
    return out

def timed(*args, **kwargs):
    wall, cpu, threads = time.perf_counter(), time.process_time(), per_thread()
    try:
        return inner(*args, **kwargs)
    finally:
        spent["wall"], spent["cpu"] = time.perf_counter() - wall, time.process_time() - cpu
        after = per_thread()
        spent["busiest"] = max(after[t] - threads.get(t, 0.0) for t in after)

pipeline.synthesize = timed
# ends as the texsynth program does (its quick exit, where the tree has one); the figures at exit
import atexit
atexit.register(lambda: print("SYNTHESIS " + json.dumps(spent), flush=True))
sys.argv = ["texsynth", *sys.argv[1:]]
import texsynth.synth.cli as cli
if hasattr(cli, "entry"):
    cli.entry()
sys.exit(main(sys.argv[1:]))
"""


def _exemplar(folder: Path) -> Path:
    soot = DATA / "hrtem-soot-128.png"
    if soot.is_file():
        return soot
    from texsynth.synth.io import save_image
    from texsynth.synth.io.patterns import undulating_laminae

    path = folder / "laminae-128.png"
    save_image(path, undulating_laminae((128, 128)))
    return path


def _constraint(folder: Path, size: str) -> Path:
    """Concentric, undulating rings of the output's size (period 12 px): a constraint for arbitrary-shape."""
    import numpy as np

    from texsynth.synth.io import save_image

    w, h = (int(v) for v in size.split("x")[:2])
    path = folder / f"rings-{w}x{h}.png"
    if not path.is_file():
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r = np.hypot(yy - h / 2, xx - w / 2) + 4.0 * np.sin(np.arctan2(yy - h / 2, xx - w / 2) * 5)
        save_image(path, (0.5 + 0.5 * np.sin(2 * np.pi * r / 12.0)).astype(np.float32))
    return path


def _load() -> float:
    return os.getloadavg()[0]


def run_once(method: str, size: str, threads: int, exemplar: Path, folder: Path) -> dict[str, float | str]:
    """One whole process: wall, CPU (all threads), the synthesis' wall and CPU, load, output digest."""
    out = folder / f"out-{threads}"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    words = ["synthesize", method, "--exemplar", str(exemplar), "--size", size, "--seed", "1"]
    words += ["--no-plots", "--threads", str(threads), "--out", str(out)]
    if method in CONSTRAINED:
        words += ["--constraint", str(_constraint(folder, size))]
    load_before = _load()
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-c", _CHILD, *words],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    stdout = proc.stdout.read() if proc.stdout else ""
    stderr = proc.stderr.read() if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{method} {size} --threads {threads} failed: {stderr.strip()[-400:]}")
    line = next(x for x in stdout.splitlines() if x.startswith("SYNTHESIS "))
    spent = json.loads(line.removeprefix("SYNTHESIS "))
    digest = hashlib.sha256((out / "output.tiff").read_bytes()).hexdigest()
    return {
        "wall": wall,
        "cpu": usage.ru_utime + usage.ru_stime,
        "synthesis_wall": spent["wall"],
        "synthesis_cpu": spent["cpu"],
        "synthesis_busiest": spent["busiest"],
        "load": max(load_before, _load()),
        "digest": digest,
    }


def measure(name: str, runs: int, folder: Path, exemplar: Path) -> dict[str, object]:
    """Paired runs of one case with 1 and 2 threads: medians per thread count, loads, same bytes."""
    method, size = CASES[name]
    run_once(method, size, 2, exemplar, folder)  # untimed: numba's cache and bytecode on disk
    rows: dict[int, list[dict[str, float | str]]] = {1: [], 2: []}
    for i in range(runs):
        for threads in (1, 2) if i % 2 == 0 else (2, 1):
            rows[threads].append(run_once(method, size, threads, exemplar, folder))
            print(f"{name} threads={threads}: {rows[threads][-1]}", flush=True)
    keys = ("wall", "cpu", "synthesis_wall", "synthesis_cpu", "synthesis_busiest")
    med = {t: {k: statistics.median(float(r[k]) for r in rows[t]) for k in keys} for t in rows}
    loads = [float(r["load"]) for t in rows for r in rows[t]]
    digests = {str(r["digest"]) for t in rows for r in rows[t]}
    return {
        "case": name,
        "method": method,
        "size": size,
        "runs": runs,
        "median": med,
        "load": (min(loads), statistics.median(loads), max(loads)),
        "same_bytes": len(digests) == 1,
    }


def report(results: list[dict[str, object]], title: str = "") -> str:
    lines = [
        f"## Threads: 1 -> 2{title} (`python -m benchmarks.bench_threads`)",
        "",
        "Whole `texsynth synthesize METHOD --threads N --no-plots` processes on `hrtem-soot-128.png`"
        " (seed 1), 1 and 2 threads alternated, medians; CPU = user + system of all the process's"
        " threads. 'Synthesis' is `texsynth.synth.api.synthesize` alone inside the same process. Speed-up ="
        " wall(1) / wall(2). Load = 1-minute load average (min / median / max over the runs) on this"
        " 2-core machine: above about 1, the 2-thread runs could not have both cores, so their speed-up"
        " is a floor. 'Busiest thread' is the CPU time of the synthesis' busiest thread (from"
        " /proc/self/task): what its wall time would be with a core per thread and nothing else running,"
        " so CPU(1) / busiest(2) estimates the speed-up of a quiet machine (it leaves out the time a"
        " thread waits for another, which overstates; under load the OpenMP threads' spin while they"
        " wait counts in the busiest thread's time, which understates).",
        "",
        "| case | runs | whole wall 1 / 2 threads | speed-up | whole CPU 1 / 2 | synthesis wall 1 / 2 |"
        " speed-up | synthesis CPU 1 / 2 | busiest thread at 2 | CPU(1) / busiest(2) | load | same bytes |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        m = r["median"]
        assert isinstance(m, dict)
        one, two = m[1], m[2]
        lo, mid, hi = r["load"]  # type: ignore[misc]
        lines.append(
            f"| {r['method']} {r['size']} | {r['runs']} | {one['wall']:.1f} / {two['wall']:.1f} s |"
            f" {one['wall'] / two['wall']:.2f}x | {one['cpu']:.1f} / {two['cpu']:.1f} s |"
            f" {one['synthesis_wall']:.1f} / {two['synthesis_wall']:.1f} s |"
            f" {one['synthesis_wall'] / two['synthesis_wall']:.2f}x |"
            f" {one['synthesis_cpu']:.1f} / {two['synthesis_cpu']:.1f} s | {two['synthesis_busiest']:.1f} s |"
            f" {one['synthesis_cpu'] / two['synthesis_busiest']:.2f}x |"
            f" {lo:.1f} / {mid:.1f} / {hi:.1f} | {'yes' if r['same_bytes'] else 'NO'} |"
        )
    return "\n".join(lines)


#: ``--stages``: what is timed in a solid-kopf run, per level (function names in solid_kopf's namespace).
STAGES = (
    "structure_schedule",
    "_mixed",
    "start_kind",
    "plan_levels",
    "laminar_phase",
    "initial_volume",
    "initial_sources",
    "upsample_volume",
    "upsample_plane_sources",
    "orientation_labels",
    "gather_plane",
    "search_plane",
    "dense_sources",
    "_position_factors",
    "_orientation_factors",
    "scan_order",
    "irls_update",
    "best_vote",
    "slice_coherence",
    "match_histogram",
)


def stage_table(exemplar: Path, side: int, threads: int, runs: int) -> str:
    """Per stage and level of ``runs`` in-process solid-kopf ``side^3`` runs (seed 1, ``threads``): wall,
    CPU of every thread, the calling thread's CPU, and the idle core-seconds ``threads * wall - CPU``
    (a stage whose CPU is the calling thread's alone ran on one core). Times are exclusive of the stages
    inside a stage; the exemplar tables are built anew each run (cache cleared); '(rest)' is the Python
    between the stages; a stage on the prefetch thread is marked '(helper thread)' (its 'calling thread'
    column is that thread's CPU). Run it where nothing else runs: another process's work shows as idle."""
    from texsynth.synth.threads import single_threaded_blas

    single_threaded_blas()
    import numpy as np  # noqa: F401  (after the BLAS setting)

    import texsynth.synth.methods.solid_kopf as kopf
    import texsynth.synth.pixel.solid as solid
    from texsynth.synth.api import synthesize
    from texsynth.synth.io import load_image

    image = load_image(exemplar)
    table: dict[tuple[str, str], list[float]] = {}
    level = ["start"]
    local = threading.local()  # each thread's stack of open stages
    caller = threading.get_ident()

    def wrap(owner: object, name: str, label: str | None = None) -> None:
        inner = getattr(owner, name)

        def timed(*args: object, **kwargs: object) -> object:
            if name == "start_level":
                level[0] = f"level {args[1].level + 1}"  # type: ignore[attr-defined]
            stack = local.__dict__.setdefault("stack", [])
            t, c, m = time.perf_counter(), time.process_time(), time.thread_time()
            stack.append([0.0, 0.0, 0.0])
            try:
                return inner(*args, **kwargs)
            finally:
                dt, dc, dm = time.perf_counter() - t, time.process_time() - c, time.thread_time() - m
                nested = stack.pop()
                where = level[0] if threading.get_ident() == caller else f"{level[0]} (helper thread)"
                row = table.setdefault((where, label or name), [0.0, 0.0, 0.0, 0.0])
                row[0] += 1
                row[1] += dt - nested[0]
                row[2] += dc - nested[1]
                row[3] += dm - nested[2]
                if stack:
                    stack[-1][0] += dt
                    stack[-1][1] += dc
                    stack[-1][2] += dm

        setattr(owner, name, timed)

    for name in STAGES:
        if hasattr(kopf, name):
            wrap(kopf, name)
    wrap(solid, "_build_neighbourhoods", "exemplar tables (PCA, k-d tree, k-coherence sets)")
    wrap(kopf.HistogramState, "start", "histogram start")
    for name in ("start_level", "iterate", "end_level", "result"):
        wrap(kopf._KopfLoop, name, f"{name} (rest)")
    wrap(kopf, "_run_solid_kopf", "run (rest)")
    synthesize("solid-kopf", image, size=(16, 16, 16), seed=1, threads=threads)  # kernels loaded
    table.clear()
    walls = []
    for _ in range(runs):
        solid._BUILT.clear()
        level[0] = "start"
        t, c = time.perf_counter(), time.process_time()
        synthesize("solid-kopf", image, size=(side,) * 3, seed=1, threads=threads)
        walls.append((time.perf_counter() - t, time.process_time() - c))
    wall = statistics.median(w for w, _ in walls)
    cpu = statistics.median(c for _, c in walls)
    lines = [
        f"solid-kopf {side}^3 from {exemplar.name}, {threads} threads, {runs} runs: synthesis {wall:.2f} s"
        f" wall, {cpu:.2f} s CPU ({cpu / wall:.2f} cores), load {_load():.1f}; per run:",
        "",
        "| level | stage | calls | wall (s) | CPU (s) | calling thread (s) | others (s) | idle core-s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (lv, name), (n, w, c, m) in sorted(table.items(), key=lambda kv: -kv[1][1]):
        if w / runs < 0.002:
            continue
        lines.append(
            f"| {lv} | {name} | {n / runs:.0f} | {w / runs:.3f} | {c / runs:.3f} | {m / runs:.3f} |"
            f" {(c - m) / runs:.3f} | {(threads * w - c) / runs:.3f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="runs per thread count (default 3)")
    parser.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {', '.join(CASES)}")
    parser.add_argument("--no-write", action="store_true", help="print the table, leave the docs alone")
    parser.add_argument(
        "--stages",
        type=int,
        metavar="THREADS",
        help="instead: solid-kopf's per-stage, per-level table at this many threads, in this process (the"
        " kopf-64 / kopf-128 cases; --runs runs); prints, writes nothing",
    )
    args = parser.parse_args(argv)
    if args.stages is not None:
        with tempfile.TemporaryDirectory(prefix="bench-threads-") as tmp:
            exemplar = _exemplar(Path(tmp))
            for name in args.cases.split(","):
                if name.strip() in ("kopf-64", "kopf-128"):
                    side = int(CASES[name.strip()][1].split("x")[0])
                    print(stage_table(exemplar, side, args.stages, args.runs) + "\n")
        return 0
    names = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = [c for c in names if c not in CASES]
    if unknown:
        parser.error(f"unknown cases: {', '.join(unknown)}")
    results = []
    with tempfile.TemporaryDirectory(prefix="bench-threads-") as tmp:
        folder = Path(tmp)
        exemplar = _exemplar(folder)
        for name in names:
            results.append(measure(name, args.runs, folder, exemplar))
    print(machine())
    # The volumes' rows and the images' rows are separate sections: a run of one family keeps the other's.
    for section, family in (("threads", True), ("threads-2d", False)):
        rows = [r for r in results if (str(r["size"]).count("x") == 2) == family]
        if not rows:
            continue
        table = report(rows, title="" if family else ", 2D methods")
        print(table)
        if not args.no_write:
            write_section(section, table)
    return 0 if all(r["same_bytes"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
