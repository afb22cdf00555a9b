"""scheduler leases, scheduler heartbeats, cost estimates, transient failures

Jobs and recordings get an owner and a lease (judged on the database's clock); schedulers report
their heartbeats; a recording's .rrd file is stored with it (any scheduler may produce it); a job stores its estimated cost; an evaluation that failed for a reason that may
not recur (a time limit, a lost worker) is marked transient and never reused from the result cache.

Revision ID: v0.2.0.a
Revises: v0.1.0.a
Create Date: 2026-11-26 02:03:47.952550
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op


revision: str = 'v0.2.0.a'
down_revision: str | None = 'v0.1.0.a'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table('schedulers',
    sa.Column('id', sa.String(length=64), nullable=False),
    sa.Column('host', sa.String(length=255), nullable=False),
    sa.Column('pid', sa.Integer(), nullable=False),
    sa.Column('executor', sa.String(length=16), nullable=False),
    sa.Column('capacity', sa.Integer(), nullable=False),
    sa.Column('started_at', sa.DateTime(), nullable=False),
    sa.Column('heartbeat_at', sa.DateTime(), nullable=False),
    sa.Column('stopped_at', sa.DateTime(), nullable=True),
    sa.PrimaryKeyConstraint('id')
    )
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.add_column(sa.Column('transient', sa.Boolean(), nullable=False, server_default=sa.false()))

    with op.batch_alter_table('jobs', schema=None) as batch_op:
        batch_op.add_column(sa.Column('cost_cpu_s', sa.Float(), nullable=True))
        batch_op.add_column(sa.Column('owner', sa.String(length=64), nullable=True))
        batch_op.add_column(sa.Column('lease_until', sa.DateTime(), nullable=True))
        batch_op.create_index('ix_jobs_owner', ['owner'], unique=False)

    with op.batch_alter_table('recordings', schema=None) as batch_op:
        batch_op.drop_column('path')
        batch_op.add_column(sa.Column('content', sa.LargeBinary(), nullable=True))
        batch_op.add_column(sa.Column('size_bytes', sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column('owner', sa.String(length=64), nullable=True))
        batch_op.add_column(sa.Column('lease_until', sa.DateTime(), nullable=True))



def downgrade() -> None:
    with op.batch_alter_table('recordings', schema=None) as batch_op:
        batch_op.drop_column('lease_until')
        batch_op.drop_column('owner')
        batch_op.drop_column('size_bytes')
        batch_op.drop_column('content')
        batch_op.add_column(sa.Column('path', sa.Text(), nullable=True))

    with op.batch_alter_table('jobs', schema=None) as batch_op:
        batch_op.drop_index('ix_jobs_owner')
        batch_op.drop_column('lease_until')
        batch_op.drop_column('owner')
        batch_op.drop_column('cost_cpu_s')

    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.drop_column('transient')

    op.drop_table('schedulers')
