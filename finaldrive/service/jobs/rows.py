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
from finaldrive.service.db.results import ROW_COLUMNS, Row, key_hash, key_hashes

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

#: Rows the writer builds and stores at a time (``Writes.chunks``, ``store_results``), so that a row is
#: bound while its values are still in the CPU's cache: built and inserted 1,000 at a time, 4.1 us a row
#: against 6.0 for a block's 20,000 at once (500: 3.8; 2,000: 4.1-5.7; SQLite, 2-core Xeon, issue 27).
CHUNK_ROWS = 1000


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


def rows_from_block(block: Block, at: slice = slice(None)) -> list[Row]:
    """The rows ``at`` of a block (ROW_COLUMNS' order; NaN stored as NULL), each column converted at once.
    A flag is 0 or 1, not a bool: SQLite's driver binds a bool through its adaptation protocol (a failed
    ``__conform__`` lookup), 0.7 us a row for two flags against 2.1 us for a 40-value row of ints, floats
    and strings (issue 27)."""
    fitness = block.values[at, _FITNESS]
    ok = np.isfinite(fitness).tolist()
    reasons = [reason or ("" if good else f"non-finite fitness ({value})")
               for reason, good, value in zip(block.reason[at], ok, fitness.tolist(), strict=True)]
    status, keys = block.status[at], block.keys[at]
    failed_for_now = [1 if lost or (state != STATUS_OK and reason.startswith(TIME_LIMIT)) else 0 for lost, state,
                      reason in zip(block.transient[at].tolist(), status, reasons, strict=True)]
    designs = block.designs[at].T
    numbers = np.vstack([np.degrees(designs[0]), designs[1], designs[2], block.values[at].T])
    numbers[~np.isfinite(numbers)] = np.nan
    columns = [
        block.roads[at].tolist(), block.steps[at].tolist(), block.candidates[at].tolist(), *numbers.tolist(),
        [_OK if good else _FAILED for good in ok], reasons, block.cached[at].astype(np.int8).tolist(), keys,
        key_hashes(keys).tolist(), failed_for_now,
    ]
    return list(zip(*columns, strict=True))


def rows_from_results(finished: list[Finished]) -> list[Row]:
    """The rows of finished parts (NaN stored as NULL)."""
    return rows_from_block(block_from_results(finished))


def row_from_cache(hit: dict[str, Any], road: int, step: int, candidate: int, design: np.ndarray, key: str) -> Row:
    """The row of a slot whose design is a result-cache hit: the stored result, marked cached, 0 s."""
    values = {name: math.nan if value is None else value for name, value in hit.items()}  # NULL read back
    values |= {"wall_s": 0.0, "cached": 1, "cache_key": key, "cache_hash": key_hash(key), "transient": 0}
    a2, l2, rws = (float(v) for v in design)
    return (road, step, candidate, math.degrees(a2), l2, rws, *(values[name] for name in ROW_COLUMNS[6:]))


def nullable(values: Sequence[float] | np.ndarray) -> list[float | None]:
    """Plain floats, None for NaN and infinities (JSON's null)."""
    column = np.asarray(values, dtype=float)
    out = column.astype(object)
    out[~np.isfinite(column)] = None
    plain: list[float | None] = out.tolist()
    return plain


