"""Evaluation of a 512 x 512 exemplar/output pair: histograms, moments, orientations, fringes.

Run ``python -m benchmarks.bench_evaluate``; writes the ``evaluate`` section of docs/benchmarks.md.
Target: ``evaluate_pair`` on a 512 x 512 pair under 1 s (median of 5 runs) on 2 cores.

The pair is real HRTEM content: the exemplar tiles ``hrtem-soot-256.png`` 2 x 2 (about 800
fringes), the output is the same tiling transposed and mirrored (the same statistics, other
orientations), so that the fringe analysis has a realistic amount of work. Also timed, for
information: the pair without fringe analysis, the plots, and a 64^3 volume (multi-2D, 192 slices).

``--volume-threads [FILE.tiff]`` (issue 25) prints, without writing docs/, ``evaluate_volume`` of a volume
(a synthesized TIFF, by default the 64^3 stack above) against ``benchmarks/data/hrtem-onion-128.png``
with 1 and 2 threads, alternated: wall, CPU and the busiest thread's CPU (sampled from /proc/self/task
every 10 ms), the evidence that the second thread works; CPU(1) / busiest(2) is the speed-up a quiet
machine would approach.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from benchmarks._report import DATA, median_time, write_section
from texsynth.synth.evaluate import evaluate_pair, evaluate_volume
from texsynth.synth.io import load_image
from texsynth.synth.output.plots import write_plots

SOOT = DATA / "hrtem-soot-256.png"
RUNS = 5
TARGET_SECONDS = 1.0
PIXEL_SIZE = 1 / 18  # nm per pixel, hrtem-soot images (data/README.md)


def pair() -> tuple[np.ndarray, np.ndarray]:
    """The 512 x 512 float32 exemplar and output."""
    soot = load_image(SOOT, mode="grey")
    exemplar = np.tile(soot, (2, 2))
    output = np.ascontiguousarray(exemplar.T[:, ::-1])
    return exemplar, output


def main() -> None:
    exemplar, output = pair()
    full, full_runs = median_time(lambda: evaluate_pair(exemplar, output, pixel_size=PIXEL_SIZE), runs=RUNS)
    plain, _ = median_time(lambda: evaluate_pair(exemplar, output, fringes=False), runs=RUNS)
    metrics = evaluate_pair(exemplar, output, pixel_size=PIXEL_SIZE)
    with tempfile.TemporaryDirectory() as tmp:
        plots, _ = median_time(lambda: write_plots(exemplar, output, metrics, tmp), runs=3)
    volume = np.stack([np.roll(exemplar[:64, :64], k, axis=1) for k in range(64)])
    vol_time, _ = median_time(lambda: evaluate_volume(exemplar[:256, :256], volume), runs=3)

    status = "meets" if full < TARGET_SECONDS else "MISSES"
    n_ex = metrics["fringes"]["exemplar"]["count"]
    markdown = "\n".join(
        [
            "## Evaluation (`texsynth.synth.evaluate`)",
            "",
            "`evaluate_pair` of a 512 x 512 pair of HRTEM content (`hrtem-soot-256.png` tiled 2 x 2, "
            f"{n_ex} fringes; the output is the same tiling transposed and mirrored), all measures "
            f"including the fringe analysis, median of {RUNS} runs after one warm-up "
            "(`python -m benchmarks.bench_evaluate`).",
            "",
            "| work | median (s) | runs (s) | target (s) |",
            "|---|---|---|---|",
            f"| `evaluate_pair`, 512 x 512, with fringes | {full:.3f} | "
            f"{', '.join(f'{t:.3f}' for t in full_runs)} | < {TARGET_SECONDS} ({status}) |",
            f"| `evaluate_pair`, 512 x 512, `fringes=False` | {plain:.3f} | | |",
            f"| `write_plots` (5 PNGs) | {plots:.3f} | | |",
            f"| `evaluate_volume`, 64^3 volume (3 x 64 slices) vs 256 x 256 exemplar | {vol_time:.3f} | | |",
        ]
    )
    write_section("evaluate", markdown)
    print(
        f"evaluate_pair 512x512: median {full:.3f} s over {RUNS} runs ({status} {TARGET_SECONDS} s); "
        f"without fringes {plain:.3f} s; plots {plots:.3f} s; 64^3 volume {vol_time:.3f} s"
    )


class _ThreadCPU:
    """CPU seconds of each thread of this process over a block, sampled every 10 ms from /proc/self/task
    (a thread that ends keeps its last sample); the sampler itself is left out."""

    def __init__(self) -> None:
        self.first: dict[str, float] = {}
        self.last: dict[str, float] = {}
        self.stop = threading.Event()
        self.own = ""

    @staticmethod
    def _sample() -> dict[str, float]:
        out = {}
        for tid in os.listdir("/proc/self/task"):
            try:
                fields = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            out[tid] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        return out

    def _run(self) -> None:
        self.own = str(threading.get_native_id())
        while not self.stop.wait(0.01):
            self.last.update(self._sample())

    def __enter__(self) -> _ThreadCPU:
        self.first = self._sample()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.stop.set()
        self.thread.join()
        self.last.update(self._sample())

    def busiest(self) -> float:
        return max(v - self.first.get(t, 0.0) for t, v in self.last.items() if t != self.own)


def volume_threads(path: Path | None, runs: int) -> None:
    """``evaluate_volume`` with 1 and 2 threads, alternated: medians of wall, CPU and the busiest thread."""
    exemplar = load_image(Path(__file__).parent / "data" / "hrtem-onion-128.png", mode="grey")
    if path is None:
        soot = load_image(SOOT, mode="grey")
        volume = np.stack([np.roll(soot[:64, :64], k, axis=1) for k in range(64)])
    else:
        import tifffile

        raw = tifffile.imread(path)
        volume = raw.astype(np.float32) / (np.iinfo(raw.dtype).max if raw.dtype.kind == "u" else 1.0)
    evaluate_volume(exemplar, volume[:8, :32, :32], threads=2)  # untimed: the kernels' first calls
    rows: dict[int, list[tuple[float, float, float]]] = {1: [], 2: []}
    loads = []
    for i in range(runs):
        for threads in (1, 2) if i % 2 == 0 else (2, 1):
            loads.append(os.getloadavg()[0])
            with _ThreadCPU() as probe:
                start, cpu = time.perf_counter(), time.process_time()
                evaluate_volume(exemplar, volume, threads=threads)
                wall, cpu = time.perf_counter() - start, time.process_time() - cpu
            rows[threads].append((wall, cpu, probe.busiest()))
    med = {t: [statistics.median(r[k] for r in rows[t]) for k in range(3)] for t in rows}
    print(
        f"evaluate_volume {'x'.join(map(str, volume.shape))}, {runs} runs per count, load "
        f"{min(loads):.1f} / {statistics.median(loads):.1f} / {max(loads):.1f}"
    )
    print("| threads | wall (s) | CPU (s) | busiest thread (s) |")
    print("|---|---|---|---|")
    for t in (1, 2):
        print(f"| {t} | {med[t][0]:.3f} | {med[t][1]:.3f} | {med[t][2]:.3f} |")
    print(f"wall(1) / wall(2) {med[1][0] / med[2][0]:.2f}x; CPU(1) / busiest(2) {med[1][1] / med[2][2]:.2f}x")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--volume-threads", nargs="?", const="", default=None, metavar="FILE.tiff")
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    if args.volume_threads is None:
        main()
    else:
        volume_threads(Path(args.volume_threads) if args.volume_threads else None, args.runs)
