"""The service's own job records (SQLite under the data directory) and each job's folder.

Celery's result backend cannot say what happened to a job: it answers PENDING for ids it never saw
and leaves a crashed task in its last state. So the API and the workers keep one row per job here;
every state change is a single conditional UPDATE, which makes the life of a job a small state
machine that several processes (API, workers, reaper) can drive safely:

    queued -> running -> succeeded | failed | cancelled
       ^         |
       +---------+  (worker lost: the reaper or the broker re-delivers; attempts counted)

A run owns a job through its ``run_token``: progress, heartbeats and the final commit only succeed
while the token is the job's current one, so a run that was superseded (worker presumed dead, job
cancelled) can never overwrite the state or the artifacts of another.

Each job's folder::

    jobs/<id>/inputs/exemplar.<ext>   the uploaded bytes, unchanged (a sweep's runs share one file:
                                      hard links)
    jobs/<id>/manifest.json           method, parameters, seed, versions (written at submission)
    jobs/<id>/preview.png             small preview of the running synthesis (replaced atomically)
    jobs/<id>/.run-<token>/           one run's artifacts while it writes them
    jobs/<id>/out/                    the committed artifacts of the run that succeeded
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import sqlite3
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from synth.io.atomic import atomic_write_bytes, atomic_write_json

__all__ = ["STATES", "TERMINAL", "JobRecord", "JobStore", "pid_alive"]

STATES = ("queued", "running", "succeeded", "failed", "cancelled")
#: The highest progress a cancelled job reports: it stopped before the end (JobStore.finish).
CANCELLED_AT_MOST = 0.99
TERMINAL = frozenset({"succeeded", "failed", "cancelled"})

_SCHEMA = """
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
    size TEXT,
    extras TEXT
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

_JSON_COLUMNS = ("params", "inputs", "artifacts", "timings", "metrics")
#: What a job keeps beside its parameters (the ``extras`` JSON column): ``input_names``, the file name
#: each input was uploaded under (shown in lists; the stored file is named by its role), and a volume's
#: ``voxel_size`` and ``voxel_unit`` (the TIFF stack's calibration).
EXTRA_FIELDS = ("input_names", "voxel_size", "voxel_unit")
#: The output's sides, a record's ``size`` (never inside ``params``). Records made before ``size``
#: had its own column kept them in ``params``: reading one moves them out.
SIZE_FIELDS = ("width", "height", "depth")


def _split_size(params: dict[str, Any], size: dict[str, int] | None) -> dict[str, int]:
    if size is not None:
        return size
    return {k: params.pop(k) for k in SIZE_FIELDS if k in params}


@dataclass(frozen=True)
class JobRecord:
    """One row of ``jobs``, with its JSON columns decoded."""

    id: str
    created: float
    method: str
    params: dict[str, Any]
    seed: int
    inputs: dict[str, str]
    sweep_id: str | None
    state: str
    stage: str
    fraction: float
    message: str
    started: float | None
    finished: float | None
    updated: float
    attempts: int
    run_token: str | None
    host: str | None
    pid: int | None
    heartbeat: float | None
    received_host: str | None
    received_pid: int | None
    cancel_requested: float | None
    preview_at: float | None
    artifacts: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=dict)
    owner: str | None = None  # the token name that submitted it (None: made without tokens)
    size: dict[str, int] = field(default_factory=dict)  # the output's width, height (, depth)
    extras: dict[str, Any] = field(default_factory=dict)  # EXTRA_FIELDS

    @classmethod
    def from_row(cls, row: sqlite3.Row) -> JobRecord:
        values = dict(row)
        for name in _JSON_COLUMNS:
            values[name] = json.loads(values[name])
        values["size"] = _split_size(values["params"], json.loads(values["size"] or "null"))
        values["extras"] = json.loads(values.get("extras") or "{}")
        return cls(**values)


def pid_alive(pid: int | None) -> bool:
    """Whether process ``pid`` exists on this machine (zombies count as dead)."""
    if not pid:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return True


class JobStore:
    """Job, sweep and worker records in one SQLite file, safe across processes (WAL, short writes)."""

    def __init__(self, db_path: Path, jobs_dir: Path) -> None:
        self.db_path = Path(db_path)
        self.jobs_dir = Path(jobs_dir)
        self.host = socket.gethostname()
        self.jobs_dir.mkdir(parents=True, exist_ok=True)
        with self._connect() as db:
            db.execute("PRAGMA journal_mode=WAL")
            db.executescript(_SCHEMA)
            for table in ("jobs", "sweeps"):  # records made before owners, sizes, extras had columns
                columns = {row[1] for row in db.execute(f"PRAGMA table_info({table})")}
                for column in ("owner", "size", "extras") if table == "jobs" else ("owner", "size"):
                    if column not in columns:
                        with contextlib.suppress(sqlite3.OperationalError):  # another process added it
                            db.execute(f"ALTER TABLE {table} ADD COLUMN {column} TEXT")
            db.execute("CREATE INDEX IF NOT EXISTS jobs_owner ON jobs(owner, state)")

    # -- plumbing -------------------------------------------------------------------------------

    @contextlib.contextmanager
    def _connect(self) -> Iterator[sqlite3.Connection]:
        db = sqlite3.connect(self.db_path, timeout=30.0, isolation_level=None)
        db.row_factory = sqlite3.Row
        db.execute("PRAGMA busy_timeout=30000")
        db.execute("PRAGMA synchronous=NORMAL")
        try:
            yield db
        finally:
            db.close()

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        with self._connect() as db:
            db.execute("BEGIN IMMEDIATE")
            try:
                yield db
            except BaseException:
                db.execute("ROLLBACK")
                raise
            db.execute("COMMIT")

    def job_dir(self, job_id: str) -> Path:
        return self.jobs_dir / job_id

    # -- jobs: submission and queries ------------------------------------------------------------

    def create_job(
        self,
        *,
        method: str,
        params: dict[str, Any],
        seed: int,
        inputs: dict[str, tuple[str, bytes]],
        manifest: dict[str, Any],
        size: dict[str, int] | None = None,
        sweep_id: str | None = None,
        job_id: str | None = None,
        owner: str | None = None,
        share_inputs_of: str | None = None,
        extras: dict[str, Any] | None = None,
    ) -> JobRecord:
        """Store the inputs and manifest in a new job folder, then insert the record as ``queued``.

        ``size`` holds the output's ``width``, ``height`` (and ``depth``); ``params`` the method's
        parameters only. ``inputs`` maps a role (``exemplar``, ``constraint``) to ``(file name,
        bytes)``. The folder is complete before the record exists, so a worker never sees a job
        without its inputs.
        ``share_inputs_of`` names a job (of the same sweep) whose stored inputs are the same bytes:
        they are hard-linked instead of written again, so a sweep stores its upload once. Nothing
        ever writes into an input file (a replacement would be a new file), and deleting one job
        removes only its own link, so the runs share the bytes safely. ``extras``: :data:`EXTRA_FIELDS`.
        """
        job_id = job_id or uuid.uuid4().hex
        folder = self.job_dir(job_id)
        (folder / "inputs").mkdir(parents=True)
        names = {}
        for role, (filename, data) in inputs.items():
            suffix = Path(filename).suffix.lower()[:8] if filename else ""
            names[role] = f"{role}{suffix}"
            target = folder / "inputs" / names[role]
            shared = share_inputs_of and self.job_dir(share_inputs_of) / "inputs" / names[role]
            if not shared or not _link(shared, target):
                atomic_write_bytes(target, data)
        now = time.time()
        manifest = {**manifest, "job_id": job_id, "inputs": names, "created": now}
        atomic_write_json(folder / "manifest.json", manifest)
        with self._connect() as db:
            db.execute(
                "INSERT INTO jobs"
                " (id, created, method, params, size, seed, inputs, sweep_id, state, updated, owner, extras)"
                " VALUES (?, ?, ?, ?, ?, ?, ?, ?, 'queued', ?, ?, ?)",
                (
                    job_id,
                    now,
                    method,
                    json.dumps(params),
                    json.dumps(size or {}),
                    seed,
                    json.dumps(names),
                    sweep_id,
                    now,
                    owner,
                    json.dumps({k: v for k, v in (extras or {}).items() if k in EXTRA_FIELDS}),
                ),
            )
        record = self.get(job_id)
        assert record is not None
        return record

    def get(self, job_id: str) -> JobRecord | None:
        with self._connect() as db:
            row = db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if row is None else JobRecord.from_row(row)

    def list(
        self,
        *,
        state: str | None = None,
        sweep_id: str | None = None,
        owner: str | None = None,
        method: str | None = None,
        limit: int = 50,
        offset: int = 0,
    ) -> tuple[list[JobRecord], int]:
        """Jobs, newest first, and the total number matching the filters (``owner``: one owner's)."""
        where, args = [], []
        if method:
            where.append("method = ?")
            args.append(method)
        if owner is not None:
            where.append("owner = ?")
            args.append(owner)
        if state:
            where.append("state = ?")
            args.append(state)
        if sweep_id:
            where.append("sweep_id = ?")
            args.append(sweep_id)
        clause = f" WHERE {' AND '.join(where)}" if where else ""
        with self._connect() as db:
            count = db.execute(f"SELECT COUNT(*) FROM jobs{clause}", args).fetchone()[0]
            rows = db.execute(
                f"SELECT * FROM jobs{clause} ORDER BY created DESC, id LIMIT ? OFFSET ?",
                [*args, limit, offset],
            ).fetchall()
        return [JobRecord.from_row(r) for r in rows], count

    def count(self) -> int:
        with self._connect() as db:
            return db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]

    def count_active(self, owner: str | None) -> int:
        """Queued and running jobs of ``owner`` (``None``: those made without a token)."""
        with self._connect() as db:
            return db.execute(
                "SELECT COUNT(*) FROM jobs WHERE owner IS ? AND state IN ('queued', 'running')", (owner,)
            ).fetchone()[0]

    # -- jobs: the worker's side ----------------------------------------------------------------

    def mark_received(self, job_id: str, pid: int) -> None:
        """A worker's main process took the job's message off the broker (it may be lost with it)."""
        with self._connect() as db:
            db.execute(
                "UPDATE jobs SET received_host = ?, received_pid = ?, updated = ?"
                " WHERE id = ? AND state = 'queued'",
                (self.host, pid, time.time(), job_id),
            )

    def claim(self, job_id: str, pid: int, stale_seconds: float) -> tuple[str | None, str]:
        """Start a run of ``job_id``: returns ``(run_token, '')``, or ``(None, why not)``.

        A queued job is claimed. A running job is taken over only when its run is dead (its process
        is gone on this machine, or its heartbeat is older than ``stale_seconds``): that is a
        re-delivery after a crash. Otherwise this delivery is a duplicate and does nothing.
        """
        now = time.time()
        with self._transaction() as db:
            row = db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                return None, "unknown job"
            job = JobRecord.from_row(row)
            if job.state in TERMINAL:
                return None, f"already {job.state}"
            if job.cancel_requested:
                db.execute(
                    "UPDATE jobs SET state = 'cancelled', stage = 'cancelled', finished = ?, updated = ?,"
                    " run_token = NULL WHERE id = ?",
                    (now, now, job_id),
                )
                return None, "cancelled"
            if job.state == "running" and not self.run_is_dead(job, now, stale_seconds):
                return None, "running elsewhere"
            token = uuid.uuid4().hex
            db.execute(
                "UPDATE jobs SET state = 'running', run_token = ?, host = ?, pid = ?, heartbeat = ?,"
                " started = ?, attempts = attempts + 1, stage = 'starting', fraction = 0, message = '',"
                " updated = ? WHERE id = ?",
                (token, self.host, pid, now, now, now, job_id),
            )
        return token, ""

    def run_is_dead(self, job: JobRecord, now: float, stale_seconds: float) -> bool:
        if job.host == self.host and job.pid and not pid_alive(job.pid):
            return True
        return job.heartbeat is None or now - job.heartbeat > stale_seconds

    def progress(self, job_id: str, token: str, stage: str, fraction: float, preview: bool = False) -> bool:
        """Record progress; ``False`` means this run must stop (cancelled, or no longer the job's run)."""
        now = time.time()
        with self._connect() as db:
            cur = db.execute(
                "UPDATE jobs SET stage = ?, fraction = ?, heartbeat = ?, updated = ?,"
                " preview_at = CASE WHEN ? THEN ? ELSE preview_at END"
                " WHERE id = ? AND run_token = ? AND state = 'running' AND cancel_requested IS NULL",
                (stage, max(0.0, min(1.0, float(fraction))), now, now, preview, now, job_id, token),
            )
            return cur.rowcount == 1

    def heartbeat(self, job_id: str, token: str) -> bool:
        with self._connect() as db:
            cur = db.execute(
                "UPDATE jobs SET heartbeat = ? WHERE id = ? AND run_token = ? AND state = 'running'",
                (time.time(), job_id, token),
            )
            return cur.rowcount == 1

    def commit_success(
        self, job_id: str, token: str, staging: Path, artifacts: list[str], timings: dict, metrics: dict
    ) -> bool:
        """Make ``staging`` the job's ``out/`` folder and mark it succeeded, if this run still owns it.

        Holding the database's write lock while swapping folders means no other run can commit (or
        be told it owns the job) in between: the job's artifacts always come from exactly one run.
        """
        now = time.time()
        out = self.job_dir(job_id) / "out"
        with self._transaction() as db:
            row = db.execute(
                "SELECT 1 FROM jobs WHERE id = ? AND run_token = ? AND state = 'running'"
                " AND cancel_requested IS NULL",
                (job_id, token),
            ).fetchone()
            if row is None:
                return False
            old = None
            if out.exists():
                old = out.with_name(f".old-{token}")
                os.replace(out, old)
            os.replace(staging, out)
            db.execute(
                "UPDATE jobs SET state = 'succeeded', stage = 'done', fraction = 1, finished = ?,"
                " updated = ?,"
                " artifacts = ?, timings = ?, metrics = ?, run_token = NULL WHERE id = ?",
                (now, now, json.dumps(artifacts), json.dumps(timings), json.dumps(metrics), job_id),
            )
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return True

    def finish(self, job_id: str, token: str | None, state: str, message: str = "") -> bool:
        """End the job as ``failed`` or ``cancelled`` (if ``token`` is given, only if the run owns it).

        A failed job keeps the stage it had reached, so that the page can say where it failed; a
        cancelled one keeps its progress where it stopped, below :data:`CANCELLED_AT_MOST` (a job
        stopped while writing its artifacts, at 1.0, did not finish: it never reads as 100 % done).
        """
        assert state in ("failed", "cancelled")
        now = time.time()
        query = (
            "UPDATE jobs SET state = ?, message = ?, stage = CASE WHEN ? = 'failed' THEN stage ELSE ? END,"
            " fraction = CASE WHEN ? = 'cancelled' THEN MIN(fraction, ?) ELSE fraction END,"
            " finished = ?, updated = ?, run_token = NULL WHERE id = ? AND state IN ('queued', 'running')"
        )
        args: list[Any] = [state, message, state, state, state, CANCELLED_AT_MOST, now, now, job_id]
        if token is not None:
            query += " AND run_token = ?"
            args.append(token)
        with self._connect() as db:
            return db.execute(query, args).rowcount == 1

    # -- jobs: the API's and the reaper's side --------------------------------------------------

    def request_cancel(self, job_id: str) -> JobRecord | None:
        """Cancel: a queued job is cancelled at once; a running one is asked to stop."""
        now = time.time()
        with self._transaction() as db:
            db.execute(
                "UPDATE jobs SET state = 'cancelled', stage = 'cancelled', message = 'cancelled by request',"
                " finished = ?, updated = ?, cancel_requested = ? WHERE id = ? AND state = 'queued'",
                (now, now, now, job_id),
            )
            db.execute(
                "UPDATE jobs SET cancel_requested = ?, stage = 'cancelling', updated = ?"
                " WHERE id = ? AND state = 'running' AND cancel_requested IS NULL",
                (now, now, job_id),
            )
        return self.get(job_id)

    def discard(self, job_ids: list[str], sweep_id: str | None = None) -> None:
        """Forget jobs that were never queued (the broker refused them): records, folders, their sweep.

        Only ``queued`` jobs that no worker received are removed, so a job that did reach a worker is
        never lost by this.
        """
        with self._transaction() as db:
            for job_id in job_ids:
                cur = db.execute(
                    "DELETE FROM jobs WHERE id = ? AND state = 'queued' AND received_pid IS NULL", (job_id,)
                )
                if cur.rowcount:
                    shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
            if sweep_id is not None:
                db.execute("DELETE FROM sweeps WHERE id = ?", (sweep_id,))

    def delete(self, job_id: str) -> bool:
        """Forget a finished job: its record, its folder (inputs, artifacts), and its sweep's record
        once the sweep has no job left. ``False`` if the job is not finished (or not there)."""
        with self._transaction() as db:
            row = db.execute(
                "SELECT sweep_id FROM jobs WHERE id = ? AND state IN ('succeeded', 'failed', 'cancelled')",
                (job_id,),
            ).fetchone()
            if row is None:
                return False
            db.execute("DELETE FROM jobs WHERE id = ?", (job_id,))
            sweep_id = row["sweep_id"]
            if sweep_id and not db.execute("SELECT 1 FROM jobs WHERE sweep_id = ?", (sweep_id,)).fetchone():
                db.execute("DELETE FROM sweeps WHERE id = ?", (sweep_id,))
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
        return True

    def expired(self, finished_before: float, limit: int = 500) -> list[str]:
        """Ids of jobs that ended before ``finished_before`` (oldest first, at most ``limit``)."""
        with self._connect() as db:
            rows = db.execute(
                "SELECT id FROM jobs WHERE state IN ('succeeded', 'failed', 'cancelled') AND finished < ?"
                " ORDER BY finished LIMIT ?",
                (finished_before, limit),
            ).fetchall()
        return [r["id"] for r in rows]

    def orphan_folders(self, older_than: float) -> list[Path]:
        """Job folders without a record, untouched since ``older_than`` (a run that outlived its
        job's deletion may leave one); fresh folders are skipped, their record may be on its way."""
        with self._connect() as db:
            known = {r[0] for r in db.execute("SELECT id FROM jobs")}
        found = []
        for folder in self.jobs_dir.iterdir():
            if folder.name in known or not folder.is_dir():
                continue
            with contextlib.suppress(OSError):
                if folder.stat().st_mtime < older_than:
                    found.append(folder)
        return found

    def requeue(self, job_id: str, message: str) -> bool:
        """A run was lost: put the job back to ``queued`` (the caller sends a new message)."""
        now = time.time()
        with self._connect() as db:
            cur = db.execute(
                "UPDATE jobs SET state = 'queued', stage = 'queued', fraction = 0, message = ?,"
                " run_token = NULL, received_host = NULL, received_pid = NULL, updated = ?"
                " WHERE id = ? AND state IN ('queued', 'running')",
                (message, now, job_id),
            )
            return cur.rowcount == 1

    def active(self) -> list[JobRecord]:
        with self._connect() as db:
            rows = db.execute("SELECT * FROM jobs WHERE state IN ('queued', 'running')").fetchall()
        return [JobRecord.from_row(r) for r in rows]

    # -- sweeps -------------------------------------------------------------------------------------

    def create_sweep(
        self,
        sweep_id: str,
        method: str,
        grid: dict,
        params: dict,
        job_ids: list[str],
        owner: str | None = None,
        size: dict[str, int] | None = None,
    ) -> None:
        with self._connect() as db:
            db.execute(
                "INSERT INTO sweeps (id, created, method, grid, params, size, job_ids, owner)"
                " VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    sweep_id,
                    time.time(),
                    method,
                    json.dumps(grid),
                    json.dumps(params),
                    json.dumps(size or {}),
                    json.dumps(job_ids),
                    owner,
                ),
            )

    def get_sweep(self, sweep_id: str) -> dict[str, Any] | None:
        with self._connect() as db:
            row = db.execute("SELECT * FROM sweeps WHERE id = ?", (sweep_id,)).fetchone()
        if row is None:
            return None
        sweep = dict(row)
        for name in ("grid", "params", "job_ids"):
            sweep[name] = json.loads(sweep[name])
        sweep["size"] = _split_size(sweep["params"], json.loads(sweep["size"] or "null"))
        return sweep

    # -- workers ------------------------------------------------------------------------------------

    def worker_heartbeat(self, name: str, pid: int, started: float) -> None:
        with self._connect() as db:
            db.execute(
                "INSERT INTO workers (name, host, pid, started, heartbeat) VALUES (?, ?, ?, ?, ?)"
                " ON CONFLICT(name) DO UPDATE SET host = excluded.host, pid = excluded.pid,"
                " started = excluded.started, heartbeat = excluded.heartbeat",
                (name, self.host, pid, started, time.time()),
            )

    def workers(self, fresh_within: float) -> list[dict[str, Any]]:
        """Workers whose main process reported within ``fresh_within`` seconds (and, here, is alive)."""
        now = time.time()
        with self._connect() as db:
            rows = [dict(r) for r in db.execute("SELECT * FROM workers").fetchall()]
        return [
            r
            for r in rows
            if now - r["heartbeat"] <= fresh_within and (r["host"] != self.host or pid_alive(r["pid"]))
        ]


def _link(source: Path, target: Path) -> bool:
    """Hard-link ``source`` as ``target``; ``False`` (the caller writes a copy) if it cannot."""
    try:
        os.link(source, target)
    except OSError:
        return False
    return True
