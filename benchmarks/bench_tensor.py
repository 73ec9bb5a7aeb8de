"""Structure-tensor analysis of a 1024 x 1024 image: tensor field + coherence + orientation.

Run ``python -m benchmarks.bench_tensor``; writes the ``tensor`` section of docs/benchmarks.md.
Target: under 0.25 s (median of 5 runs) on 2 cores, float32 input, default scales
(``sigma_d = 1``, ``sigma_w = 3``).
"""

from __future__ import annotations

import numpy as np

from benchmarks._report import median_time, write_section
from texsynth.synth.analysis.tensor import coherence, orientation, structure_tensor

SIZE = 1024
RUNS = 5
TARGET_SECONDS = 0.25
SIGMA_D, SIGMA_W = 1.0, 3.0


def lattice_image(size: int = SIZE, seed: int = 0) -> np.ndarray:
    """An HRTEM-like float32 test image: two crossed fringe systems, a slow bend, and noise."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float32)
    bend = np.float32(0.4) * np.sin(rows / np.float32(size) * np.float32(2 * np.pi))
    phase1 = (cols * np.cos(bend) + rows * np.sin(bend)) * np.float32(2 * np.pi / 7)
    phase2 = (cols * np.float32(0.5) - rows * np.float32(0.866)) * np.float32(2 * np.pi / 11)
    image = 0.5 + 0.25 * np.sin(phase1) + 0.1 * np.sin(phase2) + 0.08 * rng.standard_normal((size, size))
    return np.clip(image, 0, 1).astype(np.float32)


def analyse(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The timed work: the tensor field, then its coherence and (gradient) orientation."""
    tensors = structure_tensor(image, SIGMA_D, SIGMA_W)
    return coherence(tensors), orientation(tensors)


def main() -> None:
    image = lattice_image()
    median, times = median_time(lambda: analyse(image), runs=RUNS, warmup=1)
    status = "meets" if median < TARGET_SECONDS else "MISSES"
    markdown = "\n".join(
        [
            "## Structure tensor analysis",
            "",
            f"`structure_tensor` + `coherence` + `orientation` of a {SIZE} x {SIZE} float32 image "
            f"(`sigma_d = {SIGMA_D}`, `sigma_w = {SIGMA_W}`), median of {RUNS} runs after one warm-up "
            "(`python -m benchmarks.bench_tensor`).",
            "",
            "| image | median (s) | runs (s) | target (s) |",
            "|---|---|---|---|",
            f"| {SIZE} x {SIZE} | {median:.3f} | {', '.join(f'{t:.3f}' for t in times)} | "
            f"< {TARGET_SECONDS} ({status}) |",
        ]
    )
    write_section("tensor", markdown)
    print(
        f"tensor analysis {SIZE}x{SIZE}: median {median:.3f} s over {RUNS} runs ({status} {TARGET_SECONDS} s)"
    )


if __name__ == "__main__":
    main()
