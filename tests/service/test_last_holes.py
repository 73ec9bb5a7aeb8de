"""The last holes of issue 26, in process: the Host check (DNS rebinding), parameters that broke the
parser or the validators (500s), a full data disk (507, health degraded, reads still answered) and the
storage quota per token.

The app runs in FastAPI's test client on a temporary data directory with its sends to the broker
replaced, as in ``test_tokens.py``. The full disk is a real 8 MiB tmpfs where the machine lets the
test mount one (root), and ENOSPC injected into the writes everywhere.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import sqlite3
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from texsynth.app.auth import TokenError, Tokens
from texsynth.app.main import create_app
from texsynth.jobs.config import Settings

ALICE, BOB = "alice-token-0123456789", "bob-token-0123456789ab"


def _png(side: int = 32, seed: int = 0) -> bytes:
    buf = io.BytesIO()
    rng = np.random.default_rng(seed)
    Image.fromarray((rng.random((side, side)) * 255).astype(np.uint8)).save(buf, "PNG")
    return buf.getvalue()


def _client(settings: Settings, base_url: str = "http://localhost"):
    with warnings.catch_warnings():  # starlette's test client warns about its httpx at import
        warnings.simplefilter("ignore")
        from fastapi.testclient import TestClient
    app = create_app(settings, reaper=False)
    service = app.state.service
    service.send = lambda job_id: None  # no broker traffic: these tests are about the API's answers
    service.send_group = lambda job_ids: None
    service.broker_ok = lambda: True
    return TestClient(app, base_url=base_url, raise_server_exceptions=False), service


@pytest.fixture
def api(tmp_path):
    client, service = _client(Settings(data_dir=tmp_path / "data"))
    with client:
        yield client, service


def submit(client, headers=None, method="wei-levoy", params=None, files=None, **fields):
    data = {"method": method, "params": json.dumps(params or {}), "width": "32", "height": "32", **fields}
    return client.post(
        "/api/jobs", headers=headers or {}, data=data, files=files or {"exemplar": ("e.png", _png())}
    )


def finish(service, job_id: str, size: int = 1000) -> None:
    """Run the job as a worker would, without synthesis: claim, write an output, commit."""
    token, _ = service.store.claim(job_id, os.getpid(), 10.0)
    staging = service.store.job_dir(job_id) / f".run-{token}"
    staging.mkdir()
    (staging / "output.png").write_bytes(b"\0" * size)
    assert service.store.commit_success(job_id, token, staging, ["output.png"], {}, {})


# -- the Host header (DNS rebinding) -------------------------------------------------------------------


@pytest.mark.parametrize("host", ["attacker.example", "attacker.example:8000", "localhost.attacker.example"])
def test_a_foreign_host_name_is_refused_on_every_route(api, host):
    client, service = api
    for method, path in [("GET", "/api/jobs"), ("POST", "/api/jobs"), ("GET", "/"), ("GET", "/api/health")]:
        r = client.request(method, path, headers={"Host": host})
        assert r.status_code == 400, (method, path, r.status_code)
        assert r.json()["error"] == "bad_host"
        assert "TEXSYNTH_ALLOWED_HOSTS" in r.json()["detail"] and host.split(":")[0] in r.json()["detail"]
    assert service.store.count() == 0


@pytest.mark.parametrize(
    "host", ["localhost", "localhost:8000", "127.0.0.1:8000", "[::1]:8000", "app.localhost:8000", "10.1.2.3"]
)
def test_local_names_and_addresses_pass(api, host):
    client, _ = api
    assert client.get("/api/jobs", headers={"Host": host}).status_code == 200


def test_allowed_hosts_come_from_the_environment_and_the_allowed_origins(tmp_path):
    env = {
        "TEXSYNTH_DATA_DIR": str(tmp_path / "data"),
        "TEXSYNTH_ALLOWED_HOSTS": "texsynth.lab.example, .cluster.example",
        "TEXSYNTH_ALLOWED_ORIGINS": "https://proxy.lab.example",
    }
    client, _ = _client(Settings.from_env(env))
    with client:
        for host in ("texsynth.lab.example:8000", "node1.cluster.example", "proxy.lab.example"):
            assert client.get("/api/jobs", headers={"Host": host}).status_code == 200, host
        assert client.get("/api/jobs", headers={"Host": "cluster.example.evil"}).status_code == 400


def test_the_bound_name_is_allowed(tmp_path):
    from texsynth.app.cli import with_bound_host

    settings = with_bound_host(Settings(data_dir=tmp_path / "data"), "texsynth-box")
    assert with_bound_host(settings, "0.0.0.0") == settings  # every interface: no name to add
    client, _ = _client(settings)
    with client:
        assert client.get("/api/jobs", headers={"Host": "texsynth-box:8000"}).status_code == 200
        assert client.get("/api/jobs", headers={"Host": "other-box:8000"}).status_code == 400


def test_star_allows_every_host(tmp_path):
    client, _ = _client(Settings(data_dir=tmp_path / "data", allowed_hosts=("*",)))
    with client:
        assert client.get("/api/jobs", headers={"Host": "anything.example"}).status_code == 200


# -- parameters that broke the parser or a validator ------------------------------------------------------


@pytest.mark.parametrize(
    "raw",
    ["[" * 1000 + "]" * 1000, '{"a":' * 1000 + "1" + "}" * 1000, '{"levels": ' + "[" * 100 + "]" * 100 + "}"],
    ids=["list-1000", "object-1000", "value-100"],
)
def test_deeply_nested_params_are_a_422_naming_params(api, raw):
    client, service = api
    r = client.post(
        "/api/jobs",
        data={"method": "wei-levoy", "params": raw, "width": "32", "height": "32"},
        files={"exemplar": ("e.png", _png())},
    )
    assert r.status_code == 422, r.text
    assert r.json()["field"] == "params" and "nested" in r.json()["message"]
    assert service.store.count() == 0


def test_a_deeply_nested_sweep_grid_is_a_422(api):
    client, _ = api
    r = client.post(
        "/api/sweeps",
        data={"method": "wei-levoy", "params": "{}", "grid": '{"levels": ' + "[" * 1000 + "]" * 1000 + "}"},
        files={"exemplar": ("e.png", _png())},
    )
    assert r.status_code == 422 and r.json()["field"] == "grid"


@pytest.mark.parametrize("step", [1e-308, 5e-324, 1e-300])
def test_a_tiny_angular_step_is_a_422_naming_it(api, step):
    client, service = api
    files = {"exemplar": ("e.png", _png()), "constraint": ("c.png", _png(seed=1))}
    r = submit(client, method="arbitrary-shape", params={"angular_step": step}, files=files)
    assert r.status_code == 422, r.text
    assert r.json()["field"] == "angular_step"
    assert service.store.count() == 0


# -- a full data disk --------------------------------------------------------------------------------------


def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.fixture
def full_disk(monkeypatch):
    """Every file write and every SQLite write fails as on a full disk; reads still work."""

    def full(*_, **__):
        real_open = os.open

        def no_room(path, flags, *args, **kwargs):  # a file can be read, not made
            if flags & os.O_CREAT:
                _enospc()
            return real_open(path, flags, *args, **kwargs)

        monkeypatch.setattr(os, "open", no_room)
        monkeypatch.setattr("texsynth.jobs.store.Path.mkdir", _enospc)
        real_connect = sqlite3.connect

        def connect(*args, **kwargs):
            db = real_connect(*args, **kwargs)
            db.set_authorizer(
                lambda action, *rest: (
                    sqlite3.SQLITE_DENY
                    if action in (sqlite3.SQLITE_INSERT, sqlite3.SQLITE_UPDATE, sqlite3.SQLITE_DELETE)
                    else sqlite3.SQLITE_OK
                )
            )
            return _DiskFull(db)

        monkeypatch.setattr("texsynth.jobs.store.sqlite3.connect", connect)

    return full


class _DiskFull:
    """An SQLite connection whose writes fail with SQLite's own full-disk error."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self._db = db

    def execute(self, sql: str, *args):
        try:
            return self._db.execute(sql, *args)
        except sqlite3.DatabaseError as exc:
            if "not authorized" in str(exc):
                raise sqlite3.OperationalError("database or disk is full") from None
            raise

    def __getattr__(self, name):
        return getattr(self._db, name)

    def __setattr__(self, name, value):
        if name == "_db":
            object.__setattr__(self, name, value)
        else:
            setattr(self._db, name, value)


def test_a_full_disk_gives_507_and_health_degraded_and_reads_still_work(api, full_disk):
    client, service = api
    job = submit(client).json()
    finish(service, job["id"])
    service.store.worker_heartbeat("w@test", os.getpid(), 0.0)
    full_disk()
    r = submit(client)
    assert r.status_code == 507, r.text
    assert r.json()["error"] == "insufficient_storage" and "nothing was queued" in r.json()["detail"]
    health = client.get("/api/health")
    assert health.status_code == 200 and health.json()["status"] == "degraded"
    assert client.get("/api/jobs").json()["count"] == 1
    assert client.get(f"/api/jobs/{job['id']}").json()["state"] == "succeeded"
    assert client.get(f"/api/jobs/{job['id']}/artifacts/output.png").status_code == 200
    r = client.delete(f"/api/jobs/{job['id']}")  # a delete that cannot write is a 507 too, not a 500
    assert r.status_code == 507
    assert [p.name for p in service.store.jobs_dir.iterdir()] == [job["id"]]  # nothing half-made left


@pytest.fixture
def tiny_disk(tmp_path):
    """A real 8 MiB tmpfs (root only; skipped elsewhere, the ENOSPC test above runs everywhere)."""
    mount = tmp_path / "tiny"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(mount)], capture_output=True, check=False
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.decode().strip() or 'not root'})")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


def test_a_really_full_tmpfs_gives_507_and_health_degraded(tiny_disk):
    client, service = _client(Settings(data_dir=tiny_disk / "data"))
    with client:
        job = submit(client).json()
        finish(service, job["id"])
        service.store.worker_heartbeat("w@test", os.getpid(), 0.0)
        with contextlib.suppress(OSError), open(tiny_disk / "filler", "wb") as fh:
            while True:  # fill the disk to the last block
                fh.write(b"\0" * 4096)
                fh.flush()
        answers = [submit(client).status_code for _ in range(3)]
        assert set(answers) == {507}, answers
        health = client.get("/api/health")
        assert health.status_code == 200 and health.json()["status"] == "degraded"
        assert "full" in health.json()["message"]
        assert client.get(f"/api/jobs/{job['id']}").json()["state"] == "succeeded"
        assert client.get(f"/api/jobs/{job['id']}/artifacts/output.png").status_code == 200
        assert [p.name for p in service.store.jobs_dir.iterdir()] == [job["id"]]
        (tiny_disk / "filler").unlink()
        assert submit(client).status_code == 202  # room again: the service goes on


# -- storage quota per token ---------------------------------------------------------------------------


def test_a_token_over_its_storage_quota_is_refused_before_anything_is_stored(tmp_path):
    quota = 2 * len(_png()) + 2000 + 10  # room for two uploads and one output
    settings = Settings(
        data_dir=tmp_path / "data", api_tokens=f"alice:{ALICE},bob:{BOB}", token_quota_bytes=quota
    )
    client, service = _client(settings)
    alice, bob = {"Authorization": f"Bearer {ALICE}"}, {"Authorization": f"Bearer {BOB}"}
    with client:
        first = submit(client, alice).json()
        finish(service, first["id"], size=2000)  # inputs + artifacts count
        assert submit(client, alice).status_code == 202
        r = submit(client, alice)
        assert r.status_code == 507, r.text
        body = r.json()
        assert body["error"] == "quota_exceeded" and "TEXSYNTH_TOKEN_QUOTA_BYTES" in body["detail"]
        assert "alice" in body["detail"] and "delete" in body["detail"]
        assert service.store.count() == 2
        assert submit(client, bob).status_code == 202  # bob's storage is his own
        assert client.delete(f"/api/jobs/{first['id']}", headers=alice).status_code == 200
        assert submit(client, alice).status_code == 202  # deleting frees the room


def test_one_upload_larger_than_the_quota_is_a_413(tmp_path):
    settings = Settings(data_dir=tmp_path / "data", api_tokens=f"alice:{ALICE}", token_quota_bytes=100)
    client, service = _client(settings)
    with client:
        r = submit(client, {"Authorization": f"Bearer {ALICE}"})
        assert r.status_code == 413 and r.json()["error"] == "quota_exceeded"
        assert service.store.count() == 0


def test_a_quota_in_the_token_file_overrides_the_default(tmp_path):
    token_file = tmp_path / "tokens"
    token_file.write_text(f"alice:{ALICE}:quota=1MiB\nbob:{BOB}\n")
    settings = Settings(data_dir=tmp_path, api_token_file=token_file, token_quota_bytes=5)
    tokens = Tokens.from_settings(settings)
    assert tokens.lookup(ALICE).quota == 2**20 and tokens.lookup(BOB).quota is None
    for bad in ("quota=lots", "quota=-5", "admin:quota=1:extra"):
        token_file.write_text(f"alice:{ALICE}:{bad}\n")
        with pytest.raises(TokenError, match="quota"):
            Tokens.from_settings(settings)


def test_a_sweep_counts_its_shared_upload_once(tmp_path):
    settings = Settings(data_dir=tmp_path / "data", token_quota_bytes=10**9)
    client, service = _client(settings)
    with client:
        r = client.post(
            "/api/sweeps",
            data={
                "method": "wei-levoy",
                "params": '{"width": 32, "height": 32}',
                "grid": '{"levels": [1, 2]}',
            },
            files={"exemplar": ("e.png", _png())},
        )
        assert r.status_code == 202, r.text
        assert service.store.usage(None) == len(_png())


def test_records_made_before_the_quota_are_counted_from_their_folders(tmp_path):
    client, service = _client(Settings(data_dir=tmp_path / "data"))
    with client:
        job = submit(client).json()
    with sqlite3.connect(Path(tmp_path / "data" / "jobs.sqlite")) as db:
        db.execute("UPDATE jobs SET input_bytes = NULL, artifact_bytes = NULL")
    client, service = _client(Settings(data_dir=tmp_path / "data"))
    with client:
        assert service.store.usage(None) == len(_png())
        assert service.store.get(job["id"]) is not None
