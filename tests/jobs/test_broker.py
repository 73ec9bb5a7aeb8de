"""The embedded broker's messages: written atomically, and a malformed one set aside, not fatal."""

from __future__ import annotations

import os
import uuid
from pathlib import Path

import pytest
from kombu import Connection

from jobs.broker import SCHEME, quarantine_folder


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
