"""Where a whole ``texsynth synthesize`` command spends its time outside the synthesis, by stage (issue 25).

Run ``python -m benchmarks.bench_overhead`` (``--runs N``, ``--threads N``, ``--cases``, ``--baseline DIR``,
``--json PATH``, ``--no-write``); writes the ``overhead-stages`` section of docs/benchmarks.md.

Each run is a fresh interpreter that runs the ``texsynth`` program's entry (``texsynth.synth.cli.entry``, else
``main``) on the command's own arguments (so it imports and runs what ``texsynth synthesize`` does), after
installing probes: every
top-level import (``importlib._bootstrap._find_and_load``), numba's first call of each kernel
(``Dispatcher._compile_for_args``: the cache load and type dispatch), and the engine's stages (loading the
inputs, the synthesis, the output PNG/TIFF, the tensor images, the exemplar's analysis, the evaluation,
the plots, the JSON files). Times are exclusive: a stage's own seconds, without the imports or kernel loads
or inner stages that ran inside it, so the stages add up to the run (the writer's second thread's stages
count in its own CPU time, and leave the main thread's; an import or a kernel's cache load counts its own
thread's CPU, what the job's other threads did meanwhile staying with the stage around it, the synthesis
mostly); 'start + exit' is the process's wall
time outside ``main`` (interpreter start, shutdown). Wall (``perf_counter``) and CPU (``process_time``,
every thread) are both kept: on this shared 2-core machine the CPU seconds say what the work costs,
whatever else runs. One untimed run per case first (numba's cache and the bytecode on disk, as after a
user's first run; ``PYTHONDONTWRITEBYTECODE`` is dropped from the children's environment); then ``--runs``
runs, medians per stage. ``--baseline DIR`` (an earlier checkout: ``git archive REV | tar -x -C DIR``)
runs the same cases alternately with this tree for a before -> after table, and compares the two trees'
last outputs file by file (bytes; the JSON files without their clock fields). After each probed run the
same command runs bare: its whole process less the probed synthesis is 'outside' without the probe.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._report import machine, write_section

ROOT = Path(__file__).resolve().parent.parent
ONION = ROOT / "benchmarks" / "data" / "hrtem-onion-128.png"
#: docs/quality.md's exemplars (``benchmarks.bench_quality.exemplars``' names).
QUALITY = ("grass", "gravel", "brick", "hrtem-soot-128", "laminae-bent-128", "wood-grain-128")
#: Target (issue 25): outside the synthesis, a 256^2 command costs at most this, on every exemplar.
TARGET = 1.0
#: The stages in the table's order; 'synthesis' is the one the target leaves out.
STAGES = (
    "start + exit",
    "imports",
    "parse, load inputs",
    "kernel first calls",
    "synthesis",
    "output PNG/TIFF",
    "tensor images",
    "exemplar analysis",
    "evaluation",
    "plots",
    "JSON files",
    "other",
)

#: Run in a child: ``argv[1]`` = a JSON list of the command's arguments, ``argv[2]`` = a file to write the
#: main thread's stage changes to, or ``-``. Prints the stages as JSON.
_PROBE = r"""
import importlib._bootstrap as bootstrap, json, sys, threading, time
MAIN = threading.main_thread()
TIMED_PATH = sys.argv[2]  # where to write the timeline (JSON), else "-"
TIMED = TIMED_PATH != "-"
# CPU of a stage: on the main thread the process's (numba's workers work for it) less what the writer's
# second thread spent meanwhile (its live clock while it is inside a stage); on that thread its own
helpers, helpers_done = {}, [0.0]

def cpu():
    if threading.current_thread() is MAIN:
        live = sum(time.clock_gettime(c) - c0 for c, c0 in list(helpers.values()))
        return time.process_time() - helpers_done[0] - live
    return time.thread_time()

#: Stages that run on their calling thread alone (an import, numba's cache load of a kernel): their CPU is
#: that thread's own, and what other threads did meanwhile (a pool thread's synthesis) stays with the
#: stage around them
OWN_THREAD = {"imports", "kernel first calls"}

def clock(label):
    return time.thread_time() if label in OWN_THREAD else cpu()

T0, C0 = time.perf_counter(), cpu()
# each thread's stack of open stages: [label, wall at start, CPU at start, inner wall, inner CPU]
local, totals, lock = threading.local(), {}, threading.Lock()

def stack():
    if not hasattr(local, "stack"):
        local.stack = []
    return local.stack

# the main thread's timeline: (wall, process CPU of every thread, the stage on top of its stack) at
# every change of that stage; an interval's label is the one at its start
TIMELINE = [] if TIMED else None

def mark(st):
    if TIMELINE is not None and threading.current_thread() is MAIN:
        TIMELINE.append((time.perf_counter(), time.process_time(), st[-1][0] if st else "other"))

def push(label):
    st = stack()
    if not st and threading.current_thread() is not MAIN:
        ident = threading.get_ident()
        helpers[ident] = (time.pthread_getcpuclockid(ident), time.thread_time())
    st.append([label, time.perf_counter(), clock(label), 0.0, 0.0])
    mark(st)

def pop():
    st = stack()
    label, w0, c0, iw, ic = st.pop()
    w, c = time.perf_counter() - w0, clock(label) - c0
    with lock:
        own = totals.setdefault(label, [0.0, 0.0])
        own[0] += w - iw
        own[1] += c - ic
        if not st and threading.current_thread() is not MAIN:
            helpers_done[0] += time.thread_time() - helpers.pop(threading.get_ident())[1]
    if st:
        st[-1][3] += w
        st[-1][4] += c
    mark(st)

def wrap(label, fn):
    def probe(*args, **kwargs):
        push(label)
        try:
            return fn(*args, **kwargs)
        finally:
            pop()
    probe.__wrapped__ = fn
    return probe

#: module -> [(attribute, label)]: wrapped as soon as the module is imported, before others bind them
PATCHES = {
    "texsynth.synth.pipeline": [("load_inputs", "parse, load inputs")],
    "texsynth.synth.api": [("synthesize", "synthesis")],
    "texsynth.synth.io": [("save_image", "output PNG/TIFF"), ("save_volume", "output PNG/TIFF"),
                          ("atomic_write_json", "JSON files")],
    "texsynth.synth.output.artifacts": [("_write_tensor_images", "tensor images"),
        ("_tensor_pngs", "tensor images"), ("exemplar_side", "evaluation"),
        ("structure_tensor", "tensor images"), ("write_volume_images", "tensor images"),
        ("fringes_shown", "exemplar analysis"), ("exemplar_diagnostics", "exemplar analysis"),
        ("evaluate_pair_fringes", "evaluation"), ("evaluate_volume", "evaluation"),
        ("headline", "evaluation"),
        ("write_plots", "plots"), ("write_s2_plot", "plots"), ("versions", "JSON files")],
}
original = bootstrap._find_and_load

def find_and_load(name, import_):
    if name in sys.modules:
        return original(name, import_)
    push("imports")
    try:
        module = original(name, import_)
    finally:
        pop()
    for attr, label in PATCHES.get(name, ()):
        if hasattr(module, attr):
            setattr(module, attr, wrap(label, getattr(module, attr)))
    if name == "numba.core.dispatcher":
        cls = module.Dispatcher
        cls._compile_for_args = wrap("kernel first calls", cls._compile_for_args)
    return module

def report():  # at exit (a quick exit runs atexit too): the process's own figures, as the last line
    pop()
    wall, spent = time.perf_counter() - T0, time.process_time() - C0
    mark([])
    out = {"stages": totals, "wall": wall, "cpu": spent}
    if TIMELINE is not None:  # a file: thousands of changes would fill the pipe the parent reads at the end
        with open(TIMED_PATH, "w") as f:
            json.dump([(w - T0, c, label) for w, c, label in TIMELINE], f)
    print(json.dumps(out), flush=True)

import atexit
bootstrap._find_and_load = find_and_load
push("imports")
import texsynth.synth.cli as cli
pop()
push("other")
atexit.register(report)
sys.argv = ["texsynth", *json.loads(sys.argv[1])]
if hasattr(cli, "entry"):  # the program's own ending (an earlier tree: main, then the interpreter's)
    cli.entry()
sys.exit(cli.main())
"""


def cases(threads: int) -> dict[str, tuple[str, str, str]]:
    """name -> (method, exemplar name, size): docs/quality.md's six exemplars and laminar HRTEM, for both
    pixel methods; ``solid-kopf`` 64^3 from the onion crop; ``tensor-constrained`` 512^2,
    quilting 1024^2, ``gaussian-patch`` and ``feature-guided`` 256^2 from it."""
    out = {}
    for method, short in (("wei-levoy", "wl"), ("tensor-constrained", "tc")):
        for name in (*QUALITY, "hrtem-onion-128"):
            out[f"{short}-{name}"] = (method, name, "256x256")
    out["kopf-onion"] = ("solid-kopf", "hrtem-onion-128", "64x64x64")
    # issue 25's whole-command thread cases (the timeline's; not in the default table)
    out["tc-512"] = ("tensor-constrained", "hrtem-onion-128", "512x512")
    out["quilting-1024"] = ("quilting", "hrtem-onion-128", "1024x1024")
    # the other patch methods' (issue 25's imports: what each method loads before its synthesis)
    out["gaussian-patch-256"] = ("gaussian-patch", "hrtem-onion-128", "256x256")
    out["feature-guided-256"] = ("feature-guided", "hrtem-onion-128", "256x256")
    return out


#: The cases of the default table (the target's 256^2 rows and the volume).
TABLE_CASES = (*(f"{m}-{n}" for m in ("wl", "tc") for n in (*QUALITY, "hrtem-onion-128")), "kopf-onion")
#: The cases of ``--timeline`` by default.
TIMELINE_CASES = ("tc-hrtem-onion-128", "tc-512", "kopf-onion", "quilting-1024")


def exemplar_files(folder: Path) -> dict[str, Path]:
    """The exemplars as files: docs/quality.md's (``benchmarks.bench_quality.exemplars``, as 8-bit PNGs),
    laminar HRTEM."""
    from benchmarks.bench_quality import exemplars
    from texsynth.synth.io import save_image

    out = {}
    for name, image in exemplars().items():
        out[name] = folder / f"{name}.png"
        save_image(out[name], image)
    out["hrtem-onion-128"] = ONION
    return out


def _env(tree: Path) -> dict[str, str]:
    """The children's environment: bytecode written; another checkout's packages found first (through a
    ``texsynth`` folder of links beside it: the installed package maps ``texsynth.*`` to this tree)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONDONTWRITEBYTECODE", "PYTHONPATH")}
    import texsynth.synth

    if tree.resolve() != Path(texsynth.synth.__file__).resolve().parent.parent:  # not the installed tree
        shim = tree / ".overhead-shim"
        package = shim / "texsynth"
        package.mkdir(parents=True, exist_ok=True)
        for name in ("synth", "app", "jobs", "worker"):
            if not (package / name).exists():
                (package / name).symlink_to(tree / name)
        env["PYTHONPATH"] = str(shim)
    return env


def _timed(tree: Path, command: list[str], argv: list[str]) -> tuple[float, float, str]:
    """Run ``python COMMAND`` in ``tree`` with the children's environment: its wall and CPU seconds (user
    + system, every thread) and its standard output; a failure raises with the end of its errors."""
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, *command],
        cwd=tree,
        env=_env(tree),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    out, err = proc.stdout.read(), proc.stderr.read()  # type: ignore[union-attr]
    if status:
        raise RuntimeError(f"{' '.join(argv)} failed on {tree}:\n{err[-2000:]}")
    return wall, usage.ru_utime + usage.ru_stime, out


def run_once(tree: Path, argv: list[str], timeline: bool = False) -> dict:
    """One instrumented process: its stages (label -> [wall, CPU]), with 'start + exit' from outside;
    with ``timeline``, also the main thread's stage changes (``timeline``: [(wall, CPU, stage)])."""
    load = os.getloadavg()[0]
    changes = Path(tempfile.mkstemp(suffix=".json", prefix="texsynth-timeline-")[1]) if timeline else None
    probe = ["-c", _PROBE, json.dumps(argv), str(changes) if changes else "-"]
    wall, cpu, out = _timed(tree, probe, argv)
    inside = json.loads(out.strip().splitlines()[-1])
    stages = {k: tuple(v) for k, v in inside["stages"].items()}
    stages["start + exit"] = (wall - inside["wall"], max(cpu - inside["cpu"], 0.0))
    run = {"stages": stages, "wall": wall, "cpu": cpu, "load": load}
    if changes is not None:
        run["timeline"] = json.loads(changes.read_text())
        changes.unlink()
    return run


def run_plain(tree: Path, argv: list[str]) -> dict:
    """The same command without the probe (``python -m texsynth.synth.cli``, as the ``texsynth`` script):
    its whole wall and CPU seconds, for the probe-free 'outside'."""
    wall, cpu, _ = _timed(tree, ["-m", "texsynth.synth.cli", *argv], argv)
    return {"wall": wall, "cpu": cpu}


def segments(timeline: list, threads: int, least: float = 0.02) -> list[tuple[str, float, float, float]]:
    """The main thread's stages in time order: ``(stage, start, wall, cores busy)``, consecutive intervals
    of one stage joined, and intervals shorter than ``least`` seconds given to the stage around them
    (imports inside a stage, a kernel's first call); 'cores busy' = the process's CPU (every thread) over
    the wall: below ``threads``, a core stood idle (or another process had it)."""
    merged: list[list] = []
    for (w0, c0, label), (w1, c1, _) in itertools.pairwise(timeline):
        if merged and (merged[-1][0] == label or w1 - w0 < least):
            merged[-1][2] += w1 - w0
            merged[-1][3] += c1 - c0
        else:
            merged.append([label, w0, w1 - w0, c1 - c0])
    out: list[list] = []
    for label, start, wall, cpu in merged:  # short pieces left between two long ones join the earlier
        if out and (out[-1][0] == label or wall < least):
            out[-1][2] += wall
            out[-1][3] += cpu
        else:
            out.append([label, start, wall, cpu])
    return [
        (label, start, wall, min(cpu / wall, threads) if wall > 0 else 0.0) for label, start, wall, cpu in out
    ]


def timeline_table(name: str, run: dict, threads: int) -> str:
    """One run's :func:`segments` as a Markdown table, with the core-seconds left idle per stage."""
    rows = [
        f"**{name}** ({threads} threads, whole {run['wall']:.2f} s wall, {run['cpu']:.2f} s CPU, load "
        f"{run['load']:.1f}):",
        "",
        "| from (s) | stage | wall (s) | cores busy | idle core-s |",
        "|---|---|---|---|---|",
    ]
    for label, start, wall, busy in segments(run["timeline"], threads):
        rows.append(f"| {start:.2f} | {label} | {wall:.2f} | {busy:.2f} | {wall * (threads - busy):.2f} |")
    return "\n".join(rows)


#: What may differ between two runs of one command: when it ran and how long it took.
_CLOCK_KEYS = ("timings", "started", "finished")


def _without_clock(value: object) -> object:
    if isinstance(value, dict):
        return {k: _without_clock(v) for k, v in value.items() if k not in _CLOCK_KEYS}
    if isinstance(value, list):
        return [_without_clock(v) for v in value]
    return value


def differing_files(a: Path, b: Path) -> list[str]:
    """The files of two output folders that differ (or exist in one only): every file byte for byte,
    except the JSON files' clock fields (``timings``, ``started``, ``finished``)."""
    names = sorted(
        {p.relative_to(a).as_posix() for p in a.rglob("*") if p.is_file()}
        | {p.relative_to(b).as_posix() for p in b.rglob("*") if p.is_file()}
    )
    out = []
    for name in names:
        x, y = a / name, b / name
        if not (x.is_file() and y.is_file()):
            out.append(name)
        elif name.endswith(".json"):
            if _without_clock(json.loads(x.read_text())) != _without_clock(json.loads(y.read_text())):
                out.append(name)
        elif x.read_bytes() != y.read_bytes():
            out.append(name)
    return out


def summarise(runs: list[dict], plain: list[dict] | None = None) -> dict:
    """Median per stage (wall, CPU), total, and outside the synthesis; with ``plain`` (the same command
    without the probe, run k after probed run k), outside without the probe: its whole process less the
    probed run's synthesis (which does no imports; the probe's own cost falls outside it)."""
    med = {}
    for label in STAGES:
        med[label] = (
            statistics.median(r["stages"].get(label, (0.0, 0.0))[0] for r in runs),
            statistics.median(r["stages"].get(label, (0.0, 0.0))[1] for r in runs),
        )
    synthesis = [r["stages"].get("synthesis", (0.0, 0.0)) for r in runs]
    outside = [(r["wall"] - w, r["cpu"] - c) for r, (w, c) in zip(runs, synthesis, strict=True)]
    return {
        "stages": med,
        "wall": statistics.median(r["wall"] for r in runs),
        "cpu": statistics.median(r["cpu"] for r in runs),
        "outside_wall": statistics.median(w for w, _ in outside),
        "outside_cpu": statistics.median(c for _, c in outside),
        "loads": sorted(r["load"] for r in runs),
        "runs": len(runs),
        **(
            {
                "plain_wall": statistics.median(p["wall"] for p in plain),
                "plain_outside_wall": statistics.median(
                    p["wall"] - w for p, (w, _) in zip(plain, synthesis, strict=True)
                ),
                "plain_outside_cpu": statistics.median(
                    p["cpu"] - c for p, (_, c) in zip(plain, synthesis, strict=True)
                ),
            }
            if plain
            else {}
        ),
    }


def measure(
    trees: dict[str, Path],
    names: list[str],
    runs: int,
    threads: int,
    json_path: Path | None,
    timeline: bool = False,
) -> dict:
    """Every case on every tree, the trees alternated run by run (both see the same load)."""
    table = cases(threads)
    results: dict = {label: {} for label in trees}
    with tempfile.TemporaryDirectory(prefix="texsynth-overhead-") as tmp:
        folder = Path(tmp)
        files = exemplar_files(folder)
        for name in names:
            method, exemplar, size = table[name]
            if exemplar not in files:
                print(f"skipped {name}: no {exemplar} exemplar (the shared data: $TEXSYNTH_SHARED_DATA)")
                continue
            argv = ["synthesize", method, "--exemplar", str(files[exemplar]), "--size", size, "--seed", "1"]
            argv += ["--threads", str(threads)]
            done: dict[str, list[dict]] = {label: [] for label in trees}
            plain: dict[str, list[dict]] = {label: [] for label in trees}
            for label, tree in trees.items():
                run_once(tree, [*argv, "--out", str(folder / f"{label}-warm")])
            for k in range(runs):
                for label, tree in trees.items():
                    out = str(folder / f"{label}-{k}")
                    done[label].append(run_once(tree, [*argv, "--out", out], timeline))
                    if not timeline:
                        plain[label].append(run_plain(tree, [*argv, "--out", f"{out}-plain"]))
            same = None
            if len(trees) > 1:  # the last run of each tree: every file, byte for byte
                folders = [folder / f"{label}-{runs - 1}" for label in trees]
                same = differing_files(*folders[:2])
                print(f"{name}: files that differ from the baseline's: {same or 'none'}", flush=True)
            for label in trees:
                s = summarise(done[label], plain[label])
                s.update(method=method, exemplar=exemplar, size=size, differing=same)
                if timeline:  # the run of median wall time
                    ordered = sorted(done[label], key=lambda r: r["wall"])
                    s["timeline_run"] = ordered[len(ordered) // 2]
                results[label][name] = s
                print(
                    f"{label} {name}: whole {s['wall']:.2f} s wall / {s['cpu']:.2f} s CPU; outside the "
                    f"synthesis {s['outside_wall']:.2f} s wall / {s['outside_cpu']:.2f} s CPU"
                    + (
                        f"; without the probe {s['plain_outside_wall']:.2f} s wall / "
                        f"{s['plain_outside_cpu']:.2f} s CPU"
                        if "plain_wall" in s
                        else ""
                    )
                    + f" (load {s['loads'][0]:.1f}-{s['loads'][-1]:.1f})",
                    flush=True,
                )
            if json_path is not None:  # after every case: a long run stopped early keeps its figures
                json_path.write_text(json.dumps(results, indent=1))
    return results


def report(results: dict, threads: int) -> str:
    """The ``overhead-stages`` section: CPU seconds per stage, and the before -> after outside figures."""
    after = results["after"]
    before = results.get("before", {})
    loads = sorted(x for r in results.values() for s in r.values() for x in s["loads"])
    runs = next(iter(after.values()))["runs"]
    lines = [
        "## Outside the synthesis, stage by stage (`python -m benchmarks.bench_overhead`)",
        "",
        f"A whole `texsynth synthesize METHOD --exemplar X --size S --seed 1 --threads {threads}` process "
        "per run, every artifact written (plots included), probed from inside (the module docstring says "
        "how): "
        f"median CPU seconds (every thread) per stage over {runs} runs after one untimed run; each stage "
        "exclusive of the imports and kernel loads that ran inside it. 'Outside' = the whole process minus "
        "the synthesis, in CPU and wall seconds; 'without the probe': the same command run bare right after "
        "each probed run, its whole process less the probed run's synthesis (median over the pairs). "
        f"Target (issue 25): outside <= {TARGET:.1f} s, said of the wall and the CPU without the probe. "
        f"1-minute load during the runs {loads[0]:.1f}-{loads[-1]:.1f} on {os.cpu_count()} cores shared "
        "with other work." + (" Before: main before this work, run alternately with it." if before else ""),
        "",
        "| case | " + " | ".join(s for s in STAGES if s != "synthesis") + " | synthesis | outside CPU | "
        "outside wall | without the probe: outside wall / CPU | whole wall |"
        + (" before: outside CPU / wall |" if before else ""),
        "|---|" + "---|" * (len(STAGES) + 4) + ("---|" if before else ""),
    ]
    for name, s in after.items():
        cells = " | ".join(f"{s['stages'][k][1]:.2f}" for k in STAGES if k != "synthesis")
        # the target is a 2D command's; a volume's is said for comparison
        plain = "-"
        if "plain_wall" in s:
            wall, cpu = s["plain_outside_wall"], s["plain_outside_cpu"]
            verdict = " / ".join("meets" if x <= TARGET else "misses" for x in (wall, cpu))
            plain = f"{wall:.2f} / {cpu:.2f}" + (f" ({verdict})" if s["size"].count("x") == 1 else "")
        row = (
            f"| `{s['method']}` {s['size']} {s['exemplar']} | {cells} | {s['stages']['synthesis'][1]:.2f} | "
            f"{s['outside_cpu']:.2f} | {s['outside_wall']:.2f} | {plain} | {s['wall']:.2f} |"
        )
        if name in before:
            b = before[name]
            same = "same files" if s.get("differing") == [] else f"differ: {', '.join(s['differing'] or [])}"
            row += f" {b['outside_cpu']:.2f} / {b['outside_wall']:.2f} ({same}) |"
        lines.append(row)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="timed runs per case (median)")
    parser.add_argument("--threads", type=int, default=2, help="the command's --threads")
    parser.add_argument("--cases", default="all", help=f"comma-separated, of {', '.join(cases(2))}")
    parser.add_argument("--baseline", type=Path, help="an earlier checkout, run alternately: 'before'")
    parser.add_argument("--json", type=Path, help="also write the figures here (after every case)")
    parser.add_argument("--no-write", action="store_true", help="print the table, leave docs/ alone")
    parser.add_argument(
        "--timeline",
        action="store_true",
        help="the main thread's stages in time order and how many cores were busy in each (default cases: "
        f"{', '.join(TIMELINE_CASES)}); writes the overhead-timeline section",
    )
    args = parser.parse_args(argv)
    known = cases(args.threads)
    if args.cases == "all":
        names = [c for c in known if c.startswith(TABLE_CASES)] if not args.timeline else list(TIMELINE_CASES)
    else:
        names = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = [c for c in names if c not in known]
    if unknown:
        parser.error(f"unknown case {unknown[0]!r} (known: {', '.join(known)})")
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    if args.baseline is not None and not (args.baseline / "synth" / "cli").is_dir():
        parser.error(f"--baseline {args.baseline}: not a texsynth checkout (no synth/cli)")
    print(machine())
    trees = {"after": ROOT, **({"before": args.baseline.resolve()} if args.baseline else {})}
    results = measure(trees, names, args.runs, args.threads, args.json, args.timeline)
    if args.timeline:
        table = timeline_report(results, args.threads)
        print(table)
        if not args.no_write:
            write_section("overhead-timeline", table)
        return 0
    table = report(results, args.threads)
    print(table)
    if not args.no_write:
        write_section("overhead-stages", table)
    return 0


def timeline_report(results: dict, threads: int) -> str:
    """The ``overhead-timeline`` section: one table per case (its run of median wall time)."""
    after = results["after"]
    runs = next(iter(after.values()))["runs"]
    parts = [
        "## Outside the synthesis, in time order (`python -m benchmarks.bench_overhead --timeline`)",
        "",
        f"One whole `texsynth synthesize METHOD --exemplar hrtem-onion-128.png --size S --seed 1 --threads "
        f"{threads}` process per case (plots included; the run of median wall time of {runs}, after one "
        "untimed run), probed as the stage table's: the main thread's stages in time order (pieces shorter "
        "than 20 ms given to the stage around them), their wall time, and the process's CPU (every "
        "thread) over it: 'cores busy' below the thread count means a core stood idle in that stage or "
        f"another process had it (the load says which; {os.cpu_count()} cores here).",
    ]
    for s in after.values():
        parts += ["", timeline_table(f"`{s['method']}` {s['size']}", s["timeline_run"], threads)]
    return "\n".join(parts)


if __name__ == "__main__":
    raise SystemExit(main())
