"""A job end to end on a real worker process and a real broker (embedded default and Redis)."""

from __future__ import annotations

import io
import json
import os
import signal
import time

import httpx
import numpy as np
import pytest
import tifffile
from PIL import Image

from tests.service.conftest import Service, wait_until

pytestmark = pytest.mark.integration


def _follow(service: Service, job_id: str, timeout: float = 60) -> tuple[dict, list[dict]]:
    """Poll a job until it ends; return the final record and every record seen."""
    seen = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = service.client().job(job_id)
        seen.append(job)
        if job["state"] in ("succeeded", "failed", "cancelled"):
            return job, seen
        time.sleep(0.1)
    raise AssertionError(f"job {job_id} did not end within {timeout} s: {seen[-1]}")


def _decode_artifacts(service: Service, job: dict) -> dict[str, object]:
    client = service.client()
    decoded = {}
    for name in job["artifacts"]:
        data = client.artifact(job, name)
        if name.endswith(".png"):
            with Image.open(io.BytesIO(data)) as im:
                im.load()
                decoded[name] = np.asarray(im)
        elif name.endswith(".tiff"):
            decoded[name] = tifffile.imread(io.BytesIO(data))
        elif name.endswith(".json"):
            decoded[name] = json.loads(data)
    return decoded


def test_submit_progress_succeeds_and_artifacts_decode(service, exemplar_png, tmp_path):
    client = service.client()
    job = client.submit(
        exemplar_png,
        method="test-blur",
        seed=7,
        params={"width": 96, "height": 80, "steps": 12, "delay": 0.12},
    )
    # the answer is the record as read back after queueing: a free worker may have claimed it already
    assert job["state"] in {"queued", "running"} and job["url"] == f"/api/jobs/{job['id']}"
    final, seen = _follow(service, job["id"])
    assert final["state"] == "succeeded", final["message"]
    running = [j for j in seen if j["state"] == "running"]
    assert any(0 < j["fraction"] < 1 for j in running), "no intermediate progress seen"
    assert any(j["stage"].startswith("blur step") for j in running)
    assert any(j["preview"] for j in running), "no preview seen while running"
    art = _decode_artifacts(service, final)
    assert art["output.png"].shape == (80, 96)
    assert art["output.tiff"].shape == (80, 96) and art["output.tiff"].dtype == np.uint16
    assert {"coherence.png", "orientation.png", "metrics.json", "manifest.json"} <= set(art)
    manifest = art["manifest.json"]
    assert manifest["seed"] == 7 and manifest["method"] == "test-blur" and manifest["params"]["steps"] == 12
    assert "versions" in manifest and final["timings"]["total"] > 0
    # the client's download writes every artifact
    paths = client.download(final, tmp_path)
    assert {p.name for p in paths} >= {"output.png", "output.tiff", "metrics.json"}


def test_real_method_wei_levoy(embedded, exemplar_png):
    client = embedded.client()
    job = client.submit(
        exemplar_png,
        method="wei-levoy",
        seed=1,
        params={"width": 48, "height": 48, "levels": 2, "neighbourhood_size": 7},
    )
    final = client.wait(job["id"], timeout=180, poll=0.2)
    assert final["state"] == "succeeded", final["message"]
    art = _decode_artifacts(embedded, final)
    assert art["output.png"].shape == (48, 48)
    assert art["metrics.json"]["metrics"], "evaluation metrics are missing"
    assert any(name.startswith("plots/") for name in final["artifacts"])


def test_cancel_running_job_within_5_seconds(service, exemplar_png):
    client = service.client()
    job = client.submit(
        exemplar_png, method="test-blur", params={"width": 64, "height": 64, "steps": 200, "delay": 0.1}
    )
    wait_until(lambda: client.job(job["id"])["state"] == "running", 30, what="the job to start")
    start = time.monotonic()
    assert client.cancel(job["id"])["cancel_requested"]
    final = client.wait(job["id"], timeout=5, poll=0.1)
    assert final["state"] == "cancelled" and time.monotonic() - start < 5
    assert final["artifacts"] == {}


def test_cancel_queued_job(embedded, exemplar_png):
    client = embedded.client()
    # occupy both worker processes, then cancel a job still waiting in the queue
    blockers = [
        client.submit(exemplar_png, method="test-blur", params={"steps": 100, "delay": 0.05})
        for _ in range(2)
    ]
    waiting = client.submit(exemplar_png, method="test-blur", params={"steps": 2})
    assert client.cancel(waiting["id"])["state"] == "cancelled"
    for b in blockers:
        client.cancel(b["id"])
    for b in blockers:
        assert client.wait(b["id"], timeout=10)["state"] == "cancelled"
    time.sleep(1.0)
    assert client.job(waiting["id"])["state"] == "cancelled"


def _kill_child_mid_job(service: Service, exemplar_png: bytes) -> dict:
    client = service.client()
    job = client.submit(
        exemplar_png, method="test-blur", params={"width": 64, "height": 64, "steps": 30, "delay": 0.1}
    )
    wait_until(lambda: client.job(job["id"])["fraction"] >= 0.2, 30, what="the job to make progress")
    pid = service.store().get(job["id"]).pid
    os.kill(pid, signal.SIGKILL)
    final = client.wait(job["id"], timeout=60, poll=0.2)
    assert final["state"] in ("succeeded", "failed"), final
    return final


def test_kill_worker_child_mid_job_reruns_or_fails(service, exemplar_png):
    final = _kill_child_mid_job(service, exemplar_png)
    if final["state"] == "succeeded":
        assert final["attempts"] >= 2
        art = _decode_artifacts(service, final)
        assert art["output.png"].shape == (64, 64)
    else:
        assert "stopped" in final["message"]


def test_kill_whole_worker_mid_job_never_stuck(service, exemplar_png):
    """SIGKILL the worker's main process and its children, on either queue: the message is gone or
    unacknowledged; the reaper re-queues the job and the restarted worker runs it."""
    embedded = service
    client = embedded.client()

    def idle() -> bool:  # jobs that earlier tests left on this shared service would run first
        health = httpx.get(embedded.url + "/api/health").json()
        return health["queued"] == 0 and health["running"] == 0

    wait_until(idle, 180, what="the shared service's earlier jobs to end")
    job = client.submit(
        exemplar_png, method="test-blur", params={"width": 64, "height": 64, "steps": 30, "delay": 0.1}
    )
    wait_until(lambda: client.job(job["id"])["fraction"] >= 0.2, 30, what="the job to make progress")
    master = embedded.worker_pid()
    os.killpg(os.getpgid(master), signal.SIGKILL)
    final = client.wait(job["id"], timeout=90, poll=0.3)
    assert final["state"] in ("succeeded", "failed"), final
    if final["state"] == "succeeded":
        assert final["attempts"] >= 2
    wait_until(lambda: httpx.get(embedded.url + "/api/health").status_code == 200, 30, what="a new worker")


def test_restart_api_jobs_still_listed(embedded, exemplar_png):
    client = embedded.client()
    job = client.submit(exemplar_png, method="test-blur", params={"steps": 2})
    client.wait(job["id"], timeout=30)
    before = client.jobs(limit=500)
    # a second API on the same data directory, killed hard and started again
    api = Service(embedded.data_dir, worker=False).start()
    try:
        assert api.client().jobs(limit=500)["count"] >= before["count"]
        api.stop(signal.SIGKILL)
        api.start()
        after = api.client().jobs(limit=500)
        assert {j["id"] for j in before["data"]} <= {j["id"] for j in after["data"]}
        assert api.client().job(job["id"])["state"] == "succeeded"
    finally:
        api.stop()


def test_sweep_collects_metrics_in_one_table(service, exemplar_png):
    embedded = service
    client = embedded.client()
    sweep = client.sweep(
        exemplar_png,
        {"steps": [1, 3], "sigma": [0.5, 1.5]},
        method="test-blur",
        params={"width": 48, "height": 48, "delay": 0},
        seed=3,
    )
    assert len(sweep["rows"]) == 4
    done = wait_until(
        lambda: (s := client.get_sweep(sweep["id"]))["state"] == "done" and s, 90, 0.3, "the sweep"
    )
    assert done["counts"] == {"succeeded": 4}
    assert {(r["steps"], r["sigma"]) for r in done["rows"]} == {(1, 0.5), (1, 1.5), (3, 0.5), (3, 1.5)}
    metric_columns = [c for c in done["columns"] if c not in ("job", "state", "steps", "sigma")]
    assert metric_columns and all(r.get(metric_columns[0]) is not None for r in done["rows"])
    csv = httpx.get(f"{embedded.url}/api/sweeps/{sweep['id']}?format=csv").text.splitlines()
    assert csv[0].startswith("job,state,steps,sigma") and len(csv) == 5


def test_health_and_methods(embedded):
    health = httpx.get(embedded.url + "/api/health").json()
    assert health["status"] == "ok" and health["broker"] and health["workers"]
    methods = {m["name"]: m for m in httpx.get(embedded.url + "/api/methods").json()["data"]}
    assert "test-blur" in methods
    props = methods["test-blur"]["params_schema"]["properties"]
    assert props["steps"]["default"] == 10 and "width" in methods["test-blur"]["size_schema"]["properties"]
    page = httpx.get(embedded.url + "/")
    assert page.status_code == 200 and "texsynth" in page.text


def test_size_is_a_field_of_the_job_sent_as_form_fields_or_inside_params(embedded, exemplar_png):
    """The output size travels in its own fields (``width``/``height``), never inside the job's params;
    a client of the first API that puts them in ``params`` gets the same job. A sweep may sweep a side."""
    client = embedded.client()
    new = client.submit(
        exemplar_png, method="test-blur", params={"steps": 1, "delay": 0}, size={"width": 40, "height": 32}
    )
    old = client.submit(
        exemplar_png, method="test-blur", params={"steps": 1, "delay": 0, "width": 40, "height": 32}
    )
    for job in (new, old):
        assert job["size"] == {"width": 40, "height": 32} and "width" not in job["params"]
        done = client.wait(job["id"], timeout=120)
        assert done["state"] == "succeeded", done["message"]
        manifest = json.loads(client.artifact(done, "manifest.json"))
        assert manifest["size"] == {"width": 40, "height": 32} and "width" not in manifest["params"]
        with Image.open(io.BytesIO(client.artifact(done, "output.png"))) as im:
            assert im.size == (40, 32)
    sweep = client.sweep(
        exemplar_png,
        {"width": [24, 32]},
        method="test-blur",
        params={"steps": 1, "delay": 0},
        size={"height": 16},
    )
    assert sorted(r["width"] for r in sweep["rows"]) == [24, 32] and sweep["size"]["height"] == 16
    assert {client.job(r["job"])["size"]["height"] for r in sweep["rows"]} == {16}
