"""A worker that ends for certain: a bounded shutdown, and no life after the process that started it.

Celery's own shutdown can wait forever: a cold shutdown that begins during a warm one, after jobs ran,
blocks its main process in a futex and ignores further signals (issue 30). So the end of a worker's
main process never depends on it. :class:`ShutdownGuard` runs two daemon threads:

- signals: the interpreter writes the number of every signal it handles to a wakeup pipe
  (:func:`signal.set_wakeup_fd`), at delivery, whatever the main thread is blocked in. The first
  SIGTERM, SIGINT or SIGQUIT lets Celery's shutdown run for ``grace`` seconds (a warm one waits for
  the running jobs); a second one, or the end of the grace, ends the process: a last heartbeat, SIGKILL
  to the pool children, ``os._exit``. The jobs it held are re-run by the reaper (:mod:`texsynth.jobs.reaper`).
- parent: with ``--parent-fd`` (``texsynth serve`` passes the read end of a pipe whose write end only
  it holds), the end of that pipe means the parent is gone, however it died: the same hard exit.

:class:`texsynth.app.cli.WorkerSupervisor` adds the kernel's side of the second: SIGKILL at the parent's death
(Linux ``PR_SET_PDEATHSIG``, set between fork and exec), and Celery gives its pool children the same
towards the worker's main process. docs/service.md, "Stopping", has the signals and their bounds.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

__all__ = ["STOP_SIGNALS", "ShutdownGuard", "children"]

#: Signals that ask a worker to stop; the first starts the grace, the second ends the process.
STOP_SIGNALS = frozenset({signal.SIGTERM, signal.SIGINT, signal.SIGQUIT})
#: Exit status of a worker ended by the guard (Celery's hard shutdown uses the same).
EXIT_STATUS = 1
#: Seconds the hard exit waits for its SIGKILLed pool children to be gone.
REAP_SECONDS = 2.0


def children(pid: int) -> list[int]:
    """The live child processes of ``pid`` (from /proc; none where there is no /proc)."""
    found = []
    with contextlib.suppress(OSError):
        for entry in Path("/proc").iterdir():
            if not entry.name.isdigit():
                continue
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            state, ppid = stat[stat.rindex(")") + 2 :].split()[:2]
            if int(ppid) == pid and state not in ("Z", "X"):
                found.append(int(entry.name))
    return found


class ShutdownGuard:
    """Bounds the shutdown of this (worker main) process; see the module docstring.

    Parameters
    ----------
    grace
        Seconds the first stop signal gives the running jobs before the process ends.
    last_words
        Called (at most 1 s) just before the hard exit: the worker's last heartbeat.
    parent_fd
        Read end of a pipe from the parent; its end (EOF) means the parent is gone. ``None``: no parent
        to watch (a standalone worker).
    """

    def __init__(
        self, grace: float, last_words: Callable[[], None] | None = None, parent_fd: int | None = None
    ) -> None:
        if grace < 0:
            raise ValueError(f"grace must be >= 0 seconds, got {grace}")
        self.grace = grace
        self.last_words = last_words
        self.parent_fd = parent_fd
        self._lock = threading.Lock()

    def install(self) -> None:
        """Start watching; call from the main thread, before Celery forks its pool."""
        read, write = os.pipe()
        os.set_blocking(write, False)
        signal.set_wakeup_fd(write, warn_on_full_buffer=False)
        threading.Thread(
            target=self._watch_signals, args=(read,), name="texsynth-shutdown-guard", daemon=True
        ).start()
        if self.parent_fd is not None:
            threading.Thread(target=self._watch_parent, name="texsynth-parent-watch", daemon=True).start()

    @staticmethod
    def forget_in_child() -> None:
        """In a forked pool child: stop reporting its signals to the main process's guard."""
        with contextlib.suppress(ValueError):  # not the main thread: nothing was inherited there
            signal.set_wakeup_fd(-1)

    def _watch_signals(self, fd: int) -> None:
        deadline: float | None = None
        while True:
            timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready, _, _ = select.select([fd], [], [], timeout)
            if not ready:
                self.hard_exit(f"the shutdown grace of {self.grace:g} s ended before the worker did")
            for number in os.read(fd, 64):
                if number not in STOP_SIGNALS:
                    continue
                if deadline is not None:
                    self.hard_exit(f"a second stop signal ({signal.Signals(number).name})")
                deadline = time.monotonic() + self.grace
                _say(
                    f"{signal.Signals(number).name}: stopping; running jobs have {self.grace:g} s to end, "
                    "a second signal ends the worker now"
                )

    def _watch_parent(self) -> None:
        assert self.parent_fd is not None
        while True:
            try:
                if not os.read(self.parent_fd, 64):  # EOF: every copy of the write end is closed
                    break
            except InterruptedError:
                continue
            except OSError:
                break
        self.hard_exit(f"the process that started it (parent {os.getppid()} now) is gone")

    def hard_exit(self, why: str) -> None:
        """Last heartbeat, SIGKILL to the pool children, ``os._exit``: whatever Celery is waiting for."""
        if not self._lock.acquire(blocking=False):  # the other watcher is already on it
            return
        _say(f"{why}; ending now (the jobs it held are re-run)")
        if self.last_words is not None:
            words = threading.Thread(target=self.last_words, name="texsynth-last-words", daemon=True)
            words.start()
            words.join(1.0)  # a busy database must not hold the exit up
        killed = children(os.getpid())
        for child in killed:
            with contextlib.suppress(OSError):
                os.kill(child, signal.SIGKILL)
        _reap(killed, REAP_SECONDS)  # so nothing of the worker is left when its exit is seen
        os._exit(EXIT_STATUS)


def _reap(pids: list[int], seconds: float) -> None:
    """Wait (at most ``seconds``) until the SIGKILLed children ``pids`` are gone, reaping them."""
    deadline = time.monotonic() + seconds
    pending = set(pids)
    while pending and time.monotonic() < deadline:
        for pid in list(pending):
            try:
                done, _ = os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:  # reaped elsewhere (Celery's pool) or never ours
                done = pid
            if done:
                pending.discard(pid)
        if pending:
            time.sleep(0.01)


def _say(message: str) -> None:
    with contextlib.suppress(OSError, ValueError):
        print(f"texsynth worker {os.getpid()}: {message}", file=sys.stderr, flush=True)
