"""The worker survives a Redis outage, and ``serve`` owns its worker (issue 14, items 7 and 8).

Each test starts its own ``texsynth serve`` (and, for the outage, its own ``redis-server``), since
they stop what the session's services need.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from tests.service.conftest import REPO, Service, free_port, start_redis, wait_until
from texsynth.app.cli import ServeLock
from texsynth.jobs.store import pid_alive

CLI = [sys.executable, "-c", "import sys; from texsynth.synth.cli import main; sys.exit(main())"]

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def _redis(port: int, folder) -> subprocess.Popen:
    return start_redis(port, folder)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)


def test_the_worker_survives_a_redis_outage(tmp_path, exemplar_png):
    port = free_port()
    redis = _redis(port, tmp_path)
    service = Service(tmp_path / "data", {"REDIS_URL": f"redis://127.0.0.1:{port}/0"}, concurrency=1)
    try:
        service.start()
        client = service.client()
        worker = service.worker_pid()
        job = client.submit(
            exemplar_png, method="test-blur", params={"width": 32, "height": 32, "steps": 40, "delay": 0.1}
        )
        wait_until(lambda: client.job(job["id"])["state"] == "running", 30, what="the job to run")
        # mid-job: the broker and the result backend are gone (as `redis-cli shutdown` does it)
        with socket.create_connection(("127.0.0.1", port), timeout=2) as s:
            s.sendall(b"SHUTDOWN NOSAVE\r\n")
        redis.wait(timeout=10)
        time.sleep(6)
        assert pid_alive(worker), "the worker's main process exited during the outage"
        redis = _redis(port, tmp_path)
        done = client.wait(job["id"], timeout=60)
        assert done["state"] == "succeeded", done["message"]
        # the same worker process takes new jobs once Redis is back
        again = client.wait(
            client.submit(exemplar_png, method="test-blur", params={"width": 32, "height": 32, "steps": 2})[
                "id"
            ],
            timeout=60,
        )
        assert again["state"] == "succeeded"
        assert pid_alive(worker) and service.worker_pid() == worker
        assert "the worker exited" not in service.log.read_text()
    finally:
        service.stop()
        _stop(redis)


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def test_kill_9_of_serve_takes_its_worker_with_it(tmp_path):
    service = Service(tmp_path / "data", concurrency=1).start()
    try:
        worker = service.worker_pid()
        group = os.getpgid(worker)
        assert group != os.getpgid(service.proc.pid)  # the worker has a group of its own
        os.kill(service.proc.pid, signal.SIGKILL)  # serve alone, no chance to clean up
        wait_until(lambda: not _group_alive(group), 30, 0.2, "the worker group to end after serve died")
    finally:
        service.stop()


def test_serve_stops_a_worker_left_by_a_vanished_serve(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    # a worker group a previous serve left behind (without PR_SET_PDEATHSIG, e.g. another OS)
    leftover = subprocess.Popen(
        [sys.executable, "-c", "import time; time.sleep(300)", "-m", "texsynth.worker"],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    dead = subprocess.Popen(["true"])
    dead.wait()
    (data / "serve.pid").write_text(
        json.dumps({"pid": dead.pid, "host": socket.gethostname(), "worker_group": leftover.pid})
    )
    service = Service(data, concurrency=1)
    try:
        service.start()
        leftover.wait(timeout=10)  # killed by the new serve
        assert "stopped the worker (process group" in service.log.read_text()
        record = json.loads((data / "serve.pid").read_text())
        assert record["pid"] == service.proc.pid and record["worker_group"] == os.getpgid(
            service.worker_pid()
        )
    finally:
        if leftover.poll() is None:
            leftover.kill()
            leftover.wait()
        service.stop()
    assert not (data / "serve.pid").exists()  # a clean stop removes it


def test_a_second_serve_on_the_same_data_directory_is_refused(tmp_path):
    service = Service(tmp_path / "data", concurrency=1).start()
    try:
        second = Service(tmp_path / "data", concurrency=1)
        args = [*CLI, "serve", "--port", str(second.port), "--data-dir", str(second.data_dir)]
        done = subprocess.run(args, env=second.env, cwd=REPO, capture_output=True, text=True, timeout=60)
        assert done.returncode == 2
        assert (
            f"another texsynth serve (pid {service.proc.pid}) is running on this data directory"
            in done.stderr
        )
        assert service.worker_pid()  # the first one's worker was left alone
    finally:
        service.stop()


def test_a_pid_file_of_another_machine_or_of_unrelated_processes_is_left_alone(tmp_path):
    other = subprocess.Popen(["sleep", "60"], start_new_session=True)
    try:
        lock = ServeLock(tmp_path)
        (tmp_path / "serve.pid").write_text(json.dumps({"pid": 1, "host": "elsewhere", "worker_group": 1}))
        assert lock.acquire() is None
        # a pid reused by a process that is neither a serve nor a worker: not refused, not killed
        record = {"pid": other.pid, "host": socket.gethostname(), "worker_group": other.pid}
        (tmp_path / "serve.pid").write_text(json.dumps(record))
        assert lock.acquire() is None
        assert other.poll() is None
    finally:
        other.kill()
        other.wait()
