"""The workers' Celery application: ``celery -A texsynth.worker.celery_app worker`` (or ``texsynth worker``).

Configuration comes from :func:`texsynth.jobs.queue.create_celery` with the environment's :class:`Settings`;
the signal handlers below keep the service's job records honest about which process holds a job, and
:func:`last_heartbeat` is the worker's last word before :mod:`texsynth.worker.lifeline` ends it.
"""

from __future__ import annotations

import logging
import os
import threading
import time

from celery import signals

from texsynth.jobs.config import Settings
from texsynth.jobs.queue import TASK_NAME, create_celery
from texsynth.jobs.store import JobStore
from texsynth.worker.lifeline import ShutdownGuard

__all__ = ["app", "last_heartbeat", "settings", "store"]

log = logging.getLogger(__name__)


settings = Settings.from_env()
app = create_celery(settings)
_store: JobStore | None = None
_identity: tuple[str, int, float] | None = None  # this worker's (name, pid, start) once it is ready


def store() -> JobStore:
    """This process's job store (opened on first use, after a fork)."""
    global _store
    if _store is None:
        _store = settings.open_store()
    return _store


@signals.task_received.connect
def _on_received(request=None, **_):
    """The main process took a job's message: remember who holds it (it may be lost with it)."""
    if request is not None and request.name == TASK_NAME and request.args:
        store().mark_received(str(request.args[0]), os.getpid())


@signals.worker_ready.connect
def _on_ready(sender=None, **_):
    global _identity
    name = getattr(sender, "hostname", None) or f"worker@{os.getpid()}"
    started, pid = time.time(), os.getpid()
    _identity = (name, pid, started)

    def beat() -> None:
        while True:
            try:
                store().worker_heartbeat(name, pid, started)
            except Exception:
                log.exception("worker heartbeat failed")
            time.sleep(2.0)

    threading.Thread(target=beat, name="texsynth-worker-heartbeat", daemon=True).start()


def last_heartbeat() -> None:
    """The worker main process's heartbeat, once more (before a hard exit); nothing before it was ready."""
    if _identity is not None:
        store().worker_heartbeat(*_identity)


@signals.worker_process_init.connect
def _on_child_start(**_):
    global _store
    if _store is not None:
        _store.after_fork()  # the parent's pooled server connections stay the parent's
    _store = None  # never share a database connection across a fork
    ShutdownGuard.forget_in_child()  # a child's signals are its own, not its main process's
    if settings.worker_nice:
        os.nice(settings.worker_nice)  # the API stays responsive on a machine busy with jobs
    import importlib

    from texsynth.jobs.methods import methods

    # Everything a job imports, once per child process rather than in its first job: the methods
    # (their numba kernels load from the on-disk cache at their first call, then stay compiled in the
    # process), the artifact writer with the evaluation and the plots.
    methods(settings)
    importlib.import_module("texsynth.synth.output.artifacts")
