"""Evaluation of a 512 x 512 exemplar/output pair: histograms, moments, orientations, fringes.

Run ``python -m benchmarks.bench_evaluate``; writes the ``evaluate`` section of docs/benchmarks.md.
Target: ``evaluate_pair`` on a 512 x 512 pair under 1 s (median of 5 runs) on 2 cores.

The pair is real HRTEM content: the exemplar tiles ``hrtem-soot-256.png`` 2 x 2 (about 800
fringes), the output is the same tiling transposed and mirrored (the same statistics, other
orientations), so that the fringe analysis has a realistic amount of work. Also timed, for
information: the pair without fringe analysis, the plots, and a 64^3 volume (multi-2D, 192 slices).
"""

from __future__ import annotations

import tempfile

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


if __name__ == "__main__":
    main()
