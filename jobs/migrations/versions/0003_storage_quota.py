"""What each job keeps stored, for the storage quota per token.

Revision ID: 0003
Revises: 0002

``input_bytes`` is what a submission stored (a sweep's shared upload counts for its first run only),
``artifact_bytes`` what its committed run's artifacts hold; :meth:`texsynth.jobs.store.JobStore.usage` sums
them per owner. Records made before this revision keep NULL here and are measured from their job
folders the first time their owner's usage is asked.
"""

from __future__ import annotations

from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.execute("ALTER TABLE jobs ADD COLUMN input_bytes BIGINT")
    op.execute("ALTER TABLE jobs ADD COLUMN artifact_bytes BIGINT")
    op.execute("CREATE INDEX IF NOT EXISTS jobs_owner ON jobs(owner, state)")


def downgrade() -> None:
    op.execute("DROP INDEX IF EXISTS jobs_owner")
    op.execute("ALTER TABLE jobs DROP COLUMN artifact_bytes")
    op.execute("ALTER TABLE jobs DROP COLUMN input_bytes")
