"""``make bench``: every benchmark in turn; each rewrites its own section of docs/benchmarks.md.

Run on a quiet machine: the figures are wall-clock medians.
"""

from __future__ import annotations

import importlib
import sys

BENCHMARKS = (
    "benchmarks.bench_tensor",
    "benchmarks.bench_evaluate",
    "benchmarks.bench_synthesis",
    "benchmarks.bench_arbitrary_shape",
    "benchmarks.bench_patch",
    "benchmarks.bench_solid",
    "benchmarks.bench_service",
    "benchmarks.claim_tensor_constrained",
)


def main() -> int:
    for name in BENCHMARKS:
        print(f"== {name}", flush=True)
        code = importlib.import_module(name).main()
        if code:
            return int(code)
    return 0


if __name__ == "__main__":
    sys.exit(main())
