"""measured road profiles uploaded to the service

A table of road profiles (POST /v1/roads), each stored once per content: its points, their
extent, and the sha256 of the points that jobs naming ``profile:ID`` carry into the result-cache key.

Revision ID: v0.2.0.c
Revises: v0.2.0.b
Create Date: 2026-11-26 05:00:00.000000
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.2.0.c'
down_revision: str | None = 'v0.2.0.b'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table('road_profiles',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=64), nullable=False),
    sa.Column('content_hash', sa.String(length=64), nullable=False),
    sa.Column('n_points', sa.Integer(), nullable=False),
    sa.Column('x_min_m', sa.Float(), nullable=False),
    sa.Column('x_max_m', sa.Float(), nullable=False),
    sa.Column('y_min_m', sa.Float(), nullable=False),
    sa.Column('y_max_m', sa.Float(), nullable=False),
    sa.Column('xs', sa.JSON(), nullable=False),
    sa.Column('ys', sa.JSON(), nullable=False),
    sa.Column('created_at', sa.DateTime(), nullable=False),
    sa.PrimaryKeyConstraint('id'),
    sa.UniqueConstraint('content_hash')
    )


def downgrade() -> None:
    op.drop_table('road_profiles')
