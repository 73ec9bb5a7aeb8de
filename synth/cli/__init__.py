"""``texsynth``: the command line, a thin shell over the engine (parse -> build -> run -> report).

Each subcommand lives in its own module under :mod:`synth.cli` and exposes
``register(subparsers)``; commands that belong above the engine (``serve``, ``worker``,
``submit``) are contributed by ``app``/``worker`` through the ``texsynth.commands`` entry-point
group, so that ``synth`` never imports them. Errors from the engine print as one line and exit 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from importlib.metadata import entry_points

from synth import __version__
from synth.errors import StorageError, SynthError

__all__ = ["build_parser", "main"]

_ENGINE_COMMANDS = ("analyze", "methods", "synthesize", "evaluate")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="texsynth",
        description="Exemplar-based texture synthesis for virtual-material design.",
    )
    parser.add_argument("--version", action="version", version=f"texsynth {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in _ENGINE_COMMANDS:
        try:
            module = importlib.import_module(f"synth.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"synth.cli.{name}":
                raise
            continue
        module.register(sub)
    for ep in entry_points(group="texsynth.commands"):
        ep.load()(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
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
