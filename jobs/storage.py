"""Where a job's files live: the data directory (default) or an S3-compatible object store.

:class:`Storage` is what the API, the workers and the reaper do with a job's files; the two
implementations keep the same promises. The API stores the inputs and the manifest before the job's
record exists. A run writes its artifacts into a staging folder of its own, :meth:`Storage.publish`
makes them durable, and :meth:`Storage.commit` (called under the database lock that marks the job
succeeded) makes them the job's: so only a complete set, of exactly one run, is ever served.

- :class:`LocalStorage` (``TEXSYNTH_STORAGE_URL`` unset): the job folders of the data directory, as
  texsynth always kept them (``jobs/<id>/inputs``, ``manifest.json``, ``.run-<token>/`` swapped into
  ``out/``; a sweep's runs hard-link one upload). Every process must see the same folder.
- :class:`S3Storage` (``s3://bucket/prefix``): objects under ``<prefix>jobs/<id>/``; a run stages in
  the worker's own scratch folder (``<data dir>/scratch``), uploads to ``runs/<token>/`` (publish),
  and the commit records that token (``jobs.artifacts_run``). A crash between upload and commit
  leaves the job running; the reaper re-runs it, and the lost run's objects go with the job.
  Endpoint and credentials come from ``AWS_ENDPOINT_URL``, ``AWS_ACCESS_KEY_ID``,
  ``AWS_SECRET_ACCESS_KEY``, ``AWS_DEFAULT_REGION`` (boto3, ``texsynth[cluster]``); a store that does
  not answer is tried again for up to ``retry_seconds``.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from texsynth.synth.io.atomic import atomic_write_bytes, atomic_write_json

__all__ = ["LocalStorage", "S3Storage", "Storage", "StorageUnavailable", "open_storage"]

_T = TypeVar("_T")
CHUNK = 1 << 20


class StorageUnavailable(RuntimeError):
    """The object store did not answer (HTTP 503 in the API; a worker keeps trying, then fails)."""


class Storage(ABC):
    """A job's files; ``rel`` names are ``inputs/<name>``, ``manifest.json``, ``preview.png`` and
    ``out/<artifact>`` (``run``: the token of the committed run, for object stores)."""

    url: str
    local: bool

    @abstractmethod
    def save_inputs(
        self, job_id: str, files: dict[str, bytes], manifest: dict[str, Any], share_from: str | None
    ) -> None:
        """Store a new job's input files (name -> bytes) and manifest, before its record exists."""

    @abstractmethod
    def fetch_inputs(self, job_id: str, names: list[str], token: str) -> tuple[dict[str, bytes], dict]:
        """A run's inputs (name -> bytes) and the manifest (object stores: through the run's scratch)."""

    @abstractmethod
    def staging(self, job_id: str, token: str) -> Path:
        """The folder run ``token`` writes its artifacts into (not yet created)."""

    @abstractmethod
    def publish(self, job_id: str, token: str, staging: Path) -> None:
        """Make the staged artifacts durable (upload them), before the commit."""

    @abstractmethod
    def commit(self, job_id: str, token: str, staging: Path) -> Callable[[], None]:
        """Under the database's lock: make run ``token``'s artifacts the job's; returns the clean-up
        to call after the lock (old artifacts)."""

    @abstractmethod
    def forget_run(self, job_id: str, token: str) -> None:
        """A run ended (committed or not): its scratch and its uncommitted objects go."""

    def discard_run(self, job_id: str, token: str) -> None:  # noqa: B027 (a folder has nothing to do)
        """Run ``token`` lost the job before its commit: what it published goes (none in a folder)."""

    @abstractmethod
    def put_preview(self, job_id: str, data: bytes) -> None: ...

    @abstractmethod
    def local_path(self, job_id: str, rel: str, run: str | None) -> Path | None:
        """The file on this machine's disk, or ``None`` for an object store."""

    @abstractmethod
    def open(self, job_id: str, rel: str, run: str | None) -> tuple[Iterator[bytes], int]:
        """The bytes in chunks and their number; :class:`FileNotFoundError` if there is no such file."""

    def read(self, job_id: str, rel: str, run: str | None) -> bytes:
        chunks, _ = self.open(job_id, rel, run)
        return b"".join(chunks)

    @abstractmethod
    def delete(self, job_id: str) -> None:
        """Every file of the job (inputs, artifacts of every run, preview)."""

    @abstractmethod
    def orphans(self, known: set[str], older_than: float) -> list[str]:
        """Ids with files but no record (``known``), untouched since ``older_than``."""

    def ok(self) -> bool:
        return True


class LocalStorage(Storage):
    """The job folders under ``jobs_dir`` (see the module docstring and :mod:`texsynth.jobs.store`)."""

    local = True

    def __init__(self, jobs_dir: Path) -> None:
        self.jobs_dir = Path(jobs_dir)
        self.url = str(self.jobs_dir)
        self.jobs_dir.mkdir(parents=True, exist_ok=True)

    def job_dir(self, job_id: str) -> Path:
        return self.jobs_dir / job_id

    def save_inputs(self, job_id, files, manifest, share_from):
        folder = self.job_dir(job_id)
        (folder / "inputs").mkdir(parents=True)
        for name, data in files.items():
            target = folder / "inputs" / name
            shared = share_from and self.job_dir(share_from) / "inputs" / name
            if not shared or not _link(shared, target):
                atomic_write_bytes(target, data)
        atomic_write_json(folder / "manifest.json", manifest)

    def fetch_inputs(self, job_id, names, token):
        folder = self.job_dir(job_id)
        manifest = json.loads((folder / "manifest.json").read_text())
        return {name: (folder / "inputs" / name).read_bytes() for name in names}, manifest

    def staging(self, job_id, token):
        return self.job_dir(job_id) / f".run-{token}"

    def publish(self, job_id, token, staging):
        pass  # the staging folder is already on the shared disk

    def commit(self, job_id, token, staging):
        out = self.job_dir(job_id) / "out"
        old = None
        if out.exists():
            old = out.with_name(f".old-{token}")
            os.replace(out, old)
        os.replace(staging, out)
        return lambda: old is not None and shutil.rmtree(old, ignore_errors=True)

    def forget_run(self, job_id, token):
        shutil.rmtree(self.staging(job_id, token), ignore_errors=True)

    def put_preview(self, job_id, data):
        atomic_write_bytes(self.job_dir(job_id) / "preview.png", data)

    def local_path(self, job_id, rel, run):
        return self.job_dir(job_id) / rel

    def open(self, job_id, rel, run):
        path = self.job_dir(job_id) / rel
        size = path.stat().st_size

        def chunks() -> Iterator[bytes]:
            with open(path, "rb") as fh:
                while block := fh.read(CHUNK):
                    yield block

        return chunks(), size

    def delete(self, job_id):
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)

    def orphans(self, known, older_than):
        found = []
        for folder in self.jobs_dir.iterdir():
            if folder.name in known or not folder.is_dir():
                continue
            with contextlib.suppress(OSError):
                if folder.stat().st_mtime < older_than:
                    found.append(folder.name)
        return found


class S3Storage(Storage):
    """Objects under ``s3://bucket/prefix``; each worker stages in its own ``scratch`` folder."""

    local = False

    def __init__(self, url: str, scratch: Path, retry_seconds: float = 300.0, client: Any = None) -> None:
        bucket, _, prefix = url.removeprefix("s3://").partition("/")
        if not url.startswith("s3://") or not bucket:
            raise ValueError(f"TEXSYNTH_STORAGE_URL: expected s3://bucket/prefix, got {url!r}")
        self.url, self.bucket = url, bucket
        self.prefix = prefix.strip("/") + "/" if prefix.strip("/") else ""
        self.scratch = Path(scratch)
        self.retry_seconds = retry_seconds
        if client is None:
            try:
                import boto3
                from botocore.config import Config
            except ImportError:
                raise ValueError(
                    "TEXSYNTH_STORAGE_URL names an S3 bucket, but boto3 is not installed: "
                    "pip install 'texsynth[cluster]'"
                ) from None
            config = Config(
                s3={"addressing_style": "path"},  # MinIO, SeaweedFS, Ceph: no bucket DNS names
                retries={"max_attempts": 3, "mode": "standard"},
                connect_timeout=5,
                read_timeout=60,
            )
            endpoint = os.environ.get("AWS_ENDPOINT_URL") or None
            client = boto3.client("s3", endpoint_url=endpoint, config=config)
        self.client = client

    # -- plumbing ---------------------------------------------------------------------------------

    def key(self, job_id: str, rel: str = "", run: str | None = None) -> str:
        if rel.startswith("out/"):
            if not run:
                raise FileNotFoundError(rel)
            rel = f"runs/{run}/{rel[4:]}"
        return f"{self.prefix}jobs/{job_id}/{rel}"

    def _transient(self) -> tuple[type[BaseException], ...]:
        from boto3.exceptions import S3TransferFailedError, S3UploadFailedError
        from botocore.exceptions import BotoCoreError

        # the transfer manager wraps what went wrong (a 500 of a store still starting, a cut
        # connection) in its own errors: tried again like the others
        return (BotoCoreError, ConnectionError, S3UploadFailedError, S3TransferFailedError)

    def _retry(self, operation: Callable[[], _T], seconds: float | None = None) -> _T:
        """``operation()``, tried again while the store does not answer (or answers 5xx)."""
        from botocore.exceptions import ClientError

        deadline = time.monotonic() + (self.retry_seconds if seconds is None else seconds)
        pause = 0.2
        while True:
            try:
                return operation()
            except ClientError as exc:
                status = exc.response.get("ResponseMetadata", {}).get("HTTPStatusCode", 0)
                if status < 500:
                    raise
                if time.monotonic() + pause > deadline:
                    raise _unavailable(exc) from exc
            except self._transient() as exc:
                if time.monotonic() + pause > deadline:
                    raise _unavailable(exc) from exc
            time.sleep(pause)
            pause = min(5.0, pause * 2)

    def _put(self, key: str, data: bytes, seconds: float | None = None) -> None:
        self._retry(lambda: self.client.put_object(Bucket=self.bucket, Key=key, Body=data), seconds)

    def _keys(self, prefix: str) -> Iterator[dict[str, Any]]:
        token: str | None = None
        while True:
            args = {"Bucket": self.bucket, "Prefix": prefix}
            if token:
                args["ContinuationToken"] = token
            page = self._retry(lambda args=args: self.client.list_objects_v2(**args), 30.0)
            yield from page.get("Contents", [])
            if not page.get("IsTruncated"):
                return
            token = page["NextContinuationToken"]

    def _delete_prefix(self, prefix: str) -> None:
        batch: list[dict[str, str]] = []
        for item in self._keys(prefix):
            batch.append({"Key": item["Key"]})
            if len(batch) == 1000:
                self._delete(batch)
                batch = []
        if batch:
            self._delete(batch)

    def _delete(self, batch: list[dict[str, str]]) -> None:
        self._retry(lambda: self.client.delete_objects(Bucket=self.bucket, Delete={"Objects": batch}), 30.0)

    # -- the interface ----------------------------------------------------------------------------

    def save_inputs(self, job_id, files, manifest, share_from):
        # the API answers a client that retries: a short wait, then 503 (nothing recorded yet)
        for name, data in files.items():
            self._put(self.key(job_id, f"inputs/{name}"), data, seconds=10.0)
        self._put(self.key(job_id, "manifest.json"), json.dumps(manifest, indent=2).encode(), seconds=10.0)

    def run_scratch(self, job_id: str, token: str) -> Path:
        return self.scratch / f"{job_id}-{token}"

    def fetch_inputs(self, job_id, names, token):
        folder = self.run_scratch(job_id, token) / "inputs"
        folder.mkdir(parents=True, exist_ok=True)
        found = {}
        for rel in [*(f"inputs/{name}" for name in names), "manifest.json"]:
            target = folder / rel.rsplit("/", 1)[-1]
            # a worker waits for the store up to retry_seconds (the API's reads only briefly)
            self._retry(
                lambda r=rel, t=target: self.client.download_file(self.bucket, self.key(job_id, r), str(t))
            )
            found[rel] = target.read_bytes()
        manifest = json.loads(found.pop("manifest.json"))
        return {name: found[f"inputs/{name}"] for name in names}, manifest

    def staging(self, job_id, token):
        return self.run_scratch(job_id, token) / "out"

    def publish(self, job_id, token, staging):
        for path in sorted(staging.rglob("*")):
            if path.is_file():
                key = self.key(job_id, f"out/{path.relative_to(staging).as_posix()}", token)
                self._retry(lambda p=path, k=key: self.client.upload_file(str(p), self.bucket, k))

    def commit(self, job_id, token, staging):
        def clean() -> None:  # artifacts of runs that lost the job (a crash after their upload)
            runs = self.key(job_id, "runs/")
            with contextlib.suppress(Exception):
                stale = [i for i in self._keys(runs) if not i["Key"].startswith(f"{runs}{token}/")]
                for start in range(0, len(stale), 1000):
                    self._delete([{"Key": i["Key"]} for i in stale[start : start + 1000]])

        return clean

    def forget_run(self, job_id, token):
        shutil.rmtree(self.run_scratch(job_id, token), ignore_errors=True)

    def discard_run(self, job_id: str, token: str) -> None:
        """Objects of run ``token`` that did not become the job's (it lost the job before its commit)."""
        with contextlib.suppress(Exception):
            self._delete_prefix(self.key(job_id, f"runs/{token}/"))

    def put_preview(self, job_id, data):
        self._put(self.key(job_id, "preview.png"), data, seconds=2.0)

    def local_path(self, job_id, rel, run):
        return None

    def open(self, job_id, rel, run):
        from botocore.exceptions import ClientError

        key = self.key(job_id, rel, run)
        try:
            answer = self._retry(lambda: self.client.get_object(Bucket=self.bucket, Key=key), 10.0)
        except ClientError as exc:
            if exc.response.get("Error", {}).get("Code") in ("NoSuchKey", "404", "NotFound"):
                raise FileNotFoundError(rel) from None
            raise
        body = answer["Body"]

        def chunks() -> Iterator[bytes]:
            try:
                yield from body.iter_chunks(CHUNK)
            finally:
                body.close()

        return chunks(), int(answer["ContentLength"])

    def delete(self, job_id):
        self._delete_prefix(self.key(job_id))

    def orphans(self, known, older_than):
        root = f"{self.prefix}jobs/"
        found, token = [], None
        while True:  # one listing of the job prefixes; the objects of unknown ones only
            args = {"Bucket": self.bucket, "Prefix": root, "Delimiter": "/"}
            if token:
                args["ContinuationToken"] = token
            page = self._retry(lambda args=args: self.client.list_objects_v2(**args), 30.0)
            for entry in page.get("CommonPrefixes", []):
                job_id = entry["Prefix"][len(root) :].rstrip("/")
                if job_id in known:
                    continue
                stamps = [item["LastModified"].timestamp() for item in self._keys(entry["Prefix"])]
                if stamps and max(stamps) < older_than:  # (some stores list emptied prefixes)
                    found.append(job_id)
            if not page.get("IsTruncated"):
                return found
            token = page["NextContinuationToken"]

    def ok(self) -> bool:
        try:
            self._retry(lambda: self.client.head_bucket(Bucket=self.bucket), 0.0)
        except Exception:
            return False
        return True


def _unavailable(exc: BaseException) -> StorageUnavailable:
    return StorageUnavailable(f"the object store did not answer: {type(exc).__name__}: {exc}")


def _link(source: Path, target: Path) -> bool:
    """Hard-link ``source`` as ``target``; ``False`` (the caller writes a copy) if it cannot."""
    try:
        os.link(source, target)
    except OSError:
        return False
    return True


def open_storage(url: str | None, jobs_dir: Path, scratch: Path) -> Storage:
    """The storage of ``TEXSYNTH_STORAGE_URL``: ``None`` or a path, the data directory's job folders."""
    if not url:
        return LocalStorage(jobs_dir)
    if url.startswith("s3://"):
        return S3Storage(url, scratch)
    if "://" in url and not url.startswith("file://"):
        raise ValueError(f"TEXSYNTH_STORAGE_URL: expected s3://bucket/prefix or a folder, got {url!r}")
    return LocalStorage(Path(url.removeprefix("file://")).expanduser())
