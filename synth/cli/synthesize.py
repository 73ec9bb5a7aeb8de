"""``texsynth synthesize METHOD --exemplar PATH --size WxH --out DIR``: one synthesis, all artifacts.

Writes ``output.png`` (16-bit with ``--bit-depth 16``), ``output.tiff``, ``manifest.json``,
``metrics.json``, the tensor field's ``coherence.png``/``orientation.png`` and comparison plots (see
:mod:`texsynth.synth.output.artifacts`). Parameters come from the method's model: ``--set name=value`` (values
are read as JSON when they parse, e.g. ``--set levels=3 --set metric=ED``). A progress bar is drawn on
stderr when it is a terminal.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from texsynth.synth.cli.inputs import add_plane_arguments, add_threads_argument, input_sources, threads_from
from texsynth.synth.errors import InvalidParameter

__all__ = ["parse_size", "register"]


def parse_size(text: str) -> tuple[int, ...]:
    """``'WxH'`` -> ``(H, W)``; ``'WxHxD'`` -> ``(D, H, W)`` (array order)."""
    try:
        parts = [int(p) for p in text.lower().split("x")]
    except ValueError:
        parts = []
    if len(parts) not in (2, 3) or any(p <= 0 for p in parts):
        raise InvalidParameter("size", text, "must look like WxH (e.g. 256x256) or WxHxD for volumes")
    return tuple(reversed(parts))


class _ProgressBar:
    """A one-line progress bar on a terminal; silent otherwise (logs and pipes stay clean)."""

    def __init__(self, stream: Any = None) -> None:
        # sys.stderr as it is now, not as it was at import (pytest's capture replaces it per test)
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.start = time.perf_counter()

    def __call__(self, stage: str, fraction: float) -> None:
        if not self.enabled:
            return
        width = 30
        filled = round(width * fraction)
        elapsed = time.perf_counter() - self.start
        bar = "#" * filled + "." * (width - filled)
        line = f"\r[{bar}] {100 * fraction:5.1f}% {elapsed:6.1f}s  {stage[:48]:<48}"
        self.stream.write(line)
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


def _run(args: argparse.Namespace) -> int:
    from texsynth.synth.cli import imports_without_gc, modules_on_demand

    # deferred: ``--help`` imports no engine; only the chosen method's module is imported, and the writer
    with imports_without_gc():
        modules_on_demand()
        from texsynth.synth.api import available_methods, check_inputs, find_method
        from texsynth.synth.params import parse_assignments
        from texsynth.synth.pipeline import load_inputs, synthesize_to_folder

        spec = find_method(args.method)
        if spec is not None:
            import texsynth.synth.output.artifacts  # noqa: F401  (the writer, here: without the collector)
    if spec is None:
        known = ", ".join(sorted(available_methods()))
        raise InvalidParameter("METHOD", args.method, f"unknown method (known: {known})")
    if args.bit_depth is not None and args.bit_depth not in (8, 16):
        raise InvalidParameter("--bit-depth", args.bit_depth, "must be 8 or 16")
    if args.voxel_size is not None and not 0 < args.voxel_size < 1e6:
        raise InvalidParameter("--voxel-size", args.voxel_size, "must be a positive size in nm")
    threads = threads_from(args)
    params = parse_assignments(args.set or [])
    size = parse_size(args.size) if args.size else None
    sources = input_sources(args)
    check_inputs(spec, set(sources))  # before any image is decoded
    images = load_inputs(sources)
    out = Path(args.out)
    bar = _ProgressBar()
    try:
        outcome = synthesize_to_folder(
            args.method,
            images,
            out,
            size=size,
            params=params,
            seed=args.seed,
            progress=bar,
            manifest={role: str(path) for role, path in sources.items()},
            bit_depth=args.bit_depth,
            plots=not args.no_plots,
            voxel_size=args.voxel_size,
            threads=threads,
        )
    finally:
        bar.close()
    result, names = outcome.result, outcome.files
    summary = outcome.metrics.get("summary", {})
    shape = result.image.shape if spec.output_ndim == 3 else result.image.shape[:2]
    print(
        f"{args.method}: {'x'.join(str(s) for s in reversed(shape))} in "
        f"{result.timings.get('total', 0.0):.2f} s -> {out}/ ({len(names)} files)"
    )
    if summary:
        print("  " + ", ".join(f"{k} {v:.4g}" for k, v in summary.items() if isinstance(v, int | float)))
    stationarity = outcome.metrics.get("exemplar", {}).get("stationarity", {})
    scores = [f"{role} {r['score']:.2f}" for role, r in stationarity.items() if r.get("score") is not None]
    if scores:
        print("  exemplar stationarity (<= 1: one texture throughout): " + ", ".join(scores))
    for warning in outcome.metrics.get("exemplar", {}).get("warnings", []):
        print(f"  warning: {warning.removeprefix('exemplar: ')}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "synthesize",
        help="synthesize a texture from an exemplar",
        description="Synthesize a texture (METHOD from 'texsynth methods') and write the output, its tensor "
        "field images, metrics, plots and a manifest into DIR.",
    )
    p.add_argument("method", metavar="METHOD", help="method name, e.g. wei-levoy or tensor-constrained")
    p.add_argument("--exemplar", type=Path, help="exemplar image (PNG, TIFF or JPEG)")
    add_plane_arguments(p)
    p.add_argument("--constraint", type=Path, help="constraint image, for methods that take one")
    p.add_argument(
        "--size",
        help="output size WxH, or WxHxD for a volume (default: the constraint's, else twice the exemplar's; "
        "a volume at the exemplar's scale)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (same seed, same bytes)")
    add_threads_argument(p)
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="a method parameter (repeatable)")
    p.add_argument(
        "--bit-depth",
        type=int,
        default=None,
        help="bit depth of output.png: 8 or 16 (default: 16 for 16-bit inputs)",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the comparison plots")
    p.add_argument(
        "--voxel-size",
        type=float,
        metavar="NM",
        help="volumes: the size of a voxel in nm (the exemplar's pixel size), written into output.tiff "
        "for Fiji and used for fringe lengths",
    )
    p.add_argument("--out", required=True, type=Path, help="output directory (created)")
    p.set_defaults(func=_run)
