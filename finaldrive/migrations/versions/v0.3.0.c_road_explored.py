"""each road's explored ranges kept by the writer; the a2 index of /best dropped

``road_explored``: a job's successful evaluations on a road grouped by a2 in 1 deg buckets (-1: on
the pivot), with each group's count and ranges, updated by each store of results. /best reads the
explored ranges there. ``ix_evaluations_job_road_a2`` (eight columns, inserted at a random place for
every evaluation) served only those ranges and cost the store's ingest: ``bench/bench_commit.py``
stores 1.31x as many evaluations a second without it (docs/performance-log.md, issue 27). Existing jobs'
ranges are computed here from their evaluations.

Revision ID: v0.3.0.c
Revises: v0.3.0.b
Create Date: 2026-12-04 23:30:00.000000
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.3.0.c'
down_revision: str | None = 'v0.3.0.b'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

#: the designs on the pivot (engine CONCENTRIC_L2_M), and a2 in [0, 360) deg: as summaries.py at this revision
_CONCENTRIC_L2_M = 1e-4
_X = "(a2_deg - 360.0 * floor(a2_deg / 360.0))"
_BUCKET = f"CASE WHEN l2_m > {_CONCENTRIC_L2_M!r} THEN CAST(floor({_X}) AS INTEGER) ELSE -1 END"


def upgrade() -> None:
    op.create_table(
        'road_explored',
        sa.Column('job_id', sa.Integer(), sa.ForeignKey('jobs.id', ondelete='CASCADE'), primary_key=True),
        sa.Column('road_index', sa.Integer(), primary_key=True),
        sa.Column('bucket', sa.Integer(), primary_key=True),
        sa.Column('n', sa.Integer(), nullable=False),
        *(sa.Column(name, sa.Float(), nullable=False) for name in (
            'a2_lo_deg', 'a2_hi_deg', 'l2_lo_m', 'l2_hi_m', 'rws_lo_m', 'rws_hi_m', 'fitness_lo_m', 'fitness_hi_m')),
    )
    bind = op.get_bind()
    if bind.dialect.name == "sqlite" and bind.exec_driver_sql(
            "SELECT COUNT(*) FROM pragma_function_list WHERE name = 'floor'").scalar() == 0:
        raw = bind.connection.driver_connection
        assert raw is not None
        raw.create_function("floor", 1, math.floor, deterministic=True)
    op.execute(
        "INSERT INTO road_explored (job_id, road_index, bucket, n, a2_lo_deg, a2_hi_deg, l2_lo_m, l2_hi_m, rws_lo_m, "
        f"rws_hi_m, fitness_lo_m, fitness_hi_m) SELECT job_id, road_index, {_BUCKET} AS b, COUNT(*), MIN({_X}), "
        f"MAX({_X}), MIN(l2_m), MAX(l2_m), MIN(rws_m), MAX(rws_m), MIN(fitness_m), MAX(fitness_m) FROM evaluations "
        "WHERE status = 'ok' AND fitness_m IS NOT NULL GROUP BY job_id, road_index, b")
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.drop_index('ix_evaluations_job_road_a2')


def downgrade() -> None:
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.create_index('ix_evaluations_job_road_a2', ['job_id', 'road_index', 'status', 'a2_deg', 'l2_m',
                                                             'rws_m', 'fitness_m', 'distance_m'], unique=False)
    op.drop_table('road_explored')
