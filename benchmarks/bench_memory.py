"""Peak memory of a whole ``texsynth synthesize`` process, and in which stage it is reached (issue 25).

Run ``python -m benchmarks.bench_memory --method solid-kopf --size 256x256x256`` (``--exemplar``,
``--threads``, ``--no-plots``, ``--constraint``: concentric rings of the output's size by default for a
method that needs one). A fresh child process runs
:func:`texsynth.synth.pipeline.synthesize_to_folder` as the command does, with a progress callback that
records the stage (the synthesis' own stages, then the writer's: ``output.tiff``, the pictures, the
evaluation, the plots) and a thread that samples the resident set size (``VmRSS`` in ``/proc/self/status``)
every 0.2 s: the largest RSS seen per stage, the stage seconds, and the process' peak (``VmHWM``, as
``/usr/bin/time -v`` reports it) come out as one JSON document. The admission estimate of the service
(:func:`texsynth.app.admission.estimate_memory`) is calibrated from these peaks (docs/benchmarks.md, "Big
outputs"): ``--size`` given twice or more runs each size, one after the other, and adds the admission's
terms (:func:`admission_terms`: 1.1 times the slope between the two largest, the fixed rest of the largest).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_EXEMPLAR = ROOT / "benchmarks" / "data" / "hrtem-onion-128.png"

_CHILD = r"""
import json, os, sys, threading, time
args = json.loads(sys.argv[1])

def status(field):
    for line in open("/proc/self/status"):
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    return 0

state = {"stage": "imports", "since": time.perf_counter(), "cpu": time.process_time()}
peaks, seconds, cpu, order = {}, {}, {}, []

def sample():
    stage = state["stage"]
    if stage not in peaks:
        order.append(stage)
    peaks[stage] = max(peaks.get(stage, 0), status("VmRSS"))

def enter(stage):
    now, used = time.perf_counter(), time.process_time()
    old = state["stage"]
    seconds[old] = seconds.get(old, 0.0) + now - state["since"]
    cpu[old] = cpu.get(old, 0.0) + used - state["cpu"]
    sample()
    state["stage"], state["since"], state["cpu"] = stage, now, used
    sample()

stop = threading.Event()
def sampler():
    while not stop.wait(0.2):
        sample()
threading.Thread(target=sampler, daemon=True).start()

from texsynth.synth.pipeline import load_inputs, synthesize_to_folder
enter("loading")
images = load_inputs({"exemplar": args["exemplar"]})
size = tuple(int(v) for v in reversed(args["size"].split("x")))
if args["constraint"] == "rings":
    from texsynth.synth.io.patterns import concentric_rings
    images["constraint"] = concentric_rings(size)
elif args["constraint"]:
    images["constraint"] = load_inputs({"constraint": args["constraint"]})["constraint"]

def progress(stage, fraction, **_):
    # the synthesis' stages are many (levels, passes): one bucket; the writer's are named
    writing = stage == "writing artifacts" or state["stage"] not in ("loading", "synthesis")
    name = stage if writing else "synthesis"
    if name != state["stage"]:
        enter(name)

enter("synthesis")
synthesize_to_folder(args["method"], images, args["out"], size=size, seed=1, progress=progress,
                     plots=args["plots"], threads=args["threads"])
enter("end")
stop.set()
print(json.dumps({"stages": [{"stage": s, "peak_rss_mb": round(peaks[s] / 2**20),
                              "seconds": round(seconds.get(s, 0.0), 2),
                              "cpu_s": round(cpu.get(s, 0.0), 2)} for s in order if s != "end"],
                  "vmhwm_mb": round(status("VmHWM") / 2**20)}))
"""


def run(
    method: str,
    size: str,
    exemplar: Path,
    threads: int | None,
    plots: bool,
    out: Path,
    constraint: str | None = None,
) -> dict:
    """One child process; its stages, their peak RSS and seconds, its ``VmHWM`` and CPU seconds.

    ``constraint``: a constraint image's path, or ``'rings'`` for concentric rings of the output's size
    (:func:`texsynth.synth.io.patterns.concentric_rings`); by default ``'rings'`` for a method that needs one.
    """
    from texsynth.synth.api import available_methods

    if constraint is None and available_methods()[method].constraint == "required":
        constraint = "rings"
    args = {
        "method": method,
        "size": size,
        "constraint": constraint,
        "exemplar": str(exemplar),
        "threads": threads,
        "plots": plots,
        "out": str(out),
    }
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-c", _CHILD, json.dumps(args)], cwd=ROOT, stdout=subprocess.PIPE, text=True
    )
    stdout = proc.stdout.read() if proc.stdout else ""
    _, status, usage = os.wait4(proc.pid, 0)
    if status != 0:
        raise SystemExit(f"child failed with status {status}")
    report = json.loads(stdout.strip().splitlines()[-1])
    report.update(
        method=method,
        size=size,
        threads=threads,
        wall_s=round(time.perf_counter() - start, 1),
        cpu_s=round(usage.ru_utime + usage.ru_stime, 1),
        maxrss_mb=round(usage.ru_maxrss / 1024),
        constraint=constraint,
        load=os.getloadavg()[0],
    )
    return report


def admission_terms(peaks: dict[int, int]) -> tuple[int, int]:
    """``(fixed bytes, bytes per output element)`` from peaks (bytes) by output elements, the rule of
    :data:`texsynth.app.admission.IMAGE_MEMORY` and ``VOLUME_MEMORY``: per element 1.1 times the slope
    between the two largest sizes, rounded up to 10; fixed the largest rest of a peak (peak minus the
    per-element term), rounded up to 16 MiB, at least 0: never below a peak it was fitted on.

    >>> admission_terms({2**21: 400 * 2**20, 2**24: 1700 * 2**20})
    (201326592, 110)
    """
    if len(peaks) < 2:
        raise ValueError("peaks: at least two sizes are needed for a slope")
    (n1, p1), (n2, p2) = sorted(peaks.items())[-2:]
    per = max(0, math.ceil(1.1 * (p2 - p1) / (n2 - n1) / 10) * 10)
    mib16 = 16 * 2**20
    fixed = max([0] + [math.ceil((p - per * n) / mib16) * mib16 for n, p in peaks.items()])
    return fixed, per


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="solid-kopf")
    parser.add_argument(
        "--size", action="append", help="WxH or WxHxD (default 128x128x128); twice or more: fit the terms"
    )
    parser.add_argument("--exemplar", type=Path, default=DEFAULT_EXEMPLAR)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--no-plots", action="store_true")
    parser.add_argument(
        "--constraint",
        default=None,
        help="constraint image, or 'rings' (default when the method needs one)",
    )
    parser.add_argument("--out", type=Path, default=Path("/tmp") / "texsynth-bench-memory")
    args = parser.parse_args(argv)
    reports = [
        run(args.method, size, args.exemplar, args.threads, not args.no_plots, args.out, args.constraint)
        for size in args.size or ["128x128x128"]
    ]
    for report in reports:
        print(json.dumps(report, indent=2))
    if len(reports) > 1:
        peaks = {math.prod(int(v) for v in r["size"].split("x")): r["vmhwm_mb"] * 2**20 for r in reports}
        fixed, per = admission_terms(peaks)
        print(json.dumps({"method": args.method, "fixed_mib": fixed // 2**20, "bytes_per_element": per}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
