"""Claims, commits and the reaper's re-sends stay atomic with several workers on one database server
(and on the SQLite file); a restarted PostgreSQL costs a retry, never a lost update."""

from __future__ import annotations

import threading

import pytest

from texsynth.jobs.config import Settings
from texsynth.jobs.reaper import reap_once
from texsynth.jobs.store import JobStore

DEAD_PID = 2**22 + 12345  # above pid_max on Linux: never a live process


@pytest.fixture(params=["sqlite", "postgresql"])
def database(request, tmp_path) -> str:
    if request.param == "sqlite":
        return str(tmp_path / "jobs.sqlite")
    return request.getfixturevalue("pg_url")


def _jobs(store: JobStore, n: int) -> list[str]:
    return [
        store.create_job(method="m", params={}, seed=1, inputs={"exemplar": ("e.png", b"x")}, manifest={}).id
        for _ in range(n)
    ]


def _race(stores: list[JobStore], act) -> list:
    """``act(store)`` in one thread per store, all released at once; their answers."""
    barrier = threading.Barrier(len(stores))
    answers: list = [None] * len(stores)

    def run(i: int) -> None:
        barrier.wait()
        answers[i] = act(stores[i])

    threads = [threading.Thread(target=run, args=(i,)) for i in range(len(stores))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)
    return answers


def test_two_workers_claiming_one_job_get_one_run(database, tmp_path):
    """Two workers (each its own store, its own connections) receive the same job at the same moment,
    20 times: exactly one run each time, and the loser is told the job runs elsewhere."""
    workers = [JobStore(database, tmp_path / "jobs") for _ in range(2)]
    for job_id in _jobs(workers[0], 20):
        answers = _race(workers, lambda store, j=job_id: store.claim(j, pid=1, stale_seconds=60))
        tokens = [token for token, _ in answers if token]
        assert len(tokens) == 1, answers
        assert sorted(why for _, why in answers) == ["", "running elsewhere"]
        job = workers[0].get(job_id)
        assert job.attempts == 1 and job.run_token == tokens[0]


def test_two_workers_taking_over_a_dead_run_get_one_run(database, tmp_path):
    workers = [JobStore(database, tmp_path / "jobs") for _ in range(2)]
    for job_id in _jobs(workers[0], 10):
        workers[0].claim(job_id, pid=DEAD_PID, stale_seconds=60)  # its process is gone
        answers = _race(workers, lambda store, j=job_id: store.claim(j, pid=1, stale_seconds=60))
        assert sum(1 for token, _ in answers if token) == 1, answers
        assert workers[0].get(job_id).attempts == 2


def test_a_superseded_run_cannot_commit_while_the_new_one_does(database, tmp_path):
    workers = [JobStore(database, tmp_path / "jobs") for _ in range(2)]
    for job_id in _jobs(workers[0], 5):
        old, _ = workers[0].claim(job_id, pid=DEAD_PID, stale_seconds=60)
        new, _ = workers[1].claim(job_id, pid=1, stale_seconds=60)
        stagings = []
        for token in (old, new):
            staging = workers[0].storage.staging(job_id, token)
            staging.mkdir(parents=True)
            (staging / "output.png").write_bytes(token.encode())
            stagings.append(staging)
        runs = {id(workers[0]): (old, stagings[0]), id(workers[1]): (new, stagings[1])}
        answers = _race(
            workers,
            lambda store, j=job_id, runs=runs: store.commit_success(j, *runs[id(store)], [], {}, {}),
        )
        assert answers == [False, True]
        assert (workers[0].job_dir(job_id) / "out" / "output.png").read_bytes() == new.encode()


def test_two_reapers_resend_a_lost_job_once(database, tmp_path):
    """Two API processes' reapers find the same dead run: it is re-queued and sent once."""
    stores = [JobStore(database, tmp_path / "jobs") for _ in range(2)]
    settings = Settings(data_dir=tmp_path, stale_seconds=5, max_attempts=3)
    job_ids = _jobs(stores[0], 10)
    for job_id in job_ids:
        stores[0].claim(job_id, pid=DEAD_PID, stale_seconds=5)
    sent: list[str] = []
    lock = threading.Lock()

    def send(job_id: str) -> None:
        with lock:
            sent.append(job_id)

    _race(stores, lambda store: reap_once(store, settings, send, lambda _: None, set()))
    assert sorted(sent) == sorted(job_ids)
    assert {stores[1].get(j).state for j in job_ids} == {"queued"}


def test_a_restarted_postgres_costs_a_retry_not_an_update(postgres, pg_url, tmp_path):
    store = JobStore(pg_url, tmp_path / "jobs")
    (job_id,) = _jobs(store, 1)
    token, _ = store.claim(job_id, pid=1, stale_seconds=60)
    assert store.progress(job_id, token, "a", 0.1)
    postgres.restart()  # every pooled connection is now dead
    assert store.progress(job_id, token, "b", 0.5)
    assert store.get(job_id).stage == "b"
    restarting = threading.Thread(target=postgres.restart)
    restarting.start()
    for step in range(20):  # during the restart: the store waits for the server, nothing is lost
        assert store.progress(job_id, token, f"s{step}", step / 20)
    restarting.join()
    assert store.get(job_id).stage == "s19"
