"""The one task: run a job, given its id (never the inputs themselves)."""

from __future__ import annotations

from celery.exceptions import SoftTimeLimitExceeded

from texsynth.worker.celery_app import TASK_NAME, app, settings, store
from texsynth.worker.runner import run_job as _run_job

__all__ = ["run_job"]


@app.task(name=TASK_NAME, acks_late=True, reject_on_worker_lost=True)
def run_job(job_id: str) -> dict:
    """Run job ``job_id``; idempotent, so a re-delivered message is safe (see
    :mod:`texsynth.worker.runner`)."""
    return _run_job(store(), settings, job_id, soft_timeout=SoftTimeLimitExceeded)
