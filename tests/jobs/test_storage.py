"""The job files in an S3 store (a real SeaweedFS server): a run's artifacts are served only once
its commit names them, a lost run's uploads never are, retention deletes the objects."""

from __future__ import annotations

import time

import pytest

from texsynth.jobs.config import Settings
from texsynth.jobs.reaper import purge_expired
from texsynth.jobs.storage import LocalStorage, S3Storage, StorageUnavailable, open_storage
from texsynth.jobs.store import JobStore

DEAD_PID = 2**22 + 12345


@pytest.fixture
def s3_store(s3_url, tmp_path) -> JobStore:
    storage = S3Storage(s3_url, tmp_path / "scratch", retry_seconds=5)
    return JobStore(tmp_path / "jobs.sqlite", tmp_path / "jobs", storage)


def _job(store: JobStore, **kwargs) -> str:
    return store.create_job(
        method="m", params={}, seed=1, inputs={"exemplar": ("e.png", b"\x89PNG-input")}, manifest={}, **kwargs
    ).id


def _run(store: JobStore, job_id: str, pid: int = 1) -> tuple[str, object]:
    token, _ = store.claim(job_id, pid=pid, stale_seconds=10)
    files, manifest = store.storage.fetch_inputs(job_id, ["exemplar.png"], token)
    assert files == {"exemplar.png": b"\x89PNG-input"} and manifest["job_id"] == job_id
    staging = store.storage.staging(job_id, token)
    (staging / "sub").mkdir(parents=True)
    (staging / "output.png").write_bytes(token.encode())
    (staging / "sub" / "metrics.json").write_bytes(b"{}")
    return token, staging


def test_a_job_round_trips_through_the_store(s3_store, seaweed, tmp_path):
    job_id = _job(s3_store)
    token, staging = _run(s3_store, job_id)
    s3_store.storage.publish(job_id, token, staging)
    assert s3_store.commit_success(job_id, token, staging, ["output.png", "sub/metrics.json"], {}, {})
    s3_store.storage.forget_run(job_id, token)
    job = s3_store.get(job_id)
    assert job.artifacts_run == token
    assert s3_store.storage.read(job_id, "out/output.png", job.artifacts_run) == token.encode()
    assert s3_store.storage.read(job_id, "inputs/exemplar.png", None) == b"\x89PNG-input"
    assert not (tmp_path / "jobs" / job_id).exists() and not any((tmp_path / "scratch").iterdir())
    assert s3_store.delete(job_id)
    assert not seaweed.keys(s3_store.storage.key(job_id))


def test_a_lost_runs_uploads_are_never_served_and_go_at_the_commit(s3_store, seaweed):
    job_id = _job(s3_store)
    old, old_staging = _run(s3_store, job_id, pid=DEAD_PID)
    s3_store.storage.publish(job_id, old, old_staging)  # then the worker dies before its commit
    assert s3_store.get(job_id).artifacts_run is None  # nothing of it is the job's
    new, staging = _run(s3_store, job_id)
    assert not s3_store.commit_success(job_id, old, old_staging, ["output.png"], {}, {})
    s3_store.storage.publish(job_id, new, staging)
    assert s3_store.commit_success(job_id, new, staging, ["output.png"], {}, {})
    assert s3_store.storage.read(job_id, "out/output.png", new) == new.encode()
    keys = seaweed.keys(s3_store.storage.key(job_id, "runs/"))
    runs = {key.split("/runs/")[1].split("/")[0] for key in keys}
    assert runs == {new}


def test_a_sweep_shares_nothing_by_links_but_deleting_one_job_keeps_the_others(s3_store):
    first = _job(s3_store)
    second = _job(s3_store, share_inputs_of=first)
    s3_store.finish(first, None, "failed", "x")
    assert s3_store.delete(first)
    assert s3_store.storage.read(second, "inputs/exemplar.png", None) == b"\x89PNG-input"


def test_retention_and_orphans_delete_objects(s3_store, seaweed, tmp_path):
    old, orphan = _job(s3_store), _job(s3_store)
    s3_store.finish(old, None, "failed", "x")
    with s3_store._connect() as db:
        db.execute("UPDATE jobs SET finished = ? WHERE id = ?", (time.time() - 40 * 86400, old))
        db.execute("DELETE FROM jobs WHERE id = ?", (orphan,))  # a run outlived its job's deletion
    removed = purge_expired(s3_store, Settings(data_dir=tmp_path), now=time.time() + 2 * 3600)
    assert sorted(removed) == sorted([old, orphan])
    assert not seaweed.keys(s3_store.storage.key(old)) and not seaweed.keys(s3_store.storage.key(orphan))


def test_a_missing_object_is_file_not_found(s3_store):
    job_id = _job(s3_store)
    with pytest.raises(FileNotFoundError):
        s3_store.storage.read(job_id, "preview.png", None)
    with pytest.raises(FileNotFoundError):
        s3_store.storage.read(job_id, "out/output.png", None)  # no committed run


def test_an_unreachable_store_is_unavailable_not_a_crash(tmp_path, monkeypatch):
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "x")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", "y")
    monkeypatch.setenv("AWS_DEFAULT_REGION", "us-east-1")
    monkeypatch.setenv("AWS_ENDPOINT_URL", "http://127.0.0.1:9")  # nothing listens on the discard port
    storage = S3Storage("s3://bucket/p", tmp_path, retry_seconds=0.5)
    with pytest.raises(StorageUnavailable):
        storage.save_inputs("j", {"exemplar.png": b"x"}, {}, None)
    assert not storage.ok()


def test_the_storage_url_chooses_the_implementation(tmp_path):
    assert isinstance(open_storage(None, tmp_path / "jobs", tmp_path / "s"), LocalStorage)
    assert open_storage(str(tmp_path / "elsewhere"), tmp_path / "jobs", tmp_path / "s").url == str(
        tmp_path / "elsewhere"
    )
    with pytest.raises(ValueError, match="TEXSYNTH_STORAGE_URL"):
        open_storage("gs://bucket", tmp_path / "jobs", tmp_path / "s")
    with pytest.raises(ValueError, match="TEXSYNTH_STORAGE_URL"):
        S3Storage("s3://", tmp_path, client=object())


def test_an_upload_the_store_refuses_while_starting_is_tried_again(tmp_path):
    """A store just restarted answers 500 for a moment; boto3's transfer manager wraps that in its own
    error, which must be tried again like the others (it failed two jobs of the multi-host run)."""
    from boto3.exceptions import S3UploadFailedError

    class Flaky:
        def __init__(self) -> None:
            self.calls: list[str] = []

        def upload_file(self, path: str, bucket: str, key: str) -> None:
            self.calls.append(key)
            if len(self.calls) == 1:
                raise S3UploadFailedError("An error occurred (InternalError) when calling PutObject")

    client = Flaky()
    storage = S3Storage("s3://bucket/p", tmp_path / "scratch", retry_seconds=5, client=client)
    staging = storage.staging("j", "t")
    staging.mkdir(parents=True)
    (staging / "output.png").write_bytes(b"x")
    storage.publish("j", "t", staging)
    assert client.calls == ["p/jobs/j/runs/t/output.png"] * 2
