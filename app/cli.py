"""``texsynth serve``: the API, the browser page and a real Celery worker process, in one command.

With no ``REDIS_URL`` everything runs on the embedded default (filesystem broker and SQLite under
the data directory), so a fresh machine needs no server. The worker is a child process group that
is restarted if it dies; stopping ``serve`` (Ctrl-C) stops it too.

``serve`` owns its worker (issue 30): stopping ``serve`` sends SIGTERM to the worker's main process
(a warm shutdown: its running jobs have ``TEXSYNTH_SHUTDOWN_GRACE`` seconds), waits that long and a
little more, then SIGKILLs the worker's process group. If ``serve`` dies, even by ``kill -9``, the
worker's main process gets SIGKILL from the kernel (Linux ``PR_SET_PDEATHSIG``; its pool children
follow) and sees the end of a pipe from ``serve`` (``--parent-fd``, :mod:`texsynth.worker.lifeline`): never
Celery's cold shutdown, which can hang. ``<data dir>/serve.pid`` records ``serve`` and its worker's
process group, so a ``serve`` that starts after one that vanished stops the worker left over, and one
that finds another ``serve`` alive on the same data directory refuses to start.

Without API tokens (``TEXSYNTH_API_TOKENS``, ``TEXSYNTH_API_TOKEN_FILE``, ``TEXSYNTH_ADMIN_TOKEN``)
anyone who reaches the port can submit, read and delete every job, so ``serve`` listens on 127.0.0.1
unless ``--host`` says otherwise, says so at start, and warns when told to listen on every interface.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from texsynth.jobs.config import Settings

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="start the job service (API + browser page + worker)",
        description="Start the texsynth job service and print its URL.",
    )
    p.add_argument(
        "--host",
        help="interface to listen on (default 127.0.0.1: this machine only; use 0.0.0.0 for every "
        "interface, with TEXSYNTH_API_TOKENS set)",
    )
    p.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    p.add_argument(
        "--data-dir",
        help="where jobs, records and the embedded queue live (default: $TEXSYNTH_DATA_DIR or ./data)",
    )
    p.add_argument("--workers", type=int, help="worker processes (default: $TEXSYNTH_CONCURRENCY or CPUs)")
    p.add_argument("--no-worker", action="store_true", help="API only (workers run elsewhere)")
    p.set_defaults(func=run)


PID_FILE = "serve.pid"
_PR_SET_PDEATHSIG = 1


class ServeLock:
    """``<data dir>/serve.pid``: this ``serve`` (pid, host) and its worker's process group."""

    def __init__(self, data_dir: os.PathLike[str] | str) -> None:
        self.path = os.path.join(data_dir, PID_FILE)
        self.host = socket.gethostname()

    def _read(self) -> dict:
        try:
            with open(self.path) as fh:
                record = json.load(fh)
        except (OSError, ValueError):
            return {}
        return record if isinstance(record, dict) else {}

    def acquire(self) -> str | None:
        """Check the previous owner: ``None`` if this ``serve`` may start (a worker left over by a
        ``serve`` that vanished is stopped first, and said so), else why it may not."""
        from texsynth.jobs.store import pid_alive

        record = self._read()
        if record.get("host") != self.host:  # none, or another machine's (a shared data directory)
            return None
        pid, group = record.get("pid"), record.get("worker_group")
        if isinstance(pid, int) and pid != os.getpid() and pid_alive(pid) and _cmdline_has(pid, b"serve"):
            return (
                f"another texsynth serve (pid {pid}) is running on this data directory; stop it first, "
                "or give this one its own --data-dir"
            )
        if (
            isinstance(group, int)
            and group > 1
            and _group_has_live_member(group)  # zombies of a worker that ended are no worker
            and (not pid_alive(group) or _cmdline_has(group, b"worker"))
        ):
            try:
                os.killpg(group, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                return None
            print(
                f"texsynth serve: stopped the worker (process group {group}) left running by a previous "
                f"serve (pid {pid}) that did not exit cleanly",
                file=sys.stderr,
                flush=True,
            )
        return None

    def record(self, worker_group: int | None) -> None:
        from texsynth.synth.io.atomic import (
            atomic_write_bytes,  # not at import: building the parser stays light
        )

        record = {"pid": os.getpid(), "host": self.host, "worker_group": worker_group}
        atomic_write_bytes(self.path, json.dumps(record).encode())

    def release(self) -> None:
        if self._read().get("pid") == os.getpid():
            with contextlib.suppress(OSError):
                os.remove(self.path)


def _cmdline_has(pid: int, word: bytes) -> bool:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return word in fh.read()
    except OSError:
        return True  # no /proc: trust the record


def _group_has_live_member(pgid: int) -> bool:
    """Whether process group ``pgid`` has a member that is not a zombie (any member, without /proc)."""
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        entries = [e for e in os.listdir("/proc") if e.isdigit()]
    except OSError:
        return True
    for entry in entries:
        try:
            with open(f"/proc/{entry}/stat") as fh:
                state, _, group = fh.read().rsplit(")", 1)[1].split()[:3]
        except (OSError, ValueError, IndexError):
            continue
        if int(group) == pgid and state not in ("Z", "X"):
            return True
    return False


def _libc() -> ctypes.CDLL | None:
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl  # noqa: B018  (Linux only)
        return libc
    except (OSError, AttributeError):
        return None


class WorkerSupervisor(threading.Thread):
    """Keeps one ``python -m worker`` process group running; restarts it if it dies; stops it.

    This thread starts every worker and stops the last one itself, so it outlives them: the kernel's
    parent-death signal fires when the parent *thread* ends, not only the process.
    """

    #: Seconds ``serve`` waits beyond the worker's grace before it kills the worker's process group.
    MARGIN = 5.0

    def __init__(self, env: dict[str, str], lock: ServeLock | None = None, grace: float = 30.0) -> None:
        super().__init__(name="texsynth-worker-supervisor", daemon=True)
        self.env = env
        self.lock = lock
        self.grace = grace
        self.proc: subprocess.Popen | None = None
        self._lifeline: int | None = None  # write end of the worker's --parent-fd pipe
        self._stopping = threading.Event()
        self._stopped = threading.Event()
        self._libc = _libc()

    def _spawn(self) -> None:
        parent, libc = os.getpid(), self._libc

        def die_with_serve() -> None:  # in the child, between fork and exec
            if libc is not None:
                libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)  # serve gone -> gone, whatever Celery does
            if os.getppid() != parent:  # serve died before that took effect
                os._exit(1)

        if self._lifeline is not None:  # the previous worker's: it is dead
            os.close(self._lifeline)
        read, self._lifeline = os.pipe()  # the write end stays here only (not inheritable)
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "texsynth.worker", "--loglevel=WARNING", "--quiet",
                 f"--parent-fd={read}"],
                env=self.env,
                start_new_session=True,
                preexec_fn=die_with_serve,
                pass_fds=(read,),
            )
        finally:
            os.close(read)
        if self.lock is not None:
            self.lock.record(self.proc.pid)

    def run(self) -> None:
        try:
            self._spawn()
            while not self._stopping.wait(1.0):
                if self.proc is not None and self.proc.poll() is not None:
                    print(
                        f"texsynth serve: the worker exited ({self.proc.returncode}); restarting it",
                        flush=True,
                    )
                    _kill_group(self.proc.pid, signal.SIGKILL)  # orphaned pool children, if any
                    self._spawn()
        finally:
            self._stop_worker()
            self._stopped.set()

    def _stop_worker(self) -> None:
        """SIGTERM to the worker's main process, at most grace + MARGIN s, SIGKILL to its group."""
        if self.proc is None:
            return
        # the main process only: SIGTERM ends a pool child at once, the main process waits for its jobs
        with contextlib.suppress(ProcessLookupError):
            if self.proc.poll() is None:
                os.kill(self.proc.pid, signal.SIGTERM)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(timeout=self.grace + self.MARGIN)
        _kill_group(self.proc.pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(timeout=5)

    def stop(self) -> None:
        """Stop the worker (bounded: grace + MARGIN + a few s) and return when it is gone."""
        self._stopping.set()
        if self.is_alive():
            self.join(timeout=self.grace + self.MARGIN + 10)
        elif not self._stopped.is_set():  # never started
            self._stop_worker()


def _kill_group(pgid: int, sig: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, sig)


_LOOPBACK = ("127.0.0.1", "localhost", "::1")


def host_notice(host: str | None, tokens: bool) -> tuple[str, str | None]:
    """The interface to listen on and what to tell the person about it (``None``: nothing)."""
    chosen = host or "127.0.0.1"
    if tokens:
        return chosen, None
    if host is None:
        return chosen, (
            "texsynth serve: no API tokens are set, so the service listens on 127.0.0.1 only (this "
            "machine); to serve others, set TEXSYNTH_API_TOKENS (see docs/service.md, Tokens) and "
            "pass --host 0.0.0.0"
        )
    if chosen not in _LOOPBACK:
        return chosen, (
            f"texsynth serve: WARNING: listening on {chosen} without API tokens: anyone who can reach "
            "this port can submit jobs, read every job's inputs and outputs, and cancel or delete them. "
            "Set TEXSYNTH_API_TOKENS (see docs/service.md, Tokens)"
        )
    return chosen, None


def with_bound_host(settings: Settings, host: str) -> Settings:
    """``settings`` with the name ``serve`` was told to listen on among the allowed hosts (the Host
    check, :mod:`texsynth.app.security`); addresses and every-interface binds add nothing (addresses pass)."""
    import ipaddress

    name = host.strip().strip("[]").lower()
    try:
        ipaddress.ip_address(name)
        return settings
    except ValueError:
        pass
    if not name or name in settings.allowed_hosts:
        return settings
    return settings.model_copy(update={"allowed_hosts": (*settings.allowed_hosts, name)})


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from texsynth.app.auth import TokenError, Tokens
    from texsynth.app.main import create_app
    from texsynth.app.server import uvicorn_config
    from texsynth.jobs.config import Settings
    from texsynth.synth.threads import available_cores

    settings = Settings.from_env(data_dir=args.data_dir, concurrency=args.workers)
    settings.ensure_dirs()
    try:
        tokens = Tokens.from_settings(settings)
    except TokenError as exc:
        print(f"texsynth serve: {exc}", file=sys.stderr)
        return 2
    host, notice = host_notice(args.host, tokens.enabled)
    if notice:
        print(notice, file=sys.stderr, flush=True)
    settings = with_bound_host(settings, host)
    env = {**os.environ, **settings.to_env()}
    cwd = os.getcwd()
    env["PYTHONPATH"] = os.pathsep.join(p for p in (cwd, env.get("PYTHONPATH", "")) if p)
    lock = None
    if not args.no_worker:
        lock = ServeLock(settings.data_dir)
        refusal = lock.acquire()
        if refusal:
            print(f"texsynth serve: {refusal}", file=sys.stderr)
            return 2
        lock.record(None)
    supervisor = None if args.no_worker else WorkerSupervisor(env, lock, settings.shutdown_grace)
    server = uvicorn.Server(uvicorn_config(create_app(settings), settings, host, args.port))
    url = f"http://{'localhost' if host in ('127.0.0.1', '0.0.0.0', '::') else host}:{args.port}/"

    def announce() -> None:
        while not server.started and not server.should_exit:
            time.sleep(0.05)
        if server.started:
            queue = "Redis" if settings.redis_url else "embedded queue (no server needed)"
            access = f"tokens of {', '.join(tokens.names)}" if tokens.enabled else "no tokens"
            print(
                f"texsynth is serving at {url}  (data: {settings.data_dir}; "
                f"{settings.where() + '; ' if settings.where() else ''}{queue}; "
                f"{'no worker' if supervisor is None else f'{settings.concurrency} worker processes'} x "
                f"{settings.threads} threads of {available_cores()} cores; "
                f"{access})",
                flush=True,
            )

    def on_signal(sig: int, frame: object) -> None:
        # uvicorn restores this handler after its graceful shutdown and re-raises the signal here
        if supervisor is not None:
            supervisor.stop()
        if lock is not None:
            lock.release()
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
        if lock is not None:
            lock.release()
    return 0
