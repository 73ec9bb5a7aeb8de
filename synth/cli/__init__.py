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

A one-shot engine command also spares the work of Python's cycle collector that it does not need
(docs/benchmarks.md, "Outside the synthesis"): the collector is off while the command imports its
modules (:func:`imports_without_gc`: about 140,000 objects that live to the end, which it would
otherwise traverse several times as the heap grows) and, run as the ``texsynth`` program (:func:`entry`),
the process ends without tearing its modules down one by one (output flushed, ``atexit`` run). Modules
that the engine's dependencies import and no engine command uses (SciPy's array-API layer's ``from numpy
import *`` pulls in ``numpy.f2py`` and ``numpy.testing``; numba reads ``yaml`` only for a config file)
load on first use (:func:`modules_on_demand`).
"""

from __future__ import annotations

import argparse
import atexit
import gc
import importlib
import importlib.util
import os
import sys
import threading
import types
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from typing import NoReturn

from texsynth.synth import __version__
from texsynth.synth.errors import StorageError, SynthError
from texsynth.synth.threads import single_threaded_blas

__all__ = ["build_parser", "entry", "imports_without_gc", "main", "modules_on_demand"]

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


@contextmanager
def imports_without_gc() -> Iterator[None]:
    """Import with the cycle collector off, then move every object alive into its permanent generation.

    What a command imports (modules, classes, numba's and SciPy's tables) lives until the process ends
    and holds no garbage, yet the collector would traverse it at every full collection while the heap
    grows, and all of it once more when enabled again. Frozen (:func:`gc.freeze`), it is never traversed;
    later garbage is collected as usual. Nested blocks leave it to the outermost.
    """
    if not gc.isenabled():  # inside another block, or the caller's choice: leave the collector alone
        yield
        return
    gc.disable()
    try:
        yield
    finally:
        gc.freeze()
        gc.enable()


#: What the engine's dependencies import and no engine command uses: ``from numpy import *`` (SciPy's
#: array-API layer, when ``scipy.ndimage`` loads) binds NumPy's ``f2py`` and ``testing``; numba imports
#: ``yaml`` for a ``.numba_config.yaml`` that is seldom there. About 60 modules, 0.03-0.05 s of a start.
ON_DEMAND = ("numpy.f2py", "numpy.testing", "yaml")
_on_demand_lock = threading.Lock()


class _OnDemand(types.ModuleType):
    """Stands for one of :data:`ON_DEMAND` until an attribute is asked of it: then the real module is
    imported (once, under a lock: the writer's threads may ask too), takes its place in ``sys.modules`` (and
    on its package), and answers; the placeholder goes on answering for it where it was bound."""

    def __getattr__(self, attr: str) -> object:
        return getattr(_load(self.__name__), attr)


def _load(name: str) -> types.ModuleType:
    with _on_demand_lock:
        parent, _, short = name.rpartition(".")
        if isinstance(sys.modules.get(name), _OnDemand):
            del sys.modules[name]
            if parent:
                with suppress(AttributeError):
                    delattr(sys.modules[parent], short)
        return importlib.import_module(name)


def modules_on_demand() -> None:
    """Put placeholders for :data:`ON_DEMAND`'s modules not loaded yet (and installed) in ``sys.modules``
    and on their packages: an ``import`` or a ``from numpy import *`` binds them without loading them; the
    first attribute asked of one loads it. Imports NumPy; for a command's start, before SciPy and numba."""
    import numpy  # noqa: F401  (the package its submodules' placeholders go on)

    with _on_demand_lock:
        for name in ON_DEMAND:
            if name in sys.modules or importlib.util.find_spec(name) is None:
                continue
            parent, _, short = name.rpartition(".")
            placeholder = _OnDemand(name)
            sys.modules[name] = placeholder
            if parent:
                setattr(sys.modules[parent], short, placeholder)


def main(argv: Sequence[str] | None = None) -> int:
    single_threaded_blas()  # before NumPy loads OpenBLAS
    argv = list(sys.argv[1:] if argv is None else argv)
    with imports_without_gc():
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
    except MemoryError as exc:  # the machine's too: what the run would allocate does not fit
        print(
            f"texsynth {args.command}: error: not enough memory for this run ({exc or 'MemoryError'}); ask "
            "for a smaller output, a smaller exemplar or a coarser setting",
            file=sys.stderr,
        )
        return 1
    except KeyboardInterrupt:
        print(f"texsynth {args.command}: interrupted", file=sys.stderr)
        return 130
    finally:
        gc.unfreeze()  # what the imports froze is ordinary again (for a caller that goes on running)


def _flush(stream: object) -> None:
    with suppress(AttributeError, OSError, ValueError):  # closed, or a pipe whose reader left
        stream.flush()  # type: ignore[attr-defined]


def entry() -> NoReturn:
    """The ``texsynth`` program: :func:`main`, and for a one-shot engine command a quick exit.

    After an engine command every file is written and closed; what is left of the process is Python's
    teardown of its modules and objects (numba, SciPy, LLVM: 0.1-0.3 s of CPU after a synthesis). Its
    ``atexit`` functions are run and stdout/stderr flushed, then the process ends with the command's
    status. Other commands (``serve``, ``worker``: long-lived, with threads and children) end normally.
    """
    code = main()
    if _command(sys.argv[1:]) in _ENGINE_COMMANDS:
        atexit._run_exitfuncs()
        _flush(sys.stdout)
        _flush(sys.stderr)
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":  # pragma: no cover
    entry()
