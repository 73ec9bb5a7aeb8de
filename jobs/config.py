"""One ``Settings`` object shared by the API, the worker and ``texsynth serve``.

Every value comes from an environment variable (``TEXSYNTH_*``, plus ``REDIS_URL``) or its default,
so the API process and every worker process on every machine read the same configuration. With no
``REDIS_URL`` the service runs on the embedded default: Celery's filesystem transport and an SQLite
result backend, both under the data directory. ``TEXSYNTH_DATABASE_URL`` and ``TEXSYNTH_STORAGE_URL``
move the job records and files off it (docs/deploy.md).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ConfigDict, Field

from texsynth.synth.io.limits import LIMITS, limit_from_env
from texsynth.synth.threads import THREADS_ENV, service_threads

if TYPE_CHECKING:
    from texsynth.jobs.store import JobStore

__all__ = ["Settings"]

_ENV_PREFIX = "TEXSYNTH_"
_LISTS = ("extra_methods", "allowed_origins", "allowed_hosts")


class Settings(BaseModel):
    """Configuration of the job service; :meth:`from_env` is the one way the processes build it."""

    model_config = ConfigDict(frozen=True)

    data_dir: Path = Field(Path("data"), description="job inputs, artifacts, job records, embedded broker")
    redis_url: str | None = Field(None, description="Redis for broker and results; unset = embedded default")
    database_url: str | None = Field(
        None,
        repr=False,
        description="SQLAlchemy URL of the job records (postgresql+psycopg://...); unset = the SQLite file",
    )
    storage_url: str | None = Field(
        None, description="s3://bucket/prefix for inputs and artifacts; unset = the data directory"
    )
    # Input limits: checked by the API before anything is stored or queued, and by the worker again.
    # The image limits are texsynth.synth.io.limits': their defaults and their variables are written there.
    max_body_bytes: int = Field(32 * 2**20, description="largest accepted request body (HTTP 413 above)")
    max_input_pixels: int = Field(
        LIMITS["max_input_pixels"].default, description="largest accepted exemplar/constraint (413 above)"
    )
    max_output_pixels: int = Field(
        LIMITS["max_output_pixels"].default, description="largest output width*height"
    )
    max_output_voxels: int = Field(
        LIMITS["max_output_voxels"].default,
        description="largest output volume width*height*depth (then the memory and time estimates decide)",
    )
    max_sweep_runs: int = Field(64, description="largest parameter grid of one sweep (runs)")
    # Admission control (app/admission.py): per owner (token name; everyone together without tokens).
    max_queued_per_token: int = Field(
        100, description="queued + running jobs one token may have at once (HTTP 429 above)"
    )
    max_sweep_pixels: int = Field(
        4 * 4096 * 4096, description="output pixels (voxels) of all runs of one sweep together"
    )
    max_job_memory_bytes: int = Field(
        4 * 2**30, description="largest estimated working memory of one job (HTTP 422 above)"
    )
    max_input_output_ratio: int = Field(
        64, description="an exemplar above 512x512 may have at most this many times the output's pixels"
    )
    # Tokens and ownership (app/auth.py). No tokens: one anonymous owner, the API binds to loopback.
    api_tokens: str | None = Field(None, repr=False, description="comma-separated name:token[:admin] entries")
    api_token_file: Path | None = Field(None, description="a file of name:token[:admin] lines")
    admin_token: str | None = Field(None, repr=False, description="a token that sees and manages every job")
    allowed_origins: tuple[str, ...] = Field(
        (), description="other origins (scheme://host[:port]) whose pages may POST/DELETE (a proxy)"
    )
    allowed_hosts: tuple[str, ...] = Field(
        (),
        description="host names (Host header) this service answers to besides localhost names, IP addresses "
        "and this machine's name: 'lab.example', '.example' for every subdomain, '*' for any",
    )
    token_quota_bytes: int = Field(
        10 * 2**30,
        ge=0,
        description="bytes of inputs and artifacts one token may keep stored (0: no quota; without "
        "tokens, everyone together); a token file entry may give its own",
    )
    # Connections (app/server.py): slow or idle clients are closed, and the open connections capped.
    client_timeout: float = Field(
        15.0,
        gt=0.0,
        description="seconds a client has to send a request's head, and may pause inside its body",
    )
    max_connections: int = Field(
        256, ge=1, description="open connections the API serves at once (HTTP 503 above)"
    )
    signed_url_seconds: int = Field(
        3600, description="lifetime of the signed file URLs (artifacts, inputs) given to token holders"
    )
    # Retention: the reaper deletes finished jobs (files and records) this long after they ended.
    retention_days: float = Field(30.0, description="days a finished job is kept; 0 keeps jobs forever")
    # Worker: long CPU tasks, at-least-once delivery (DESIGN.md "Queue and storage").
    soft_time_limit: int = Field(1800, description="seconds before the job is asked to stop (fails)")
    hard_time_limit: int = Field(1860, description="seconds before the worker child is killed")
    concurrency: int = Field(max(1, os.cpu_count() or 1), description="worker processes")
    threads: int | None = Field(
        None, ge=1, description="threads of one job; default the cores divided between the worker processes"
    )
    worker_nice: int = Field(5, description="niceness of worker children, keeps the API responsive")
    max_attempts: int = Field(3, description="runs of one job (worker lost -> re-run) before it fails")
    heartbeat_seconds: float = Field(1.0, description="how often a running job proves it is alive")
    stale_seconds: float = Field(10.0, description="a run silent this long is dead (other machines)")
    cancel_grace_seconds: float = Field(2.0, description="after this, a cancel terminates the worker child")
    shutdown_grace: float = Field(
        30.0,
        ge=0.0,
        description="seconds a stopping worker gives its running jobs; then, or at a second signal, it exits",
    )
    resend_seconds: float = Field(
        30.0,
        description="a queued job that no worker received this long while workers have room is sent again",
    )
    extra_methods: tuple[str, ...] = Field((), description="modules imported to register more methods")

    def max_output(self, ndim: int) -> int:
        """The output limit of an image (``ndim`` 2) or a volume (3)."""
        return self.max_output_voxels if ndim == 3 else self.max_output_pixels

    @classmethod
    def from_env(cls, environ: dict[str, str] | None = None, **overrides: Any) -> Settings:
        """Build from ``TEXSYNTH_<NAME>`` variables (``TEXSYNTH_DATA_DIR``, ...) and ``REDIS_URL``; the
        size limits from their variables in :data:`texsynth.synth.io.limits.LIMITS`. ``threads`` always comes
        out a number (:func:`texsynth.synth.threads.service_threads`); a bad ``TEXSYNTH_THREADS`` raises
        :class:`texsynth.synth.errors.InvalidParameter`."""
        env = os.environ if environ is None else environ
        values: dict[str, Any] = {}
        threads = overrides.pop("threads", None) or env.get(THREADS_ENV)
        for name in cls.model_fields:
            if name == "threads":
                continue
            if name in LIMITS:
                found = limit_from_env(name, env)
                if found is not None:
                    values[name] = found[1]
                continue
            raw = env.get(_ENV_PREFIX + name.upper())
            if raw is not None and raw != "":
                values[name] = (
                    tuple(m.strip() for m in raw.split(",") if m.strip()) if name in _LISTS else raw
                )
        if env.get("REDIS_URL"):
            values.setdefault("redis_url", env["REDIS_URL"])
        values.update({k: v for k, v in overrides.items() if v is not None})
        settings = cls.model_validate(values)
        return settings.model_copy(
            update={
                "data_dir": settings.data_dir.expanduser().resolve(),
                "threads": service_threads(settings.concurrency, threads),  # InvalidParameter at start
            }
        )

    def to_env(self) -> dict[str, str]:
        """The environment that makes :meth:`from_env` rebuild these settings in a child process."""
        env = {}
        for name, value in self.model_dump().items():
            if name == "redis_url":
                if value:
                    env["REDIS_URL"] = value
                continue
            if value is None:
                continue
            if name in _LISTS:
                value = ",".join(value)
            env[LIMITS[name].env if name in LIMITS else _ENV_PREFIX + name.upper()] = str(value)
        return env

    @property
    def embedded(self) -> bool:
        return not self.redis_url

    @property
    def jobs_dir(self) -> Path:
        return self.data_dir / "jobs"

    @property
    def db_path(self) -> Path:
        return self.data_dir / "jobs.sqlite"

    @property
    def database(self) -> Path | str:
        """What :class:`texsynth.jobs.store.JobStore` opens: the URL, or the SQLite file of the data
        directory."""
        return self.database_url or self.db_path

    def where(self) -> str:
        """Where records and files live, for a start-up line (no password): '' for the data directory."""
        parts = []
        if self.database_url:
            from sqlalchemy.engine import make_url

            parts.append(f"records {make_url(self.database_url).render_as_string(hide_password=True)}")
        if self.storage_url:
            parts.append(f"files {self.storage_url}")
        return "; ".join(parts)

    @property
    def scratch_dir(self) -> Path:
        """This machine's own folder for a run's inputs and artifacts before upload (object storage)."""
        return self.data_dir / "scratch"

    def open_store(self, *, keep_open: bool = False) -> JobStore:
        """The job store these settings name (records and files); imported here to keep config light."""
        from texsynth.jobs.storage import open_storage
        from texsynth.jobs.store import JobStore

        storage = open_storage(self.storage_url, self.jobs_dir, self.scratch_dir)
        return JobStore(self.database, self.jobs_dir, storage, keep_open=keep_open)

    @property
    def broker_dir(self) -> Path:
        return self.data_dir / "broker"

    def ensure_dirs(self) -> None:
        for folder in (
            self.jobs_dir,
            self.broker_dir / "queue",
            self.broker_dir / "control",
            self.broker_dir / "processed",
        ):
            folder.mkdir(parents=True, exist_ok=True)
