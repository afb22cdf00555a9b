"""one vocabulary: the design's columns and stored keys carry their units (a2_deg, l2_m, rws_m)

Every output names a quantity with its unit (docs/fields.md). The evaluations' design columns
become ``a2_deg`` (converted from radians), ``l2_m`` and ``rws_m``; fitness columns end in ``_m``
(``generations.fitness_m``, ``best_fitness_m``; ``job_roads.best_fitness_m``); stored job specs' grid strings
and stored recording requests' designs take the same names. DE populations (``generations``)
stay the optimiser's own state, in radians, as the optimiser sees them.

Revision ID: v0.2.0.d
Revises: v0.2.0.c
Create Date: 2026-11-26 05:00:00.000000
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from typing import Any

import sqlalchemy as sa
from alembic import op

revision: str = 'v0.2.0.d'
down_revision: str | None = 'v0.2.0.c'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_COLUMNS = (('a2', 'a2_deg'), ('l2', 'l2_m'), ('rws', 'rws_m'))
#: other tables' renamed columns: table -> ((old, new, type), ...)
_RENAMES = {
    'generations': (('fitness', 'fitness_m', sa.JSON()), ('best_f', 'best_fitness_m', sa.Float())),
    'job_roads': (('best_fitness', 'best_fitness_m', sa.Float()),),
}


def _grid_to_units(grid: str) -> str:
    """``a2=`` (radians), ``l2=``, ``rws=`` items of a grid spec in the new names (a2 in degrees)."""
    items = []
    for item in grid.split(','):
        name, sep, values = (part.strip() for part in item.partition('='))
        key = name.lower()
        if sep and key == 'a2':
            sep_char = ':' if ':' in values else '|'
            try:
                numbers = [math.degrees(float(v)) for v in values.split(sep_char)]
            except ValueError:  # invalid already: leave it for the parser to name
                items.append(item)
                continue
            items.append('a2_deg=' + sep_char.join(repr(v) for v in numbers))
        elif sep and key in ('l2', 'rws'):
            items.append(f'{key}_m={values}')
        else:
            items.append(item)
    return ','.join(items)


def _grid_from_units(grid: str) -> str:
    return re.sub(r'(^|,)\s*(l2|rws)_m\s*=', r'\1\2=', grid)


def _design_keys(design: dict[str, Any], renames: dict[str, str]) -> dict[str, Any]:
    return {renames.get(k, k): v for k, v in design.items()}


def _rewrite_json(table: str, fix: Callable[[dict[str, Any]], dict[str, Any]]) -> None:
    bind = op.get_bind()
    t = sa.table(table, sa.column('id', sa.Integer()), sa.column('spec', sa.JSON()))
    rows = bind.execute(sa.select(t.c.id, t.c.spec)).all()
    changed = [{'row_id': i, 'new': fix(dict(spec))} for i, spec in rows if spec is not None]
    if changed:
        bind.execute(t.update().where(t.c.id == sa.bindparam('row_id')).values(spec=sa.bindparam('new')), changed)


def _jobs(grid: Callable[[str], str]) -> Callable[[dict[str, Any]], dict[str, Any]]:
    def fix(spec: dict[str, Any]) -> dict[str, Any]:
        if isinstance(spec.get('grid'), str):
            spec['grid'] = grid(spec['grid'])
        return spec
    return fix


def _recordings(renames: dict[str, str]) -> Callable[[dict[str, Any]], dict[str, Any]]:
    def fix(spec: dict[str, Any]) -> dict[str, Any]:
        if isinstance(spec.get('designs'), list):
            spec['designs'] = [_design_keys(d, renames) if isinstance(d, dict) else d for d in spec['designs']]
        return spec
    return fix


def _rename_columns(forward: bool) -> None:
    """The evaluations' design columns and the other tables' renamed columns, old -> new (or back)."""
    def pair(old: str, new: str) -> tuple[str, str]:
        return (old, new) if forward else (new, old)

    with op.batch_alter_table('evaluations', schema=None) as batch_op:
        for old, new in _COLUMNS:
            source, target = pair(old, new)
            batch_op.alter_column(source, new_column_name=target, existing_type=sa.Float(), existing_nullable=False)
    for table, columns in _RENAMES.items():
        with op.batch_alter_table(table, schema=None) as batch_op:
            for old, new, kind in columns:
                source, target = pair(old, new)
                batch_op.alter_column(source, new_column_name=target, existing_type=kind)


def upgrade() -> None:
    _rename_columns(forward=True)
    op.execute(f'UPDATE evaluations SET a2_deg = a2_deg * {180.0 / math.pi!r}')
    _rewrite_json('jobs', _jobs(_grid_to_units))
    _rewrite_json('recordings', _recordings({'l2': 'l2_m', 'rws': 'rws_m'}))


def downgrade() -> None:
    op.execute(f'UPDATE evaluations SET a2_deg = a2_deg * {math.pi / 180.0!r}')
    _rename_columns(forward=False)
    _rewrite_json('jobs', _jobs(_grid_from_units))
    _rewrite_json('recordings', _recordings({'l2_m': 'l2', 'rws_m': 'rws'}))
