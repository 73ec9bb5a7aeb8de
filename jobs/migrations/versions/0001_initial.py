"""The job records as they were before migrations: jobs, sweeps, workers.

Revision ID: 0001
Revises:

Creates only what is missing, so a data directory made by an earlier texsynth (its SQLite file had
no ``alembic_version``, and records made before owners and sizes had columns lack those two) is
upgraded in place, its records kept. SQLite gets exactly the schema texsynth always made; PostgreSQL
the same columns with its own types (timestamps in double precision, the seed in 64 bits).
"""

from __future__ import annotations

from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

_JOBS = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    created {real} NOT NULL,
    method TEXT NOT NULL,
    params TEXT NOT NULL,
    seed {bigint} NOT NULL,
    inputs TEXT NOT NULL,
    sweep_id TEXT,
    state TEXT NOT NULL,
    stage TEXT NOT NULL DEFAULT '',
    fraction {real} NOT NULL DEFAULT 0,
    message TEXT NOT NULL DEFAULT '',
    started {real},
    finished {real},
    updated {real} NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 0,
    run_token TEXT,
    host TEXT,
    pid INTEGER,
    heartbeat {real},
    received_host TEXT,
    received_pid INTEGER,
    cancel_requested {real},
    preview_at {real},
    artifacts TEXT NOT NULL DEFAULT '[]',
    timings TEXT NOT NULL DEFAULT '{{}}',
    metrics TEXT NOT NULL DEFAULT '{{}}',
    owner TEXT,
    size TEXT
)"""
_SWEEPS = """
CREATE TABLE IF NOT EXISTS sweeps (
    id TEXT PRIMARY KEY,
    created {real} NOT NULL,
    method TEXT NOT NULL,
    grid TEXT NOT NULL,
    params TEXT NOT NULL,
    job_ids TEXT NOT NULL,
    owner TEXT,
    size TEXT
)"""
_WORKERS = """
CREATE TABLE IF NOT EXISTS workers (
    name TEXT PRIMARY KEY,
    host TEXT NOT NULL,
    pid INTEGER NOT NULL,
    started {real} NOT NULL,
    heartbeat {real} NOT NULL
)"""
_INDEXES = (
    "CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state, created)",
    "CREATE INDEX IF NOT EXISTS jobs_created ON jobs(created)",
    "CREATE INDEX IF NOT EXISTS jobs_sweep ON jobs(sweep_id)",
)


def upgrade() -> None:
    sqlite = op.get_bind().dialect.name == "sqlite"
    types = {"real": "REAL", "bigint": "INTEGER"}
    if not sqlite:
        types = {"real": "DOUBLE PRECISION", "bigint": "BIGINT"}
    for ddl in (_JOBS, _SWEEPS, _WORKERS):
        op.execute(ddl.format(**types))
    for ddl in _INDEXES:
        op.execute(ddl)
    if sqlite:  # records made before owners and sizes had columns
        for table in ("jobs", "sweeps"):
            columns = {row[1] for row in op.get_bind().exec_driver_sql(f"PRAGMA table_info({table})")}
            for column in ("owner", "size"):
                if column not in columns:
                    op.execute(f"ALTER TABLE {table} ADD COLUMN {column} TEXT")
    op.execute("CREATE INDEX IF NOT EXISTS jobs_owner ON jobs(owner, state)")


def downgrade() -> None:
    for table in ("workers", "sweeps", "jobs"):
        op.execute(f"DROP TABLE IF EXISTS {table}")
