"""The evaluation rows a scheduler stores, built from results in bulk (columns converted at once).

A row holds the values of :data:`~finaldrive.service.db.results.ROW_COLUMNS` in order; NaN and
infinities are stored as NULL.
"""

from __future__ import annotations

from collections.abc import Sequence
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


def rows_from_results(finished: list[Finished]) -> list[Row]:
    """The rows of finished parts (NaN stored as NULL), the numbers of all of them converted in one block."""
    counts = [len(part) for part, *_ in finished]
    fitness = np.concatenate([f for _, _, f, _, _ in finished])
    batches = [batch for _, batch, *_ in finished]
    ok = np.isfinite(fitness).tolist()
    reasons = [reason or ("" if good else f"non-finite fitness ({value})") for reason, good, value in zip(
        (r for b in batches for r in b.reason), ok, (v for b in batches for v in b.fitness_m.tolist()), strict=True)]
    transient = np.repeat([t for *_, t in finished], counts).tolist()
    failed_for_now = [lost or (status != STATUS_OK and reason.startswith(TIME_LIMIT)) for lost, status, reason
                      in zip(transient, (s for b in batches for s in b.status), reasons, strict=True)]
    designs = np.concatenate([part.designs for part, *_ in finished]).T

    def joined(name: str) -> np.ndarray:
        return np.concatenate([getattr(b, name) for b in batches])

    numbers = nullable_columns(np.array([
        np.degrees(designs[0]), designs[1], designs[2], joined("distance_m"), joined("squat_ratio"),
        joined("slack_m"), fitness, joined("chain_length_m"), *(joined(name) for name in DIAGNOSTICS)], dtype=float))
    keys = [key for *_, part_keys, _ in finished for key in part_keys]
    n = len(keys)
    columns = [
        np.repeat([part.road for part, *_ in finished], counts).tolist(),
        np.repeat([part.step for part, *_ in finished], counts).tolist(),
        np.concatenate([part.candidates for part, *_ in finished]).tolist(), *numbers[:8],
        [_OK if good else _FAILED for good in ok], reasons, joined("wall_s").tolist(), [False] * n, keys,
        [key_hash(key) for key in keys], failed_for_now, *numbers[8:],
    ]
    return list(zip(*columns, strict=True))


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


