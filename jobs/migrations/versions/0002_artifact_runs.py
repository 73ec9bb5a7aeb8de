"""Which run's uploaded objects are a job's artifacts (object storage).

Revision ID: 0002
Revises: 0001

With ``TEXSYNTH_STORAGE_URL=s3://...`` a run uploads its artifacts under its own key prefix
(``jobs/<id>/runs/<run token>/``) and the commit records that token here, in the same statement that
marks the job succeeded: the API serves only a run whose upload was complete. In a data directory the
committed run is the ``out/`` folder, and this column stays empty.
"""

from __future__ import annotations

from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.execute("ALTER TABLE jobs ADD COLUMN artifacts_run TEXT")


def downgrade() -> None:
    op.execute("ALTER TABLE jobs DROP COLUMN artifacts_run")
