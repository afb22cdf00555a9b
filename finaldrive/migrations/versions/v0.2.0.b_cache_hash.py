"""result cache indexed by a 60-bit integer hash of the key

The index on the 64-character cache key made every insert touch a random page of a large text
index (about half the scheduler's write cost); an integer index is a third of its size. The full
key is kept and compared on lookup, so a collision of the hash can never return a wrong result.

Revision ID: v0.2.0.b
Revises: v0.2.0.a
Create Date: 2026-11-26 04:20:00.000000
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.2.0.b'
down_revision: str | None = 'v0.2.0.a'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

#: hex digits of the key that make the hash (60 bits: a positive BIGINT on every backend)
HASH_DIGITS = 15


def upgrade() -> None:
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.add_column(sa.Column('cache_hash', sa.BigInteger(), nullable=True))
    bind = op.get_bind()
    table = sa.table('evaluations', sa.column('id', sa.Integer()), sa.column('cache_key', sa.String()),
                     sa.column('cache_hash', sa.BigInteger()))
    rows = bind.execute(sa.select(table.c.id, table.c.cache_key)).all()
    if rows:
        bind.execute(table.update().where(table.c.id == sa.bindparam('row_id')).values(cache_hash=sa.bindparam('h')),
                     [{'row_id': i, 'h': int(key[:HASH_DIGITS], 16)} for i, key in rows])
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.alter_column('cache_hash', existing_type=sa.BigInteger(), nullable=False)
        batch_op.drop_index('ix_evaluations_cache_key')
        batch_op.create_index('ix_evaluations_cache_hash', ['cache_hash'], unique=False)


def downgrade() -> None:
    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        batch_op.drop_index('ix_evaluations_cache_hash')
        batch_op.create_index('ix_evaluations_cache_key', ['cache_key'], unique=False)
        batch_op.drop_column('cache_hash')
