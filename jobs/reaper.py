"""Settle jobs whose worker vanished, so that no job is shown as running (or queued) forever.

Runs in the API process every couple of seconds (:class:`Reaper`). A run is dead when its process
is gone on this machine or its heartbeat is older than ``stale_seconds``. A dead run is re-queued
(at-least-once: the task is idempotent) until ``max_attempts`` runs were lost or the hard time
limit was reached; then the job fails with a message that says why. A queued job whose message was
taken by a worker main process that died (the filesystem transport loses it) is sent again, and so
is a queued job that no worker received within ``resend_seconds`` while the workers have room (its
message was lost or set aside as unreadable), or that a live worker received but did not start within
that time while workers have room (its message was lost with a broker connection): no queue may lose
work. A cancel that the engine did not honour within ``cancel_grace_seconds`` kills the worker child.

On the embedded queue it also removes the control mailboxes of workers that stopped
(:func:`texsynth.jobs.broker.prune_mailboxes`): messages no worker read within ``resend_seconds``.

Every minute it also applies the retention period (:func:`purge_expired`): a job that ended more than
``retention_days`` ago is deleted, files (or objects) and record, like ``DELETE /api/jobs/{id}``; and
a job folder (objects) left without a record for an hour (a run that outlived its job's deletion) is
removed.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from texsynth.jobs.broker import prune_mailboxes
from texsynth.jobs.config import Settings
from texsynth.jobs.store import JobRecord, JobStore, pid_alive

__all__ = ["Reaper", "prune_dead_mailboxes", "purge_expired", "reap_once", "stranded"]

#: A job folder without a record this old (seconds) is left over, never a job being created.
ORPHAN_SECONDS = 3600.0

log = logging.getLogger(__name__)


def stranded(store: JobStore, settings: Settings, now: float | None = None) -> list[JobRecord]:
    """Queued jobs that have not started within ``resend_seconds`` although the workers have room.

    Two kinds: a job that no worker received, and a job that a live worker's main process received
    but did not start (its message went with a broker connection: redis-server restarted empty after
    the worker had prefetched it, and the worker process itself lived on). Room: the live workers'
    processes (``concurrency`` each) less the jobs they run or hold, a held job counting only until it
    is overdue. A job waiting behind busy workers is not stranded; one waiting while workers idle is.
    At most as many as there is room for, oldest first, so a worker between two jobs causes at most
    one duplicate message, and a held message that does arrive late is a duplicate too: harmless, a
    run claims its job once (:meth:`texsynth.jobs.store.JobStore.claim`).
    """
    now = time.time() if now is None else now
    workers = store.workers(fresh_within=max(10.0, settings.stale_seconds))
    active = store.active()

    def overdue(job: JobRecord) -> bool:
        return (
            job.state == "queued" and not job.cancel_requested and now - job.updated > settings.resend_seconds
        )

    busy = sum(1 for job in active if job.state == "running" or (job.received_pid and not overdue(job)))
    room = len(workers) * settings.concurrency - busy
    if room <= 0:
        return []
    waiting = [job for job in active if overdue(job)]
    return sorted(waiting, key=lambda job: job.updated)[:room]


def reap_once(
    store: JobStore,
    settings: Settings,
    send: Callable[[str], None],
    terminate: Callable[[str], None],
    terminated: set[str],
    now: float | None = None,
) -> list[tuple[str, str]]:
    """One pass over the active jobs; returns ``(job id, action)`` for what it changed."""
    now = time.time() if now is None else now
    actions = []
    for job in store.active():
        if job.state == "running" and job.cancel_requested:
            waited = now - job.cancel_requested
            dead = store.run_is_dead(job, now, settings.stale_seconds)
            if waited > settings.cancel_grace_seconds and job.id not in terminated and not dead:
                terminate(job.id)
                terminated.add(job.id)
                actions.append((job.id, "terminate"))
            settle = dead or waited > settings.cancel_grace_seconds + 5
            why = "cancelled by request (the run was stopped)"
            if settle and store.finish(job.id, None, "cancelled", why):
                actions.append((job.id, "cancelled"))
        elif job.state == "running" and store.run_is_dead(job, now, settings.stale_seconds):
            ran = now - (job.started or now)
            if ran >= settings.hard_time_limit:
                message = (
                    f"stopped at the hard time limit of {settings.hard_time_limit} s; "
                    "try a smaller output size"
                )
                if store.finish(job.id, None, "failed", message):
                    actions.append((job.id, "failed"))
            elif job.attempts >= settings.max_attempts:
                message = (
                    f"the worker running this job stopped unexpectedly {job.attempts} times "
                    "(killed, or out of memory?); giving up - try a smaller output size"
                )
                if store.finish(job.id, None, "failed", message):
                    actions.append((job.id, "failed"))
            elif store.requeue(
                job.id,
                f"the worker running this job stopped; re-queued (run {job.attempts + 1} "
                f"of at most {settings.max_attempts})",
                seen=job.updated,
            ):
                send(job.id)
                actions.append((job.id, "requeued"))
        elif (
            job.state == "queued"
            and job.received_pid
            and job.received_host == store.host
            and not pid_alive(job.received_pid)
        ) and store.requeue(job.id, "the worker holding this job stopped; re-queued", seen=job.updated):
            send(job.id)
            actions.append((job.id, "resent"))
    for job in stranded(store, settings, now):
        why = (
            "no worker started this job; sent again"
            if job.received_pid
            else ("no worker received this job; sent again")
        )
        if store.requeue(job.id, why, seen=job.updated):
            send(job.id)
            actions.append((job.id, "resent"))
    for job_id, action in actions:
        log.warning("reaper: job %s %s", job_id, action)
    return actions


def prune_dead_mailboxes(store: JobStore, settings: Settings) -> int:
    """The embedded broker's control messages that no worker read within ``resend_seconds``, and the
    mailboxes of the workers that left them (none with a fresh heartbeat); returns how many went."""
    live = [w["name"] for w in store.workers(fresh_within=max(10.0, settings.stale_seconds))]
    folder = settings.broker_dir
    return prune_mailboxes(folder / "queue", folder / "control", live, max_age=settings.resend_seconds)


def purge_expired(store: JobStore, settings: Settings, now: float | None = None) -> list[str]:
    """Delete the jobs that ended more than ``retention_days`` ago (none if it is 0) and left-over
    job folders without a record; returns the ids (folder names) removed."""
    now = time.time() if now is None else now
    removed = []
    if settings.retention_days > 0:
        for job_id in store.expired(now - settings.retention_days * 86400.0):
            if store.delete(job_id):
                removed.append(job_id)
    for job_id in store.orphan_folders(now - ORPHAN_SECONDS):
        store.storage.delete(job_id)
        removed.append(job_id)
    if removed:
        log.warning("reaper: %d finished job(s) past the retention period deleted", len(removed))
    return removed


class Reaper(threading.Thread):
    """Calls :func:`reap_once` every ``interval`` seconds until :meth:`stop`."""

    def __init__(
        self,
        store: JobStore,
        settings: Settings,
        send: Callable[[str], None],
        terminate: Callable[[str], None],
        interval: float = 1.0,
        purge_interval: float = 60.0,
    ) -> None:
        super().__init__(name="texsynth-reaper", daemon=True)
        self.store, self.settings, self.send, self.terminate = store, settings, send, terminate
        self.interval = interval
        self.purge_interval = purge_interval
        self.terminated: set[str] = set()
        self._stop_event = threading.Event()

    def run(self) -> None:
        next_purge = 0.0
        while not self._stop_event.wait(self.interval):
            try:
                if self.settings.embedded:
                    prune_dead_mailboxes(self.store, self.settings)
                reap_once(self.store, self.settings, self.send, self.terminate, self.terminated)
                if time.monotonic() >= next_purge:
                    next_purge = time.monotonic() + self.purge_interval
                    purge_expired(self.store, self.settings)
            except Exception:  # keep reaping; a broker hiccup must not end the thread
                log.exception("reaper pass failed")

    def stop(self) -> None:
        self._stop_event.set()
