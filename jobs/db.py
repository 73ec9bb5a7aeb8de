"""The job records' database: today's SQLite file, or a server named by an SQLAlchemy URL.

``TEXSYNTH_DATABASE_URL`` unset: the SQLite file under the data directory, opened exactly as before
(WAL, a new connection per operation, ``BEGIN IMMEDIATE`` for the few read-then-write steps). Set to
``postgresql+psycopg://user:password@host/db``: PostgreSQL through psycopg 3 (``texsynth[cluster]``),
with a small connection pool that checks a connection before use, so a restarted server costs one
failed attempt, which :meth:`Database.retrying` repeats for up to ``retry_seconds``.

The store's SQL is written once, with ``?`` placeholders; :meth:`Connection.execute` turns them into
psycopg's ``%s``. Read-then-write steps run in :meth:`Database.transaction`, which on PostgreSQL locks
the rows read with ``FOR UPDATE`` (the store appends :attr:`Database.for_update`).

The schema is Alembic's (``jobs/migrations``): every process that opens the database brings it to the
newest revision first (:func:`migrate`), one at a time (SQLite's write lock, PostgreSQL's advisory
lock), so an upgrade keeps every record. A data directory made before the migrations existed is
upgraded in place: the first revision creates only what is missing.
"""

from __future__ import annotations

import contextlib
import sqlite3
import time
import weakref
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

__all__ = ["HEAD", "Connection", "Database", "migrate"]

#: The newest migration (``jobs/migrations/versions``); a test checks it is Alembic's head.
HEAD = "0004"
#: Key of the PostgreSQL advisory lock held while migrating (any constant shared by all processes).
_MIGRATE_LOCK = 0x7465787379
_T = TypeVar("_T")


class _Row(dict):
    """A PostgreSQL row that reads like :class:`sqlite3.Row`: by column name and by position."""

    def __getitem__(self, key: Any) -> Any:
        if isinstance(key, int):
            return list(self.values())[key]
        return super().__getitem__(key)


def _row_factory(cursor: Any) -> Callable[[Sequence[Any]], _Row]:
    names = [column.name for column in cursor.description or ()]
    return lambda values: _Row(zip(names, values, strict=True))


class Connection:
    """A PostgreSQL connection that takes the store's ``?`` SQL (SQLite connections are used as is)."""

    def __init__(self, raw: Any) -> None:
        self.raw = raw

    def execute(self, sql: str, args: Sequence[Any] = ()) -> Any:
        cursor = self.raw.cursor(row_factory=_row_factory)
        cursor.execute(sql.replace("?", "%s"), tuple(args))
        return cursor


class Database:
    """Connections to the job records' database; ``target`` is a file path or an SQLAlchemy URL."""

    def __init__(self, target: Path | str, retry_seconds: float = 60.0) -> None:
        self.retry_seconds = retry_seconds
        self.engine: Any = None
        text = str(target)
        if isinstance(target, Path) or "://" not in text:
            self.dialect, self.path = "sqlite", Path(target)
        else:
            from sqlalchemy.engine import make_url

            url = make_url(text)
            backend = url.get_backend_name()
            if backend == "sqlite":
                if not url.database or url.database == ":memory:":
                    raise ValueError(f"TEXSYNTH_DATABASE_URL: an SQLite URL needs a file, got {text!r}")
                self.dialect, self.path = "sqlite", Path(url.database)
            elif backend == "postgresql":
                if url.get_driver_name() != "psycopg":
                    raise ValueError(
                        "TEXSYNTH_DATABASE_URL: use the psycopg 3 driver, postgresql+psycopg://..., "
                        f"not {url.drivername!r}"
                    )
                try:
                    import psycopg  # noqa: F401
                except ImportError:
                    raise ValueError(
                        "TEXSYNTH_DATABASE_URL names PostgreSQL, but psycopg is not installed: "
                        "pip install 'texsynth[cluster]'"
                    ) from None
                from sqlalchemy import create_engine

                self.dialect, self.path = "postgresql", None
                self.engine = create_engine(url, pool_pre_ping=True, pool_size=4, max_overflow=8)
                # the pooled connections are closed when this object goes (psycopg warns otherwise)
                weakref.finalize(self, self.engine.dispose)
            else:
                raise ValueError(
                    f"TEXSYNTH_DATABASE_URL: {backend!r} is not supported; use an SQLite file or "
                    "postgresql+psycopg://user:password@host/database"
                )
        migrate(self)

    @property
    def postgres(self) -> bool:
        return self.dialect == "postgresql"

    @property
    def for_update(self) -> str:
        """Appended to a SELECT in :meth:`transaction` that is followed by writes to the same rows."""
        return " FOR UPDATE" if self.postgres else ""

    @property
    def transient(self) -> tuple[type[BaseException], ...]:
        """Errors that mean the server is (briefly) unreachable: the operation is tried again."""
        if not self.postgres:
            return ()
        import psycopg
        from sqlalchemy.exc import DBAPIError

        return (psycopg.OperationalError, DBAPIError)

    def dispose(self) -> None:
        """Drop pooled connections (after a fork: a child never uses its parent's sockets)."""
        if self.engine is not None:
            self.engine.dispose(close=False)

    def close(self) -> None:
        """Close the pooled connections (a server database); the next use opens new ones."""
        if self.engine is not None:
            self.engine.dispose()

    @contextlib.contextmanager
    def connect(self) -> Iterator[Any]:
        """A connection for independent statements (SQLite: autocommit; PostgreSQL: one transaction)."""
        if not self.postgres:
            assert self.path is not None
            db = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
            db.row_factory = sqlite3.Row
            db.execute("PRAGMA busy_timeout=30000")
            db.execute("PRAGMA synchronous=NORMAL")
            try:
                yield db
            finally:
                db.close()
            return
        raw = self.engine.raw_connection()
        try:
            yield Connection(raw)
            raw.commit()
        except BaseException:
            with contextlib.suppress(Exception):
                raw.rollback()
            raise
        finally:
            raw.close()

    @contextlib.contextmanager
    def transaction(self) -> Iterator[Any]:
        """One atomic read-then-write step (SQLite: the write lock from the start)."""
        if self.postgres:
            with self.connect() as db:
                yield db
            return
        with self.connect() as db:
            db.execute("BEGIN IMMEDIATE")
            try:
                yield db
            except BaseException:
                db.execute("ROLLBACK")
                raise
            db.execute("COMMIT")

    def retrying(self, operation: Callable[[], _T]) -> _T:
        """``operation()``, tried again while the server is unreachable (at most ``retry_seconds``)."""
        transient = self.transient
        if not transient:
            return operation()
        deadline = time.monotonic() + self.retry_seconds
        pause = 0.1
        while True:
            try:
                return operation()
            except transient:
                if time.monotonic() + pause > deadline:
                    raise
                time.sleep(pause)
                pause = min(2.0, pause * 2)


def _version(db: Any) -> str | None:
    try:
        row = db.execute("SELECT version_num FROM alembic_version").fetchone()
    except Exception:
        return None
    return None if row is None else row[0]


def _write_ahead_log(db: sqlite3.Connection, wait: float = 30.0) -> None:
    """Put the SQLite file in WAL mode. The switch needs the file to itself and SQLite does not call
    the busy handler for it: a process that starts beside another gets "database is locked" at once,
    so the switch is tried again, for up to ``wait`` seconds, until it holds or another process made it."""
    deadline = time.monotonic() + wait
    while True:
        try:
            if db.execute("PRAGMA journal_mode").fetchone()[0] == "wal":
                return
            db.execute("PRAGMA journal_mode=WAL")
            return
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() > deadline:
                raise
            time.sleep(0.02)


def migrate(database: Database) -> None:
    """Bring the schema to :data:`HEAD` with Alembic, unless it is there already (the usual case)."""
    if database.postgres:
        with database.connect() as db:
            if _version(db) == HEAD:
                return
    else:
        with database.connect() as db:
            _write_ahead_log(db)
            if _version(db) == HEAD:
                return
    from alembic import command
    from alembic.config import Config
    from sqlalchemy import create_engine, text
    from sqlalchemy.pool import NullPool

    config = Config()
    config.set_main_option("script_location", str(Path(__file__).with_name("migrations")))
    if database.postgres:
        engine = database.engine
    else:
        path = database.path

        def creator() -> sqlite3.Connection:
            return sqlite3.connect(path, timeout=30.0, isolation_level=None)

        engine = create_engine("sqlite://", creator=creator, poolclass=NullPool)
    with engine.connect() as connection:
        if database.postgres:
            connection.execute(text("SELECT pg_advisory_lock(:key)"), {"key": _MIGRATE_LOCK})
        else:
            connection.exec_driver_sql("PRAGMA busy_timeout=30000")
            connection.exec_driver_sql("BEGIN IMMEDIATE")  # one migrating process at a time
        try:
            config.attributes["connection"] = connection
            command.upgrade(config, "head")
            if not database.postgres:
                connection.exec_driver_sql("COMMIT")
            connection.commit()
        except BaseException:
            if not database.postgres:
                with contextlib.suppress(Exception):
                    connection.exec_driver_sql("ROLLBACK")
            raise
        finally:
            if database.postgres:
                connection.execute(text("SELECT pg_advisory_unlock(:key)"), {"key": _MIGRATE_LOCK})
                connection.commit()
