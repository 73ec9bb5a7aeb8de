"""The HTTP server's limits (issue 26): slow or idle connections are closed, open ones are capped.

uvicorn 0.54 times only the pause *between* requests of a kept-alive connection
(``timeout_keep_alive``); a client that connects and sends its request head one byte at a time, or
nothing at all, holds a connection (a file descriptor, a slot) for ever: 500 such "slowloris"
connections stayed open in the hostile probe. So ``texsynth serve`` runs uvicorn with

- :class:`GuardedH11Protocol`: uvicorn's h11 protocol plus a deadline on every request head: from the
  connection's start, and from the first byte of each further request on it, the whole head must
  arrive within ``TEXSYNTH_CLIENT_TIMEOUT`` seconds, else ``408`` and the connection is closed. h11
  always (never httptools, which sets no limit on a head's size): a head above
  :data:`MAX_HEAD_BYTES` is a 400;
- the request body's pauses and total time bounded by :class:`texsynth.app.limits.BodyLimitMiddleware`;
- ``timeout_keep_alive`` (:data:`KEEP_ALIVE_SECONDS`) between requests and ``limit_concurrency``
  (``TEXSYNTH_MAX_CONNECTIONS``): above it a new request gets 503 until connections close.
"""

from __future__ import annotations

import asyncio
from typing import Any

import h11
import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from texsynth.jobs.config import Settings

__all__ = ["KEEP_ALIVE_SECONDS", "MAX_HEAD_BYTES", "GuardedH11Protocol", "uvicorn_config"]

#: Seconds an idle kept-alive connection stays open between two requests (uvicorn's default).
KEEP_ALIVE_SECONDS = 5
#: Largest request head (request line and headers) in bytes: h11's default, said explicitly.
MAX_HEAD_BYTES = 16 * 1024

_TIMEOUT_ANSWER = (
    b"HTTP/1.1 408 Request Timeout\r\ncontent-type: text/plain; charset=utf-8\r\nconnection: close\r\n"
    b"content-length: %d\r\n\r\n%s"
)


class GuardedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with a deadline on each request head (``head_timeout`` seconds)."""

    head_timeout: float = 15.0

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._head_deadline: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        if self.conn.their_state is h11.IDLE:  # the first bytes of a (further) request's head
            self._arm()
        super().data_received(data)
        if self.conn.their_state is not h11.IDLE:  # the head is complete (or the request failed)
            self._disarm()

    def _arm(self) -> None:
        if self._head_deadline is None:
            self._head_deadline = self.loop.call_later(self.head_timeout, self._head_timed_out)

    def _disarm(self) -> None:
        if self._head_deadline is not None:
            self._head_deadline.cancel()
            self._head_deadline = None

    def _head_timed_out(self) -> None:
        self._head_deadline = None
        if self.transport.is_closing() or self.conn.their_state is not h11.IDLE:
            return
        if self.cycle is not None and not self.cycle.response_complete:
            return  # a request is being answered: the keep-alive rules apply after it
        message = (
            f"the request was not received within {self.head_timeout:g} s (TEXSYNTH_CLIENT_TIMEOUT)\n"
        ).encode()
        self.transport.write(_TIMEOUT_ANSWER % (len(message), message))
        self.transport.close()


def uvicorn_config(app: Any, settings: Settings, host: str, port: int) -> uvicorn.Config:
    """The uvicorn configuration of ``texsynth serve``: the limits above from ``settings``."""
    protocol = type(
        "GuardedH11Protocol", (GuardedH11Protocol,), {"head_timeout": float(settings.client_timeout)}
    )
    return uvicorn.Config(
        app,
        host=host,
        port=port,
        log_level="warning",
        timeout_graceful_shutdown=3,
        http=protocol,
        timeout_keep_alive=KEEP_ALIVE_SECONDS,
        h11_max_incomplete_event_size=MAX_HEAD_BYTES,
        limit_concurrency=settings.max_connections,
    )
