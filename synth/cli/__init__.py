"""``texsynth``: the command line, a thin shell over the engine (parse -> build -> run -> report).

Each subcommand lives in its own module under :mod:`synth.cli` and exposes
``register(subparsers)``; commands that belong above the engine (``serve``, ``worker``,
``submit``) are contributed by ``app``/``worker`` through the ``texsynth.commands`` entry-point
group, so that ``synth`` never imports them. Errors from the engine print as one line and exit 2.

Start-up is kept short: building the parser imports no numpy, numba, scipy or matplotlib (each
command imports what it needs when it runs), and when the command line names an engine command only
that command's parser is built (the entry points are not scanned).

OpenBLAS runs single-threaded in every ``texsynth`` command, and in the processes they start (the
workers of ``texsynth serve``), unless ``OPENBLAS_NUM_THREADS`` says otherwise (set before NumPy
loads it): the engine's matrix work is small (the k-coherence PCA of a few thousand neighbourhoods
of at most a few hundred values), where its threads cost more than they give, and on a shared
2-core machine they spin against the other work (wei-levoy 128 -> 256 under load 4-5: its three
levels' k-coherence sets took 1.69 s of CPU with two threads, 1.23 s with one, the covariance and
``eigh`` 0.45 s against 0.005 s). The bytes are the same whatever the count
(``tests/synth/cli/test_cli_synthesize.py``).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from synth import __version__
from synth.errors import StorageError, SynthError

__all__ = ["build_parser", "main"]

_ENGINE_COMMANDS = ("analyze", "methods", "synthesize", "evaluate")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The ``texsynth`` parser with every command; with ``only`` (an engine command), just that one."""
    parser = argparse.ArgumentParser(
        prog="texsynth",
        description="Exemplar-based texture synthesis for virtual-material design.",
    )
    parser.add_argument("--version", action="version", version=f"texsynth {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in (only,) if only in _ENGINE_COMMANDS else _ENGINE_COMMANDS:
        try:
            module = importlib.import_module(f"synth.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"synth.cli.{name}":
                raise
            continue
        module.register(sub)
    if only not in _ENGINE_COMMANDS:
        from importlib.metadata import entry_points  # scans every installed package: only when needed

        for ep in entry_points(group="texsynth.commands"):
            ep.load()(sub)
    return parser


def _command(argv: Sequence[str]) -> str | None:
    """The command named on the command line (its first word that is not an option), if any."""
    return next((word for word in argv if not word.startswith("-")), None)


def main(argv: Sequence[str] | None = None) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before NumPy loads OpenBLAS (module docstring)
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(_command(argv))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except SynthError as exc:
        print(f"texsynth {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except StorageError as exc:  # the machine's problem (full disk, permissions), not the input's
        print(f"texsynth {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"texsynth {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
