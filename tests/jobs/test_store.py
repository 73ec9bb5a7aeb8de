"""The job record state machine and the reaper, without processes (fast, deterministic), on SQLite
and on PostgreSQL."""

from __future__ import annotations

import time

import pytest

from texsynth.jobs.config import Settings
from texsynth.jobs.reaper import reap_once
from texsynth.jobs.store import JobStore

DEAD_PID = 2**22 + 12345  # above pid_max on Linux: never a live process


@pytest.fixture(params=["sqlite", "postgresql"])
def store(request, tmp_path) -> JobStore:
    """Every test of the state machine runs on the SQLite file and on a PostgreSQL server."""
    if request.param == "sqlite":
        return JobStore(tmp_path / "jobs.sqlite", tmp_path / "jobs")
    return JobStore(request.getfixturevalue("pg_url"), tmp_path / "jobs")


def _job(store: JobStore) -> str:
    return store.create_job(
        method="m", params={"width": 8}, seed=1, inputs={"exemplar": ("e.png", b"x")}, manifest={}
    ).id


def test_duplicate_delivery_of_a_running_job_does_nothing(store):
    job_id = _job(store)
    token, _ = store.claim(job_id, pid=1, stale_seconds=10)  # pid 1 is alive
    assert token
    again, why = store.claim(job_id, pid=1, stale_seconds=10)
    assert again is None and why == "running elsewhere"


def test_redelivery_after_a_crash_takes_over_and_the_old_run_cannot_commit(store, tmp_path):
    job_id = _job(store)
    old, _ = store.claim(job_id, pid=DEAD_PID, stale_seconds=10)
    new, _ = store.claim(job_id, pid=1, stale_seconds=10)  # the old run's process is gone
    assert new and new != old and store.get(job_id).attempts == 2
    assert not store.progress(job_id, old, "x", 0.5)
    staging = tmp_path / "staging"
    staging.mkdir()
    assert not store.commit_success(job_id, old, staging, ["a"], {}, {})
    assert store.commit_success(job_id, new, staging, ["a"], {}, {})
    assert store.get(job_id).state == "succeeded" and (store.job_dir(job_id) / "out").is_dir()
    assert store.claim(job_id, pid=1, stale_seconds=10) == (None, "already succeeded")


def test_cancel_stops_progress_and_queued_jobs_never_start(store):
    running, queued = _job(store), _job(store)
    token, _ = store.claim(running, pid=1, stale_seconds=10)
    store.request_cancel(running)
    assert not store.progress(running, token, "x", 0.5)
    assert store.request_cancel(queued).state == "cancelled"
    assert store.claim(queued, pid=1, stale_seconds=10) == (None, "already cancelled")


def test_reaper_requeues_a_dead_run_then_gives_up(store):
    settings = Settings(data_dir=store.jobs_dir.parent, max_attempts=2, stale_seconds=5)
    job_id = _job(store)
    sent = []
    for attempt in (1, 2):
        token, _ = store.claim(job_id, pid=DEAD_PID, stale_seconds=5)
        assert token and store.get(job_id).attempts == attempt
        actions = reap_once(store, settings, sent.append, lambda _: None, set())
        if attempt == 1:
            assert actions == [(job_id, "requeued")] and sent == [job_id]
            assert store.get(job_id).state == "queued"
    assert actions == [(job_id, "failed")]
    job = store.get(job_id)
    assert job.state == "failed" and "2 times" in job.message


def test_reaper_settles_an_unanswered_cancel(store):
    settings = Settings(data_dir=store.jobs_dir.parent, cancel_grace_seconds=0.0, stale_seconds=60)
    job_id = _job(store)
    store.claim(job_id, pid=1, stale_seconds=60)
    store.request_cancel(job_id)
    terminated: list[str] = []
    actions = reap_once(store, settings, lambda _: None, terminated.append, set(), now=time.time() + 1)
    assert terminated == [job_id] and (job_id, "terminate") in actions
    reap_once(store, settings, lambda _: None, terminated.append, set(), now=time.time() + 10)
    assert store.get(job_id).state == "cancelled"


def test_settings_round_trip_through_the_environment(tmp_path):
    settings = Settings.from_env({}, data_dir=tmp_path, concurrency=3, extra_methods=("a.b", "c"))
    again = Settings.from_env(settings.to_env())
    assert again == settings and again.embedded
    assert Settings.from_env({"REDIS_URL": "redis://h:1/0", "TEXSYNTH_DATA_DIR": str(tmp_path)}).redis_url


def _backdate(store: JobStore, job_id: str, seconds: float) -> None:
    with store._connect() as db:
        db.execute("UPDATE jobs SET updated = updated - ? WHERE id = ?", (seconds, job_id))


def test_reaper_resends_a_job_no_worker_received_while_workers_idle(store):
    settings = Settings(data_dir=store.jobs_dir.parent, concurrency=2, resend_seconds=30)
    old, fresh = _job(store), _job(store)
    _backdate(store, old, 31)
    store.worker_heartbeat("w1", pid=1, started=time.time())  # a live, idle worker (pid 1 is alive)
    sent: list[str] = []
    assert reap_once(store, settings, sent.append, lambda j: None, set()) == [(old, "resent")]
    assert sent == [old] and store.get(old).state == "queued"
    # the re-send restarts its clock, and the fresh job is not stranded yet
    assert reap_once(store, settings, sent.append, lambda j: None, set()) == []
    assert fresh not in sent


def test_a_job_waiting_behind_busy_workers_is_not_resent(store):
    settings = Settings(data_dir=store.jobs_dir.parent, concurrency=1, resend_seconds=30)
    busy, waiting = _job(store), _job(store)
    store.worker_heartbeat("w1", pid=1, started=time.time())
    store.claim(busy, pid=1, stale_seconds=10)
    _backdate(store, waiting, 300)
    assert reap_once(store, settings, lambda j: None, lambda j: None, set()) == []


def test_a_job_held_by_a_live_worker_that_never_starts_it_is_resent_once_and_runs_once(store, tmp_path):
    """Issue 14's Redis case: a live worker's main process received (prefetched) the message, then
    redis-server restarted empty and the message was gone; the worker lives on, idle."""
    settings = Settings(data_dir=store.jobs_dir.parent, concurrency=2, resend_seconds=30)
    held = _job(store)
    store.worker_heartbeat("w1", pid=1, started=time.time())  # pid 1 is alive
    store.mark_received(held, pid=1)
    sent: list[str] = []
    assert reap_once(store, settings, sent.append, lambda j: None, set()) == []  # not overdue yet
    _backdate(store, held, 31)
    assert reap_once(store, settings, sent.append, lambda j: None, set()) == [(held, "resent")]
    job = store.get(held)
    assert sent == [held] and job.state == "queued" and job.received_pid is None
    assert "no worker started this job" in job.message
    assert reap_once(store, settings, sent.append, lambda j: None, set()) == []  # once
    # The new message runs it; the old one, should it arrive after all, is a duplicate.
    token, _ = store.claim(held, pid=1, stale_seconds=10)
    assert token and store.claim(held, pid=1, stale_seconds=10) == (None, "running elsewhere")
    staging = tmp_path / "staging"
    staging.mkdir()
    assert store.commit_success(held, token, staging, ["a"], {}, {})
    assert store.claim(held, pid=1, stale_seconds=10) == (None, "already succeeded")
    assert store.get(held).attempts == 1


def test_a_job_held_behind_a_busy_worker_is_not_resent(store):
    settings = Settings(data_dir=store.jobs_dir.parent, concurrency=1, resend_seconds=30)
    busy, held = _job(store), _job(store)
    store.worker_heartbeat("w1", pid=1, started=time.time())
    store.claim(busy, pid=1, stale_seconds=10)
    store.mark_received(held, pid=1)
    _backdate(store, held, 300)  # overdue, but the only slot runs the other job
    assert reap_once(store, settings, lambda j: None, lambda j: None, set()) == []


def test_no_resend_without_a_live_worker(store):
    settings = Settings(data_dir=store.jobs_dir.parent, resend_seconds=30)
    job_id = _job(store)
    _backdate(store, job_id, 300)
    assert reap_once(store, settings, lambda j: None, lambda j: None, set()) == []


def test_a_failed_job_keeps_the_stage_it_failed_in_and_a_cancelled_one_says_cancelled(store):
    failed, cancelled = _job(store), _job(store)
    for job_id in (failed, cancelled):
        token, _ = store.claim(job_id, pid=1, stale_seconds=10)
        assert store.progress(job_id, token, "level 2 of 3", 0.4)
        assert store.finish(job_id, token, "failed" if job_id == failed else "cancelled", "why")
    assert store.get(failed).stage == "level 2 of 3" and store.get(failed).state == "failed"
    assert store.get(cancelled).stage == "cancelled"


def test_size_is_a_field_of_its_own_and_older_records_move_it_out_of_params(store):
    job = store.create_job(
        method="m",
        params={"levels": 2},
        size={"width": 16, "height": 8},
        seed=1,
        inputs={"exemplar": ("e.png", b"x")},
        manifest={},
    )
    assert job.size == {"width": 16, "height": 8} and job.params == {"levels": 2}
    with store._connect() as db:  # a record written before the size had its own column
        db.execute(
            "UPDATE jobs SET params = ?, size = NULL WHERE id = ?",
            ('{"levels": 2, "width": 16, "height": 8}', job.id),
        )
    older = store.get(job.id)
    assert older.size == {"width": 16, "height": 8} and older.params == {"levels": 2}
