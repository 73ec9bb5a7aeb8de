"""One place that turns errors into JSON a person can act on: ``{"detail", "field", "error"}``.

Engine errors map by kind (DESIGN.md): InputTooLarge -> 413, UnsupportedFormat -> 415,
InvalidInput / InvalidParameter -> 422; a broker that does not answer -> 503; a file the server
cannot write (full disk) -> 507, naming the file but none of the server's folders; so does a full
disk met anywhere else (a job record that cannot be written, a folder that cannot be made): a route
that only reads goes on answering on a full disk, one that writes answers 507, never 500.
"""

from __future__ import annotations

import errno
import sqlite3
import time

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException

from app.admission import QuotaExceeded
from app.service import BrokerUnavailable
from jobs.storage import StorageUnavailable
from synth.errors import (
    InputTooLarge,
    InvalidInput,
    InvalidParameter,
    StorageError,
    SynthError,
    UnsupportedFormat,
)

__all__ = ["disk_full", "install_error_handlers"]

#: errno values of a disk (or the owner's filesystem quota) with no room left.
_FULL = frozenset({errno.ENOSPC, errno.EDQUOT})

_HTTP_KINDS = {
    400: "bad_request",
    408: "timeout",
    401: "unauthorized",
    403: "forbidden",
    404: "not_found",
    405: "method_not_allowed",
    413: "input_too_large",
    415: "unsupported_format",
    422: "invalid_parameter",
    429: "too_many_jobs",
    503: "unavailable",
    507: "insufficient_storage",
}


def _error(status: int, detail: str, field: str | None, kind: str) -> JSONResponse:
    return JSONResponse({"detail": detail, "field": field, "error": kind}, status_code=status)


def synth_error_response(exc: SynthError) -> JSONResponse:
    if isinstance(exc, InputTooLarge):
        return _error(413, str(exc), exc.source, "input_too_large")
    if isinstance(exc, UnsupportedFormat):
        return _error(415, str(exc), exc.source, "unsupported_format")
    if isinstance(exc, InvalidInput):
        return _error(422, str(exc), exc.source, "invalid_input")
    if isinstance(exc, InvalidParameter):
        return _error(422, str(exc), exc.name, "invalid_parameter")
    return _error(422, str(exc), None, "invalid_request")


def disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` says the disk has no room: ``ENOSPC``/``EDQUOT``, or SQLite's own words."""
    if isinstance(exc, OSError):
        return exc.errno in _FULL
    if isinstance(exc, sqlite3.OperationalError):
        return "disk is full" in str(exc) or "disk I/O error" in str(exc)
    return False


def install_error_handlers(app: FastAPI) -> None:
    @app.exception_handler(SynthError)
    async def _synth(request: Request, exc: SynthError) -> JSONResponse:
        return synth_error_response(exc)

    @app.exception_handler(HTTPException)
    async def _http(request: Request, exc: HTTPException) -> JSONResponse:
        detail = str(exc.detail)
        response = _error(exc.status_code, detail, None, _HTTP_KINDS.get(exc.status_code, "error"))
        response.headers.update(exc.headers or {})
        return response

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        err = exc.errors()[0]
        loc = [str(p) for p in err.get("loc", ()) if p not in ("body", "query", "path", "form")]
        field = ".".join(loc) or None
        return _error(
            422, f"{field or 'request'}: {err.get('msg', 'invalid value')}", field, "invalid_parameter"
        )

    @app.exception_handler(StorageError)
    async def _storage(request: Request, exc: StorageError) -> JSONResponse:
        request.app.state.service.disk_full_at = time.time()
        return _error(
            507,
            f"the server could not store the job ({exc}); nothing was queued, try again later",
            None,
            "insufficient_storage",
        )

    async def _full(request: Request, exc: Exception) -> JSONResponse:
        if not disk_full(exc):
            raise exc  # anything else is a bug: the server's 500
        request.app.state.service.disk_full_at = time.time()
        why = getattr(exc, "strerror", None) or exc
        return _error(
            507,
            f"the server could not write to its disk, which is full ({why}); "
            "nothing was queued or changed, try again later",
            None,
            "insufficient_storage",
        )

    app.add_exception_handler(OSError, _full)
    app.add_exception_handler(sqlite3.OperationalError, _full)

    @app.exception_handler(QuotaExceeded)
    async def _quota(request: Request, exc: QuotaExceeded) -> JSONResponse:
        return _error(exc.status, exc.detail, None, "quota_exceeded")

    @app.exception_handler(StorageUnavailable)
    async def _store_down(request: Request, exc: StorageUnavailable) -> JSONResponse:
        return _error(
            503,
            "the object store is unreachable; nothing was queued, try again shortly",
            None,
            "unavailable",
        )

    @app.exception_handler(BrokerUnavailable)
    async def _broker(request: Request, exc: BrokerUnavailable) -> JSONResponse:
        return _error(
            503,
            f"the job queue is unreachable, nothing was queued; try again shortly ({exc})",
            None,
            "unavailable",
        )
