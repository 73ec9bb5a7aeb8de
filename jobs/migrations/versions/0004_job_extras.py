"""What a job keeps beside its parameters, for the page: input file names, voxel size and unit.

Revision ID: 0004
Revises: 0003

One JSON text column, ``extras`` (:data:`texsynth.jobs.store.EXTRA_FIELDS`); records made before it read as
``{}``.
"""

from __future__ import annotations

from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.execute("ALTER TABLE jobs ADD COLUMN extras TEXT")


def downgrade() -> None:
    op.execute("ALTER TABLE jobs DROP COLUMN extras")
