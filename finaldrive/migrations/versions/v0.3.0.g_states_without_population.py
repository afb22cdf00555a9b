"""stored optimiser states without their population and fitness, which the generation's columns hold

A generation's row stored the optimiser's population and fitness twice: in its ``population`` and
``fitness_m`` columns (what the API reads) and again in its ``state``; encoding them as JSON twice
took 14 % of the writer's time on the paper plan (issue 27). From this revision on, a stored state
leaves them out and the scheduler puts them back from the columns when it resumes a run
(``engine.optimize.with_population``). States stored before keep their copies: the scheduler reads
either, so upgrading rewrites nothing. Downgrading puts the population and fitness back into each
state that lacks them, from its row's columns.

Revision ID: v0.3.0.g
Revises: v0.3.0.f
Create Date: 2026-12-07 13:00:00.000000
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.3.0.g'
down_revision: str | None = 'v0.3.0.f'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

#: rows read and rewritten at a time (a state and its columns are O(NP): a few kB)
_BATCH_ROWS = 500

_generations = sa.table(
    'generations', sa.column('id', sa.Integer()), sa.column('state', sa.JSON()),
    sa.column('population', sa.JSON()), sa.column('fitness_m', sa.JSON()),
)


def upgrade() -> None:
    """Nothing to rewrite: the states stored before hold their own copies."""


def downgrade() -> None:
    t, bind, last = _generations, op.get_bind(), 0
    while True:
        rows = bind.execute(sa.select(t.c.id, t.c.state, t.c.population, t.c.fitness_m)
                            .where(t.c.id > last).order_by(t.c.id).limit(_BATCH_ROWS)).all()
        if not rows:
            return
        last = rows[-1].id
        changed = [{'row_id': row_id, 'new_state': {**state, 'population': population, 'fitness': fitness}}
                   for row_id, state, population, fitness in rows
                   if isinstance(state, dict) and not ('population' in state and 'fitness' in state)]
        if changed:
            bind.execute(t.update().where(t.c.id == sa.bindparam('row_id')).values(state=sa.bindparam('new_state')),
                         changed)
