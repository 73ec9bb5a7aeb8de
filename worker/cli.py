"""``texsynth worker``: start a Celery worker (prefork pool) on the configured broker.

Run as many as you like, on as many machines as share the broker (``REDIS_URL``) and the data
directory. ``python -m worker`` does the same (``texsynth serve`` starts one that way, with
``--parent-fd``). A stop signal gives the running jobs ``TEXSYNTH_SHUTDOWN_GRACE`` seconds; a second
one, or the end of the grace, ends the worker for certain (:mod:`texsynth.worker.lifeline`).
"""

from __future__ import annotations

import argparse
import os
import socket

__all__ = ["main", "register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "worker",
        help="run a job worker (Celery, prefork pool)",
        description="Run a Celery worker for texsynth jobs on the configured broker.",
    )
    add_arguments(p)
    p.set_defaults(func=run)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data-dir", help="shared data directory (default: $TEXSYNTH_DATA_DIR or ./data)")
    p.add_argument(
        "--concurrency", type=int, help="worker processes (default: $TEXSYNTH_CONCURRENCY or CPUs)"
    )
    p.add_argument("--name", help="worker node name (default: texsynth-<pid>@<host>)")
    p.add_argument("--loglevel", default="INFO")
    p.add_argument("--quiet", action="store_true", help="no start-up banner")
    p.add_argument(
        "--parent-fd",
        type=int,
        help="read end of a pipe from the process that started this worker: exit when it closes",
    )


def run(args: argparse.Namespace) -> int:
    # The Celery app reads Settings from the environment when first imported: set it first.
    if args.data_dir:
        os.environ["TEXSYNTH_DATA_DIR"] = os.path.abspath(args.data_dir)
    if args.concurrency:
        os.environ["TEXSYNTH_CONCURRENCY"] = str(args.concurrency)
    from texsynth.synth.threads import available_cores
    from texsynth.worker.celery_app import app, last_heartbeat, settings
    from texsynth.worker.lifeline import ShutdownGuard

    name = args.name or f"texsynth-{os.getpid()}@{socket.gethostname()}"
    if not args.quiet:
        print(
            f"texsynth worker {name}: {settings.concurrency} processes x {settings.threads} threads "
            f"({available_cores()} cores), data {settings.data_dir}, "
            f"broker {'redis' if settings.redis_url else 'filesystem (embedded)'}"
            + (f"; {settings.where()}" if settings.where() else ""),
            flush=True,
        )
    # before Celery forks its pool and installs its signal handlers: its shutdown can hang (issue 30)
    ShutdownGuard(settings.shutdown_grace, last_heartbeat, args.parent_fd).install()
    app.worker_main(
        [
            *(["--quiet"] if args.quiet else []),
            "worker",
            f"--loglevel={args.loglevel}",
            f"--hostname={name}",
            f"--concurrency={settings.concurrency}",
            "--pool=prefork",
            "--without-gossip",
            "--without-mingle",
        ]
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m worker")
    add_arguments(parser)
    return run(parser.parse_args(argv))
