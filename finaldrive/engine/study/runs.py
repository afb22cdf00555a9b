"""Runs: the parts of a study that ask for simulations and take their results back.

A study is a list of runs over a list of roads: a sweep (every grid design on every road)
or a differential evolution (one road, as in the paper, or several roads scored together).
A run hands out :class:`Request` s, designs to simulate on one road, and takes the fitness
of each back in any order. Everything a run has handed out and not yet been told is
independent work: callers may split, merge, reorder and spread it over any executor.

A :class:`DERun` hands out one whole generation (on each of its roads) and the next only
once every result of that generation is told, in the order the optimiser asked for its
rows; so a seeded DE gives bit-identical results however and wherever the work runs.
The rule for a failed evaluation is :func:`finaldrive.engine.study.scoring.fitness_values`:
a failure is NaN, ranked below every finite fitness.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from finaldrive.engine.optimize import Optimiser
from finaldrive.engine.study.scoring import Aggregate, score


@dataclass(frozen=True)
class Request:
    """Designs to simulate on one road for one step of a run.

    run: index of the run in its study; step: the DE generation (0 = initial population) or
    the sweep's step; road: index into the study's roads; candidates: each design's row in
    the sweep grid or in the generation; designs: (n, 3) rows a2 [rad], L2 [m], R_WS [m].
    """

    run: int
    step: int
    road: int
    candidates: np.ndarray
    designs: np.ndarray
    #: the run waits for these results before it can ask for more (a DE generation, not a sweep's road)
    waited: bool = False

    def __len__(self) -> int:
        return len(self.candidates)

    def part(self, rows: np.ndarray) -> Request:
        """The same request restricted to some of its rows (positions 0..n-1)."""
        rows = np.asarray(rows, dtype=int)
        return Request(self.run, self.step, self.road, self.candidates[rows], self.designs[rows], self.waited)

    def split(self, n: int) -> tuple[Request, Request]:
        """The first ``n`` rows and the rest (views, nothing copied)."""
        return (Request(self.run, self.step, self.road, self.candidates[:n], self.designs[:n], self.waited),
                Request(self.run, self.step, self.road, self.candidates[n:], self.designs[n:], self.waited))


class SweepRun:
    """Every design of a grid on every road of the run: one request a road, all at once."""

    def __init__(self, index: int, roads: Sequence[int], designs: np.ndarray, *, step: int = 0,
                 done: set[tuple[int, int]] | None = None) -> None:
        """``done``: (road, candidate) pairs already evaluated (a resumed run skips them)."""
        self.index = index
        self.step = step
        self._designs = np.asarray(designs, dtype=float).reshape(-1, 3)
        skip = done or set()
        self._pending = [
            (road, np.array([c for c in range(len(self._designs)) if (road, c) not in skip], dtype=int))
            for road in roads
        ]
        self._left = sum(len(c) for _, c in self._pending)
        self._slots = len(self._designs) * len(roads)

    @property
    def evaluations(self) -> int:
        """The evaluations this run makes in all (a stored job holds exactly these once it is done)."""
        return self._slots

    @property
    def generations(self) -> int:
        """A sweep tells no generations."""
        return 0

    def take(self) -> list[Request]:
        """The requests not handed out yet (everything, the first time)."""
        out = [Request(self.index, self.step, road, c, self._designs[c]) for road, c in self._pending if len(c)]
        self._pending = []
        return out

    def tell(self, road: int, step: int, candidates: np.ndarray, fitness: np.ndarray) -> bool:
        """Record results; a sweep has no generations, so this never completes one (returns False)."""
        self._left -= len(candidates)
        return False

    @property
    def done(self) -> bool:
        return self._left <= 0 and not self._pending


class DERun:
    """One optimiser run (any method of engine.optimize): each round is evaluated on every road of
    the run and told to the optimiser as one score a design (the fitness on one road, else ``aggregate``
    over the roads, engine.study.scoring)."""

    def __init__(self, index: int, optimiser: Optimiser, roads: Sequence[int], *,
                 aggregate: Aggregate = "mean", generation: int = 0) -> None:
        """``generation``: how many rounds ``optimiser`` has been told (a resumed run's count)."""
        if not roads:
            raise ValueError("a DE run needs at least one road")
        self.index = index
        self.optimiser = optimiser
        self.roads = tuple(roads)
        self.aggregate = aggregate
        self.generation = generation
        self._issued = False
        self._table: np.ndarray | None = None
        self._missing = 0

    def take(self) -> list[Request]:
        """The current generation on every road, once; nothing while it is being evaluated."""
        if self._issued or self.optimiser.done:
            return []
        x = self.optimiser.ask()
        self._issued = True
        self._table = np.full((len(self.roads), len(x)), np.nan)
        self._missing = self._table.size
        rows = np.arange(len(x))
        return [Request(self.index, self.generation, road, rows, x, waited=True) for road in self.roads]

    def tell(self, road: int, step: int, candidates: np.ndarray, fitness: np.ndarray) -> bool:
        """Record results of the current generation; True when that completed it (and it was told)."""
        if self._table is None or step != self.generation:
            raise ValueError(f"run {self.index}: results for generation {step}, expected {self.generation}")
        self._table[self.roads.index(road), np.asarray(candidates, dtype=int)] = fitness
        self._missing -= len(candidates)
        if self._missing > 0:
            return False
        self.optimiser.tell(score(self._table, self.aggregate))
        self.generation += 1
        self._issued = False
        self._table = None
        return True

    @property
    def done(self) -> bool:
        return self.optimiser.done

    @property
    def evaluations(self) -> int:
        """The evaluations of the generations told so far (each design once on each road)."""
        return self.optimiser.n_evals * len(self.roads)

    @property
    def generations(self) -> int:
        """The generations told so far (the initial population is the first)."""
        return self.generation
