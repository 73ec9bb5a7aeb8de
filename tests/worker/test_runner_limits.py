"""The worker runs a job under the service's limits (not the engine's larger defaults): a job whose
record asks for more than the service allows fails, naming the limit, before any work."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

from texsynth.jobs.config import Settings
from texsynth.jobs.store import JobStore
from texsynth.worker.runner import run_job


def _png(side: int) -> bytes:
    buf = io.BytesIO()
    Image.fromarray((np.random.default_rng(0).random((side, side)) * 255).astype(np.uint8)).save(buf, "PNG")
    return buf.getvalue()


def _run(tmp_path, size: dict[str, int], **limits: int) -> dict:
    settings = Settings(data_dir=tmp_path, **limits)
    store = JobStore(settings.db_path, settings.jobs_dir)
    job = store.create_job(
        method="random-phase",
        params={},
        size=size,
        seed=1,
        inputs={"exemplar": ("exemplar.png", _png(32))},
        manifest={"method": "random-phase"},
    )
    return run_job(store, settings, job.id)


def test_the_worker_passes_the_services_output_limit_to_the_engine(tmp_path) -> None:
    outcome = _run(tmp_path, {"width": 16, "height": 16}, max_output_pixels=100)
    assert outcome["state"] == "failed" and "limit of 100" in outcome["message"]
    ran = _run(tmp_path / "b", {"width": 16, "height": 16})
    assert ran["state"] == "succeeded", ran


def test_the_worker_passes_the_services_input_limit_to_the_engine(tmp_path) -> None:
    outcome = _run(tmp_path, {"width": 16, "height": 16}, max_input_pixels=1000)
    assert outcome["state"] == "failed" and "limit of 1000" in outcome["message"]
