"""Synthesis benchmark: Akl 2014 Table 1 settings (time, memory) and fast search against exact search.

Run: ``python -m benchmarks.bench_synthesis`` (writes the ``synthesis`` section of docs/benchmarks.md).

Fast against exact, on the same inputs: after a full synthesis at the figure-3 settings, the final
state of each stage is frozen and, for a sample of output positions, the best-match distance of
the k-coherence search is compared with that of the exhaustive search over every exemplar position
(the definition), for the very same neighbourhood. Reported: the ratio of the mean best distances
(1.00 = as good as exact) and the share of positions where the fast search found the exact optimum.

OpenBLAS runs single-threaded here, as in the ``texsynth`` command (set before NumPy loads; see
:mod:`texsynth.synth.cli`): on the shared 2-core machine its threads spin against the other jobs and make the
k-coherence PCA's small matrix products slower, never faster.
"""

from __future__ import annotations

from texsynth.synth.threads import single_threaded_blas

single_threaded_blas()  # before NumPy loads OpenBLAS

import os
import resource
import statistics
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

import texsynth.synth.methods.tensor_constrained as tc
import texsynth.synth.methods.wei_levoy as wl
from benchmarks._report import DATA, median_time, write_section
from texsynth.synth.api import synthesize
from texsynth.synth.io import load_image
from texsynth.synth.kernels.pixel_search import SearchState, synthesize_chunk

# Akl 2014, Table 1: (figure, exemplar, output side, params)
TABLE1: list[tuple[str, str, int, dict[str, Any]]] = [
    (
        "3",
        "hrtem-soot-128.png",
        256,
        {
            "neighbourhood_size": 13,
            "structure_levels": 4,
            "texture_levels": 1,
            "metric": "SO",
            "structure_iterations": 2,
            "texture_iterations": 2,
        },
    ),
    (
        "4",
        "hrtem-soot-128.png:108",
        200,
        {
            "neighbourhood_size": 19,
            "structure_levels": 3,
            "texture_levels": 1,
            "metric": "ED",
            "structure_iterations": 3,
            "texture_iterations": 2,
        },
    ),
    (
        "5",
        "hrtem-soot-256.png",
        512,
        {
            "neighbourhood_size": 7,
            "structure_levels": 1,
            "texture_levels": 1,
            "metric": "ED",
            "structure_iterations": 1,
            "texture_iterations": 1,
        },
    ),
]


def exemplar(spec: str) -> np.ndarray:
    """``name.png`` or ``name.png:N`` (the central N x N crop)."""
    name, _, crop = spec.partition(":")
    img = load_image(f"{DATA}/{name}")
    if crop:
        n = int(crop)
        y0, x0 = (img.shape[0] - n) // 2, (img.shape[1] - n) // 2
        img = np.ascontiguousarray(img[y0 : y0 + n, x0 : x0 + n])
    return img


def frozen_search_comparison(state: SearchState, n_positions: int, seed: int = 0) -> dict[str, float]:
    """Best distance of k-coherence vs exhaustive search on the same frozen neighbourhoods."""
    H, W = state.run.best_out.shape
    rng = np.random.default_rng(seed)
    positions = rng.choice(H * W, size=min(n_positions, H * W), replace=False)
    # The nearest-neighbour question only: histogram matching (which trades distance for balance) is off.
    hist = state.hist._replace(count=state.hist.count.copy(), weight=0.0)
    run = state.run._replace(first_pass=False, done=np.ones((H, W), dtype=np.uint8))
    src, out = state.cands.src, state.cur.out
    fast, exact = [], []
    for p in positions:
        y, x = divmod(int(p), W)
        keep_src, keep_out = src[y, x].copy(), out[y, x].copy()
        for is_exact, sink in ((False, fast), (True, exact)):
            trial = replace(
                state,
                hist=hist,
                cands=state.cands._replace(exact=is_exact),
                run=run._replace(order=np.array([p], dtype=np.int64)),
            )
            synthesize_chunk(trial, 0, 1)
            sink.append(float(trial.run.best_out[y, x]))
            src[y, x], out[y, x] = keep_src, keep_out
    f, e = np.asarray(fast), np.asarray(exact)
    return {
        "ratio": float(f.mean() / e.mean()),
        "optimal_share": float(np.mean(f <= e * (1 + 1e-6) + 1e-12)),
        "positions": len(positions),
    }


def _capture_states(module: Any) -> tuple[list[SearchState], Callable[[], None]]:
    """Wrap ``module.synthesize_source_map`` so the finest level's final state of every stage is kept."""
    original = module.synthesize_source_map
    states: list[SearchState] = []

    def wrapped(*args: Any, **kwargs: Any) -> Any:
        kwargs["on_level_done"] = lambda level, state: states.append(state) if level == 0 else None
        return original(*args, **kwargs)

    module.synthesize_source_map = wrapped

    def restore() -> None:
        module.synthesize_source_map = original

    return states, restore


#: The texture stage's distances before issue 13 (no falloff) and its k: the search compared on them.
FLAT = {"falloff": 0.0, "k": 3}


def search_quality(n_positions: int = 600) -> list[tuple[str, dict[str, float]]]:
    ex = exemplar(TABLE1[0][1])
    rows = []
    states, restore = _capture_states(tc)
    try:
        synthesize("tensor-constrained", ex, size=(256, 256), params=TABLE1[0][3], seed=1)
    finally:
        restore()
    rows.append(
        ("tensor-constrained, structure stage (SO tensors)", frozen_search_comparison(states[0], n_positions))
    )
    rows.append(
        ("tensor-constrained, texture stage (eq 13)", frozen_search_comparison(states[1], n_positions))
    )
    # The same search with issue 3's texture distances (flat weights, k = 3): what the falloff changes.
    states, restore = _capture_states(tc)
    try:
        synthesize("tensor-constrained", ex, size=(256, 256), params={**TABLE1[0][3], **FLAT}, seed=1)
    finally:
        restore()
    rows.append(
        (
            "tensor-constrained, texture stage, flat weights and k = 3 (issue 3's)",
            frozen_search_comparison(states[1], n_positions),
        )
    )
    states, restore = _capture_states(wl)
    try:
        synthesize("wei-levoy", ex, size=(256, 256), params={"neighbourhood_size": 13, "levels": 3}, seed=1)
    finally:
        restore()
    rows.append(("wei-levoy, 3 levels (pixels)", frozen_search_comparison(states[0], n_positions)))
    return rows


def _timed(fn: Callable[[], object], runs: int) -> tuple[float, list[float], float]:
    """:func:`median_time` of ``fn``, and the median CPU time of the same runs (every thread)."""
    cpu: list[float] = []

    def run() -> None:
        start = time.process_time()
        fn()
        cpu.append(time.process_time() - start)

    med, times = median_time(run, runs=runs)
    return med, times, statistics.median(cpu[-runs:])


def table1_timings(runs: int = 3) -> list[tuple[str, str, float, list[float], float, float, float]]:
    """Per figure: size, tensor-constrained median wall, its runs, wei-levoy median wall, and the
    median CPU time of each."""
    out = []
    for fig, spec, side, params in TABLE1:
        ex = exemplar(spec)
        med, times, cpu = _timed(
            lambda ex=ex, side=side, params=params: synthesize(
                "tensor-constrained", ex, size=(side, side), params=params, seed=1
            ),
            runs,
        )
        wl_med, _, wl_cpu = _timed(
            lambda ex=ex, side=side, params=params: synthesize(
                "wei-levoy",
                ex,
                size=(side, side),
                seed=1,
                params={
                    "neighbourhood_size": params["neighbourhood_size"],
                    "levels": params["texture_levels"],
                    "iterations": params["texture_iterations"],
                },
            ),
            runs,
        )
        out.append((fig, f"{ex.shape[0]}->{side}", med, times, wl_med, cpu, wl_cpu))
    return out


def main() -> None:
    start = time.perf_counter()
    load_before = os.getloadavg()[0]
    timings = table1_timings()
    load = f"{min(load_before, os.getloadavg()[0]):.1f}-{max(load_before, os.getloadavg()[0]):.1f}"
    quality = search_quality()
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    targets = {"3": 2.0, "5": 6.0}
    lines = [
        "## Pixel synthesis (Akl 2014, Table 1 settings)",
        "",
        "`tensor-constrained` at the three settings of Table 1 (defaults: k-coherence search, k = "
        f"{tc.TensorConstrainedParams().k}), median of 3 runs after a warm-up; `wei-levoy` at the same "
        "neighbourhood, texture levels and iterations for comparison "
        "(`python -m benchmarks.bench_synthesis`; OpenBLAS single-threaded, as the `texsynth` command "
        f"runs it; load average {load} before and after the timings; CPU = the median process CPU "
        "time of the same runs, every thread).",
        "",
        "| figure | size | tensor-constrained median (s) | runs (s) | CPU (s) | wei-levoy median (s) "
        "| CPU (s) | target (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for fig, size, med, times, wl_med, cpu, wl_cpu in timings:
        target = targets.get(fig)
        verdict = "" if target is None else f"< {target:g} ({'meets' if med < target else 'misses'})"
        lines.append(
            f"| {fig} | {size} | {med:.2f} | {', '.join(f'{t:.2f}' for t in times)} | {cpu:.2f} "
            f"| {wl_med:.2f} | {wl_cpu:.2f} | {verdict} |"
        )
    lines += [
        "",
        "`wei-levoy` runs with its current defaults (k = 10, histogram matching, k-coherence sets on "
        "neighbourhoods of up to 9 x 9 projected on 16 principal components). At figure 5 its time is "
        "the k-d tree query that builds those sets: 62,500 points of 16 dimensions, 11 nearest each, "
        "10.0 s of the run's 11.4 s of CPU (measured 2026-11-25). On main before the pixel-speed "
        "work, that figure-5 run took as long under the same load (21.5 s, 14.3 s of CPU) and the "
        "fast/exact figures below were the same: both changed with the defaults, not with the speed "
        "work.",
        "",
        f"Peak resident memory of the whole benchmark process: {peak_mb:.0f} MB.",
        "",
        "### Fast search against exact search, same neighbourhoods",
        "",
        "After a full run at figure-3 settings, the final state is frozen and, at 600 random output "
        "positions, "
        "the k-coherence search and the exhaustive search answer the same query. Ratio = mean best distance "
        "fast / exact (1.00 = as good as exact). The texture stage's default distance weighs the entries by "
        "a Gaussian falloff (issue 13; docs/quality.md): the few pixels nearest the centre then decide, and "
        "many exemplar positions that the k-coherent candidates do not propose match those few pixels as "
        "well as a coherent continuation does, so the exhaustive search finds a smaller distance more often "
        "(issue 3's 5% target is missed by the default texture stage). The defaults were chosen on the "
        "outputs' measures, not on this ratio (docs/quality.md: the seams fell with the falloff); the last "
        "row measures the search on the flat weights and k of issue 3's defaults.",
        "",
        "| stage | ratio fast / exact | exact optimum found |",
        "|---|---|---|",
    ]
    for name, q in quality:
        lines.append(f"| {name} | {q['ratio']:.3f} | {100 * q['optimal_share']:.0f}% |")
    write_section("synthesis", "\n".join(lines))
    print("\n".join(lines))
    print(f"({time.perf_counter() - start:.0f} s)", statistics.mean([t[2] for t in timings]))


if __name__ == "__main__":
    main()
