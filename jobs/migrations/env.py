"""Alembic's environment for the job records: run by :func:`texsynth.jobs.db.migrate` with an open connection.

Every texsynth process migrates on start, so there is no command to run by hand; ``script.py.mako``
is the template of a new revision (``alembic revision -m "..."`` with this folder as script location).
"""

from __future__ import annotations

from alembic import context

connection = context.config.attributes.get("connection")
if connection is None:
    raise RuntimeError("jobs/migrations runs from texsynth.jobs.db.migrate(), which passes the connection")
context.configure(connection=connection, target_metadata=None)
with context.begin_transaction():
    context.run_migrations()
