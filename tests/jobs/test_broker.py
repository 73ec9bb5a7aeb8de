"""The embedded broker's messages: written atomically, and a malformed one set aside, not fatal."""

from __future__ import annotations

import json
import logging
import os
import time
import uuid
from pathlib import Path

import pytest
from kombu import Connection
from kombu.pidbox import Mailbox

from texsynth.jobs.broker import SCHEME, prune_mailboxes, quarantine_folder


@pytest.fixture
def connection(tmp_path):
    queue = tmp_path / "broker" / "queue"
    queue.mkdir(parents=True)
    options = {
        "data_folder_in": str(queue),
        "data_folder_out": str(queue),
        "control_folder": str(tmp_path / "broker" / "control"),
        "processed_folder": str(tmp_path / "broker" / "processed"),
        "store_processed": False,
    }
    with Connection(f"{SCHEME}://localhost/", transport_options=options) as conn:
        yield conn, queue


def test_messages_round_trip_and_no_partial_file_is_ever_visible(connection):
    conn, queue = connection
    name = f"jobs{uuid.uuid4().hex[:8]}"
    q = conn.SimpleQueue(name)
    q.put({"job": "a"})
    names = os.listdir(queue)
    assert len(names) == 1 and names[0].endswith(f".{name}.msg")  # no temporary file left behind
    message = q.get(timeout=2)
    assert message.payload == {"job": "a"}
    message.ack()
    q.close()


@pytest.mark.parametrize("content", [b"", b'{"bo', b"[1, 2]"], ids=["empty", "half-written", "not-a-message"])
def test_a_malformed_message_is_quarantined_and_the_next_one_delivered(connection, content):
    conn, queue = connection
    name = f"jobs{uuid.uuid4().hex[:8]}"  # kombu keeps bindings per name across connections
    q = conn.SimpleQueue(name)
    (queue / f"0_bad.{name}.msg").write_bytes(content)  # sorts first: read before the good one
    q.put({"job": "b"})
    message = q.get(timeout=5)
    assert message.payload == {"job": "b"}
    message.ack()
    assert [p.name for p in quarantine_folder(queue).iterdir()] == [f"0_bad.{name}.msg"]
    assert Path(quarantine_folder(queue) / f"0_bad.{name}.msg").read_bytes() == content
    q.close()


def _envelope(body: str = "eyJqb2IiOiAiYyJ9", **changes) -> dict:
    """A complete kombu envelope as SafeChannel writes one (body: base64 of ``{"job": "c"}``)."""
    envelope = {
        "body": body,
        "content-encoding": "utf-8",
        "content-type": "application/json",
        "headers": {},
        "properties": {
            "body_encoding": "base64",
            "delivery_info": {"exchange": "", "routing_key": "q"},
            "delivery_mode": 2,
            "delivery_tag": "5f6c3a1e-0000-4000-8000-000000000000",
            "priority": 0,
        },
    }
    for path, value in changes.items():
        *parents, last = path.split("__")
        target = envelope
        for name in parents:
            target = target[name]
        if value is _DROP:
            del target[last]
        else:
            target[last] = value
    return envelope


_DROP = object()


@pytest.mark.parametrize(
    "envelope",
    [
        {"body": "x"},
        _envelope(properties=_DROP),
        _envelope(properties="p"),
        _envelope(properties__delivery_tag=_DROP),
        _envelope(properties__delivery_tag=7),
        _envelope(properties__delivery_info=_DROP),
        _envelope(properties__delivery_info=[1]),
        _envelope(properties__delivery_info__exchange=_DROP),
        _envelope(properties__delivery_info__routing_key=3),
        _envelope(properties__body_encoding="rot13"),
        _envelope(body="!!! not base64 !!!"),
        _envelope(body=17),
        _envelope(headers="h"),
        _envelope(headers={"compression": 5}),
        _envelope(**{"content-type": 5}),
    ],
    ids=lambda e: json.dumps(e)[:60],
)
def test_an_incomplete_envelope_is_quarantined_and_the_consumer_goes_on(connection, envelope, caplog):
    conn, queue = connection
    name = f"jobs{uuid.uuid4().hex[:8]}"
    q = conn.SimpleQueue(name)
    (queue / f"0_bad.{name}.msg").write_text(json.dumps(envelope))
    q.put({"job": "b"})
    with caplog.at_level(logging.WARNING, logger="texsynth.jobs.broker"):
        message = q.get(timeout=5)
    assert message.payload == {"job": "b"}
    message.ack()
    held = quarantine_folder(queue) / f"0_bad.{name}.msg"
    assert held.exists()
    assert str(held) in caplog.text  # the log says where the file went
    q.close()


def test_a_complete_envelope_written_by_hand_is_delivered(connection):
    conn, queue = connection
    name = f"jobs{uuid.uuid4().hex[:8]}"
    q = conn.SimpleQueue(name)
    envelope = _envelope(properties__delivery_info={"exchange": name, "routing_key": name})
    (queue / f"0_good.{name}.msg").write_text(json.dumps(envelope))
    message = q.get(timeout=5)
    assert message.payload == {"job": "c"}
    message.ack()
    q.close()


def test_dead_consumers_mailboxes_are_pruned_and_live_ones_kept(connection, tmp_path):
    conn, queue = connection
    control = tmp_path / "broker" / "control"
    live, dead = "texsynth-1@here", "texsynth-2@gone"
    mailbox = Mailbox("celery", type="fanout")(conn)
    for node in (live, dead):
        mailbox.get_queue(node).bind(conn.default_channel).declare()
    for _ in range(3):
        mailbox._broadcast("revoke", {"task_id": "x"})
    stale = time.time() - 120
    for path in queue.glob("*.pidbox.msg"):
        os.utime(path, (stale, stale))
    mailbox._broadcast("revoke", {"task_id": "y"})  # a fresh one: still kept for a live reader

    removed = prune_mailboxes(queue, control, live_nodes={live}, max_age=60)

    assert removed == 3 + 4  # the live node's 3 stale messages and all 4 of the dead one
    left = sorted(p.name.split(".", 1)[1] for p in queue.glob("*.pidbox.msg"))
    assert left == [f"{live}.celery.pidbox.msg"]
    table = json.loads((control / "celery.pidbox.exchange").read_text())
    assert [entry[2] for entry in table] == [f"{live}.celery.pidbox"]
    mailbox._broadcast("revoke", {"task_id": "z"})  # a broadcast now reaches the live node only
    assert not [p for p in queue.glob("*.pidbox.msg") if dead in p.name]
