"""a scheduler's load, for /v1/health and for claiming jobs by free capacity

``schedulers``: ``tasks_per_s``, ``evaluations_per_s`` and ``busy_share`` over its last heartbeat
interval, and ``in_flight_tasks`` and ``backlog_designs`` at that heartbeat (workers/dispatch.py,
``Load``); null until its first heartbeat with them.

Revision ID: v0.3.0.d
Revises: v0.3.0.c
Create Date: 2026-12-05 18:00:00.000000
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.3.0.d'
down_revision: str | None = 'v0.3.0.c'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_COLUMNS = (("tasks_per_s", sa.Float), ("evaluations_per_s", sa.Float), ("busy_share", sa.Float),
            ("in_flight_tasks", sa.Integer), ("backlog_designs", sa.Integer))


def upgrade() -> None:
    with op.batch_alter_table('schedulers') as batch:
        for name, kind in _COLUMNS:
            batch.add_column(sa.Column(name, kind(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('schedulers') as batch:
        for name, _ in reversed(_COLUMNS):
            batch.drop_column(name)
