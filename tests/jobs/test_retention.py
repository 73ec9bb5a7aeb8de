"""DELETE of a finished job, the retention period, sweep uploads stored once (issue 14, item 6)."""

from __future__ import annotations

import os
import time

import pytest

from texsynth.jobs.config import Settings
from texsynth.jobs.reaper import ORPHAN_SECONDS, purge_expired
from texsynth.jobs.store import JobStore

UPLOAD = b"\x89PNG" + bytes(range(256)) * 64  # the bytes are never decoded here


@pytest.fixture
def store(tmp_path) -> JobStore:
    return JobStore(tmp_path / "jobs.sqlite", tmp_path / "jobs")


def _job(store: JobStore, **kwargs) -> str:
    return store.create_job(
        method="m", params={}, seed=1, inputs={"exemplar": ("e.png", UPLOAD)}, manifest={}, **kwargs
    ).id


def _finish(store: JobStore, job_id: str, finished: float | None = None) -> None:
    token, _ = store.claim(job_id, pid=os.getpid(), stale_seconds=10)
    staging = store.job_dir(job_id) / f".run-{token}"
    staging.mkdir()
    (staging / "output.png").write_bytes(b"out")
    assert store.commit_success(job_id, token, staging, ["output.png"], {}, {})
    if finished is not None:
        with store._connect() as db:
            db.execute("UPDATE jobs SET finished = ? WHERE id = ?", (finished, job_id))


def test_delete_frees_a_finished_jobs_files_and_record(store):
    job_id = _job(store)
    _finish(store, job_id)
    assert store.delete(job_id)
    assert store.get(job_id) is None
    assert not store.job_dir(job_id).exists()


def test_delete_leaves_a_queued_or_running_job(store):
    queued, running = _job(store), _job(store)
    store.claim(running, pid=os.getpid(), stale_seconds=10)
    assert not store.delete(queued) and not store.delete(running)
    assert store.get(queued).state == "queued" and store.job_dir(running).exists()


def test_a_sweeps_runs_share_one_stored_upload(store):
    first = _job(store, sweep_id="s")
    others = [_job(store, sweep_id="s", share_inputs_of=first) for _ in range(7)]
    files = [store.job_dir(j) / "inputs" / "exemplar.png" for j in [first, *others]]
    assert len({f.stat().st_ino for f in files}) == 1  # one file, eight names
    assert files[0].stat().st_nlink == 8
    assert all(f.read_bytes() == UPLOAD for f in files)
    # deleting a run (even the first) leaves the others' input intact
    _finish(store, first)
    store.delete(first)
    assert files[1].read_bytes() == UPLOAD and files[1].stat().st_nlink == 7


def test_the_last_deleted_run_of_a_sweep_removes_the_sweep(store):
    a, b = _job(store, sweep_id="s"), _job(store, sweep_id="s")
    store.create_sweep("s", "m", {"n": [1, 2]}, {}, [a, b])
    for job_id in (a, b):
        _finish(store, job_id)
    store.delete(a)
    assert store.get_sweep("s") is not None
    store.delete(b)
    assert store.get_sweep("s") is None


def test_the_reaper_deletes_jobs_past_the_retention_period(store, tmp_path):
    settings = Settings(data_dir=tmp_path, retention_days=30)
    now = time.time()
    old, recent, running = _job(store), _job(store), _job(store)
    _finish(store, old, finished=now - 31 * 86400)
    _finish(store, recent, finished=now - 29 * 86400)
    store.claim(running, pid=os.getpid(), stale_seconds=10)
    with store._connect() as db:  # running for long: never deleted by retention
        db.execute(
            "UPDATE jobs SET created = ?, started = ? WHERE id = ?", (now - 40 * 86400,) * 2 + (running,)
        )
    assert purge_expired(store, settings, now) == [old]
    assert store.get(old) is None and not store.job_dir(old).exists()
    assert store.get(recent) is not None and store.get(running) is not None


def test_retention_zero_keeps_jobs_forever(store, tmp_path):
    job_id = _job(store)
    _finish(store, job_id, finished=1.0)
    assert purge_expired(store, Settings(data_dir=tmp_path, retention_days=0)) == []
    assert store.get(job_id) is not None


def test_the_reaper_removes_old_folders_without_a_record(store, tmp_path):
    orphan = store.job_dir("orphan")
    (orphan / "out").mkdir(parents=True)
    fresh = store.job_dir("fresh")
    fresh.mkdir()
    old = time.time() - ORPHAN_SECONDS - 10
    os.utime(orphan, (old, old))
    assert purge_expired(store, Settings(data_dir=tmp_path)) == ["orphan"]
    assert not orphan.exists() and fresh.exists()
