"""Request body limit that answers with the service's JSON error (HTTP 413).

FastAPI's own ``max_body_size`` (0.165) enforces the same limit, but when the request declares its
``Content-Length`` Starlette replaces whatever the app answers with a plain-text "Content Too
Large"; a person (or the browser page) then gets no actionable message. This middleware rejects a
declared oversize body before reading it and counts the bytes of a streamed (chunked) one.
"""

from __future__ import annotations

import json

from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

__all__ = ["BodyLimitMiddleware"]


class BodyLimitMiddleware:
    def __init__(self, app: ASGIApp, max_body_bytes: int) -> None:
        self.app = app
        self.max_body_bytes = max_body_bytes

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
        seen = 0

        async def limited_receive() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_body_bytes:
                    raise HTTPException(413, self._message())
            return message

        await self.app(scope, limited_receive, send)
