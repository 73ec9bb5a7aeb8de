"""The embedded queue does not lose work (issue 14): torn or malformed messages do not kill the worker,
and a job whose message vanished between enqueue and receipt is sent again and finishes."""

from __future__ import annotations

import json
import os
import signal
import time

import pytest

from tests.service.conftest import Service, wait_until
from texsynth.jobs.broker import quarantine_folder
from texsynth.jobs.config import Settings
from texsynth.jobs.queue import create_celery

pytestmark = pytest.mark.integration


def test_empty_and_half_written_messages_do_not_kill_the_worker(embedded, exemplar_png):
    queue = embedded.data_dir / "broker" / "queue"
    worker = embedded.worker_pid()
    (queue / "0_empty.texsynth.msg").write_bytes(b"")
    (queue / "0_half.texsynth.msg").write_bytes(b'{"body": "eyJ')
    client = embedded.client()
    job = client.submit(exemplar_png, method="test-blur", params={"width": 32, "height": 32, "steps": 2})
    final = client.wait(job["id"], timeout=60)
    assert final["state"] == "succeeded", final["message"]
    assert embedded.worker_pid() == worker  # the same worker main process: it never died
    quarantined = {p.name for p in quarantine_folder(queue).iterdir()}
    assert {"0_empty.texsynth.msg", "0_half.texsynth.msg"} <= quarantined


def test_a_job_lost_between_enqueue_and_receipt_is_sent_again_and_finishes(tmp_path, exemplar_png):
    service = Service(tmp_path / "data", {"TEXSYNTH_RESEND_SECONDS": "3"}, concurrency=1).start()
    try:
        queue = service.data_dir / "broker" / "queue"
        worker = service.worker_pid()
        os.kill(worker, signal.SIGSTOP)  # the worker's main process cannot take the message yet
        client = service.client()
        job = client.submit(exemplar_png, method="test-blur", params={"width": 32, "height": 32, "steps": 2})
        wait_until(lambda: any(queue.glob("*.texsynth.msg")), 10, what="the job's message")
        for message in queue.glob("*.texsynth.msg"):  # taken by a worker that then died: lost
            message.unlink()
        os.killpg(os.getpgid(worker), signal.SIGKILL)
        wait_until(lambda: service.store().workers(fresh_within=3) != [], 60, 0.5, what="a new worker")
        final = client.wait(job["id"], timeout=90)
        assert final["state"] == "succeeded", final["message"]
        assert service.store().get(job["id"]).attempts == 1  # sent again, run once
    finally:
        service.stop()
        time.sleep(0.1)


def test_incomplete_envelopes_do_not_kill_the_worker_and_are_quarantined(embedded, exemplar_png):
    queue = embedded.data_dir / "broker" / "queue"
    worker = embedded.worker_pid()
    planted = {
        "0_body-only.texsynth.msg": {"body": "x"},
        "0_no-properties.texsynth.msg": {"body": "eyJ9", "headers": {}, "content-type": "application/json"},
        "0_bad-types.texsynth.msg": {"body": 5, "properties": {"delivery_tag": 1, "delivery_info": "d"}},
    }
    for name, envelope in planted.items():
        (queue / name).write_text(json.dumps(envelope))
    client = embedded.client()
    job = client.submit(exemplar_png, method="test-blur", params={"width": 32, "height": 32, "steps": 2})
    final = client.wait(job["id"], timeout=60)
    assert final["state"] == "succeeded", final["message"]
    assert embedded.worker_pid() == worker  # the same worker main process: it never died
    assert set(planted) <= {p.name for p in quarantine_folder(queue).iterdir()}


def test_a_dead_workers_mailbox_does_not_pile_up(tmp_path):
    service = Service(tmp_path / "data", {"TEXSYNTH_RESEND_SECONDS": "2"}, concurrency=1).start()
    try:
        queue = service.data_dir / "broker" / "queue"
        control = service.data_dir / "broker" / "control" / "celery.pidbox.exchange"
        (dead,) = service.store().workers(fresh_within=10)
        os.killpg(os.getpgid(dead["pid"]), signal.SIGKILL)
        wait_until(lambda: service.store().workers(fresh_within=3) != [], 60, 0.5, what="a new worker")
        app = create_celery(Settings.from_env({"TEXSYNTH_DATA_DIR": str(service.data_dir)}))
        for i in range(5):  # what DELETE and the reaper's terminate send: broadcasts to every mailbox
            app.control.revoke(f"no-such-job-{i}")
        mailbox = f"{dead['name']}.celery.pidbox"
        wait_until(lambda: mailbox not in control.read_text(), 30, 0.5, what="the dead mailbox unbound")
        wait_until(lambda: not list(queue.glob(f"*.{mailbox}.msg")), 10, 0.5, what="its messages removed")
        app.control.revoke("after")
        time.sleep(1.0)
        assert not list(queue.glob(f"*.{mailbox}.msg"))  # no longer sent at all
        live = service.store().workers(fresh_within=5)[0]["name"]
        assert f"{live}.celery.pidbox" in control.read_text()  # the live worker keeps its mailbox
    finally:
        service.stop()
