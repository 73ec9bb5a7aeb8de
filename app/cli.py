"""``texsynth serve``: the API, the browser page and a real Celery worker process, in one command.

With no ``REDIS_URL`` everything runs on the embedded default (filesystem broker and SQLite under
the data directory), so a fresh machine needs no server. The worker is a child process group that
is restarted if it dies; stopping ``serve`` (Ctrl-C) stops it too.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import threading
import time

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="start the job service (API + browser page + worker)",
        description="Start the texsynth job service and print its URL.",
    )
    p.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    p.add_argument(
        "--data-dir",
        help="where jobs, records and the embedded queue live (default: $TEXSYNTH_DATA_DIR or ./data)",
    )
    p.add_argument("--workers", type=int, help="worker processes (default: $TEXSYNTH_CONCURRENCY or CPUs)")
    p.add_argument("--no-worker", action="store_true", help="API only (workers run elsewhere)")
    p.set_defaults(func=run)


class WorkerSupervisor(threading.Thread):
    """Keeps one ``python -m worker`` process group running; restarts it if it dies."""

    def __init__(self, env: dict[str, str]) -> None:
        super().__init__(name="texsynth-worker-supervisor", daemon=True)
        self.env = env
        self.proc: subprocess.Popen | None = None
        self._stopping = threading.Event()

    def _spawn(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "worker", "--loglevel=WARNING", "--quiet"],
            env=self.env,
            start_new_session=True,
        )

    def run(self) -> None:
        self._spawn()
        while not self._stopping.wait(1.0):
            if self.proc is not None and self.proc.poll() is not None:
                print(
                    f"texsynth serve: the worker exited ({self.proc.returncode}); restarting it", flush=True
                )
                _kill_group(self.proc.pid, signal.SIGKILL)  # orphaned pool children, if any
                self._spawn()

    def stop(self) -> None:
        self._stopping.set()
        if self.proc is None:
            return
        _kill_group(self.proc.pid, signal.SIGTERM)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(timeout=5)
        _kill_group(self.proc.pid, signal.SIGKILL)


def _kill_group(pgid: int, sig: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, sig)


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from app.main import create_app
    from jobs.config import Settings

    settings = Settings.from_env(data_dir=args.data_dir, concurrency=args.workers)
    settings.ensure_dirs()
    env = {**os.environ, **settings.to_env()}
    cwd = os.getcwd()
    env["PYTHONPATH"] = os.pathsep.join(p for p in (cwd, env.get("PYTHONPATH", "")) if p)
    supervisor = None if args.no_worker else WorkerSupervisor(env)
    config = uvicorn.Config(
        create_app(settings), host=args.host, port=args.port, log_level="warning", timeout_graceful_shutdown=3
    )
    server = uvicorn.Server(config)
    url = f"http://{'localhost' if args.host in ('127.0.0.1', '0.0.0.0', '::') else args.host}:{args.port}/"

    def announce() -> None:
        while not server.started and not server.should_exit:
            time.sleep(0.05)
        if server.started:
            queue = "Redis" if settings.redis_url else "embedded queue (no server needed)"
            print(
                f"texsynth is serving at {url}  (data: {settings.data_dir}; {queue}; "
                f"{'no worker' if supervisor is None else f'{settings.concurrency} worker processes'})",
                flush=True,
            )

    def on_signal(sig: int, frame: object) -> None:
        # uvicorn restores this handler after its graceful shutdown and re-raises the signal here
        if supervisor is not None:
            supervisor.stop()
        raise SystemExit(130 if sig == signal.SIGINT else 0)

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    if supervisor is not None:
        supervisor.start()
    threading.Thread(target=announce, daemon=True).start()
    try:
        server.run()
    finally:
        if supervisor is not None:
            supervisor.stop()
    return 0
