"""Slow and idle connections are closed (issue 26): a client that sends its request head byte by byte,
one that connects and says nothing, one that pauses in its body, and an idle kept-alive connection.

Runs against its own ``texsynth serve --no-worker`` with ``TEXSYNTH_CLIENT_TIMEOUT=2``; each case
must see the server close the connection within that timeout plus a generous margin (a bound on a
timeout, not a speed measurement), and the service still answers others afterwards.
"""

from __future__ import annotations

import socket
import time

import httpx
import pytest

from tests.service.conftest import Service

pytestmark = pytest.mark.integration

TIMEOUT = 2.0
MARGIN = 6.0


@pytest.fixture(scope="module")
def guarded(tmp_path_factory):
    service = Service(
        tmp_path_factory.mktemp("slow") / "data", {"TEXSYNTH_CLIENT_TIMEOUT": str(TIMEOUT)}, worker=False
    ).start()
    yield service
    service.stop()


def _closed_within(sock: socket.socket, limit: float, drip: bytes = b"") -> tuple[float, bytes]:
    """Send ``drip`` one byte every 0.1 s until the server closes; ``(seconds, what it answered)``."""
    start = time.monotonic()
    answer = b""
    sock.settimeout(0.1)
    for i in range(int(limit / 0.1)):
        if drip:
            try:
                sock.sendall(drip[i % len(drip) : i % len(drip) + 1])
            except OSError:  # reset by the server
                return time.monotonic() - start, answer
        try:
            chunk = sock.recv(4096)
        except TimeoutError:
            continue
        except OSError:
            return time.monotonic() - start, answer
        if not chunk:
            return time.monotonic() - start, answer
        answer += chunk
    raise AssertionError(f"the server kept the connection open for {limit} s; it answered {answer[:200]!r}")


def _connect(service: Service) -> socket.socket:
    return socket.create_connection(("127.0.0.1", service.port), timeout=5)


def test_a_request_head_sent_byte_by_byte_is_closed_within_the_timeout(guarded):
    head = b"GET /api/health HTTP/1.1\r\nHost: localhost\r\nX-Slow: " + b"a" * 400 + b"\r\n\r\n"
    with _connect(guarded) as sock:
        seconds, answer = _closed_within(sock, TIMEOUT + MARGIN, drip=head)
    assert seconds < TIMEOUT + MARGIN
    assert answer == b"" or answer.startswith(b"HTTP/1.1 408")
    assert httpx.get(guarded.url + "/api/health", timeout=5).status_code in (200, 503)


def test_a_connection_that_sends_nothing_is_closed(guarded):
    with _connect(guarded) as sock:
        seconds, _ = _closed_within(sock, TIMEOUT + MARGIN)
    assert seconds < TIMEOUT + MARGIN


def _read_response(sock: socket.socket) -> bytes:
    """One whole response (its head and a ``content-length`` body) from ``sock``."""
    data = b""
    while b"\r\n\r\n" not in data:
        data += sock.recv(4096)
    head, _, body = data.partition(b"\r\n\r\n")
    length = int(
        next(line for line in head.split(b"\r\n") if line.lower().startswith(b"content-length:"))[15:]
    )
    while len(body) < length:
        body += sock.recv(4096)
    return head


def test_a_second_request_head_on_a_kept_alive_connection_is_timed_too(guarded):
    with _connect(guarded) as sock:
        sock.sendall(b"GET /api/metrics HTTP/1.1\r\nHost: localhost\r\n\r\n")
        assert _read_response(sock).startswith(b"HTTP/1.1 200")  # the connection is kept alive
        drip = b"GET /api/health HTTP/1.1\r\nHost: x" + b"y" * 200
        seconds, _ = _closed_within(sock, TIMEOUT + MARGIN, drip=drip)
    assert seconds < TIMEOUT + MARGIN


def test_a_body_that_stops_arriving_gets_408_and_the_connection_closes(guarded):
    head = (
        b"POST /api/jobs HTTP/1.1\r\nHost: localhost\r\nContent-Type: multipart/form-data; boundary=xx\r\n"
        b'Content-Length: 100000\r\n\r\n--xx\r\nContent-Disposition: form-data; name="method"\r\n\r\nwei'
    )
    with _connect(guarded) as sock:
        sock.sendall(head)
        seconds, answer = _closed_within(sock, TIMEOUT + MARGIN)
    assert seconds < TIMEOUT + MARGIN
    assert answer.startswith(b"HTTP/1.1 408"), answer[:200]
    assert b"TEXSYNTH_CLIENT_TIMEOUT" in answer


def test_many_slow_connections_do_not_starve_a_normal_client(guarded):
    slow = [_connect(guarded) for _ in range(50)]
    try:
        for sock in slow:
            sock.sendall(b"GET / HTTP/1.1\r\n")
        r = httpx.get(guarded.url + "/api/methods", timeout=10)
        assert r.status_code == 200
    finally:
        for sock in slow:
            sock.close()
