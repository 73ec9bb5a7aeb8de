"""One place that turns errors into JSON a person can act on: ``{"detail", "field", "error"}``.

Engine errors map by kind (DESIGN.md): InputTooLarge -> 413, UnsupportedFormat -> 415,
InvalidInput / InvalidParameter -> 422; a broker that does not answer -> 503; a file the server
cannot write (full disk) -> 507, naming the file but none of the server's folders; so does a full
disk met anywhere else (a job record that cannot be written, a folder that cannot be made): a route
that only reads goes on answering on a full disk, one that writes answers 507, never 500.

A ``422`` has FastAPI's shape, one entry per bad field, so that a form can mark each one:
``{"detail": [{"loc": ["params", "neighbourhood_size"], "msg": "neighbourhood_size must be odd",
"type": "invalid_parameter", "input": 12}], "field": "neighbourhood_size", "message": "<one line>"}``;
``loc`` starts with ``params`` for a method's parameter, ``body`` for another form field or an input
image, ``query`` for a list's filter. Other errors keep ``detail`` a sentence.
"""

from __future__ import annotations

import errno
import sqlite3
import time
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException

from texsynth.app.admission import QuotaExceeded
from texsynth.app.service import BrokerUnavailable
from texsynth.jobs.storage import StorageUnavailable
from texsynth.synth.errors import (
    InputTooLarge,
    InvalidInput,
    InvalidParameter,
    InvalidParameters,
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


#: Form fields of the submit and sweep routes that are not a method's parameters, and the lists' queries.
FORM_FIELDS = frozenset(
    {"method", "params", "seed", "width", "height", "depth", "voxel_size", "voxel_unit", "grid"}
)
QUERY_FIELDS = frozenset({"state", "method", "limit", "offset"})


def _error(status: int, detail: str, field: str | None, kind: str) -> JSONResponse:
    return JSONResponse({"detail": detail, "field": field, "error": kind}, status_code=status)


def field_loc(name: str, *, query: bool = False) -> list[str]:
    """Where a field lives, FastAPI's way: ``['params', 'k']``, ``['body', 'width']``,
    ``['query', 'state']``."""
    head = name.split(".", 1)[0]
    if query and head in QUERY_FIELDS:
        return ["query", *name.split(".")]
    if head in FORM_FIELDS or head.startswith(("exemplar", "constraint")):
        return ["body", *name.split(".")]
    return ["params", *name.split(".")]


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def unprocessable(items: list[dict[str, Any]], kind: str = "invalid_parameter") -> JSONResponse:
    """A ``422`` listing ``items`` (``loc``, ``msg``, ``type``, maybe ``input``) in FastAPI's shape."""
    items = [{key: _encodable(value) for key, value in item.items()} for item in items]
    first = items[0]
    field = ".".join(str(p) for p in first["loc"][1:]) or None
    message = "; ".join(
        f"{'.'.join(str(p) for p in item['loc'][1:]) or 'request'}: {item['msg']}" for item in items
    )
    return JSONResponse({"detail": items, "field": field, "error": kind, "message": message}, status_code=422)


def _encodable(value: Any) -> Any:
    """``value`` with any text that UTF-8 cannot carry (a lone surrogate a client sent as ``\\ud800``)
    escaped, so that the answer itself can be written."""
    if isinstance(value, str):
        return value.encode("utf-8", "backslashreplace").decode("utf-8")
    if isinstance(value, list):
        return [_encodable(v) for v in value]
    return value


def _parameter_items(exc: InvalidParameter) -> list[dict[str, Any]]:
    problems = exc.problems if isinstance(exc, InvalidParameters) else [exc]
    items = []
    for problem in problems:
        item: dict[str, Any] = {
            "loc": field_loc(problem.name),
            "msg": _one_line(problem.reason),
            "type": "invalid_parameter",
        }
        if isinstance(problem.value, int | float | str | bool) or problem.value is None:
            item["input"] = problem.value if not isinstance(problem.value, str) else problem.value[:80]
        items.append(item)
    return items


def synth_error_response(exc: SynthError) -> JSONResponse:
    if isinstance(exc, InputTooLarge):
        return _error(413, str(exc), exc.source, "input_too_large")
    if isinstance(exc, UnsupportedFormat):
        return _error(415, str(exc), exc.source, "unsupported_format")
    if isinstance(exc, InvalidInput):
        item = {"loc": field_loc(exc.source), "msg": _one_line(exc.problem), "type": "invalid_input"}
        return unprocessable([item], "invalid_input")
    if isinstance(exc, InvalidParameter):
        return unprocessable(_parameter_items(exc))
    item = {"loc": ["body"], "msg": _one_line(str(exc)), "type": "invalid_request"}
    return unprocessable([item], "invalid_request")


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
        if exc.status_code == 422:
            return unprocessable([{"loc": ["path"], "msg": _one_line(detail), "type": "invalid_request"}])
        response = _error(exc.status_code, detail, None, _HTTP_KINDS.get(exc.status_code, "error"))
        response.headers.update(exc.headers or {})
        return response

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        items, seen = [], set()
        for err in exc.errors():
            where = [str(p) for p in err.get("loc", ())]
            place = where[0] if where and where[0] in ("body", "query", "path") else "body"
            name = [p for p in where if p not in ("body", "query", "path", "form")]
            key = (place, *name)
            if key in seen:
                continue
            seen.add(key)
            item = {
                "loc": [place, *name],
                "msg": _one_line(err.get("msg", "invalid value")),
                "type": str(err.get("type", "invalid_parameter")),
            }
            value = err.get("input")
            if isinstance(value, int | float | str | bool):
                item["input"] = value if not isinstance(value, str) else value[:80]
            items.append(item)
        fallback = {"loc": ["body"], "msg": "invalid request", "type": "invalid_request"}
        return unprocessable(items or [fallback])

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
