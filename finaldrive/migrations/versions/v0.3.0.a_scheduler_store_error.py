"""a scheduler's failing result writes, for /v1/health

``schedulers.store_error``: why the scheduler's last result write failed (the database's message,
no SQL), cleared by its next one that passes. A full disk fails result transactions while small
ones (heartbeats, the health probe) still pass; /v1/health reads this column to say so at once.

Revision ID: v0.3.0.a
Revises: v0.2.0.e
Create Date: 2026-12-04 20:40:00.000000
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.3.0.a'
down_revision: str | None = 'v0.2.0.e'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table('schedulers') as batch:
        batch.add_column(sa.Column('store_error', sa.String(length=500), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('schedulers') as batch:
        batch.drop_column('store_error')
