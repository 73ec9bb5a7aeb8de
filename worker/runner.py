"""Run one job: claim it, synthesize with progress, write artifacts, commit - or record why not.

This is the body of the Celery task, kept free of Celery so that it reads top to bottom. It is
idempotent, the condition for at-least-once delivery (``acks_late``): a duplicate delivery of a job
that is running or finished does nothing; a re-delivery after a crash takes the job over and writes
a fresh set of artifacts into its own staging folder, published (uploaded, with object storage) and
then committed only if it still owns the job: a crash in between leaves the job to be re-run.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from typing import Any

from texsynth.jobs.config import Settings
from texsynth.jobs.methods import methods
from texsynth.jobs.storage import StorageUnavailable
from texsynth.jobs.store import JobStore
from texsynth.synth.errors import Cancelled, SynthError
from texsynth.synth.output.preview import preview_png
from texsynth.synth.pipeline import load_inputs, synthesize_to_folder

__all__ = ["JobProgress", "run_job"]

log = logging.getLogger(__name__)


class JobProgress:
    """The engine's progress callback for one run: records stage/fraction, previews, and cancels.

    ``(stage, fraction)`` is the engine's protocol; a method may also pass ``preview=<float image>``
    now and then, which becomes the job's small ``preview.png``. Writes are throttled; each write
    also tells whether the run must stop (job cancelled, or taken over), and then this raises
    :class:`synth.Cancelled` from inside the engine.
    """

    accepts_preview = True  # a method checks this before passing ``preview=``

    def __init__(self, store: JobStore, job_id: str, token: str, min_interval: float = 0.2) -> None:
        self.store, self.job_id, self.token = store, job_id, token
        self.min_interval = min_interval
        self._last_write = 0.0
        self._last_preview = 0.0
        self._last_stage = ""
        self.stopped = False

    def __call__(self, stage: str, fraction: float, preview: Any = None, **_: Any) -> None:
        now = time.monotonic()
        wrote_preview = False
        if preview is not None and now - self._last_preview >= 1.0:
            try:
                self.store.storage.put_preview(self.job_id, preview_png(preview))
                wrote_preview = True
                self._last_preview = now
            except (ValueError, TypeError, StorageUnavailable) as exc:  # a preview must not kill the run
                log.warning("job %s: preview not written: %s", self.job_id, exc)
        if stage == self._last_stage and now - self._last_write < self.min_interval and not wrote_preview:
            return
        self._last_write, self._last_stage = now, stage
        if not self.store.progress(self.job_id, self.token, stage, fraction, preview=wrote_preview):
            self.stopped = True
            raise Cancelled(f"job {self.job_id} was cancelled")


class _Heartbeat(threading.Thread):
    """Proves the run is alive while the engine computes (also between progress calls)."""

    def __init__(self, store: JobStore, job_id: str, token: str, interval: float) -> None:
        super().__init__(name=f"heartbeat-{job_id}", daemon=True)
        self.store, self.job_id, self.token, self.interval = store, job_id, token, interval
        self.done = threading.Event()

    def run(self) -> None:
        while not self.done.wait(self.interval):
            try:
                if not self.store.heartbeat(self.job_id, self.token):
                    return
            except Exception:  # a busy database must not kill the run; the next beat retries
                log.exception("heartbeat of job %s failed", self.job_id)


def run_job(
    store: JobStore, settings: Settings, job_id: str, *, soft_timeout: type[BaseException] = ()
) -> dict:
    """Run job ``job_id`` to its end; return small metadata (state, message) for the result backend.

    ``soft_timeout`` is the exception the queue raises at the soft time limit (Celery's
    ``SoftTimeLimitExceeded``), recorded as a failure with the limit in the message.
    """
    token, why = store.claim(job_id, os.getpid(), settings.stale_seconds)
    if token is None:
        log.info("job %s not run: %s", job_id, why)
        return {"job": job_id, "state": "skipped", "message": why}
    job = store.get(job_id)
    assert job is not None
    staging = store.storage.staging(job_id, token)
    committed = False
    beat = _Heartbeat(store, job_id, token, settings.heartbeat_seconds)
    beat.start()
    progress = JobProgress(store, job_id, token)
    try:
        progress("loading inputs", 0.0)
        files, manifest = store.storage.fetch_inputs(job_id, list(job.inputs.values()), token)
        images = load_inputs(  # under the service's limits, as the API checked them
            {role: files[name] for role, name in job.inputs.items()},
            max_pixels=settings.max_input_pixels,
        )
        del files
        methods(settings)  # registers TEXSYNTH_EXTRA_METHODS in this process
        size = tuple(job.size[k] for k in ("depth", "height", "width") if k in job.size) or None
        manifest["attempt"] = job.attempts
        outcome = synthesize_to_folder(
            job.method,
            images,
            staging,
            size=size,
            params=job.params,
            seed=job.seed,
            progress=progress,
            manifest=manifest,
            max_output=settings.max_output(len(size) if size else 2),
            threads=settings.threads,
            voxel_size=job.extras.get("voxel_size"),
            voxel_unit=job.extras.get("voxel_unit") or "nm",
        )
        timings = {k: float(v) for k, v in outcome.result.timings.items()}
        if not store.storage.local:
            progress("uploading artifacts", 1.0)
        store.storage.publish(job_id, token, staging)  # a crash from here to the commit: re-run
        committed = store.commit_success(job_id, token, staging, outcome.files, timings, outcome.metrics)
        if committed:
            return {"job": job_id, "state": "succeeded"}
        return _stopped(store, job_id, token)
    except Cancelled:
        return _stopped(store, job_id, token)
    except SynthError as exc:
        store.finish(job_id, token, "failed", str(exc))
        return {"job": job_id, "state": "failed", "message": str(exc)}
    except soft_timeout:
        message = (
            f"stopped after the time limit of {settings.soft_time_limit} s; "
            "try a smaller output size or fewer pyramid levels"
        )
        store.finish(job_id, token, "failed", message)
        return {"job": job_id, "state": "failed", "message": message}
    except Exception as exc:
        log.exception("job %s crashed", job_id)
        message = f"internal error in the worker: {type(exc).__name__}: {exc}"
        store.finish(job_id, token, "failed", message)
        return {"job": job_id, "state": "failed", "message": message}
    finally:
        beat.done.set()
        if not committed:  # what this run uploaded (object storage) is nobody's artifacts
            store.storage.discard_run(job_id, token)
        store.storage.forget_run(job_id, token)


def _stopped(store: JobStore, job_id: str, token: str) -> dict:
    """The run had to stop: record ``cancelled`` if the job was cancelled, else leave it to its new run."""
    job = store.get(job_id)
    if job is not None and job.cancel_requested and job.run_token == token:
        store.finish(job_id, token, "cancelled", "cancelled by request")
        return {"job": job_id, "state": "cancelled"}
    return {"job": job_id, "state": "superseded"}
