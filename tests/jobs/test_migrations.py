"""Schema migrations (Alembic): a fresh database, and data directories made by earlier texsynth
versions upgraded in place with their records kept."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from alembic.config import Config
from alembic.script import ScriptDirectory

from texsynth.jobs.db import HEAD
from texsynth.jobs.store import JobStore

# The schema texsynth made before migrations (jobs/store.py at cc74b7e), verbatim.
OLD_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    created REAL NOT NULL,
    method TEXT NOT NULL,
    params TEXT NOT NULL,
    seed INTEGER NOT NULL,
    inputs TEXT NOT NULL,
    sweep_id TEXT,
    state TEXT NOT NULL,
    stage TEXT NOT NULL DEFAULT '',
    fraction REAL NOT NULL DEFAULT 0,
    message TEXT NOT NULL DEFAULT '',
    started REAL,
    finished REAL,
    updated REAL NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 0,
    run_token TEXT,
    host TEXT,
    pid INTEGER,
    heartbeat REAL,
    received_host TEXT,
    received_pid INTEGER,
    cancel_requested REAL,
    preview_at REAL,
    artifacts TEXT NOT NULL DEFAULT '[]',
    timings TEXT NOT NULL DEFAULT '{}',
    metrics TEXT NOT NULL DEFAULT '{}',
    owner TEXT,
    size TEXT
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state, created);
CREATE INDEX IF NOT EXISTS jobs_created ON jobs(created);
CREATE INDEX IF NOT EXISTS jobs_sweep ON jobs(sweep_id);
CREATE TABLE IF NOT EXISTS sweeps (
    id TEXT PRIMARY KEY,
    created REAL NOT NULL,
    method TEXT NOT NULL,
    grid TEXT NOT NULL,
    params TEXT NOT NULL,
    job_ids TEXT NOT NULL,
    owner TEXT,
    size TEXT
);
CREATE TABLE IF NOT EXISTS workers (
    name TEXT PRIMARY KEY,
    host TEXT NOT NULL,
    pid INTEGER NOT NULL,
    started REAL NOT NULL,
    heartbeat REAL NOT NULL
);
"""

ROW = (
    "INSERT INTO jobs (id, created, method, params, seed, inputs, state, updated, artifacts, owner, size)"
    " VALUES ('old', 1.5, 'm', '{\"n\": 3}', 7, '{\"exemplar\": \"exemplar.png\"}', 'succeeded', 2.5,"
    " '[\"output.png\"]', 'alice', '{\"width\": 8, \"height\": 8}')"
)


def _columns(path: Path, table: str) -> set[str]:
    db = sqlite3.connect(path)
    try:
        return {row[1] for row in db.execute(f"PRAGMA table_info({table})")}
    finally:
        db.close()


def _old_data_dir(tmp_path: Path, schema: str) -> Path:
    path = tmp_path / "jobs.sqlite"
    db = sqlite3.connect(path)
    db.executescript(schema)
    if "owner TEXT,\n    size TEXT\n);\nCREATE INDEX" in schema:
        db.execute(ROW)
    db.commit()
    db.close()
    return path


def test_head_is_alembics_head():
    config = Config()
    config.set_main_option("script_location", str(Path(__file__).parents[2] / "jobs" / "migrations"))
    assert ScriptDirectory.from_config(config).get_current_head() == HEAD


def test_a_fresh_database_gets_every_revision(tmp_path):
    JobStore(tmp_path / "jobs.sqlite", tmp_path / "jobs")
    db = sqlite3.connect(tmp_path / "jobs.sqlite")
    assert db.execute("SELECT version_num FROM alembic_version").fetchall() == [(HEAD,)]
    assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert "artifacts_run" in _columns(tmp_path / "jobs.sqlite", "jobs")


def test_a_data_dir_of_the_previous_version_is_upgraded_in_place(tmp_path):
    path = _old_data_dir(tmp_path, OLD_SCHEMA)
    store = JobStore(path, tmp_path / "jobs")
    job = store.get("old")
    assert job is not None and job.state == "succeeded" and job.owner == "alice"
    assert job.params == {"n": 3} and job.size == {"width": 8, "height": 8} and job.artifacts_run is None
    assert "artifacts_run" in _columns(path, "jobs")
    again = JobStore(path, tmp_path / "jobs")  # the second open finds it at the head: nothing to do
    assert again.get("old") == job


@pytest.mark.parametrize("column", ["owner", "size"])
def test_records_made_before_owners_and_sizes_get_the_columns(tmp_path, column):
    schema = OLD_SCHEMA.replace(f",\n    {column} TEXT", "")
    assert schema.count(f"{column} TEXT") == 0
    path = _old_data_dir(tmp_path, schema)
    JobStore(path, tmp_path / "jobs")
    assert column in _columns(path, "jobs") and column in _columns(path, "sweeps")


def test_an_sqlite_url_is_the_same_file(tmp_path):
    store = JobStore(f"sqlite:///{tmp_path / 'records.sqlite'}", tmp_path / "jobs")
    assert store.db_path == tmp_path / "records.sqlite" and store.count() == 0


@pytest.mark.parametrize(
    ("url", "says"),
    [
        ("mysql://u:p@h/db", "not supported"),
        ("postgresql+psycopg2://u:p@h/db", "psycopg 3 driver"),
        ("sqlite://", "needs a file"),
    ],
)
def test_a_bad_database_url_names_the_variable(tmp_path, url, says):
    with pytest.raises(ValueError, match=f"TEXSYNTH_DATABASE_URL.*{says}"):
        JobStore(url, tmp_path / "jobs")


@pytest.mark.parametrize("kind", ["sqlite", "postgresql"])
def test_processes_starting_together_migrate_once(request, tmp_path, kind):
    """API and workers open a fresh database at the same moment: one migrates, the others wait."""
    import threading

    database = str(tmp_path / "jobs.sqlite") if kind == "sqlite" else request.getfixturevalue("pg_url")
    barrier, errors = threading.Barrier(4), []

    def open_store() -> None:
        barrier.wait()
        try:
            JobStore(database, tmp_path / "jobs").count()
        except Exception as exc:  # reported below with the others
            errors.append(exc)

    threads = [threading.Thread(target=open_store) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    assert not errors
    store = JobStore(database, tmp_path / "jobs")
    with store._connect() as db:
        assert [
            tuple(r) if kind == "sqlite" else (r[0],)
            for r in db.execute("SELECT version_num FROM alembic_version").fetchall()
        ] == [(HEAD,)]


def test_the_switch_to_wal_waits_for_a_process_holding_the_file(tmp_path):
    """SQLite refuses ``journal_mode=WAL`` at once (no busy handler) while another connection holds a
    lock: the switch is tried again until the lock goes, and gives up with SQLite's error at its deadline."""
    import threading

    from texsynth.jobs.db import _write_ahead_log

    path = tmp_path / "jobs.sqlite"
    holder = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
    holder.execute("CREATE TABLE t (x)")
    holder.execute("BEGIN EXCLUSIVE")
    db = sqlite3.connect(path, timeout=0.01, isolation_level=None)
    with pytest.raises(sqlite3.OperationalError, match="locked"):
        _write_ahead_log(db, wait=0.1)
    release = threading.Timer(0.3, lambda: holder.execute("COMMIT"))
    release.start()
    _write_ahead_log(db, wait=10.0)
    release.join()
    assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    _write_ahead_log(db, wait=0.0)  # already WAL: nothing to switch, no lock needed
    holder.close()
    db.close()
