"""The test servers' ports: free, distinct, and outside the range the kernel gives outgoing connections."""

from __future__ import annotations

import socket

from tests import servers
from tests.servers import _ephemeral_start, free_port


def test_free_ports_are_distinct_listenable_and_below_the_ephemeral_range() -> None:
    ports = [free_port() for _ in range(40)]
    assert len(set(ports)) == len(ports)
    assert all(10000 <= port < min(_ephemeral_start(), 32768) for port in ports)
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", ports[-1]))


def test_a_port_in_use_or_handed_out_before_is_passed_over(monkeypatch) -> None:
    first = free_port()
    with socket.socket() as busy:
        for candidate in range(20000, 30000):
            try:
                busy.bind(("127.0.0.1", candidate))
                break
            except OSError:
                continue
        busy.listen()

        class Proposals:
            """Proposes the busy port, then the one handed out before, then a third."""

            def __init__(self) -> None:
                self.queue = [candidate, first, candidate + 1 if candidate + 1 != first else candidate + 2]

            def randrange(self, low: int, high: int) -> int:
                return self.queue.pop(0)

        monkeypatch.setattr(servers, "_ports", Proposals())
        assert free_port() not in (candidate, first)
