"""A client of the texsynth job service for lab scripts and overnight batches, and ``texsynth submit``.

::

    from texsynth.app.client import Client

    client = Client("http://localhost:8000")     # token=... or $TEXSYNTH_TOKEN when the service has tokens
    job = client.submit("carbon.png", method="wei-levoy", width=256, height=128, seed=1)
    job = client.wait(job.id, progress=lambda j: print(j.stage, j.fraction))
    paths = client.download(job, "out/")          # output.png, output.tiff, metrics.json, ... (streamed)
    runs = client.submit_many([{"seed": s} for s in range(20)], exemplar=array, method="quilting")
    finished = client.wait_all(runs, progress=lambda job, done, total: print(done, "/", total))

Built on httpx (timeouts, connection pooling, streaming). Every request is retried on connection errors
and on 5xx/429 answers with exponential backoff and jitter from a seeded generator, honouring
``Retry-After`` (seconds or an HTTP date), within :attr:`Retry.total` seconds; a request that may have
changed something (POST, DELETE) is resent only when the service cannot have acted on it (no
connection, 429, 503). :meth:`Client.wait` and :meth:`Client.wait_all` outlast an API restart.

Answers are the service's own pydantic models (:mod:`texsynth.app.schemas`); ``job["id"]`` still works as
``job.id`` for scripts written for the first client, whose answers were dicts. Sizes are keywords,
``width=``, ``height=``, ``depth=`` (never an ``(H, W)`` tuple). Inputs are paths, bytes, ``(file name,
bytes)`` or numpy arrays (uint8 -> 8-bit PNG, uint16 and floats in [0, 1] -> 16-bit PNG, or TIFF for
16-bit colour: lossless). Errors the service reports raise :class:`ServiceError`, a
:class:`~texsynth.synth.errors.SynthError`, so the CLI prints them on one line.
"""

from __future__ import annotations

import argparse
import contextlib
import email.utils
import io
import json
import os
import random
import sys
import time
import urllib.parse
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, TypeVar

from texsynth.synth.cli.inputs import add_plane_arguments, input_sources
from texsynth.synth.errors import InvalidInput, SynthError

if TYPE_CHECKING:  # the models are built on first use: see _model
    from texsynth.app.schemas import DeletedPublic as Deleted
    from texsynth.app.schemas import HealthPublic as Health
    from texsynth.app.schemas import JobPublic as Job
    from texsynth.app.schemas import JobsPublic as Jobs
    from texsynth.app.schemas import MethodPublic as Method
    from texsynth.app.schemas import SweepPublic as Sweep

__all__ = [
    "Client",
    "Deleted",
    "Health",
    "Job",
    "Jobs",
    "Method",
    "Retry",
    "ServiceError",
    "Sweep",
    "encode_array",
    "register",
]

TERMINAL = ("succeeded", "failed", "cancelled")
DEFAULT_URL = "http://localhost:8000"
#: Statuses after which the service did nothing, so any request may be sent again (503: the broker did
#: not take the job and the service forgot it; 429: refused before anything was stored).
_RETRY_ANY = frozenset({429, 503})
#: Statuses after which a request that changes nothing (GET) is sent again.
_RETRY_READ = frozenset({429, 500, 502, 503, 504})


class ServiceError(SynthError):
    """The service answered with an error: ``status`` (HTTP; 0: not reached), ``detail``, ``field``."""

    def __init__(self, status: int, detail: str, field: str | None = None) -> None:
        self.status, self.detail, self.field = status, detail, field
        self.submitted: list = []  # submit_many: the jobs queued before this refusal
        super().__init__(f"HTTP {status}: {detail}")

    @property
    def transient(self) -> bool:
        """Whether trying again later may succeed (not reached, 5xx, 429)."""
        return self.status == 0 or self.status == 429 or self.status >= 500


# -- typed answers: the service's models (texsynth.app.schemas), readable as dicts too ----------------------


def _build_models() -> dict[str, type]:
    from pydantic import BaseModel

    from texsynth.app.schemas import (
        DeletedPublic,
        HealthPublic,
        JobPublic,
        JobsPublic,
        MethodPublic,
        SweepPublic,
    )

    class _Subscriptable(BaseModel):
        """``answer["id"]`` as ``answer.id``: scripts of the first client (dict answers) keep working."""

        def __getitem__(self, key: str) -> Any:
            if key not in type(self).model_fields:
                raise KeyError(key)
            return getattr(self, key)

        def get(self, key: str, default: Any = None) -> Any:
            return getattr(self, key) if key in type(self).model_fields else default

    class Job(JobPublic, _Subscriptable):
        """A job's record (:class:`texsynth.app.schemas.JobPublic`)."""

    class Jobs(JobsPublic, _Subscriptable):
        """A page of jobs (:class:`texsynth.app.schemas.JobsPublic`)."""

        data: list[Job]

    class Method(MethodPublic, _Subscriptable):
        """A method's description (:class:`texsynth.app.schemas.MethodPublic`)."""

    class Sweep(SweepPublic, _Subscriptable):
        """A sweep's table (:class:`texsynth.app.schemas.SweepPublic`)."""

    class Health(HealthPublic, _Subscriptable):
        """The service's health (:class:`texsynth.app.schemas.HealthPublic`); ``status`` ``degraded`` on
        503."""

    class Deleted(DeletedPublic, _Subscriptable):
        """A finished job deleted (:class:`texsynth.app.schemas.DeletedPublic`)."""

    models: dict[str, type] = {m.__name__: m for m in (Job, Jobs, Method, Sweep, Health, Deleted)}
    for model in models.values():
        model.__module__, model.__qualname__ = __name__, model.__name__
    return models


_MODELS: dict[str, type] = {}
_MODEL_NAMES = ("Job", "Jobs", "Method", "Sweep", "Health", "Deleted")


def _model(name: str) -> Any:
    """One of the answer models, built on first use (``texsynth --help`` imports no pydantic)."""
    if not _MODELS:
        _MODELS.update(_build_models())
    return _MODELS[name]


def __getattr__(name: str) -> Any:
    if name in _MODEL_NAMES:
        return _model(name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


T = TypeVar("T")


# -- retries ---------------------------------------------------------------------------------------


@dataclass
class Retry:
    """How a request is tried again: exponential backoff with full jitter, bounded in total time.

    The ``n``-th wait (from 0) is drawn uniformly in ``[0, min(cap, base * 2**n)]`` from
    ``random.Random(seed)`` (``seed=None``: seeded by the system; give one for reproducible waits), and
    is at least the answer's ``Retry-After``. A request gives up, raising the last error, when the
    next wait would end more than ``total`` seconds after its first try, or after ``attempts`` tries.
    """

    total: float = 300.0
    base: float = 0.5
    cap: float = 30.0
    attempts: int = 1000
    seed: int | None = None
    _rng: random.Random = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.total < 0 or self.base <= 0 or self.cap <= 0 or self.attempts < 1:
            raise ValueError("Retry needs total >= 0, base > 0, cap > 0 and attempts >= 1")
        self._rng = random.Random(self.seed)

    def backoff(self, n: int) -> float:
        """The ``n``-th wait without ``Retry-After`` (seconds)."""
        return self._rng.uniform(0.0, min(self.cap, self.base * 2.0 ** min(n, 60)))


def retry_after(value: str | None, now: float | None = None) -> float | None:
    """Seconds to wait from a ``Retry-After`` header: a number of seconds or an HTTP date; None if absent
    or unreadable."""
    if not value:
        return None
    value = value.strip()
    with contextlib.suppress(ValueError):
        return max(0.0, float(value))
    try:
        when = email.utils.parsedate_to_datetime(value)
    except (TypeError, ValueError, IndexError):
        return None
    if when.tzinfo is None:  # an HTTP date is GMT
        return None
    return max(0.0, when.timestamp() - (time.time() if now is None else now))


# -- inputs ----------------------------------------------------------------------------------------

Array = Any  # numpy.ndarray (numpy is imported only when an array is given)
FileLike = str | os.PathLike[str] | bytes | tuple[str, bytes] | Array
_EXTENSIONS = {"PNG": "png", "TIFF": "tiff", "JPEG": "jpg"}


def encode_array(image: Array, role: str = "exemplar") -> tuple[str, bytes]:
    """A numpy image as a lossless file ``(name, bytes)`` that keeps its dtype's range.

    ``uint8`` and ``bool`` -> 8-bit PNG (``True`` is 255); ``uint16`` -> 16-bit PNG (grey) or 16-bit
    TIFF (colour: Pillow writes no 16-bit RGB PNG); floats in [0, 1] -> 16 bits the same way
    (``round(x * 65535)``). ``(H, W)`` grey, ``(H, W, 1)``, ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA.

    Raises
    ------
    InvalidInput
        Another dtype, another shape, NaN/inf, or floats outside [0, 1] (the message says how to scale).
    """
    import numpy as np
    from PIL import Image

    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] in (3, 4))) or min(arr.shape[:2]) < 1:
        raise InvalidInput(
            role, f"an array of shape {arr.shape}: give (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA"
        )
    if arr.dtype == bool:
        arr = arr.astype(np.uint8) * 255
    elif np.issubdtype(arr.dtype, np.floating):
        if not np.all(np.isfinite(arr)):
            raise InvalidInput(role, "a float array with NaN or inf values")
        lo, hi = float(arr.min()), float(arr.max())
        if lo < 0.0 or hi > 1.0:
            raise InvalidInput(
                role,
                f"a float array with values in [{lo:g}, {hi:g}], outside [0, 1]: scale it first, e.g. "
                "(a - a.min()) / (a.max() - a.min()), or a / 255 for 8-bit values; or pass the uint8 "
                "or uint16 array itself",
            )
        arr = np.rint(arr.astype(np.float64) * 65535.0).astype(np.uint16)
    elif arr.dtype not in (np.uint8, np.uint16):
        raise InvalidInput(
            role,
            f"an array of {arr.dtype}: give uint8, uint16, bool, or floats in [0, 1] "
            "(e.g. a.astype(np.uint16))",
        )
    arr = np.ascontiguousarray(arr)
    buf = io.BytesIO()
    if arr.dtype == np.uint16 and arr.ndim == 3:
        import tifffile

        tifffile.imwrite(buf, arr, photometric="rgb", compression="zlib")
        return f"{role}.tiff", buf.getvalue()
    Image.fromarray(arr).save(buf, format="PNG")
    return f"{role}.png", buf.getvalue()


def _file(source: FileLike, role: str) -> tuple[str, bytes]:
    """``(file name, bytes)`` of one input: a path's own name, a byte string's name from its format."""
    from texsynth.synth.io import sniff_format

    if isinstance(source, tuple) and len(source) == 2 and isinstance(source[1], bytes | bytearray):
        return str(source[0]), bytes(source[1])
    if isinstance(source, bytes | bytearray):
        return f"{role}.{_EXTENSIONS.get(sniff_format(bytes(source)) or '', 'png')}", bytes(source)
    if isinstance(source, str | os.PathLike):
        path = Path(source)
        try:
            return path.name, path.read_bytes()
        except OSError as exc:
            raise InvalidInput(role, f"cannot read {path} ({exc.strerror or exc})") from None
    if hasattr(source, "__array__") or hasattr(source, "dtype"):
        return encode_array(source, role)
    raise InvalidInput(role, f"a {type(source).__name__}: give a path, bytes, (name, bytes) or a numpy array")


def _files(
    exemplar: FileLike | None, constraint: FileLike | None, exemplars: Mapping[str, FileLike] | None
) -> dict[str, tuple[str, bytes]]:
    """The multipart files by role: ``exemplar`` or ``exemplar_{xy,xz,yz}``, and ``constraint``."""
    roles: dict[str, FileLike | None] = {"exemplar": exemplar, "constraint": constraint}
    roles.update({f"exemplar_{plane}": source for plane, source in (exemplars or {}).items()})
    return {role: _file(source, role) for role, source in roles.items() if source is not None}


def _size_fields(
    width: int | None, height: int | None, depth: int | None, size: Mapping[str, int] | None
) -> dict[str, int]:
    fields = dict(size or {})
    for name, value in (("width", width), ("height", height), ("depth", depth)):
        if value is None:
            continue
        if name in fields and fields[name] != value:
            raise InvalidInput(name, f"given twice: {name}={value} and size[{name!r}]={fields[name]}")
        fields[name] = value
    unknown = set(fields) - {"width", "height", "depth"}
    if unknown:
        raise InvalidInput(sorted(unknown)[0], "is not a size field (width, height, depth)")
    return fields


# -- the client ------------------------------------------------------------------------------------


class Client:
    """Talks to one texsynth service at ``base_url``, with ``token`` (default ``$TEXSYNTH_TOKEN``)
    sent as ``Authorization: Bearer`` on every request when the service has tokens.

    Parameters
    ----------
    base_url : str, optional
        Default ``$TEXSYNTH_URL`` or ``http://localhost:8000``.
    timeout : float
        Seconds for connecting, and between two received chunks of an answer.
    token : str, optional
        The service's API token (default ``$TEXSYNTH_TOKEN``); sent only to ``base_url``.
    retry : Retry, optional
        Backoff and total time of each request's retries (default ``Retry()``: up to 300 s).
    on_retry : callable, optional
        ``on_retry(what, error, wait)`` before each wait: what is retried (``"GET /api/jobs/..."``),
        the :class:`ServiceError` that caused it and the seconds about to be slept (for a log).
    """

    def __init__(
        self,
        base_url: str | None = None,
        timeout: float = 30.0,
        token: str | None = None,
        *,
        retry: Retry | None = None,
        on_retry: Callable[[str, ServiceError, float], None] | None = None,
    ) -> None:
        import httpx

        self.base_url = (base_url or os.environ.get("TEXSYNTH_URL") or DEFAULT_URL).rstrip("/")
        self.timeout = timeout
        self.token = (token or os.environ.get("TEXSYNTH_TOKEN") or "").strip() or None
        self.retry = retry or Retry()
        self.on_retry = on_retry
        self._sleep = time.sleep
        self._http = httpx.Client(timeout=httpx.Timeout(timeout), follow_redirects=False)

    def close(self) -> None:
        """Close the pooled connections (also done by ``with Client(...)`` and when the client is
        garbage-collected, as scripts of the first client, which held none, never close it)."""
        self._http.close()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self._http.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- plumbing -----------------------------------------------------------------------------------

    def _url(self, path: str) -> str:
        return path if path.startswith(("http://", "https://")) else self.base_url + path

    def _headers(self, url: str) -> dict[str, str]:
        # never send the token to another host
        if self.token and (url == self.base_url or url.startswith(self.base_url + "/")):
            return {"Authorization": f"Bearer {self.token}"}
        return {}

    @staticmethod
    def _error(response: Any) -> ServiceError:
        raw = response.read()
        try:
            err = json.loads(raw)
        except ValueError:
            err = None
        if isinstance(err, dict) and "detail" in err:
            detail = err["detail"]
            if not isinstance(detail, str):  # a 422's list of fields: its one-line summary
                detail = err.get("message") or json.dumps(detail)
            return ServiceError(response.status_code, str(detail), err.get("field"))
        text = raw.decode(errors="replace")[:200] or response.reason_phrase
        return ServiceError(response.status_code, text)

    def _call(
        self,
        method: str,
        path: str,
        handle: Callable[[Any], T],
        *,
        budget: float | None = None,
        **kwargs: Any,
    ) -> T:
        """Send a request and give its answer to ``handle`` (inside the stream, for downloads), with
        retries for at most ``budget`` seconds (default ``retry.total``). An answer of 400 or more
        becomes a :class:`ServiceError`."""
        import httpx

        url = self._url(path)
        what = f"{method} {urllib.parse.urlsplit(url).path}"
        start = time.monotonic()
        policy = self.retry
        total = policy.total if budget is None else min(policy.total, max(0.0, budget))
        for n in range(policy.attempts):
            wait_at_least: float | None = None
            try:
                with self._http.stream(method, url, headers=self._headers(url), **kwargs) as response:
                    if response.status_code < 400:
                        return handle(response)
                    error = self._error(response)
                    wait_at_least = retry_after(response.headers.get("Retry-After"))
                    retriable = error.status in (_RETRY_READ if method == "GET" else _RETRY_ANY)
            except httpx.TransportError as exc:
                # resent only if nothing may have reached the service, unless the request only reads
                retriable = method == "GET" or isinstance(exc, httpx.ConnectError | httpx.ConnectTimeout)
                reason = str(exc) or type(exc).__name__
                detail = f"cannot reach the service at {self.base_url} ({reason})"
                if not retriable:
                    detail = (
                        f"the connection to {self.base_url} broke before an answer ({reason}); the "
                        f"service may have acted on this {method}: look before sending it again"
                    )
                error = ServiceError(0, detail)
            if not retriable or n + 1 >= policy.attempts:
                raise error
            wait = max(policy.backoff(n), wait_at_least or 0.0)
            if time.monotonic() - start + wait > total:
                if wait_at_least is not None and wait_at_least > total:
                    asks = f" (the service asks to retry after {wait_at_least:.0f} s)"
                    error = ServiceError(error.status, error.detail + asks, error.field)
                raise error
            if self.on_retry is not None:
                self.on_retry(what, error, wait)
            self._sleep(wait)
        raise AssertionError("unreachable")  # pragma: no cover

    def _json(self, method: str, path: str, **kwargs: Any) -> Any:
        return self._call(method, path, lambda r: json.loads(r.read()), **kwargs)

    def _post_form(self, path: str, fields: dict[str, Any], files: dict[str, tuple[str, bytes]]) -> Any:
        data = {k: str(v) for k, v in fields.items() if v is not None}
        multipart = {role: (name, body, "application/octet-stream") for role, (name, body) in files.items()}
        return self._json("POST", path, data=data, files=multipart or None)

    # -- API ----------------------------------------------------------------------------------------

    def health(self) -> Health:
        """The service's health; ``status == "degraded"`` (with ``message``) when it answers 503."""
        import httpx

        url = self._url("/api/health")
        try:
            response = self._http.get(url, headers=self._headers(url))
        except httpx.TransportError as exc:
            raise ServiceError(0, f"cannot reach the service at {self.base_url} ({exc})") from None
        if response.status_code in (200, 503):
            return _model("Health").model_validate(response.json())
        raise self._error(response)

    def methods(self) -> list[Method]:
        return [_model("Method").model_validate(m) for m in self._json("GET", "/api/methods")["data"]]

    def submit(
        self,
        exemplar: FileLike | None = None,
        *,
        method: str = "wei-levoy",
        params: dict[str, Any] | None = None,
        seed: int | None = None,
        constraint: FileLike | None = None,
        exemplars: Mapping[str, FileLike] | None = None,
        width: int | None = None,
        height: int | None = None,
        depth: int | None = None,
        size: Mapping[str, int] | None = None,
    ) -> Job:
        """Queue a job; returns its record (``id``, ``state``, ...).

        ``params`` holds the method's parameters; ``width``, ``height`` (and ``depth``, the slices of a
        volume) the output's size (``size={"width": ...}`` says the same). A solid method takes
        ``exemplars={'xy': ..., 'xz': ..., 'yz': ...}`` instead of ``exemplar`` for an anisotropic
        material. Inputs: paths (their file names are kept), bytes, ``(name, bytes)`` or numpy arrays.
        """
        files = _files(exemplar, constraint, exemplars)
        return self._submit_files(files, method, params, seed, _size_fields(width, height, depth, size))

    def _submit_files(
        self,
        files: dict[str, tuple[str, bytes]],
        method: str,
        params: dict[str, Any] | None,
        seed: int | None,
        size: dict[str, int],
    ) -> Job:
        fields = {"method": method, "params": json.dumps(params or {}), "seed": seed, **size}
        return _model("Job").model_validate(self._post_form("/api/jobs", fields, files))

    def submit_many(
        self,
        runs: Iterable[Mapping[str, Any]],
        *,
        progress: Callable[[int, Job], None] | None = None,
        **common: Any,
    ) -> list[Job]:
        """Queue one job per run: each run's keywords of :meth:`submit` over ``common``'s.

        ``client.submit_many([{"seed": s} for s in range(20)], exemplar=img, method="quilting",
        width=128, height=128)``; a run's ``params`` are merged over the common ones. Inputs shared by
        every run are read and encoded once. ``progress(i, job)`` after each. A refusal (422, ...)
        raises :class:`ServiceError` with ``submitted``, the jobs queued before it.
        """
        allowed = {"exemplar", "constraint", "exemplars", "method", "params", "seed", "width", "height"}
        allowed |= {"depth", "size"}
        shared = {"exemplar": common.get("exemplar"), "constraint": common.get("constraint")}
        shared.update({f"exemplar_{p}": s for p, s in (common.get("exemplars") or {}).items()})
        encoded = {role: _file(source, role) for role, source in shared.items() if source is not None}
        jobs: list[Job] = []
        for run in runs:
            kw = {**common, **run}
            if "params" in common and "params" in run:
                kw["params"] = {**(common["params"] or {}), **(run["params"] or {})}
            unknown = set(kw) - allowed
            if unknown:
                raise TypeError(f"submit_many: unknown keyword {sorted(unknown)[0]!r}")
            roles = {"exemplar": kw.get("exemplar"), "constraint": kw.get("constraint")}
            roles.update({f"exemplar_{p}": s for p, s in (kw.get("exemplars") or {}).items()})
            files = {
                role: encoded[role] if source is shared.get(role) else _file(source, role)
                for role, source in roles.items()
                if source is not None
            }
            size = _size_fields(kw.get("width"), kw.get("height"), kw.get("depth"), kw.get("size"))
            try:
                job = self._submit_files(
                    files, kw.get("method", "wei-levoy"), kw.get("params"), kw.get("seed"), size
                )
            except ServiceError as exc:
                exc.submitted = jobs
                raise
            jobs.append(job)
            if progress is not None:
                progress(len(jobs) - 1, job)
        return jobs

    def job(self, job_id: str, *, budget: float | None = None) -> Job:
        """One job's record; ``budget``: seconds of retries at most (default ``retry.total``)."""
        answer = self._json("GET", f"/api/jobs/{urllib.parse.quote(str(job_id))}", budget=budget)
        return _model("Job").model_validate(answer)

    def jobs(self, state: str | None = None, limit: int = 50, offset: int = 0) -> Jobs:
        query = {k: v for k, v in {"state": state, "limit": limit, "offset": offset}.items() if v is not None}
        return _model("Jobs").model_validate(self._json("GET", f"/api/jobs?{urllib.parse.urlencode(query)}"))

    def cancel(self, job_id: str) -> Job | Deleted:
        """Cancel a queued or running job (``DELETE``); returns its record (a finished job is deleted)."""
        answer = self._json("DELETE", f"/api/jobs/{urllib.parse.quote(str(job_id))}")
        return _model("Deleted" if answer.get("state") == "deleted" else "Job").model_validate(answer)

    def delete(self, job_id: str) -> Job | Deleted:
        """Delete a finished job's files and record (a running one is cancelled first, then deleted)."""
        answer = self.cancel(job_id)
        if answer.state != "deleted":
            self.wait(job_id, timeout=60)
            answer = self.cancel(job_id)
        return answer

    def wait(
        self,
        job_id: str,
        *,
        progress: Callable[[Job], None] | None = None,
        poll: float = 0.5,
        timeout: float | None = None,
    ) -> Job:
        """Poll until the job ends; ``progress(job)`` on every answer. Returns the final record.

        A poll that fails for a passing reason (service restarting, 5xx, 429) is tried again at the
        next poll, however long it lasts, until ``timeout``; a 404 or 401 ends the wait.
        """
        return self.wait_all(
            [job_id],
            progress=None if progress is None else (lambda j, d, t: progress(j)),
            poll=poll,
            timeout=timeout,
        )[0]

    def wait_all(
        self,
        jobs: Sequence[str | Job | Mapping[str, Any]],
        *,
        progress: Callable[[Job, int, int], None] | None = None,
        poll: float = 0.5,
        timeout: float | None = None,
    ) -> list[Job]:
        """Poll the jobs (ids or records) until all ended; returns their final records, in order.

        ``progress(job, finished, total)`` after every answer. Failed polls as in :meth:`wait`;
        ``TimeoutError`` names the jobs still unfinished after ``timeout`` seconds.
        """
        ids = [j if isinstance(j, str) else j["id"] if isinstance(j, Mapping) else j.id for j in jobs]
        final: dict[str, Job] = {}
        last: dict[str, Job] = {}
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            for job_id in ids:
                if job_id in final:
                    continue
                try:
                    left = None if deadline is None else deadline - time.monotonic()
                    job = self.job(job_id, budget=left)  # retries never outlast the wait's timeout
                except ServiceError as exc:
                    if not exc.transient:
                        raise
                    continue  # the next round polls it again
                last[job_id] = job
                if job.state in TERMINAL:
                    final[job_id] = job
                if progress is not None:
                    progress(job, len(final), len(set(ids)))
            if len(final) == len(set(ids)):
                return [final[j] for j in ids]
            if deadline is not None and time.monotonic() > deadline:
                waiting = [j for j in ids if j not in final]
                states = ", ".join(
                    f"{j} {last[j].state if j in last else 'unreachable'}" for j in waiting[:5]
                )
                raise TimeoutError(f"{len(waiting)} job(s) unfinished after {timeout} s: {states}")
            self._sleep(poll)

    def artifact(self, job: Job | Mapping[str, Any], name: str) -> bytes:
        """One artifact's bytes (``output.png``, ``metrics.json``, ...)."""
        return self._call("GET", _artifacts(job)[name], lambda r: r.read())

    def download(
        self,
        job: Job | Mapping[str, Any],
        out_dir: str | os.PathLike[str],
        names: Iterable[str] | None = None,
    ) -> list[Path]:
        """Stream the job's artifacts (all, or ``names``) into files under ``out_dir``; returns their
        paths. Each file appears whole or not at all (written beside, then renamed)."""
        from texsynth.synth.io.atomic import atomic_writer  # deferred: texsynth.synth.io loads Pillow

        out = Path(out_dir)
        artifacts = _artifacts(job)
        paths = []
        for name in names if names is not None else artifacts:
            path = out / name
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_writer(path) as fh:

                def save(response: Any, fh: BinaryIO = fh) -> None:
                    fh.seek(0)  # a broken stream is retried from the start
                    fh.truncate()
                    for chunk in response.iter_bytes(1 << 16):
                        fh.write(chunk)

                self._call("GET", artifacts[name], save)
            paths.append(path)
        return paths

    def sweep(
        self,
        exemplar: FileLike | None,
        grid: dict[str, list[Any]],
        *,
        method: str = "wei-levoy",
        params: dict[str, Any] | None = None,
        seed: int | None = None,
        constraint: FileLike | None = None,
        exemplars: Mapping[str, FileLike] | None = None,
        width: int | None = None,
        height: int | None = None,
        depth: int | None = None,
        size: Mapping[str, int] | None = None,
    ) -> dict:
        """Queue one job per point of ``grid`` on the service (``{"id": sweep id, ...}``);
        :meth:`get_sweep` then gives all their metrics in one table."""
        files = _files(exemplar, constraint, exemplars)
        fields = {
            "method": method,
            "grid": json.dumps(grid),
            "params": json.dumps(params or {}),
            "seed": seed,
            **_size_fields(width, height, depth, size),
        }
        return self._post_form("/api/sweeps", fields, files)

    def get_sweep(self, sweep_id: str) -> Sweep:
        return _model("Sweep").model_validate(
            self._json("GET", f"/api/sweeps/{urllib.parse.quote(str(sweep_id))}")
        )


def _artifacts(job: Job | Mapping[str, Any]) -> Mapping[str, str]:
    return job.artifacts if hasattr(job, "artifacts") else job["artifacts"]


# -- texsynth submit -------------------------------------------------------------------------------


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "submit",
        help="submit a job to a texsynth service, wait, download the results",
        description="Submit a synthesis job to a running service (texsynth serve), show its "
        "progress and download its artifacts. Failed polls (a service restarting) are retried.",
    )
    p.add_argument("exemplar", nargs="?", help="exemplar image (PNG, TIFF, JPEG)")
    add_plane_arguments(p)
    p.add_argument("--url", help=f"service URL (default: $TEXSYNTH_URL or {DEFAULT_URL})")
    p.add_argument(
        "--token",
        help="the service's API token, when it has tokens (default: $TEXSYNTH_TOKEN; the variable keeps "
        "it out of the process list)",
    )
    p.add_argument("--method", default="wei-levoy")
    p.add_argument("--constraint", help="constraint image, for methods that take one")
    p.add_argument("--width", type=int, help="output width (pixels)")
    p.add_argument("--height", type=int, help="output height (pixels)")
    p.add_argument("--depth", type=int, help="slices of a volume (solid methods)")
    p.add_argument("--seed", type=int)
    p.add_argument(
        "--set",
        dest="sets",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a method parameter (value parsed as JSON, else a string); repeatable",
    )
    p.add_argument(
        "--out", default="out", help="download folder; artifacts go to OUT/<job id>/ (default ./out)"
    )
    p.add_argument("--no-wait", action="store_true", help="print the job id and return at once")
    p.set_defaults(func=_submit)


def _submit(args: argparse.Namespace) -> int:
    from texsynth.synth.params import parse_assignments  # deferred: ``texsynth --help`` needs no pydantic

    params = parse_assignments(args.sets)
    sources = input_sources(args)
    planes = {role[len("exemplar_") :]: p for role, p in sources.items() if role.startswith("exemplar_")}

    def said(what: str, error: ServiceError, wait: float) -> None:
        print(f"\n{what}: {error}; trying again in {wait:.1f} s", file=sys.stderr, flush=True)

    with Client(args.url, token=args.token, on_retry=said) as client:
        job = client.submit(
            sources.get("exemplar"),
            method=args.method,
            params=params,
            seed=args.seed,
            constraint=sources.get("constraint"),
            exemplars=planes or None,
            width=args.width,
            height=args.height,
            depth=args.depth,
        )
        print(f"job {job.id} queued: {client.base_url}{job.page}", file=sys.stderr)
        if args.no_wait:
            print(job.id)
            return 0

        def show(j: Job) -> None:
            if sys.stderr.isatty():
                bar = "#" * int(30 * j.fraction)
                print(
                    f"\r[{bar:<30}] {100 * j.fraction:5.1f}% {j.state}: {j.stage[:40]:<40}",
                    end="",
                    file=sys.stderr,
                    flush=True,
                )

        try:
            job = client.wait(job.id, progress=show)
        except KeyboardInterrupt:
            client.cancel(job.id)
            print(f"\njob {job.id} cancelled", file=sys.stderr)
            return 130
        if sys.stderr.isatty():
            print(file=sys.stderr)
        if job.state != "succeeded":
            print(f"job {job.id} {job.state}: {job.message}", file=sys.stderr)
            return 1
        folder = Path(args.out) / job.id
        paths = client.download(job, folder)
    print(
        f"job {job.id} succeeded in {job.elapsed or 0:.1f} s; {len(paths)} files in {folder}",
        file=sys.stderr,
    )
    print(folder)
    return 0
