"""The evaluation rows a scheduler stores, built from results in bulk (columns converted at once).

A row holds the values of :data:`~finaldrive.service.db.results.ROW_COLUMNS` in order; a number
the run did not produce (or a non-finite one) is NaN in a row and NULL in the store (SQLite
stores a NaN as NULL; the PostgreSQL path converts it, service.db.results).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import chain
from typing import Any

import numpy as np

from finaldrive.engine import STATUS_OK, VALUES, BatchResult, Request
from finaldrive.service.db.models import EvalStatus
from finaldrive.service.db.results import ROW_COLUMNS, Row, key_hash

#: How the engine's reason for a simulation stopped by its wall-time limit begins (not reused from the cache).
TIME_LIMIT = "time limit"

_OK, _FAILED = EvalStatus.ok.value, EvalStatus.failed.value


#: A finished part of a request: (part, its results, their fitness, their cache keys, transient).
Finished = tuple[Request, BatchResult, np.ndarray, list[str], bool]


@dataclass
class Block:
    """Stored-to-be evaluations as columns: the slots' identity (road, step, candidate), the
    designs, the engine's result records (``values``, engine.record.VALUES' columns, the job's
    fitness in ``fitness_m``), status, reason, cache keys and flags. Built with a few array
    operations a finished part, cheap to pickle (a writer process receives these), made rows by
    :func:`rows_from_block`."""

    roads: np.ndarray
    steps: np.ndarray
    candidates: np.ndarray
    designs: np.ndarray       # (n, 3): a2 [rad], L2 [m], R_WS [m]
    values: np.ndarray        # (n, len(VALUES)), NaN where not produced
    status: list[str]
    reason: list[str]
    keys: list[str]
    transient: np.ndarray
    cached: np.ndarray

    def __len__(self) -> int:
        return len(self.keys)

    def copied(self, rows: list[int], candidates: list[int]) -> Block:
        """Rows of this block as the results of other candidates of their (road, step): duplicates of
        a design evaluated once, stored as cached with 0 s of wall time."""
        index = np.asarray(rows, dtype=int)
        values = self.values[index]
        values[:, _WALL] = 0.0
        return Block(self.roads[index], self.steps[index], np.asarray(candidates, dtype=int), self.designs[index],
                     values, [self.status[i] for i in rows], [self.reason[i] for i in rows],
                     [self.keys[i] for i in rows], self.transient[index], np.ones(len(rows), dtype=bool))


_WALL, _FITNESS = VALUES.index("wall_s"), VALUES.index("fitness_m")


def block_from_results(finished: list[Finished]) -> Block:
    """The finished parts' results concatenated column by column (the job's fitness replacing the engine's)."""
    counts = [len(part) for part, *_ in finished]
    values = np.concatenate([batch.values for _, batch, *_ in finished])
    values[:, _FITNESS] = np.concatenate([f for _, _, f, _, _ in finished])
    return Block(
        roads=np.repeat([part.road for part, *_ in finished], counts),
        steps=np.repeat([part.step for part, *_ in finished], counts),
        candidates=np.concatenate([part.candidates for part, *_ in finished]),
        designs=np.concatenate([part.designs for part, *_ in finished]),
        values=values,
        status=list(chain.from_iterable(b.status for _, b, *_ in finished)),
        reason=list(chain.from_iterable(b.reason for _, b, *_ in finished)),
        keys=list(chain.from_iterable(keys for *_, keys, _ in finished)),
        transient=np.repeat([t for *_, t in finished], counts),
        cached=np.zeros(sum(counts), dtype=bool),
    )


def rows_from_block(block: Block) -> list[Row]:
    """The rows of a block (ROW_COLUMNS' order; NaN stored as NULL), each column converted at once into
    a table of Python objects read out row by row: 1.3 us a row of 40 values against 2.1 for the columns
    zipped into tuples (the rows' building was 13 % of the writer's CPU on the big plan, issue 27)."""
    fitness = block.values[:, _FITNESS]
    ok = np.isfinite(fitness)
    reasons = block.reason if ok.all() else [
        reason or ("" if good else f"non-finite fitness ({value})")
        for reason, good, value in zip(block.reason, ok.tolist(), fitness.tolist(), strict=True)]
    failed_for_now = [lost or (status != STATUS_OK and reason.startswith(TIME_LIMIT)) for lost, status, reason
                      in zip(block.transient.tolist(), block.status, reasons, strict=True)]
    table = np.empty((len(block), len(ROW_COLUMNS)), dtype=object)
    table[:, _SLOT] = np.column_stack([block.roads, block.steps, block.candidates])
    numbers = np.column_stack([np.degrees(block.designs[:, 0]), block.designs[:, 1:], block.values])
    numbers[~np.isfinite(numbers)] = np.nan
    table[:, _NUMBERS] = numbers
    table[:, _STATUS] = [_OK if good else _FAILED for good in ok.tolist()]
    table[:, _REASON] = reasons
    table[:, _CACHED] = block.cached
    table[:, _KEY] = block.keys
    table[:, _HASH] = [key_hash(key) for key in block.keys]
    table[:, _TRANSIENT] = failed_for_now
    return list(map(tuple, table.tolist()))


_SLOT, _NUMBERS = slice(0, 3), slice(3, 6 + len(VALUES))
_STATUS, _REASON, _CACHED, _KEY, _HASH, _TRANSIENT = (ROW_COLUMNS.index(name) for name in (
    "status", "reason", "cached", "cache_key", "cache_hash", "transient"))


def rows_from_results(finished: list[Finished]) -> list[Row]:
    """The rows of finished parts (NaN stored as NULL)."""
    return rows_from_block(block_from_results(finished))


def row_from_cache(hit: dict[str, Any], road: int, step: int, candidate: int, design: np.ndarray, key: str) -> Row:
    """The row of a slot whose design is a result-cache hit: the stored result, marked cached, 0 s."""
    values = {name: math.nan if value is None else value for name, value in hit.items()}  # NULL read back
    values |= {"wall_s": 0.0, "cached": True, "cache_key": key, "cache_hash": key_hash(key), "transient": False}
    a2, l2, rws = (float(v) for v in design)
    return (road, step, candidate, math.degrees(a2), l2, rws, *(values[name] for name in ROW_COLUMNS[6:]))


def nullable(values: Sequence[float] | np.ndarray) -> list[float | None]:
    """Plain floats, None for NaN and infinities (JSON's null)."""
    column = np.asarray(values, dtype=float)
    out = column.astype(object)
    out[~np.isfinite(column)] = None
    plain: list[float | None] = out.tolist()
    return plain


