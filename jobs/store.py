"""The service's own job records (SQLite under the data directory, or PostgreSQL) and each job's files.

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

The records live in :class:`texsynth.jobs.db.Database` (schema: Alembic, ``jobs/migrations``); the files in a
:class:`texsynth.jobs.storage.Storage`: by default each job's folder in the data directory::

    jobs/<id>/inputs/exemplar.<ext>   the uploaded bytes, unchanged (a sweep's runs share one file:
                                      hard links)
    jobs/<id>/manifest.json           method, parameters, seed, versions (written at submission)
    jobs/<id>/preview.png             small preview of the running synthesis (replaced atomically)
    jobs/<id>/.run-<token>/           one run's artifacts while it writes them
    jobs/<id>/out/                    the committed artifacts of the run that succeeded

or, with ``TEXSYNTH_STORAGE_URL=s3://...``, the same under object keys (:mod:`texsynth.jobs.storage`).
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import socket
import sqlite3
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from texsynth.jobs.db import Database
from texsynth.jobs.storage import LocalStorage, Storage

__all__ = ["STATES", "TERMINAL", "JobRecord", "JobStore", "pid_alive"]

STATES = ("queued", "running", "succeeded", "failed", "cancelled")
#: The highest progress a cancelled job reports: it stopped before the end (JobStore.finish).
CANCELLED_AT_MOST = 0.99
TERMINAL = frozenset({"succeeded", "failed", "cancelled"})

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
    input_bytes: int | None = None  # bytes its inputs hold on disk (a sweep's shared upload: its first run)
    artifact_bytes: int | None = None  # bytes of its committed artifacts
    artifacts_run: str | None = None  # object storage: the run whose uploaded artifacts are the job's
    extras: dict[str, Any] = field(default_factory=dict)  # EXTRA_FIELDS

    @classmethod
    def from_row(cls, row: Any) -> JobRecord:
        values = dict(row)
        for name in _JSON_COLUMNS:
            values[name] = json.loads(values[name])
        values["size"] = _split_size(values["params"], json.loads(values["size"] or "null"))
        values["extras"] = json.loads(values.get("extras") or "{}")
        return cls(**values)


_F = TypeVar("_F", bound=Callable[..., Any])


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


def _retrying(method: _F) -> _F:
    """Run a store method again while a database server is unreachable (SQLite: just once)."""

    @functools.wraps(method)
    def wrapper(self: JobStore, *args: Any, **kwargs: Any) -> Any:
        return self.db.retrying(lambda: method(self, *args, **kwargs))

    return wrapper  # type: ignore[return-value]


class JobStore:
    """Job, sweep and worker records, safe across processes and hosts; the jobs' files in ``storage``.

    ``database``: the SQLite file (a path), or an SQLAlchemy URL (``postgresql+psycopg://...``).
    ``storage``: default the job folders under ``jobs_dir``.
    """

    def __init__(
        self, database: Path | str, jobs_dir: Path, storage: Storage | None = None, *, keep_open: bool = False
    ) -> None:
        """``keep_open`` (SQLite): hold one connection for the life of this store (the API's), so that
        SQLite keeps its write-ahead log and shared-memory files: on a full disk, where they could not
        be made again, the records can still be read."""
        self.jobs_dir = Path(jobs_dir)
        self.host = socket.gethostname()
        self.storage = storage if storage is not None else LocalStorage(self.jobs_dir)
        self.db = Database(database)
        self.db_path = self.db.path
        self._kept: sqlite3.Connection | None = None
        if keep_open and self.db_path is not None:
            self._kept = sqlite3.connect(self.db_path, timeout=30.0, check_same_thread=False)
            self._kept.execute("SELECT 1 FROM jobs LIMIT 1").fetchall()  # opens the log files

    # -- plumbing -------------------------------------------------------------------------------

    def _connect(self) -> contextlib.AbstractContextManager[Any]:
        return self.db.connect()

    def _transaction(self) -> contextlib.AbstractContextManager[Any]:
        return self.db.transaction()

    def job_dir(self, job_id: str) -> Path:
        return self.jobs_dir / job_id

    def after_fork(self) -> None:
        """In a forked child: drop the parent's pooled database connections."""
        self.db.dispose()

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
        """Store the inputs and manifest (a new job folder), then insert the record as ``queued``.

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
        names, files = {}, {}
        for role, (filename, data) in inputs.items():
            suffix = Path(filename).suffix.lower()[:8] if filename else ""
            names[role] = f"{role}{suffix}"
            files[names[role]] = data
        # the quota's count: a sweep's shared upload is stored (and counted) once, by its first run
        written = 0 if share_inputs_of else sum(len(data) for data in files.values())
        now = time.time()
        manifest = {**manifest, "job_id": job_id, "inputs": names, "created": now}
        self.storage.save_inputs(job_id, files, manifest, share_inputs_of)
        self._insert_job(job_id, now, method, params, size, seed, names, sweep_id, owner, written, extras)
        record = self.get(job_id)
        assert record is not None
        return record

    @_retrying
    def _insert_job(
        self,
        job_id: str,
        now: float,
        method: str,
        params: dict[str, Any],
        size: dict[str, int] | None,
        seed: int,
        names: dict[str, str],
        sweep_id: str | None,
        owner: str | None,
        input_bytes: int,
        extras: dict[str, Any] | None,
    ) -> None:
        with self._connect() as db:
            db.execute(
                "INSERT INTO jobs (id, created, method, params, size, seed, inputs, sweep_id, state,"
                " updated, owner, input_bytes, extras)"
                " VALUES (?, ?, ?, ?, ?, ?, ?, ?, 'queued', ?, ?, ?, ?)",
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
                    input_bytes,
                    json.dumps({k: v for k, v in (extras or {}).items() if k in EXTRA_FIELDS}),
                ),
            )

    @_retrying
    def get(self, job_id: str) -> JobRecord | None:
        with self._connect() as db:
            row = db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if row is None else JobRecord.from_row(row)

    @_retrying
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

    @_retrying
    def count(self) -> int:
        with self._connect() as db:
            return db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]

    @_retrying
    def usage(self, owner: str | None) -> int:
        """Bytes the jobs of ``owner`` keep stored: inputs and artifacts (``None``: jobs made without
        a token). Records made before these were counted are measured from their folders first (a
        data directory; in an object store they count from then on)."""
        same = "IS NOT DISTINCT FROM" if self.db.postgres else "IS"
        with self._connect() as db:
            old = db.execute(
                f"SELECT id FROM jobs WHERE owner {same} ? AND (input_bytes IS NULL OR"
                " (artifact_bytes IS NULL AND state = 'succeeded'))",
                (owner,),
            ).fetchall()
            for row in old:
                job_id = row[0]
                local = self.storage.local
                inputs = _folder_bytes(self.job_dir(job_id) / "inputs") if local else 0
                artifacts = _folder_bytes(self.job_dir(job_id) / "out") if local else 0
                db.execute(
                    "UPDATE jobs SET input_bytes = ?, artifact_bytes = ? WHERE id = ?",
                    (inputs, artifacts, job_id),
                )
            return db.execute(
                "SELECT COALESCE(SUM(COALESCE(input_bytes, 0) + COALESCE(artifact_bytes, 0)), 0)"
                f" FROM jobs WHERE owner {same} ?",
                (owner,),
            ).fetchone()[0]

    @_retrying
    def count_active(self, owner: str | None) -> int:
        """Queued and running jobs of ``owner`` (``None``: those made without a token)."""
        same = "IS NOT DISTINCT FROM" if self.db.postgres else "IS"
        with self._connect() as db:
            return db.execute(
                f"SELECT COUNT(*) FROM jobs WHERE owner {same} ? AND state IN ('queued', 'running')", (owner,)
            ).fetchone()[0]

    # -- jobs: the worker's side ----------------------------------------------------------------

    @_retrying
    def mark_received(self, job_id: str, pid: int) -> None:
        """A worker's main process took the job's message off the broker (it may be lost with it)."""
        with self._connect() as db:
            db.execute(
                "UPDATE jobs SET received_host = ?, received_pid = ?, updated = ?"
                " WHERE id = ? AND state = 'queued'",
                (self.host, pid, time.time(), job_id),
            )

    @_retrying
    def claim(self, job_id: str, pid: int, stale_seconds: float) -> tuple[str | None, str]:
        """Start a run of ``job_id``: returns ``(run_token, '')``, or ``(None, why not)``.

        A queued job is claimed. A running job is taken over only when its run is dead (its process
        is gone on this machine, or its heartbeat is older than ``stale_seconds``): that is a
        re-delivery after a crash. Otherwise this delivery is a duplicate and does nothing.
        """
        now = time.time()
        with self._transaction() as db:
            row = db.execute("SELECT * FROM jobs WHERE id = ?" + self.db.for_update, (job_id,)).fetchone()
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

    @_retrying
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

    @_retrying
    def heartbeat(self, job_id: str, token: str) -> bool:
        with self._connect() as db:
            cur = db.execute(
                "UPDATE jobs SET heartbeat = ? WHERE id = ? AND run_token = ? AND state = 'running'",
                (time.time(), job_id, token),
            )
            return cur.rowcount == 1

    @_retrying
    def commit_success(
        self, job_id: str, token: str, staging: Path, artifacts: list[str], timings: dict, metrics: dict
    ) -> bool:
        """Make the run's staged (and published) artifacts the job's and mark it succeeded, if this
        run still owns it.

        Holding the database's write lock (PostgreSQL: the job's row lock) while swapping folders means
        no other run can commit (or be told it owns the job) in between: the job's artifacts always
        come from exactly one run. In an object store the swap is the ``artifacts_run`` column.
        """
        now = time.time()
        size = _folder_bytes(staging)
        with self._transaction() as db:
            row = db.execute(
                "SELECT 1 FROM jobs WHERE id = ? AND run_token = ? AND state = 'running'"
                " AND cancel_requested IS NULL" + self.db.for_update,
                (job_id, token),
            ).fetchone()
            if row is None:
                return False
            clean = self.storage.commit(job_id, token, staging)
            db.execute(
                "UPDATE jobs SET state = 'succeeded', stage = 'done', fraction = 1, finished = ?,"
                " updated = ?, artifacts = ?, timings = ?, metrics = ?, run_token = NULL,"
                " artifacts_run = ?, artifact_bytes = ? WHERE id = ?",
                (
                    now,
                    now,
                    json.dumps(artifacts),
                    json.dumps(timings),
                    json.dumps(metrics),
                    None if self.storage.local else token,
                    size,
                    job_id,
                ),
            )
        clean()
        return True

    @_retrying
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
            # (no MIN(a, b): PostgreSQL's is LEAST)
            " fraction = CASE WHEN ? = 'cancelled' AND fraction > ? THEN ? ELSE fraction END,"
            " finished = ?, updated = ?, run_token = NULL WHERE id = ? AND state IN ('queued', 'running')"
        )
        cap = CANCELLED_AT_MOST
        args: list[Any] = [state, message, state, state, state, cap, cap, now, now, job_id]
        if token is not None:
            query += " AND run_token = ?"
            args.append(token)
        with self._connect() as db:
            return db.execute(query, args).rowcount == 1

    # -- jobs: the API's and the reaper's side --------------------------------------------------

    @_retrying
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

    @_retrying
    def discard(self, job_ids: list[str], sweep_id: str | None = None) -> None:
        """Forget jobs that were never queued (the broker refused them): records, folders, their sweep.

        Only ``queued`` jobs that no worker received are removed, so a job that did reach a worker is
        never lost by this.
        """
        removed = []
        with self._transaction() as db:
            for job_id in job_ids:
                cur = db.execute(
                    "DELETE FROM jobs WHERE id = ? AND state = 'queued' AND received_pid IS NULL", (job_id,)
                )
                if cur.rowcount:
                    removed.append(job_id)
            if sweep_id is not None:
                db.execute("DELETE FROM sweeps WHERE id = ?", (sweep_id,))
        for job_id in removed:
            self.storage.delete(job_id)

    @_retrying
    def delete(self, job_id: str) -> bool:
        """Forget a finished job: its record, its folder (inputs, artifacts), and its sweep's record
        once the sweep has no job left. ``False`` if the job is not finished (or not there)."""
        with self._transaction() as db:
            row = db.execute(
                "SELECT sweep_id FROM jobs WHERE id = ? AND state IN ('succeeded', 'failed', 'cancelled')"
                + self.db.for_update,
                (job_id,),
            ).fetchone()
            if row is None:
                return False
            db.execute("DELETE FROM jobs WHERE id = ?", (job_id,))
            sweep_id = row["sweep_id"]
            if sweep_id and not db.execute("SELECT 1 FROM jobs WHERE sweep_id = ?", (sweep_id,)).fetchone():
                db.execute("DELETE FROM sweeps WHERE id = ?", (sweep_id,))
        self.storage.delete(job_id)
        return True

    @_retrying
    def expired(self, finished_before: float, limit: int = 500) -> list[str]:
        """Ids of jobs that ended before ``finished_before`` (oldest first, at most ``limit``)."""
        with self._connect() as db:
            rows = db.execute(
                "SELECT id FROM jobs WHERE state IN ('succeeded', 'failed', 'cancelled') AND finished < ?"
                " ORDER BY finished LIMIT ?",
                (finished_before, limit),
            ).fetchall()
        return [r["id"] for r in rows]

    def orphan_folders(self, older_than: float) -> list[str]:
        """Ids of job folders (objects) without a record, untouched since ``older_than`` (a run that
        outlived its job's deletion may leave one); fresh ones are skipped, their record may be on its
        way."""
        known = self._known_ids()
        return self.storage.orphans(known, older_than)

    @_retrying
    def _known_ids(self) -> set[str]:
        with self._connect() as db:
            return {r[0] for r in db.execute("SELECT id FROM jobs").fetchall()}

    @_retrying
    def requeue(self, job_id: str, message: str, seen: float | None = None) -> bool:
        """A run was lost: put the job back to ``queued`` (the caller sends a new message).

        ``seen``: the record's ``updated`` when the caller judged it lost; the job is re-queued only if
        nothing changed it since, so two reapers (two API processes) re-send a lost job once, and a
        run that reported meanwhile is left alone.
        """
        now = time.time()
        query = (
            "UPDATE jobs SET state = 'queued', stage = 'queued', fraction = 0, message = ?,"
            " run_token = NULL, received_host = NULL, received_pid = NULL, updated = ?"
            " WHERE id = ? AND state IN ('queued', 'running')"
        )
        args: list[Any] = [message, now, job_id]
        if seen is not None:
            query += " AND updated = ?"
            args.append(seen)
        with self._connect() as db:
            cur = db.execute(query, args)
            return cur.rowcount == 1

    @_retrying
    def active(self) -> list[JobRecord]:
        with self._connect() as db:
            rows = db.execute("SELECT * FROM jobs WHERE state IN ('queued', 'running')").fetchall()
        return [JobRecord.from_row(r) for r in rows]

    # -- sweeps -------------------------------------------------------------------------------------

    @_retrying
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

    @_retrying
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

    @_retrying
    def worker_heartbeat(self, name: str, pid: int, started: float) -> None:
        with self._connect() as db:
            db.execute(
                "INSERT INTO workers (name, host, pid, started, heartbeat) VALUES (?, ?, ?, ?, ?)"
                " ON CONFLICT(name) DO UPDATE SET host = excluded.host, pid = excluded.pid,"
                " started = excluded.started, heartbeat = excluded.heartbeat",
                (name, self.host, pid, started, time.time()),
            )

    @_retrying
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


def _folder_bytes(folder: Path) -> int:
    """Bytes of the files under ``folder`` (0 if absent); a file with several hard links counts its
    share (size / links), so a sweep's shared upload adds up to its size once over its runs."""
    total = 0
    for path in folder.rglob("*") if folder.is_dir() else ():
        with contextlib.suppress(OSError):
            info = path.stat()
            if path.is_file():
                total += info.st_size // max(1, info.st_nlink)
    return total

