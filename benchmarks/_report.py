"""Shared machinery of the benchmarks: timing (median of runs) and writing a section of docs/benchmarks.md
(or of another document).

Each benchmark owns one section, delimited by HTML comments, and rewrites only that section, so that
benchmarks can run in any order and the document keeps the latest figures of each.
"""

from __future__ import annotations

import os
import platform
import re
import statistics
import time
from collections.abc import Callable
from pathlib import Path

from tests.paths import SHARED_DATA

DOC = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"
#: The project's shared test images (``$TEXSYNTH_SHARED_DATA``, else ``shared/data`` beside the checkout).
DATA = SHARED_DATA
_HEADER = (
    "# Benchmarks\n\nMeasured by `make bench` (or `python -m benchmarks.<name>`); "
    "every figure is a median of several runs.\n"
)


def machine() -> str:
    """One line naming the machine the figures were measured on."""
    return f"{os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}"


def median_time(fn: Callable[[], object], runs: int = 5, warmup: int = 1) -> tuple[float, list[float]]:
    """Median wall-clock seconds of ``fn`` over ``runs`` runs, after ``warmup`` untimed runs (JIT)."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), times


def write_section(name: str, markdown: str, doc: Path = DOC) -> None:
    """Replace (or append) section ``name`` of ``doc`` (default docs/benchmarks.md) with ``markdown``."""
    doc.parent.mkdir(parents=True, exist_ok=True)
    text = doc.read_text() if doc.exists() else _HEADER
    stamp = f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}._"
    block = f"<!-- begin:{name} -->\n{markdown.rstrip()}\n\n{stamp}\n<!-- end:{name} -->"
    pattern = re.compile(rf"<!-- begin:{re.escape(name)} -->.*?<!-- end:{re.escape(name)} -->", re.S)
    text = (
        pattern.sub(lambda _: block, text) if pattern.search(text) else text.rstrip() + "\n\n" + block + "\n"
    )
    doc.write_text(text)
