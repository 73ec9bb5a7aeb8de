"""``texsynth``: the command line, a thin shell over the engine (parse -> build -> run -> report).

Each subcommand lives in its own module under :mod:`texsynth.synth.cli` and exposes
``register(subparsers)``; commands that belong above the engine (``serve``, ``worker``,
``submit``) are contributed by ``app``/``worker`` through the ``texsynth.commands`` entry-point
group, so that ``synth`` never imports them. Errors from the engine print as one line and exit 2.

Start-up is kept short: building the parser imports no numpy, numba, scipy or matplotlib (each
command imports what it needs when it runs), and when the command line names an engine command only
that command's parser is built (the entry points are not scanned).

OpenBLAS runs single-threaded in every ``texsynth`` command and the processes it starts
(:mod:`texsynth.synth.threads`, the one place that sets it; docs/benchmarks.md measures why).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from texsynth.synth import __version__
from texsynth.synth.errors import StorageError, SynthError
from texsynth.synth.threads import single_threaded_blas

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
            module = importlib.import_module(f"texsynth.synth.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"texsynth.synth.cli.{name}":
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
    single_threaded_blas()  # before NumPy loads OpenBLAS
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
