"""Celery configuration from :class:`Settings`: one function used by the API and by the workers.

With ``REDIS_URL`` the broker and result backend are Redis; without, the embedded default needs no
server: Celery's filesystem transport (with atomic messages and a reader that sets malformed ones
aside, :mod:`texsynth.jobs.broker`) and an SQLite result backend, both under the data directory (DESIGN.md,
"Queue and storage", measured facts).
"""

from __future__ import annotations

from celery import Celery

from texsynth.jobs.broker import SCHEME
from texsynth.jobs.config import Settings

__all__ = ["QUEUE", "TASK_NAME", "create_celery"]

TASK_NAME = "texsynth.run_job"
QUEUE = "texsynth"


def create_celery(settings: Settings) -> Celery:
    """A Celery app configured from ``settings`` (the same in the API and in every worker)."""
    settings.ensure_dirs()
    if settings.redis_url:
        broker, backend = settings.redis_url, settings.redis_url
        # A message not acknowledged within the visibility timeout is delivered again: keep it above
        # the hard time limit, or long jobs run several times at once.
        transport = {"visibility_timeout": settings.hard_time_limit + 600}
    else:
        broker, backend = (
            f"{SCHEME}://localhost/",  # kombu's filesystem transport, made safe (texsynth.jobs.broker)
            f"db+sqlite:///{settings.data_dir / 'celery-results.sqlite'}",
        )
        queue = str(settings.broker_dir / "queue")
        transport = {
            "data_folder_in": queue,
            "data_folder_out": queue,
            "control_folder": str(settings.broker_dir / "control"),
            "processed_folder": str(settings.broker_dir / "processed"),
            "store_processed": False,
            "polling_interval": 0.1,
        }
    app = Celery("texsynth", broker=broker, backend=backend, include=["texsynth.worker.tasks"])
    app.conf.update(
        broker_transport_options=transport,
        broker_connection_retry_on_startup=True,
        # A broker outage (Redis restarted, network gone) must not end the worker (issue 14): the
        # consumer reconnects with back-off for as long as it takes; running jobs go on (their
        # records are in the job store, not in the broker) and a result that cannot be stored is
        # retried a few times, then dropped (the service never reads Celery's results).
        broker_connection_retry=True,
        broker_connection_max_retries=None,
        worker_cancel_long_running_tasks_on_connection_loss=False,
        result_backend_always_retry=True,
        result_backend_max_retries=5,
        task_default_queue=QUEUE,
        task_acks_late=True,  # a job's message is acknowledged only when its run ended ...
        task_reject_on_worker_lost=True,  # ... and re-queued if the worker child died under it
        worker_prefetch_multiplier=1,  # a busy worker holds no further jobs
        task_soft_time_limit=settings.soft_time_limit,
        task_time_limit=settings.hard_time_limit,
        worker_pool="prefork",  # the solo pool ignores time limits and terminate
        worker_concurrency=settings.concurrency,
        task_serializer="json",
        result_serializer="json",
        accept_content=["json"],
        result_expires=7 * 24 * 3600,
        result_extended=False,
        worker_send_task_events=False,
        database_engine_options={"connect_args": {"timeout": 30}},
    )
    return app
