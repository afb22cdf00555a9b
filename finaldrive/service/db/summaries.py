"""A job's near-optimal sets, computed in the database: what the API reads stays small however many
evaluations a job has.

A set (one road's successful evaluations, or a robust-de's designs by their aggregate score over
its roads) is read as at most :data:`BUCKETS` + 1 groups: the designs with L2 > 0 grouped by a2 in
1 deg buckets of the circle, and those on the pivot, each group with its count and the minimum
and maximum of every column. The ranges of L2, R_WS, fitness and distance follow exactly; so does
a2's shortest arc (engine :func:`~finaldrive.engine.angle_arc`) whenever its largest gap between
successive angles is at least a bucket wide, else (angles closer than 1 deg all around the
circle) it is found within 1 deg.

On a road, the best fitness is a seek in each level of ``fitness_index`` (the road's successful
evaluations by fitness: finaldrive.service.db.levels) and the near-optimal set
(``fitness_m >= best - tolerance``) a range of each; the explored ranges are read
from ``road_explored``, the same groups over all the road's successful evaluations, which the writer
keeps with each store (:func:`add_explored`; an index on a2 for them cost the store a quarter of
its ingest).
A robust-de's designs are grouped (``GROUP BY`` the design) once, in the database.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from sqlalchemy import Connection, text
from sqlalchemy.orm import Session

from finaldrive.engine import CONCENTRIC_L2_M, near_summary
from finaldrive.service.db.engine import marker
from finaldrive.service.db.levels import ALL_LEVELS, LEVELS

#: Buckets of a2 over the circle (1 deg each).
BUCKETS = 360
_WIDTH_DEG = 360.0 / BUCKETS
#: Gaps within this of the widest tie (engine angle_arc).
_TIE = 1e-9

_X = "(a2_deg - 360.0 * floor(a2_deg / 360.0))"
_GROUPS = f"CASE WHEN l2_m > {CONCENTRIC_L2_M!r} THEN CAST(floor({_X} / {_WIDTH_DEG!r}) AS INTEGER) ELSE -1 END"
#: A group's count and ranges, as road_explored holds them
_EXPLORED = (f"COUNT(*), MIN({_X}), MAX({_X}), MIN(l2_m), MAX(l2_m), MIN(rws_m), MAX(rws_m), MIN(fitness_m), "
             "MAX(fitness_m)")
#: ... and the distance's range: a near-optimal set's group
_COLUMNS = f"{_EXPLORED}, MIN(distance_m), MAX(distance_m)"


def road_sharpness(session: Session, job_id: int, road_index: int, tolerance_pct: float) -> dict[str, Any]:
    """The near-optimal set of one road's evaluations (engine :func:`~finaldrive.engine.near_optimal`)."""
    connection = session.connection()
    _need_floor(connection)
    m = marker(connection)
    road = f"FROM evaluations WHERE job_id = {m} AND road_index = {m} AND status = 'ok' AND fitness_m IS NOT NULL"
    key = (job_id, road_index)
    best = connection.exec_driver_sql(f"SELECT MAX(b) FROM ({_best_of_levels(m)}) AS t", key * LEVELS).scalar()
    if best is None:
        return near_summary(tolerance_pct, math.nan, math.nan, {}, {}, 0, 0, 0)
    tol = abs(best) * tolerance_pct / 100.0
    near = connection.exec_driver_sql(
        f"SELECT 1, {_GROUPS} AS b, {_COLUMNS} FROM (SELECT e.a2_deg, e.l2_m, e.rws_m, e.fitness_m, e.distance_m "
        f"{by_fitness(m)} AND f.fitness_m >= {m}) AS s GROUP BY b", (*key, best - tol)).all()
    cells = connection.exec_driver_sql(
        f"SELECT bucket, n, {', '.join(_RANGES)} FROM road_explored WHERE job_id = {m} AND road_index = {m} "
        "ORDER BY bucket", key).all()
    if not cells:  # stored by a writer that does not keep them (an older release's): count them here
        cells = connection.exec_driver_sql(f"SELECT {_GROUPS} AS b, {_EXPLORED} {road} GROUP BY b ORDER BY b",
                                           key).all()
    explored = {"a2_deg": list(_arc([(c[2], c[3]) for c in cells if c[0] >= 0])),
                "l2_m": [min(c[4] for c in cells), max(c[5] for c in cells)],
                "rws_m": [min(c[6] for c in cells), max(c[7] for c in cells)],
                "fitness_m": [min(c[8] for c in cells), best]}
    return near_summary(tolerance_pct, best, tol, _ranges(sorted(near, key=lambda r: r[1]), distance=True),
                        {k: [float(v) for v in r] for k, r in explored.items()}, sum(r[2] for r in near),
                        sum(c[1] for c in cells), sum(r[2] for r in near if r[1] < 0))


def _best_of_levels(marker: str) -> str:
    """The best fitness of a road (job and road bound once a level) in each level of ``fitness_index``,
    as rows ``b``: a seek each (one over every level would scan them)."""
    return " UNION ALL ".join(f"SELECT MAX(fitness_m) AS b FROM fitness_index WHERE level = {level} AND "
                              f"job_id = {marker} AND road_index = {marker}" for level in range(LEVELS))


def by_fitness(marker: str, levels: str = ALL_LEVELS) -> str:
    """``FROM`` a road's successful evaluations (``e``, job and road bound) joined to their entries in
    ``fitness_index`` (``f``, finaldrive.service.db.levels) at ``levels``, to be narrowed by ``f.fitness_m``."""
    return ("FROM fitness_index f JOIN evaluations e ON e.job_id = f.job_id AND e.road_index = f.road_index "
            f"AND e.step = f.step AND e.candidate = f.candidate WHERE f.level IN ({levels}) AND f.job_id = {marker} "
            f"AND f.road_index = {marker}")


#: road_explored's ranges, (low, high) pairs in the order of _COLUMNS' after the count
_RANGES = ("a2_lo_deg", "a2_hi_deg", "l2_lo_m", "l2_hi_m", "rws_lo_m", "rws_hi_m", "fitness_lo_m", "fitness_hi_m")
def add_explored(session: Session, job_id: int, road: np.ndarray, a2_deg: np.ndarray, l2_m: np.ndarray,
                 rws_m: np.ndarray, fitness_m: np.ndarray) -> None:
    """Merge successful evaluations (columns, one element each) into the job's ``road_explored`` groups
    (the writer, with each store): grouped and reduced with numpy, one upsert a group."""
    if not len(road):
        return
    x = a2_deg - 360.0 * np.floor(a2_deg / 360.0) + 0.0   # as _X (+0.0: SQL gives +0.0 where floor keeps -0.0)
    bucket = np.where(l2_m > CONCENTRIC_L2_M, np.floor(x / _WIDTH_DEG), -1.0).astype(np.int64)
    key = np.asarray(road, dtype=np.int64) * (BUCKETS + 2) + bucket + 1   # bucket -1 to BUCKETS (a2 just below 0)
    order = np.argsort(key, kind="stable")
    key = key[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    counts = np.diff(np.r_[starts, len(key)])
    ranges = []
    for values in (x, l2_m, rws_m, fitness_m):
        grouped = np.asarray(values, dtype=float)[order]
        ranges += [np.minimum.reduceat(grouped, starts), np.maximum.reduceat(grouped, starts)]
    connection = session.connection()
    m = marker(connection)
    low, high = ("LEAST", "GREATEST") if connection.dialect.name == "postgresql" else ("MIN", "MAX")
    merged = ", ".join(f"{name} = {low if i % 2 == 0 else high}(road_explored.{name}, excluded.{name})"
                       for i, name in enumerate(_RANGES))
    roads, buckets = np.divmod(key[starts], BUCKETS + 2)
    connection.exec_driver_sql(
        f"INSERT INTO road_explored (job_id, road_index, bucket, n, {', '.join(_RANGES)}) "
        f"VALUES ({', '.join([m] * (4 + len(_RANGES)))}) ON CONFLICT (job_id, road_index, bucket) DO UPDATE SET "
        f"n = road_explored.n + excluded.n, {merged}",
        [(job_id, *group) for group in zip(roads.tolist(), (buckets - 1).tolist(), counts.tolist(),
                                           *(r.tolist() for r in ranges), strict=True)])


def recount_explored(session: Session, job_id: int) -> None:
    """The job's ``road_explored`` groups computed afresh from its evaluations."""
    connection = session.connection()
    _need_floor(connection)
    m = marker(connection)
    connection.exec_driver_sql(f"DELETE FROM road_explored WHERE job_id = {m}", (job_id,))
    connection.exec_driver_sql(
        f"INSERT INTO road_explored (job_id, road_index, bucket, n, {', '.join(_RANGES)}) "
        f"SELECT job_id, road_index, {_GROUPS} AS b, {_EXPLORED} FROM evaluations WHERE job_id = {m} "
        "AND status = 'ok' AND fitness_m IS NOT NULL GROUP BY job_id, road_index, b", (job_id,))


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


def aggregate_sharpness(session: Session, job_id: int, roads: int, aggregate: str,
                        tolerance_pct: float) -> dict[str, Any]:
    """The near-optimal set of a robust-de's designs by their aggregate score (``mean`` or ``worst``
    over its ``roads`` roads; a design that failed on one of them has none)."""
    _need_floor(session.connection())
    source = _DESIGNS.format(score={"mean": "AVG", "worst": "MIN"}[aggregate])
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
