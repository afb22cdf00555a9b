"""scheduler leases, scheduler heartbeats, cost estimates, transient failures

Jobs and recordings get an owner and a lease (judged on the database's clock); schedulers report
their heartbeats; a recording's .rrd file is stored with it (any scheduler may produce it); a job stores its estimated cost; an evaluation carries the run's extremes and energy ledger; an evaluation that failed for a reason
that may not recur (a time limit, a lost worker) is marked transient and never reused from the result cache.

Revision ID: v0.2.0.a
Revises: v0.1.0.a
Create Date: 2026-11-26 02:03:47.952550
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

#: The run's extremes and energy ledger as of this revision (finaldrive.engine.DIAGNOSTICS), frozen
#: here so that the migration does not change when the engine's list does.
DIAGNOSTICS = (
    "chain_tension_max_n", "chain_tension_min_n", "chain_compression_s", "fz_rear_max_n", "fz_rear_min_n",
    "fz_front_max_n", "fz_front_min_n", "slip_max", "airborne_rear_s", "airborne_front_s",
    "tyre_compression_rear_max_m", "tyre_compression_front_max_m", "drive_work_j", "kinetic_energy_j",
    "potential_energy_j", "damper_dissipation_j", "tyre_slip_work_j", "tyre_carcass_energy_j", "tyre_dissipation_j",
    "tyre_lever_work_j", "ledger_residual_j", "tyre_dissipation_min_w",
)


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
        for name in DIAGNOSTICS:
            batch_op.add_column(sa.Column(name, sa.Float(), nullable=True))

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
        for name in reversed(DIAGNOSTICS):
            batch_op.drop_column(name)
        batch_op.drop_column('transient')

    op.drop_table('schedulers')
