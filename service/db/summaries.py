"""A job's near-optimal sets, computed in the database: what the API reads stays small however many
evaluations a job has.

A set (one road's successful evaluations, or a robust-de's designs by their aggregate score over
its roads) is read as at most :data:`BUCKETS` + 1 groups: the designs with L2 > 0 grouped by a2 in
1 deg buckets of the circle, and those on the pivot, each group with its count and the minimum
and maximum of every column. The ranges of L2, R_WS, fitness and distance follow exactly; so does
a2's shortest arc (engine :func:`~finaldrive.engine.angle_arc`) whenever its largest gap between
successive angles is at least a bucket wide, else (angles closer than 1 deg all around the
circle) it is found within 1 deg.

On a road, the best fitness is a seek of the index on (job, road, status, fitness), the near-optimal
set (``fitness_m >= best - tolerance``) a range of it (a large one: a scan of the a2 index), the
explored range of a2 two seeks a non-empty bucket of the index on (job, road, status, a2, ...) (at
most :data:`MAX_SEEKS`; else one grouped scan of that index), the other explored ranges a scan of
that index. A robust-de's designs are grouped (``GROUP BY`` the design) once, in the database.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

from sqlalchemy import Connection, text
from sqlalchemy.orm import Session

from finaldrive.engine import CONCENTRIC_L2_M, near_summary

#: Buckets of a2 over the circle (1 deg each).
BUCKETS = 360
_WIDTH_DEG = 360.0 / BUCKETS
#: Bucket seeks of one road's explored a2 range, beyond which one grouped scan is cheaper.
MAX_SEEKS = 2000
#: Near-optimal sets up to this size are read through the fitness index (and the table), larger ones
#: by a scan of the a2 index alone.
NEAR_BY_FITNESS = 20_000
#: Gaps within this of the widest tie (engine angle_arc).
_TIE = 1e-9

_X = "(a2_deg - 360.0 * floor(a2_deg / 360.0))"
_GROUPS = f"CASE WHEN l2_m > {CONCENTRIC_L2_M!r} THEN CAST(floor({_X} / {_WIDTH_DEG!r}) AS INTEGER) ELSE -1 END"
_COLUMNS = (f"COUNT(*), MIN({_X}), MAX({_X}), MIN(l2_m), MAX(l2_m), MIN(rws_m), MAX(rws_m), "
            "MIN(fitness_m), MAX(fitness_m), MIN(distance_m), MAX(distance_m)")


def road_sharpness(session: Session, job_id: int, road_index: int, tolerance_pct: float) -> dict[str, Any]:
    """The near-optimal set of one road's evaluations (engine :func:`~finaldrive.engine.near_optimal`)."""
    connection = session.connection()
    _need_floor(connection)
    m = "?" if connection.dialect.paramstyle == "qmark" else "%s"
    road = f"FROM evaluations WHERE job_id = {m} AND road_index = {m} AND status = 'ok' AND fitness_m IS NOT NULL"
    key = (job_id, road_index)
    best = connection.exec_driver_sql(f"SELECT MAX(fitness_m) {road}", key).scalar()
    if best is None:
        return near_summary(tolerance_pct, math.nan, math.nan, {}, {}, 0, 0, 0)
    tol = abs(best) * tolerance_pct / 100.0
    size = connection.exec_driver_sql(f"SELECT COUNT(*) {road} AND fitness_m >= {m}", (*key, best - tol)).scalar()
    # a large set: a scan of the covering a2 index beats a lookup in the table for each of its rows
    fitness = "fitness_m" if int(size or 0) <= NEAR_BY_FITNESS else "fitness_m + 0"
    near = connection.exec_driver_sql(f"SELECT 1, {_GROUPS} AS b, {_COLUMNS} {road} AND {fitness} >= {m} GROUP BY b",
                                      (*key, best - tol)).all()
    n, l2_lo, l2_hi, rws_lo, rws_hi, f_lo = connection.exec_driver_sql(
        f"SELECT COUNT(*), MIN(l2_m), MAX(l2_m), MIN(rws_m), MAX(rws_m), MIN(fitness_m) {road}", key).one()
    explored = {"a2_deg": list(_arc(_a2_buckets(connection, road, key, m))), "l2_m": [l2_lo, l2_hi],
                "rws_m": [rws_lo, rws_hi], "fitness_m": [f_lo, best]}
    return near_summary(tolerance_pct, best, tol, _ranges(sorted(near, key=lambda r: r[1]), distance=True),
                        {k: [float(v) for v in r] for k, r in explored.items()}, sum(r[2] for r in near), n,
                        sum(r[2] for r in near if r[1] < 0))


def _a2_buckets(connection: Connection, road: str, key: tuple[int, int], m: str) -> list[tuple[float, float]]:
    """(min, max) of the angles in [0, 360) of each non-empty bucket, in order, of the road's designs
    with L2 > 0: a loose scan of the a2 index (two seeks a bucket), or one grouped scan."""
    placed = f"{road} AND l2_m > {CONCENTRIC_L2_M!r}"
    first = f"SELECT a2_deg {placed} AND a2_deg >= {m} ORDER BY a2_deg LIMIT 1"
    last = f"SELECT a2_deg {placed} AND a2_deg < {m} ORDER BY a2_deg DESC LIMIT 1"
    cursor = connection.connection.dbapi_connection.cursor()  # type: ignore[union-attr]  # thousands of tiny seeks

    def seek(sql: str, bound: float) -> float | None:
        cursor.execute(sql, (*key, bound))
        row = cursor.fetchone()
        return None if row is None else float(row[0])

    found: dict[int, tuple[float, float]] = {}
    low = seek(first, -math.inf)
    try:
        for _ in range(MAX_SEEKS // 2):
            if low is None:
                return [found[b] for b in sorted(found)]
            end = (math.floor(low / _WIDTH_DEG) + 1) * _WIDTH_DEG
            for v in (low, seek(last, end)):
                assert v is not None
                x = v - 360.0 * math.floor(v / 360.0)
                b = math.floor(x / _WIDTH_DEG)
                old = found.get(b, (x, x))
                found[b] = (min(old[0], x), max(old[1], x))
            low = seek(first, end)
    finally:
        cursor.close()
    rows = connection.exec_driver_sql(f"SELECT {_GROUPS} AS b, MIN({_X}), MAX({_X}) {placed} GROUP BY b", key).all()
    return [(lo, hi) for _, lo, hi in sorted(rows)]


#: A robust-de's designs evaluated successfully on every one of its roads, with their aggregate score.
_DESIGNS = ("SELECT a2_deg, l2_m, rws_m, {score}(fitness_m) AS fitness_m, CAST(NULL AS DOUBLE PRECISION) AS distance_m "
            "FROM evaluations WHERE job_id = :job AND status = 'ok' AND fitness_m IS NOT NULL "
            "GROUP BY a2_deg, l2_m, rws_m HAVING COUNT(DISTINCT road_index) = :roads")


def _sets_sql(source: str) -> str:
    """Grouped rows (near, bucket, count, min and max of x, l2, rws, fitness, distance) of every design
    of ``source`` and of its near-optimal ones, in one statement (``source`` computed once)."""
    return (f"WITH s AS MATERIALIZED ({source}), t AS (SELECT MAX(fitness_m) AS best FROM s) "
            f"SELECT 0 AS near, {_GROUPS} AS b, {_COLUMNS} FROM s GROUP BY b "
            f"UNION ALL SELECT 1 AS near, {_GROUPS} AS b, {_COLUMNS} FROM s, t "
            "WHERE s.fitness_m >= t.best - abs(t.best) * :pct / 100.0 GROUP BY b")


def aggregate_sharpness(session: Session, job_id: int, roads: int, objective: str,
                        tolerance_pct: float) -> dict[str, Any]:
    """The near-optimal set of a robust-de's designs by their aggregate score (``mean`` or ``worst``
    over its ``roads`` roads; a design that failed on one of them has none)."""
    _need_floor(session.connection())
    source = _DESIGNS.format(score={"mean": "AVG", "worst": "MIN"}[objective])
    rows = session.execute(text(_sets_sql(source)),
                           {"job": job_id, "roads": roads, "pct": tolerance_pct}).all()
    return _summary(rows, tolerance_pct, distance=False)


def _summary(rows: Sequence[Any], tolerance_pct: float, *, distance: bool) -> dict[str, Any]:
    every = sorted((r for r in rows if r[0] == 0), key=lambda r: r[1])
    near = sorted((r for r in rows if r[0] == 1), key=lambda r: r[1])
    if not every:
        return near_summary(tolerance_pct, math.nan, math.nan, {}, {}, 0, 0, 0)
    best = max(r[10] for r in every)
    ranges = _ranges(near, distance=distance)
    return near_summary(tolerance_pct, best, abs(best) * tolerance_pct / 100.0, ranges, _ranges(every, distance=False),
                        sum(r[2] for r in near), sum(r[2] for r in every), sum(r[2] for r in near if r[1] < 0))


def _ranges(groups: list[Any], *, distance: bool) -> dict[str, list[float]]:
    """engine :func:`~finaldrive.engine.spread` (and the distance's range) from grouped rows."""
    out = {"a2_deg": list(_arc([(r[3], r[4]) for r in groups if r[1] >= 0])),
           "l2_m": [min(r[5] for r in groups), max(r[6] for r in groups)],
           "rws_m": [min(r[7] for r in groups), max(r[8] for r in groups)],
           "fitness_m": [min(r[9] for r in groups), max(r[10] for r in groups)]}
    lows, highs = [r[11] for r in groups if r[11] is not None], [r[12] for r in groups if r[12] is not None]
    if distance and lows:
        out["distance_m"] = [min(lows), max(highs)]
    return {k: [float(v) for v in r] for k, r in out.items()}


def _arc(buckets: list[tuple[float, float]]) -> tuple[float, float]:
    """The shortest arc holding the angles of ``buckets`` ((min, max) of each non-empty one, in
    order): as engine angle_arc, the gap that wraps past 360 wins ties, else the first widest."""
    if not buckets:
        return math.nan, math.nan
    gaps = [nxt[0] - cur[1] for cur, nxt in itertools.pairwise(buckets)]
    wrap = buckets[0][0] + 360.0 - buckets[-1][1]
    widest = max([wrap, *gaps])
    if wrap >= widest - _TIE:
        return buckets[0][0], buckets[-1][1]
    i = next(i for i, g in enumerate(gaps) if g >= widest - _TIE)
    start = buckets[i + 1][0]
    return start, start + 360.0 - gaps[i]


def _need_floor(connection: Connection) -> None:
    """SQLite built without its math functions gets ``floor`` from Python (on this connection)."""
    if connection.dialect.name == "sqlite" and connection.exec_driver_sql(
            "SELECT COUNT(*) FROM pragma_function_list WHERE name = 'floor'").scalar() == 0:
        raw = connection.connection.driver_connection
        assert raw is not None
        raw.create_function("floor", 1, math.floor, deterministic=True)
