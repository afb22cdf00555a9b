"""indexes on each road's evaluations by fitness and by a2, for /best

``ix_evaluations_job_road_fitness`` (job_id, road_index, status, fitness_m): a road's best fitness
is one index seek and its near-optimal set (fitness at least the best less a tolerance) one range
of the index. ``ix_evaluations_job_road_a2`` (job_id, road_index, status, a2_deg, l2_m, rws_m,
fitness_m, distance_m): the explored range of a2 is found by two seeks a 1 deg bucket, and the
other ranges by scans of the index alone (never of the table).

Revision ID: v0.3.0.b
Revises: v0.3.0.a
Create Date: 2026-12-04 21:00:00.000000
"""

from __future__ import annotations

from collections.abc import Sequence

from alembic import op

revision: str = 'v0.3.0.b'
down_revision: str | None = 'v0.3.0.a'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.create_index('ix_evaluations_job_road_fitness', ['job_id', 'road_index', 'status', 'fitness_m'],
                              unique=False)
        batch_op.create_index('ix_evaluations_job_road_a2', ['job_id', 'road_index', 'status', 'a2_deg', 'l2_m',
                                                             'rws_m', 'fitness_m', 'distance_m'], unique=False)


def downgrade() -> None:
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.drop_index('ix_evaluations_job_road_a2')
        batch_op.drop_index('ix_evaluations_job_road_fitness')
