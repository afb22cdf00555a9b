"""Evaluations read as columns and row chunks, never as ORM objects (plots, /points, CSV pages).

Memory then follows what is asked for: a road's few numeric columns as numpy arrays, or a CSV
page a few thousand rows at a time.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
from sqlalchemy import Select, select
from sqlalchemy.orm import Session

from finaldrive.service.db.engine import Database
from finaldrive.service.db.models import EvalStatus, Evaluation

#: Rows fetched at a time.
CHUNK_ROWS = 5000
#: The numeric columns of a road's points, in this order (``ok`` follows: 1 when the simulation succeeded).
POINT_COLUMNS = ("id", "step", "a2_deg", "l2_m", "rws_m", "distance_m", "fitness_m", "squat_ratio", "slack_m")


def _where(query: Select[Any], job_id: int, road_index: int | None) -> Select[Any]:
    query = query.where(Evaluation.job_id == job_id)
    return query if road_index is None else query.where(Evaluation.road_index == road_index)


def road_points(session: Session, job_id: int, road_index: int) -> dict[str, np.ndarray]:
    """Every evaluation of a job on a road, in storage order: :data:`POINT_COLUMNS` as float arrays
    (NaN where a failed simulation has no value; ``id`` and ``step`` as integers) and ``ok`` as booleans."""
    columns = [getattr(Evaluation, name) for name in POINT_COLUMNS]
    query = _where(select(*columns, Evaluation.status == EvalStatus.ok.value), job_id, road_index)
    result = session.execute(query.order_by(Evaluation.id).execution_options(yield_per=CHUNK_ROWS))
    parts = [np.array(part, dtype=float) for part in result.partitions()]
    table = np.concatenate(parts) if parts else np.empty((0, len(columns) + 1))
    out = {name: table[:, i] for i, name in enumerate(POINT_COLUMNS)}
    for whole in ("id", "step"):
        out[whole] = out[whole].astype(np.int64)
    out["ok"] = table[:, -1] == 1.0
    return out


def page_end(session: Session, job_id: int, road_index: int | None, after_id: int | None,
             limit: int) -> tuple[int | None, bool]:
    """The last id of a page of ``limit`` evaluations after ``after_id`` (None: the page takes the rest),
    and whether more follow (an index-only query)."""
    query = _where(select(Evaluation.id), job_id, road_index)
    if after_id is not None:
        query = query.where(Evaluation.id > after_id)
    ids = list(session.scalars(query.order_by(Evaluation.id).offset(limit - 1).limit(2)))
    return (ids[0] if ids else None), len(ids) == 2


def row_chunks(db: Database, job_id: int, road_index: int | None, columns: Sequence[str], *,
               after_id: int | None, until_id: int | None) -> Iterator[list[tuple[Any, ...]]]:
    """Evaluations with ``after_id < id <= until_id`` (None: unbounded) as tuples of ``columns`` (``id``
    first among them), :data:`CHUNK_ROWS` at a time, each chunk in a short read transaction of its own."""
    selected = [getattr(Evaluation, name) for name in columns]
    key = list(columns).index("id")
    cursor = after_id
    while True:
        query = _where(select(*selected), job_id, road_index)
        if cursor is not None:
            query = query.where(Evaluation.id > cursor)
        if until_id is not None:
            query = query.where(Evaluation.id <= until_id)
        with db.read() as session:
            rows = [tuple(row) for row in session.execute(query.order_by(Evaluation.id).limit(CHUNK_ROWS))]
        if rows:
            yield rows
        if len(rows) < CHUNK_ROWS:
            return
        cursor = rows[-1][key]
