"""The evaluation rows a scheduler stores, built from results in bulk (columns converted at once).

A row holds the values of :data:`~finaldrive.service.db.results.ROW_COLUMNS` in order; NaN and
infinities are stored as NULL.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import chain
from typing import Any

import numpy as np

from finaldrive.engine import DIAGNOSTICS, STATUS_OK, BatchResult, Request
from finaldrive.service.db.models import EvalStatus
from finaldrive.service.db.results import ROW_COLUMNS, Row, key_hash

#: How the engine's reason for a simulation stopped by its wall-time limit begins (not reused from the cache).
TIME_LIMIT = "time limit"

_OK, _FAILED = EvalStatus.ok.value, EvalStatus.failed.value
#: where the wall time and the cached flag sit in a row (a copy of a duplicate: 0 s, cached)
WALL, CACHED = ROW_COLUMNS.index("wall_s"), ROW_COLUMNS.index("cached")


#: A finished part of a request: (part, its results, their fitness, their cache keys, transient).
Finished = tuple[Request, BatchResult, np.ndarray, list[str], bool]


@dataclass
class Block:
    """Finished parts' results as concatenated columns: built with a few array operations a part,
    cheap to pickle (a writer process receives these), made rows by :func:`rows_from_block`."""

    roads: np.ndarray
    steps: np.ndarray
    candidates: np.ndarray
    designs: np.ndarray       # (n, 3): a2 [rad], L2 [m], R_WS [m]
    fitness: np.ndarray       # the job's fitness (Finished's), NaN when failed
    numbers: np.ndarray       # (len(_NUMBERS), n): the batches' values
    status: list[str]
    reason: list[str]
    keys: list[str]
    transient: np.ndarray

    def __len__(self) -> int:
        return len(self.keys)


#: The batches' values a row holds besides the design and the job's fitness, in ROW_COLUMNS' order.
_NUMBERS = ("distance_m", "squat_ratio", "slack_m", "fitness_m", "chain_length_m", "wall_s", *DIAGNOSTICS)


def block_from_results(finished: list[Finished]) -> Block:
    """The finished parts' results concatenated column by column."""
    counts = [len(part) for part, *_ in finished]
    batches = [batch for _, batch, *_ in finished]
    return Block(
        roads=np.repeat([part.road for part, *_ in finished], counts),
        steps=np.repeat([part.step for part, *_ in finished], counts),
        candidates=np.concatenate([part.candidates for part, *_ in finished]),
        designs=np.concatenate([part.designs for part, *_ in finished]),
        fitness=np.concatenate([f for _, _, f, _, _ in finished]),
        numbers=np.array([np.concatenate([getattr(b, name) for b in batches]) for name in _NUMBERS], dtype=float),
        status=list(chain.from_iterable(b.status for b in batches)),
        reason=list(chain.from_iterable(b.reason for b in batches)),
        keys=list(chain.from_iterable(keys for *_, keys, _ in finished)),
        transient=np.repeat([t for *_, t in finished], counts),
    )


def rows_from_block(block: Block) -> list[Row]:
    """The rows of a block (NaN stored as NULL), each column converted at once."""
    values = dict(zip(_NUMBERS, block.numbers, strict=True))
    ok = np.isfinite(block.fitness).tolist()
    reasons = [reason or ("" if good else f"non-finite fitness ({value})")
               for reason, good, value in zip(block.reason, ok, values["fitness_m"].tolist(), strict=True)]
    failed_for_now = [lost or (status != STATUS_OK and reason.startswith(TIME_LIMIT)) for lost, status, reason
                      in zip(block.transient.tolist(), block.status, reasons, strict=True)]
    designs = block.designs.T
    numbers = nullable_columns(np.array([
        np.degrees(designs[0]), designs[1], designs[2], values["distance_m"], values["squat_ratio"],
        values["slack_m"], block.fitness, values["chain_length_m"], *(values[name] for name in DIAGNOSTICS)],
        dtype=float))
    n = len(block)
    columns = [
        block.roads.tolist(), block.steps.tolist(), block.candidates.tolist(), *numbers[:8],
        [_OK if good else _FAILED for good in ok], reasons, values["wall_s"].tolist(), [False] * n, block.keys,
        [key_hash(key) for key in block.keys], failed_for_now, *numbers[8:],
    ]
    return list(zip(*columns, strict=True))


def rows_from_results(finished: list[Finished]) -> list[Row]:
    """The rows of finished parts (NaN stored as NULL)."""
    return rows_from_block(block_from_results(finished))


def row_from_cache(hit: dict[str, Any], road: int, step: int, candidate: int, design: np.ndarray, key: str) -> Row:
    """The row of a slot whose design is a result-cache hit: the stored result, marked cached, 0 s."""
    values = hit | {"wall_s": 0.0, "cached": True, "cache_key": key, "cache_hash": key_hash(key), "transient": False}
    a2, l2, rws = (c[0] for c in nullable_columns(np.array([[np.degrees(design[0])], [design[1]], [design[2]]])))
    return (road, step, candidate, a2, l2, rws, *(values[name] for name in ROW_COLUMNS[6:]))


def nullable_columns(columns: np.ndarray) -> list[list[float | None]]:
    """Columns given as the rows of a float block, as plain floats, None for NaN and infinities."""
    out = columns.astype(object)
    out[~np.isfinite(columns)] = None
    plain: list[list[float | None]] = out.tolist()
    return plain


def nullable(values: Sequence[float] | np.ndarray) -> list[float | None]:
    """Plain floats, None for NaN and infinities."""
    return nullable_columns(np.asarray(values, dtype=float)[None, :])[0]


