"""Stopping the service never leaves a worker behind (issue 30), on both queues.

Real processes: ``texsynth serve`` stopped as process managers and impatient people do it (SIGTERM,
then SIGKILL 1 s later) after jobs ran; a standalone ``texsynth worker`` stopped by two SIGTERMs, or by
one and the end of its grace (``TEXSYNTH_SHUTDOWN_GRACE``); the job it was running is re-run by the
reaper and succeeds once; the next ``serve`` on the same data directory starts clean.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.service.conftest import REPO, Service, wait_until

pytestmark = [pytest.mark.integration, pytest.mark.slow]

#: A job that runs for about 6 s unless stopped (test-blur sleeps ``delay`` per step).
LONG = {"width": 32, "height": 32, "steps": 40, "delay": 0.15}
SHORT = {"width": 32, "height": 32, "steps": 2}


@pytest.fixture(params=["embedded", "redis"])
def queue_env(request) -> dict[str, str]:
    """The environment that selects the queue: nothing (embedded) or a live Redis's URL."""
    if request.param == "embedded":
        return {}
    return {"REDIS_URL": request.getfixturevalue("redis_url").rsplit("/", 1)[0] + f"/{_redis_db()}"}


_dbs = iter(range(1, 16))


def _redis_db() -> int:
    """A Redis database of its own for each test, so no test sees another's messages."""
    return next(_dbs)


def _group_members(pgid: int) -> list[int]:
    """Live (not zombie) processes of process group ``pgid``, read from /proc."""
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()  # state, ppid, pgrp, ...
        if int(fields[2]) == pgid and fields[0] not in ("Z", "X"):
            members.append(int(entry.name))
    return members


def _kill_group(pgid: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, signal.SIGKILL)


def _end(proc: subprocess.Popen) -> None:
    """SIGKILL ``proc``'s process group (its own session) and reap ``proc``."""
    _kill_group(proc.pid)
    proc.wait(timeout=10)


def _run_jobs(service: Service, exemplar_png: bytes, n: int = 3) -> None:
    client = service.client()
    ids = [client.submit(exemplar_png, method="test-blur", params=SHORT)["id"] for _ in range(n)]
    for job_id in ids:
        assert client.wait(job_id, timeout=90)["state"] == "succeeded"


def _job_done_once(service: Service, job_id: str) -> None:
    """The job succeeded in its second run (the first was stopped), and nothing runs it again."""
    client = service.client()
    final = client.wait(job_id, timeout=120)
    assert final["state"] == "succeeded", final["message"]
    assert service.store().get(job_id).attempts == 2
    time.sleep(2.0)  # a duplicate delivery would claim it again now; a claim is refused after success
    record = service.store().get(job_id)
    assert record.state == "succeeded" and record.attempts == 2


def test_sigterm_then_sigkill_of_serve_leaves_no_worker(tmp_path, queue_env, exemplar_png):
    env = {**queue_env, "TEXSYNTH_SHUTDOWN_GRACE": "5"}
    service = Service(tmp_path / "data", env, concurrency=2).start()
    group = os.getpgid(service.worker_pid())
    try:
        _run_jobs(service, exemplar_png)
        assert len(_group_members(group)) == 3  # the worker's main process and its 2 children
        client = service.client()
        job = client.submit(exemplar_png, method="test-blur", params=LONG)["id"]
        wait_until(lambda: client.job(job)["state"] == "running", 60, what="the long job to run")
        os.kill(service.proc.pid, signal.SIGTERM)
        time.sleep(1.0)
        os.kill(service.proc.pid, signal.SIGKILL)
        service.proc.wait(timeout=10)
        killed = time.monotonic()
        wait_until(lambda: not _group_members(group), 15, 0.05, "every worker process to end")
        print(f"worker gone {time.monotonic() - killed:.2f} s after SIGKILL of serve")
    finally:
        _kill_group(group)
        service.stop()
    # the next serve on the same data directory starts clean and runs the job stopped mid-way again
    again = Service(tmp_path / "data", env, concurrency=2)
    try:
        again.start()
        assert "left running by a previous serve" not in again.log.read_text()
        assert os.getpgid(again.worker_pid()) != group
        _job_done_once(again, job)
    finally:
        again.stop(signal.SIGKILL)  # quicker than a warm stop; its worker goes with it (shown above)


def _start_worker(service: Service, grace: float) -> subprocess.Popen:
    """A standalone ``texsynth worker`` (1 process) on ``service``'s data directory and queue."""
    env = {
        **service.env,
        "TEXSYNTH_DATA_DIR": str(service.data_dir),
        "TEXSYNTH_SHUTDOWN_GRACE": str(grace),
        "TEXSYNTH_CONCURRENCY": "1",
    }
    log = open(service.data_dir.parent / "worker.log", "ab")  # noqa: SIM115 (the worker writes it)
    proc = subprocess.Popen(
        [sys.executable, "-m", "texsynth.worker", "--loglevel=WARNING"],
        env=env,
        cwd=REPO,
        start_new_session=True,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    log.close()
    wait_until(
        lambda: proc.pid in {w["pid"] for w in service.store().workers(fresh_within=10)},
        60,
        0.2,
        "the standalone worker to report",
    )
    return proc


@pytest.fixture
def api(tmp_path, queue_env) -> Iterator[Service]:
    """``texsynth serve --no-worker`` (the API and its reaper) on a fresh data directory."""
    service = Service(tmp_path / "data", queue_env, worker=False).start()
    yield service
    service.stop()


def _stop_standalone(
    api: Service, exemplar_png: bytes, grace: float, signals: int
) -> tuple[str, subprocess.Popen, float]:
    """Run a long job on a standalone worker, send it ``signals`` SIGTERMs 1 s apart; wait for its end.

    Returns the job's id, the ended worker and the seconds from the last SIGTERM to its end.
    """
    worker = _start_worker(api, grace)
    try:
        client = api.client()
        job = client.submit(exemplar_png, method="test-blur", params=LONG)["id"]
        wait_until(lambda: client.job(job)["state"] == "running", 60, what="the long job to run")
        for n in range(signals):
            if n:
                time.sleep(1.0)
                assert worker.poll() is None  # a warm shutdown: it waits for its job
            os.kill(worker.pid, signal.SIGTERM)
            sent = time.monotonic()
        worker.wait(timeout=grace + 15)
        took = time.monotonic() - sent
        assert client.job(job)["state"] != "succeeded"  # the job (about 6 s) was stopped, not finished
        assert _group_members(worker.pid) == []  # its pool child went with it
        return job, worker, took
    finally:
        _end(worker)


def test_a_second_sigterm_ends_a_standalone_worker(api, exemplar_png):
    job, worker, took = _stop_standalone(api, exemplar_png, grace=60, signals=2)
    print(f"standalone worker ended {took:.2f} s after its second SIGTERM")
    assert worker.returncode == 1
    assert "a second stop signal (SIGTERM)" in (api.data_dir.parent / "worker.log").read_text()
    # the reaper re-queues the job; the next worker runs it again, once
    again = _start_worker(api, grace=5)
    try:
        _job_done_once(api, job)
    finally:
        _end(again)


def test_the_end_of_the_grace_ends_a_standalone_worker(api, exemplar_png):
    job, worker, took = _stop_standalone(api, exemplar_png, grace=2, signals=1)
    print(f"standalone worker ended {took:.2f} s after its SIGTERM (grace 2 s)")
    assert worker.returncode == 1
    assert "the shutdown grace of 2 s ended" in (api.data_dir.parent / "worker.log").read_text()
    again = _start_worker(api, grace=5)
    try:
        _job_done_once(api, job)
    finally:
        _end(again)


def test_a_warm_stop_lets_the_running_job_finish_within_the_grace(api, exemplar_png):
    worker = _start_worker(api, grace=60)
    try:
        client = api.client()
        job = client.submit(exemplar_png, method="test-blur", params={**SHORT, "steps": 15, "delay": 0.2})[
            "id"
        ]
        wait_until(lambda: client.job(job)["state"] == "running", 60, what="the job to run")
        os.kill(worker.pid, signal.SIGTERM)
        assert worker.wait(timeout=60) == 0  # Celery's own warm shutdown, after the job
        record = api.store().get(job)
        assert record.state == "succeeded" and record.attempts == 1
    finally:
        _end(worker)
