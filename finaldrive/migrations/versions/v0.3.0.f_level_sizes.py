"""the index tables' levels moved a chunk at a time: a fifth level, and each level's size kept

``index_levels`` (index_table, level, entries) holds how many entries each level from 1 on of
``cache_index`` and ``fitness_index`` holds, counted here from the stored entries; each move
changes it (finaldrive.service.db.levels). Level 3 is no longer the last: a level 4 takes it over
a chunk at a time. Downgrading puts level 4's entries back on level 3, the last before.

Revision ID: v0.3.0.f
Revises: v0.3.0.e
Create Date: 2026-12-06 18:00:00.000000
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.3.0.f'
down_revision: str | None = 'v0.3.0.e'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_TABLES = ("cache_index", "fitness_index")
_LEVELS = 5


def upgrade() -> None:
    sizes = op.create_table(
        'index_levels',
        sa.Column('index_table', sa.String(length=32), nullable=False),
        sa.Column('level', sa.SmallInteger(), nullable=False),
        sa.Column('entries', sa.BigInteger(), nullable=False),
        sa.PrimaryKeyConstraint('index_table', 'level'))
    connection = op.get_bind()
    op.bulk_insert(sizes, [
        {"index_table": table, "level": level,
         "entries": connection.scalar(sa.text(f"SELECT COUNT(*) FROM {table} WHERE level = :level"), {"level": level})}
        for table in _TABLES for level in range(1, _LEVELS)])


def downgrade() -> None:
    for table in _TABLES:
        op.execute(f"UPDATE {table} SET level = 3 WHERE level = 4")
    op.drop_table('index_levels')
