"""the result cache's and /best's lookups as index tables of levels

``cache_index`` (level, cache_hash, slot) and ``fitness_index`` (level, job_id, road_index,
fitness_m, step, candidate) replace the indexes ``ix_evaluations_cache_hash`` and
``ix_evaluations_job_road_fitness``, whose keys arrive in random order and made each stored
batch dirty pages all over them (finaldrive.service.db.levels). Stored evaluations are indexed at
level 3, the last.

Revision ID: v0.3.0.e
Revises: v0.3.0.d
Create Date: 2026-12-06 15:00:00.000000
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.3.0.e'
down_revision: str | None = 'v0.3.0.d'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_SLOT = ("job_id", "road_index", "step", "candidate")


def upgrade() -> None:
    op.create_table(
        'cache_index',
        sa.Column('level', sa.SmallInteger(), nullable=False),
        sa.Column('cache_hash', sa.BigInteger(), nullable=False),
        *(sa.Column(name, sa.Integer(), nullable=False) for name in _SLOT),
        sa.PrimaryKeyConstraint('level', 'cache_hash', *_SLOT),
        sqlite_with_rowid=False)
    op.create_table(
        'fitness_index',
        sa.Column('level', sa.SmallInteger(), nullable=False),
        sa.Column('job_id', sa.Integer(), nullable=False),
        sa.Column('road_index', sa.Integer(), nullable=False),
        sa.Column('fitness_m', sa.Float(), nullable=False),
        sa.Column('step', sa.Integer(), nullable=False),
        sa.Column('candidate', sa.Integer(), nullable=False),
        sa.PrimaryKeyConstraint('level', 'job_id', 'road_index', 'fitness_m', 'step', 'candidate'),
        sqlite_with_rowid=False)
    op.execute("INSERT INTO cache_index (level, cache_hash, job_id, road_index, step, candidate) "
               "SELECT 3, cache_hash, job_id, road_index, step, candidate FROM evaluations "
               "ORDER BY cache_hash, job_id, road_index, step, candidate")
    op.execute("INSERT INTO fitness_index (level, job_id, road_index, fitness_m, step, candidate) "
               "SELECT 3, job_id, road_index, fitness_m, step, candidate FROM evaluations "
               "WHERE status = 'ok' AND fitness_m IS NOT NULL ORDER BY job_id, road_index, fitness_m, step, candidate")
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.drop_index('ix_evaluations_cache_hash')
        batch_op.drop_index('ix_evaluations_job_road_fitness')


def downgrade() -> None:
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.create_index('ix_evaluations_job_road_fitness', ['job_id', 'road_index', 'status', 'fitness_m'],
                              unique=False)
        batch_op.create_index('ix_evaluations_cache_hash', ['cache_hash'], unique=False)
    op.drop_table('fitness_index')
    op.drop_table('cache_index')
