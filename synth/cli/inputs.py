"""The input-image options shared by ``texsynth synthesize`` and ``texsynth submit``.

Solid methods take one exemplar for all three axes, or one per orthogonal plane for an anisotropic
material: ``--exemplar-xy`` is what the slices at fixed z look like (x to the right, y down),
``--exemplar-xz`` the slices at fixed y (x to the right, z down), ``--exemplar-yz`` the slices at
fixed x (y to the right, z down). Volumes are ``(D, H, W) = (z, y, x)``; a TIFF stack has one page
per z.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = [
    "PLANES",
    "PLANE_HELP",
    "add_plane_arguments",
    "add_threads_argument",
    "input_sources",
    "threads_from",
]

PLANE_HELP = {
    "xy": "what the xy slices (fixed z: x right, y down) look like",
    "xz": "what the xz slices (fixed y: x right, z down) look like",
    "yz": "what the yz slices (fixed x: y right, z down) look like",
}
#: :data:`texsynth.synth.api.PLANES`, in its order (a test pins the two together): spelled here so that
# building
#: the parser (``--help``) does not import the engine.
PLANES: tuple[str, ...] = tuple(PLANE_HELP)


def add_plane_arguments(parser: argparse.ArgumentParser) -> None:
    """``--exemplar-xy/--exemplar-xz/--exemplar-yz``: per-plane exemplars of solid methods."""
    for plane in PLANES:
        parser.add_argument(
            f"--exemplar-{plane}",
            type=Path,
            metavar="PATH",
            help=f"solid methods, anisotropic material: {PLANE_HELP[plane]} (give all three, no --exemplar)",
        )


def input_sources(args: argparse.Namespace) -> dict[str, Path]:
    """The input images given on the command line, by role (``exemplar``, ``exemplar_xy``, ...)."""
    roles = {"exemplar": args.exemplar, "constraint": args.constraint}
    roles.update({f"exemplar_{plane}": getattr(args, f"exemplar_{plane}") for plane in PLANES})
    return {role: Path(path) for role, path in roles.items() if path is not None}


def add_threads_argument(parser: argparse.ArgumentParser) -> None:
    """``--threads N``: the job's numba threads (default: every core; the same bytes whatever N)."""
    parser.add_argument(
        "--threads",
        metavar="N",
        help="threads to run on, 1 to NUMBA_NUM_THREADS (default: every core); the same bytes whatever N",
    )


def threads_from(args: argparse.Namespace) -> int | None:
    """``--threads`` checked (:func:`texsynth.synth.threads.check_threads`): a bad value is one line and exit
    2."""
    from texsynth.synth.threads import check_threads

    return check_threads(args.threads, "--threads")
