"""A small client of the texsynth job service (HTTP only, standard library), and ``texsynth submit``.

For lab scripts that run batches on the service instead of on their own machine::

    from app.client import Client

    client = Client("http://localhost:8000")     # token=... or $TEXSYNTH_TOKEN when the service has tokens
    job = client.submit("carbon.png", method="wei-levoy", size={"width": 256, "height": 256}, seed=1)
    job = client.wait(job["id"], progress=lambda j: print(j["stage"], j["fraction"]))
    paths = client.download(job, "out/")          # output.png, output.tiff, metrics.json, ...

Errors the service reports (401/403/404/413/415/422/429, with its message) raise :class:`ServiceError`, a
:class:`~synth.errors.SynthError`, so the CLI prints them on one line.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import urllib.error
import urllib.parse
import urllib.request
import uuid
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from synth.cli.inputs import add_plane_arguments, input_sources
from synth.errors import InvalidInput, SynthError

__all__ = ["Client", "ServiceError", "register"]

TERMINAL = ("succeeded", "failed", "cancelled")
DEFAULT_URL = "http://localhost:8000"


class ServiceError(SynthError):
    """The service answered with an error: ``status`` (HTTP), ``detail`` (its message), ``field``."""

    def __init__(self, status: int, detail: str, field: str | None = None) -> None:
        self.status, self.detail, self.field = status, detail, field
        super().__init__(f"HTTP {status}: {detail}")


FileLike = str | os.PathLike[str] | bytes


class Client:
    """Talks to one texsynth service at ``base_url``, with ``token`` (default ``$TEXSYNTH_TOKEN``)
    sent as ``Authorization: Bearer`` on every request when the service has tokens."""

    def __init__(self, base_url: str | None = None, timeout: float = 30.0, token: str | None = None) -> None:
        self.base_url = (base_url or os.environ.get("TEXSYNTH_URL") or DEFAULT_URL).rstrip("/")
        self.timeout = timeout
        self.token = (token or os.environ.get("TEXSYNTH_TOKEN") or "").strip() or None

    # -- plumbing -----------------------------------------------------------------------------------

    def _request(
        self, method: str, path: str, body: bytes | None = None, headers: dict | None = None
    ) -> bytes:
        url = path if path.startswith("http") else self.base_url + path
        headers = dict(headers or {})
        if self.token and url.startswith(self.base_url):  # never send the token to another host
            headers["Authorization"] = f"Bearer {self.token}"
        req = urllib.request.Request(url, data=body, method=method, headers=headers)
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as resp:
                return resp.read()
        except urllib.error.HTTPError as exc:
            raw = exc.read()
            try:
                err = json.loads(raw)
            except ValueError:
                err = None
            # (ServiceError is a ValueError: raised outside the try, or it would be caught as bad JSON)
            if isinstance(err, dict) and "detail" in err:
                raise ServiceError(exc.code, str(err["detail"]), err.get("field")) from None
            raise ServiceError(exc.code, raw.decode(errors="replace")[:200] or exc.reason) from None
        except urllib.error.URLError as exc:
            raise ServiceError(0, f"cannot reach the service at {self.base_url} ({exc.reason})") from None

    def _json(self, method: str, path: str, body: bytes | None = None, headers: dict | None = None) -> Any:
        return json.loads(self._request(method, path, body, headers))

    @staticmethod
    def _multipart(fields: dict[str, str], files: dict[str, tuple[str, bytes]]) -> tuple[bytes, str]:
        boundary = uuid.uuid4().hex
        parts = []
        for name, value in fields.items():
            parts.append(
                f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n{value}\r\n'.encode()
            )
        for name, (filename, data) in files.items():
            head = (
                f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"; filename="{filename}"\r\n'
                "Content-Type: application/octet-stream\r\n\r\n"
            )
            parts.append(head.encode() + data + b"\r\n")
        parts.append(f"--{boundary}--\r\n".encode())
        return b"".join(parts), f"multipart/form-data; boundary={boundary}"

    @staticmethod
    def _file(source: FileLike, role: str) -> tuple[str, bytes]:
        if isinstance(source, bytes):
            return f"{role}.png", source
        path = Path(source)
        try:
            return path.name, path.read_bytes()
        except OSError as exc:
            raise InvalidInput(role, f"cannot read {path} ({exc.strerror or exc})") from None

    @classmethod
    def _files(
        cls,
        exemplar: FileLike | None,
        constraint: FileLike | None,
        exemplars: Mapping[str, FileLike] | None,
    ) -> dict[str, tuple[str, bytes]]:
        """The multipart files by role: ``exemplar`` or ``exemplar_{xy,xz,yz}``, and ``constraint``."""
        roles: dict[str, FileLike | None] = {"exemplar": exemplar, "constraint": constraint}
        roles.update({f"exemplar_{plane}": source for plane, source in (exemplars or {}).items()})
        return {role: cls._file(source, role) for role, source in roles.items() if source is not None}

    def _post_form(self, path: str, fields: dict[str, Any], files: dict[str, tuple[str, bytes]]) -> Any:
        body, ctype = self._multipart({k: str(v) for k, v in fields.items() if v is not None}, files)
        return self._json("POST", path, body, {"Content-Type": ctype})

    # -- API ----------------------------------------------------------------------------------------

    def health(self) -> dict:
        try:
            return self._json("GET", "/api/health")
        except ServiceError as exc:
            if exc.status == 503:
                return {"status": "degraded", "message": exc.detail}
            raise

    def methods(self) -> list[dict]:
        return self._json("GET", "/api/methods")["data"]

    def submit(
        self,
        exemplar: FileLike | None = None,
        *,
        method: str = "wei-levoy",
        params: dict[str, Any] | None = None,
        seed: int | None = None,
        constraint: FileLike | None = None,
        exemplars: Mapping[str, FileLike] | None = None,
        size: Mapping[str, int] | None = None,
    ) -> dict:
        """Queue a job; returns its record (``id``, ``state``, ...).

        ``params`` holds the method's parameters, ``size`` the output's ``width``/``height`` (and
        ``depth`` for volumes; the service also reads them from ``params``, as its first clients sent
        them). A solid method takes ``exemplars={'xy': ..., 'xz': ..., 'yz': ...}`` instead of
        ``exemplar`` for an anisotropic material.
        """
        files = self._files(exemplar, constraint, exemplars)
        fields = {"method": method, "params": json.dumps(params or {}), "seed": seed, **(size or {})}
        return self._post_form("/api/jobs", fields, files)

    def job(self, job_id: str) -> dict:
        return self._json("GET", f"/api/jobs/{urllib.parse.quote(job_id)}")

    def jobs(self, state: str | None = None, limit: int = 50, offset: int = 0) -> dict:
        query = urllib.parse.urlencode(
            {k: v for k, v in {"state": state, "limit": limit, "offset": offset}.items() if v is not None}
        )
        return self._json("GET", f"/api/jobs?{query}")

    def cancel(self, job_id: str) -> dict:
        """Cancel a queued or running job (``DELETE``); returns its record."""
        return self._json("DELETE", f"/api/jobs/{urllib.parse.quote(job_id)}")

    def delete(self, job_id: str) -> dict:
        """Delete a finished job's files and record (a running one is cancelled first, then deleted)."""
        answer = self.cancel(job_id)
        if answer.get("state") != "deleted":
            self.wait(job_id, timeout=60)
            answer = self.cancel(job_id)
        return answer

    def wait(
        self,
        job_id: str,
        *,
        progress: Callable[[dict], None] | None = None,
        poll: float = 0.5,
        timeout: float | None = None,
    ) -> dict:
        """Poll until the job ends; ``progress(job)`` is called on every poll. Returns the final record."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            job = self.job(job_id)
            if progress is not None:
                progress(job)
            if job["state"] in TERMINAL:
                return job
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"job {job_id} still {job['state']} after {timeout} s")
            time.sleep(poll)

    def artifact(self, job: dict, name: str) -> bytes:
        return self._request("GET", job["artifacts"][name])

    def download(
        self, job: dict, out_dir: str | os.PathLike[str], names: Iterable[str] | None = None
    ) -> list[Path]:
        """Save the job's artifacts (all, or ``names``) under ``out_dir``; returns the paths written."""
        out = Path(out_dir)
        paths = []
        for name in names if names is not None else job["artifacts"]:
            path = out / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(self.artifact(job, name))
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
        size: Mapping[str, int] | None = None,
    ) -> dict:
        """Queue one job per point of ``grid``; ``get_sweep`` then gives all their metrics in one table."""
        files = self._files(exemplar, constraint, exemplars)
        fields = {
            "method": method,
            "grid": json.dumps(grid),
            "params": json.dumps(params or {}),
            "seed": seed,
            **(size or {}),
        }
        return self._post_form("/api/sweeps", fields, files)

    def get_sweep(self, sweep_id: str) -> dict:
        return self._json("GET", f"/api/sweeps/{urllib.parse.quote(sweep_id)}")


# -- texsynth submit -------------------------------------------------------------------------------


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "submit",
        help="submit a job to a texsynth service, wait, download the results",
        description="Submit a synthesis job to a running service (texsynth serve), show its "
        "progress and download its artifacts.",
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
    p.add_argument("--width", type=int)
    p.add_argument("--height", type=int)
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
    from synth.params import parse_assignments  # deferred: ``texsynth --help`` needs no pydantic

    client = Client(args.url, token=args.token)
    params = parse_assignments(args.sets)
    size = {"width": args.width, "height": args.height, "depth": args.depth}
    sources = input_sources(args)
    planes = {role[len("exemplar_") :]: p for role, p in sources.items() if role.startswith("exemplar_")}
    job = client.submit(
        sources.get("exemplar"),
        method=args.method,
        params=params,
        seed=args.seed,
        constraint=sources.get("constraint"),
        exemplars=planes or None,
        size={k: v for k, v in size.items() if v is not None},
    )
    print(f"job {job['id']} queued: {client.base_url}{job['page']}", file=sys.stderr)
    if args.no_wait:
        print(job["id"])
        return 0

    def show(j: dict) -> None:
        if sys.stderr.isatty():
            bar = "#" * int(30 * j["fraction"])
            print(
                f"\r[{bar:<30}] {100 * j['fraction']:5.1f}% {j['state']}: {j['stage'][:40]:<40}",
                end="",
                file=sys.stderr,
                flush=True,
            )

    try:
        job = client.wait(job["id"], progress=show)
    except KeyboardInterrupt:
        client.cancel(job["id"])
        print(f"\njob {job['id']} cancelled", file=sys.stderr)
        return 130
    if sys.stderr.isatty():
        print(file=sys.stderr)
    if job["state"] != "succeeded":
        print(f"job {job['id']} {job['state']}: {job['message']}", file=sys.stderr)
        return 1
    paths = client.download(job, Path(args.out) / job["id"])
    print(
        f"job {job['id']} succeeded in {job['elapsed'] or 0:.1f} s; {len(paths)} files in "
        f"{Path(args.out) / job['id']}",
        file=sys.stderr,
    )
    print(Path(args.out) / job["id"])
    return 0
