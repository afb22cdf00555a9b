"""each DE generation's record in columns of its own; stored optimiser states without their history

A generation's row stored the optimiser's whole state, whose ``history`` held the record of every
generation so far: a run of G generations stored O(G^2) records, and each of its tells wrote O(G)
(at NP = 4 and the API's 100,000 generations, about 550 GB a run). Each row now holds its own
generation's record (``best_fitness_m`` and ``n_evals`` as before, ``mean_fitness_m`` and
``n_failed``, that generation's failures, added) and the state without its history, O(NP); a run's
history is its rows. Downgrading puts each state's history back from its run's rows up to it.

Stop every scheduler before upgrading (one still running would go on storing whole histories).
The rows shrink, but the database's file does not: ``VACUUM`` (SQLite) or ``VACUUM FULL
generations`` (PostgreSQL) afterwards gives the space back.

Revision ID: v0.2.0.e
Revises: v0.2.0.d
Create Date: 2026-11-27 04:00:00.000000
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.2.0.e'
down_revision: str | None = 'v0.2.0.d'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

#: rows read at a time, and at most this many bytes of stored states (a state before the upgrade
#: is O(generations): ~12 MB at generation 100,000, several times that once decoded)
_BATCH_ROWS = 100
_BATCH_BYTES = 16_000_000
#: bytes of JSON a history record takes, to bound the downgrade's rebuilt states the same way
_RECORD_BYTES = 120

_generations = sa.table(
    'generations', sa.column('id', sa.Integer()), sa.column('job_id', sa.Integer()), sa.column('run', sa.Integer()),
    sa.column('generation', sa.Integer()), sa.column('state', sa.JSON()), sa.column('best_fitness_m', sa.Float()),
    sa.column('mean_fitness_m', sa.Float()), sa.column('n_evals', sa.Integer()), sa.column('n_failed', sa.Integer()),
)


def _rewrite(changed: list[dict[str, Any]], **columns: str) -> None:
    if changed:
        t = _generations
        op.get_bind().execute(
            t.update().where(t.c.id == sa.bindparam('row_id')).values(
                {column: sa.bindparam(name) for column, name in columns.items()}),
            changed)


def _batches() -> Iterator[list[int]]:
    """The rows' ids in order, in groups of at most _BATCH_ROWS rows and _BATCH_BYTES of states (or one row)."""
    t, bind, last = _generations, op.get_bind(), 0
    size = sa.func.length(sa.cast(t.c.state, sa.Text()))
    while True:
        rows = bind.execute(sa.select(t.c.id, size).where(t.c.id > last).order_by(t.c.id).limit(_BATCH_ROWS)).all()
        if not rows:
            return
        batch, total = [], 0
        for row_id, length in rows:
            if batch and total + (length or 0) > _BATCH_BYTES:
                break
            batch.append(row_id)
            total += length or 0
        last = batch[-1]
        yield batch


def upgrade() -> None:
    with op.batch_alter_table('generations', schema=None) as batch_op:
        batch_op.add_column(sa.Column('mean_fitness_m', sa.Float(), nullable=True))
        batch_op.add_column(sa.Column('n_failed', sa.Integer(), server_default='0', nullable=False))
    t = _generations
    for ids in _batches():
        rows = op.get_bind().execute(sa.select(t.c.id, t.c.generation, t.c.state).where(t.c.id.in_(ids))).all()
        changed = []
        for row_id, generation, state in rows:
            if isinstance(state, dict) and 'history' in state:
                history = state.pop('history')
                record = history[-1] if history else {}
                own = record.get('generation') == generation - 1  # the optimiser counts from 0
                changed.append({'row_id': row_id, 'new_state': state,
                                'new_mean': record.get('mean_f') if own else None,
                                'new_failed': int(record.get('n_failed') or 0) if own else 0})
        _rewrite(changed, state='new_state', mean_fitness_m='new_mean', n_failed='new_failed')


def downgrade() -> None:
    t, bind = _generations, op.get_bind()
    runs = bind.execute(sa.select(t.c.job_id, t.c.run).distinct()).all()
    for job_id, run in runs:
        history: list[dict[str, Any]] = []
        last = 0
        while True:
            budget = max(1, min(_BATCH_ROWS, _BATCH_BYTES // (_RECORD_BYTES * (len(history) + 1))))
            rows = bind.execute(
                sa.select(t.c.id, t.c.generation, t.c.state, t.c.best_fitness_m, t.c.mean_fitness_m, t.c.n_evals,
                          t.c.n_failed)
                .where(t.c.job_id == job_id, t.c.run == run, t.c.generation > last)
                .order_by(t.c.generation).limit(budget)).all()
            if not rows:
                break
            last = rows[-1].generation
            changed = []
            for row_id, generation, state, best, mean, n_evals, n_failed in rows:
                # the optimiser's record (engine.optimize.de): its generation counts from 0
                history.append({'generation': generation - 1, 'n_evals': n_evals, 'best_f': best, 'mean_f': mean,
                                'n_failed': n_failed})
                changed.append({'row_id': row_id, 'new_state': {**state, 'history': list(history)}})
            _rewrite(changed, state='new_state')
    with op.batch_alter_table('generations', schema=None) as batch_op:
        batch_op.drop_column('n_failed')
        batch_op.drop_column('mean_fitness_m')
