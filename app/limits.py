"""Request body limits that answer with the service's JSON error: size (HTTP 413) and time (HTTP 408).

FastAPI's own ``max_body_size`` (0.165) enforces the same size limit, but when the request declares its
``Content-Length`` Starlette replaces whatever the app answers with a plain-text "Content Too
Large"; a person (or the browser page) then gets no actionable message. This middleware rejects a
declared oversize body before reading it and counts the bytes of a streamed (chunked) one.

A body that stops arriving would hold its connection and a worker thread for ever (the server times
request heads only, :mod:`texsynth.app.server`): with ``client_timeout`` set, the body may pause at most that
long, and must be complete within :data:`BODY_TIMEOUTS` times it; else ``408`` and the connection closes.
"""

from __future__ import annotations

import asyncio
import json

from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

__all__ = ["BODY_TIMEOUTS", "BodyLimitMiddleware"]

#: A whole body must arrive within this many client timeouts (15 s -> 5 minutes: 32 MiB at 110 kB/s).
BODY_TIMEOUTS = 20


class BodyLimitMiddleware:
    def __init__(self, app: ASGIApp, max_body_bytes: int, client_timeout: float | None = None) -> None:
        self.app = app
        self.max_body_bytes = max_body_bytes
        self.client_timeout = client_timeout

    def _too_slow(self, total: bool) -> HTTPException:
        assert self.client_timeout is not None
        why = (
            f"did not arrive within {self.client_timeout * BODY_TIMEOUTS:g} s"
            if total
            else f"paused for more than {self.client_timeout:g} s"
        )
        return HTTPException(
            408,
            f"the request body {why} (TEXSYNTH_CLIENT_TIMEOUT); send it again on a working connection",
            headers={"Connection": "close"},
        )

    def _message(self) -> str:
        return (
            f"the request body is larger than this service's limit of {self.max_body_bytes / 2**20:.3g} MiB; "
            "upload a smaller (cropped or downscaled) image"
        )

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope.get("headers") or []).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.max_body_bytes:
            body = json.dumps({"detail": self._message(), "field": None, "error": "input_too_large"}).encode()
            await send(
                {
                    "type": "http.response.start",
                    "status": 413,
                    "headers": [
                        (b"content-type", b"application/json"),
                        (b"content-length", str(len(body)).encode()),
                        (b"connection", b"close"),
                    ],
                }
            )
            await send({"type": "http.response.body", "body": body})
            return
        seen, complete = 0, False
        loop = asyncio.get_running_loop()
        deadline = loop.time() + (self.client_timeout or 0.0) * BODY_TIMEOUTS

        async def limited_receive() -> Message:
            nonlocal seen, complete
            if complete or self.client_timeout is None:  # after the body: waits for the disconnect
                message = await receive()
            else:
                left = deadline - loop.time()
                try:
                    message = await asyncio.wait_for(receive(), max(0.0, min(self.client_timeout, left)))
                except TimeoutError:
                    raise self._too_slow(total=left <= self.client_timeout) from None
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                complete = not message.get("more_body", False)
                if seen > self.max_body_bytes:
                    raise HTTPException(413, self._message())
            return message

        await self.app(scope, limited_receive, send)
