"""Scoring designs: the rule for a failed evaluation, and scores over a set of roads.

A simulation that failed, or whose fitness is not finite, scores NaN: the DE ranks it below
every finite value (engine.optimize.de) and stores it as failed.

The paper optimises each road on its own (Tables 11-13). A rider meets many roads, so
here a design is scored over several: ``aggregate`` reduces a (roads x designs) fitness
table to one score a design, and ``regret`` says what a design costs on each road
against that road's own optimum. A failed evaluation (NaN or any non-finite value) on
any road makes the design's aggregate score NaN: a design that cannot be simulated on
one of the roads is not robust.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
import numpy.typing as npt

from finaldrive.engine.api import STATUS_OK, BatchResult

Aggregate = Literal["mean", "worst"]
AGGREGATES: tuple[str, ...] = ("mean", "worst")


class Regret(NamedTuple):
    """Loss against each road's optimum: ``optimum - fitness`` [m] and as % of the optimum."""

    absolute_m: np.ndarray
    percent: np.ndarray


def fitness_values(batch: BatchResult) -> np.ndarray:
    """Fitness [m] of each row of a batch; NaN where the simulation failed or gave a non-finite value."""
    f = np.array(batch.fitness_m, dtype=float)
    ok = np.array([s == STATUS_OK for s in batch.status], dtype=bool)
    f[~(ok & np.isfinite(f))] = np.nan
    return f


def score(table: npt.ArrayLike, how: Aggregate = "mean") -> np.ndarray:
    """One score a design from a (roads x designs) fitness table: the fitness itself on one road,
    else :func:`aggregate` over the roads."""
    t = _table(table)
    return t[0] if t.shape[0] == 1 else aggregate(t, how)


def aggregate(fitness: npt.ArrayLike, how: Aggregate = "mean") -> np.ndarray:
    """Score (n_designs,) of a fitness table (n_roads, n_designs); larger is better.

    ``mean``: mean fitness over the roads; ``worst``: the smallest (max-min design).
    NaN for a design that failed on any road.
    """
    table = _table(fitness)
    if how == "mean":
        score = table.mean(axis=0)
    elif how == "worst":
        score = table.min(axis=0)
    else:
        raise ValueError(f"unknown aggregate {how!r}: expected one of {', '.join(AGGREGATES)}")
    score = np.asarray(score, dtype=float)
    score[np.any(np.isnan(table), axis=0)] = np.nan
    return score


def best_per_road(fitness: npt.ArrayLike) -> np.ndarray:
    """Each road's best finite fitness over the designs (n_roads,); NaN if all failed."""
    table = _table(fitness)
    out = np.full(table.shape[0], np.nan)
    ok = np.any(np.isfinite(table), axis=1)
    out[ok] = np.nanmax(table[ok], axis=1)
    return out


def regret(per_road_fitness: npt.ArrayLike, per_road_optimum: npt.ArrayLike) -> Regret:
    """What designs cost on each road against the road's own optimum.

    ``per_road_fitness``: (n_roads,) for one design or (n_roads, n_designs);
    ``per_road_optimum``: (n_roads,), e.g. :func:`best_per_road` or the paper's rows.
    Returns ``optimum - fitness`` [m] (>= 0 when the optimum is the best) and
    ``100 (optimum - fitness) / optimum`` [%], shaped like ``per_road_fitness``.
    Failed evaluations give NaN.
    """
    fit = np.array(per_road_fitness, dtype=float)
    opt = np.array(per_road_optimum, dtype=float).ravel()
    if fit.ndim not in (1, 2) or fit.shape[0] != opt.size:
        raise ValueError(
            f"per_road_fitness {fit.shape} must have one row a road ({opt.size} optima)"
        )
    fit[~np.isfinite(fit)] = np.nan
    opt_col = opt if fit.ndim == 1 else opt[:, None]
    absolute = opt_col - fit
    with np.errstate(divide="ignore", invalid="ignore"):
        percent = np.where(opt_col != 0, 100.0 * absolute / opt_col, np.nan)
    return Regret(absolute, percent)


def _table(fitness: npt.ArrayLike) -> np.ndarray:
    table = np.array(fitness, dtype=float)
    if table.ndim != 2 or table.shape[0] == 0:
        raise ValueError(f"fitness must have shape (n_roads >= 1, n_designs), got {table.shape}")
    table[~np.isfinite(table)] = np.nan
    return table
