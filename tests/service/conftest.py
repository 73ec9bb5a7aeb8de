"""Shared, session-scoped services for the integration tests: real processes, real brokers.

``embedded`` runs ``texsynth serve`` (API + a real Celery worker process) on the embedded default;
``redis_service`` runs the same against a ``redis-server`` the fixture starts on a free loopback
port. Both register the small ``test-blur`` method through ``TEXSYNTH_EXTRA_METHODS``. Tests only
read the job store directly to find a worker's pid (to kill it).
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from PIL import Image

from tests.servers import free_port
from texsynth.app.client import Client
from texsynth.jobs.store import JobStore

REPO = Path(__file__).resolve().parents[2]
TEST_METHODS = "tests.service.methods_for_tests"
MAX_BODY = 2 * 2**20


def wait_until(predicate, timeout: float, interval: float = 0.1, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def _kill_group(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 10) -> None:
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        return
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=5)


class Service:
    """One ``texsynth serve`` process (its own process group) on ``data_dir``."""

    def __init__(
        self, data_dir: Path, env: dict[str, str] | None = None, *, worker: bool = True, concurrency: int = 2
    ) -> None:
        self.data_dir = data_dir
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.env = {
            **os.environ,
            "PYTHONPATH": str(REPO),
            "TEXSYNTH_EXTRA_METHODS": TEST_METHODS,
            "TEXSYNTH_CONCURRENCY": str(concurrency),
            "TEXSYNTH_MAX_BODY_BYTES": str(MAX_BODY),
            "TEXSYNTH_STALE_SECONDS": "5",
            "TEXSYNTH_CANCEL_GRACE_SECONDS": "1.5",
            **(env or {}),
        }
        self.worker = worker
        self.proc: subprocess.Popen | None = None
        self.log = data_dir.parent / f"serve-{self.port}.log"

    def start(self, timeout: float = 60) -> Service:
        args = [
            sys.executable,
            "-c",
            "import sys; from texsynth.synth.cli import main; sys.exit(main())",
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            str(self.port),
            "--data-dir",
            str(self.data_dir),
        ]
        if not self.worker:
            args.append("--no-worker")
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen(
                args, env=self.env, cwd=REPO, start_new_session=True, stdout=log, stderr=subprocess.STDOUT
            )

        def ready() -> bool:
            if self.proc.poll() is not None:
                raise AssertionError(
                    f"texsynth serve exited ({self.proc.returncode}):\n{self.log.read_text()[-3000:]}"
                )
            try:
                r = httpx.get(self.url + "/api/health", timeout=2)
            except httpx.HTTPError:
                return False
            return r.status_code == 200 or (not self.worker and r.json()["broker"])

        wait_until(ready, timeout, 0.2, f"texsynth serve at {self.url}")
        return self

    def stop(self, sig: int = signal.SIGTERM) -> None:
        if self.proc is not None:
            _kill_group(self.proc, sig)
        if not self.worker:
            return
        # the worker runs in its own process group: stop any left over (after SIGKILL of serve)
        for w in self.store().workers(fresh_within=3600):
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(os.getpgid(w["pid"]), signal.SIGKILL)

    def store(self) -> JobStore:
        """The service's job records (its database; its files stay where they are)."""
        database = self.env.get("TEXSYNTH_DATABASE_URL") or self.data_dir / "jobs.sqlite"
        return JobStore(database, self.data_dir / "jobs")

    def client(self) -> Client:
        return Client(self.url, timeout=30)

    def worker_pid(self) -> int:
        workers = self.store().workers(fresh_within=10)
        assert workers, "no live worker"
        return max(workers, key=lambda w: w["started"])["pid"]


@pytest.fixture(scope="session")
def embedded(tmp_path_factory) -> Iterator[Service]:
    service = Service(tmp_path_factory.mktemp("embedded") / "data").start()
    yield service
    service.stop()


def start_redis(port: int, folder) -> subprocess.Popen:
    """A real redis-server on ``port`` (no persistence, its own process group), answering PING."""
    binary = shutil.which("redis-server")
    if binary is None:
        pytest.skip("redis-server is not installed (`apt-get install redis-server`; .ci/run installs it)")
    options = ["--bind", "127.0.0.1", "--save", "", "--appendonly", "no", "--dir", str(folder)]
    proc = subprocess.Popen(
        [binary, "--port", str(port), *options],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )

    def up() -> bool:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5) as s:
                s.sendall(b"PING\r\n")
                return s.recv(16).startswith(b"+PONG")
        except OSError:
            return False

    wait_until(up, 10, 0.1, "redis-server")
    return proc


@pytest.fixture(scope="session")
def redis_url(tmp_path_factory) -> Iterator[str]:
    port = free_port()
    proc = start_redis(port, tmp_path_factory.mktemp("redis"))
    yield f"redis://127.0.0.1:{port}/0"
    _kill_group(proc)


@pytest.fixture(scope="session")
def redis_service(tmp_path_factory, redis_url) -> Iterator[Service]:
    service = Service(tmp_path_factory.mktemp("redis-data") / "data", {"REDIS_URL": redis_url}).start()
    yield service
    service.stop()


#: The token service's tokens (``texsynth serve`` with TEXSYNTH_API_TOKENS and an admin token).
TOKENS = {"alice": "alice-live-token-0123456789", "bob": "bob-live-token-0123456789ab"}
ADMIN_TOKEN = "admin-live-token-0123456789"


@pytest.fixture(scope="session")
def token_service(tmp_path_factory) -> Iterator[Service]:
    """``texsynth serve`` on the embedded queue with tokens for alice and bob and an admin token."""
    env = {
        "TEXSYNTH_API_TOKENS": ",".join(f"{name}:{token}" for name, token in TOKENS.items()),
        "TEXSYNTH_ADMIN_TOKEN": ADMIN_TOKEN,
    }
    service = Service(tmp_path_factory.mktemp("tokens") / "data", env, concurrency=1).start()
    yield service
    service.stop()


@pytest.fixture(params=["embedded", "redis"])
def service(request) -> Service:
    """Each test using this runs on both brokers."""
    return request.getfixturevalue("embedded" if request.param == "embedded" else "redis_service")


def png(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(array).save(buf, format="PNG")
    return buf.getvalue()


@pytest.fixture(scope="session")
def exemplar_png() -> bytes:
    """A 64x64 grey fringe pattern with noise (a small HRTEM-like exemplar)."""
    y, x = np.mgrid[0:64, 0:64]
    rng = np.random.default_rng(0)
    image = 0.5 + 0.4 * np.sin(2 * np.pi * (0.8 * x + 0.6 * y) / 8) + 0.08 * rng.standard_normal((64, 64))
    return png((np.clip(image, 0, 1) * 255).astype(np.uint8))
