"""The paper's differential evolution as a pure ask/tell optimiser.

Implements the algorithm of the seed paper, section 4, Fig. 7, with the parameters of
Table 10 (NP = 50, F = 0.6, CP = 0.6, MP = 0.1, MR = 0.2 (upper - lower), IterMax = 50).
It maximises, knows nothing of what it optimises, and imports numpy and the standard
library only. The caller owns the loop, the evaluation and any persistence::

    de = DifferentialEvolution(lower, upper, periodic=[True, False, False], seed=1)
    while not de.done:
        x = de.ask()              # (n, d) rows
        de.tell(evaluate(x))      # fitness of those rows, same order
    de.best_x, de.best_f

One generation (paper section 4, steps 3-6), for parent i of the population P (kept
sorted best first, so P[0] is the best individual):

3. donor      v_i = P[0] + F (P[r1] - P[r2]), r1 != r2 drawn uniformly from the whole
              population ("best/1"); on a periodic dimension the difference is taken
              the short way round the circle (wrapped into [-range/2, range/2)).
4. crossover  each component of the offspring u_i comes from the donor with
              probability CP, otherwise from the parent P[i] (binomial); one component,
              chosen uniformly, always comes from the donor.
5. mutation   each component of u_i, independently with probability MP, gets a uniform
              perturbation drawn from [-MR, +MR), MR = mr_fraction (upper - lower).
   bounds     applied once, to the finished offspring: periodic dimensions wrap modulo
              the range into [lower, upper); the others REFLECT at the bounds (repeated
              folding, so any excursion lands inside [lower, upper]).
6. selection  (mu + lambda): the NP best of parents and offspring survive. Ties are
              broken deterministically: offspring before parents (DE's usual "the trial
              wins on equal fitness"), then by index.

Step 4 of the paper reads "the new population is composed of a fraction of individuals
from the previous generation; the remaining members come from the offspring"; we read
it as the binomial crossover of Storn and Price (the paper's reference [32]), per
component, with CP as the donor fraction.

Failed evaluations: any non-finite fitness (NaN, -inf, +inf) is a failure, stored as
NaN; it ranks below every finite value, so a failed design is never the best while a
finite one exists.

Budget: NP evaluations for the initial population, then NP a generation, so Table 10
costs NP + IterMax NP = 2,550. With ``max_evals`` an ask never exceeds the budget: the
last generation is truncated to the remaining evaluations, and then only the best
parents (P[0], P[1], ...) get an offspring. ``max_evals`` must be >= ``pop_size``.

Determinism: all randomness comes from one ``np.random.Generator``, drawn in a fixed
order a generation. The same seed and the same fitness values give bit-identical runs;
fitness is told in ask order, so how or where rows were evaluated cannot matter.
:meth:`state` is JSON-serialisable, and ``from_state(state())`` continues exactly as the
uninterrupted run would, including rows asked but not yet told.

References
----------
[1] Motorcycle final drive geometry optimization on uneven roads, Mechanism and Machine
    Theory (2019), doi 10.1016/j.mechmachtheory.2019.103647: section 4, Fig. 7, Table 10.
[2] R. Storn, K. Price, Differential evolution, J. Global Optimization 11 (1997) 341-359.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from finaldrive.engine.optimize.common import (
    AskTell,
    Stall,
    StopReason,
    check_float,
    check_int,
    decode,
    encode,
    generator_for,
    jsonable,
    plain_json,
    rank_key,
)

STATE_VERSION = 1

class DifferentialEvolution(AskTell):
    """Ask/tell differential evolution of the paper (section 4, Fig. 7, Table 10); maximises.

    Parameters
    ----------
    lower, upper : array_like, shape (d,)
        Search box (Table 8). ``upper >= lower``; a dimension with ``upper == lower`` is
        held fixed. Periodic dimensions need ``upper > lower``.
    periodic : sequence of bool, optional
        Per dimension: True wraps modulo the range (an angle on [0, 2 pi)); False
        reflects at the bounds. Default: no periodic dimension.
    pop_size : int
        NP, the population size (>= 2).
    f : float
        F, the differential weight of the donor (step 3).
    cp : float
        CP, the probability that an offspring component comes from the donor (step 4).
    mp : float
        MP, the probability that an offspring component mutates (step 5).
    mr_fraction : float
        MR as a fraction of the range: MR = mr_fraction (upper - lower) (step 5).
    max_iter : int
        IterMax, generations after the initial population.
    max_evals : int, optional
        Evaluation budget, initial population included (>= pop_size).
    patience : int, optional
        Stop after this many generations without an improvement of ``best_f`` by more than ``tol``.
    tol : float
        The smallest improvement of ``best_f`` that counts for ``patience`` (the objective's noise:
        gains below it are not progress). 0 counts any improvement.
    seed : int, np.random.Generator or None
        The only source of randomness. A Generator is used (and advanced) as given.
    """

    method: ClassVar[str] = "de"

    def __init__(
        self,
        lower: npt.ArrayLike,
        upper: npt.ArrayLike,
        *,
        periodic: Sequence[bool] | npt.ArrayLike | None = None,
        pop_size: int = 50,
        f: float = 0.6,
        cp: float = 0.6,
        mp: float = 0.1,
        mr_fraction: float = 0.2,
        max_iter: int = 50,
        max_evals: int | None = None,
        patience: int | None = None,
        tol: float = 0.0,
        seed: int | np.random.Generator | None = 0,
    ) -> None:
        self._lower = np.array(lower, dtype=float).ravel()
        self._upper = np.array(upper, dtype=float).ravel()
        d = self._lower.size
        if d == 0 or self._upper.size != d:
            raise ValueError("lower and upper must be non-empty and of the same length")
        if not (np.all(np.isfinite(self._lower)) and np.all(np.isfinite(self._upper))):
            raise ValueError("lower and upper must be finite")
        if np.any(self._upper < self._lower):
            raise ValueError("upper must be >= lower in every dimension")
        if periodic is None:
            self._periodic = np.zeros(d, dtype=bool)
        else:
            self._periodic = np.array(periodic, dtype=bool).ravel()
            if self._periodic.size != d:
                raise ValueError(f"periodic must have {d} entries, got {self._periodic.size}")
        if np.any(self._periodic & (self._upper <= self._lower)):
            raise ValueError("a periodic dimension needs upper > lower")
        self.pop_size = check_int("pop_size", pop_size, 2)
        self.f = check_float("f", f, 0.0, math.inf)
        self.cp = check_float("cp", cp, 0.0, 1.0)
        self.mp = check_float("mp", mp, 0.0, 1.0)
        self.mr_fraction = check_float("mr_fraction", mr_fraction, 0.0, math.inf)
        self.max_iter = check_int("max_iter", max_iter, 0)
        self.max_evals = None if max_evals is None else check_int("max_evals", max_evals, self.pop_size)
        self.patience = None if patience is None else check_int("patience", patience, 1)
        self.tol = check_float("tol", tol, 0.0, math.inf)
        self._rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)

        self._width = self._upper - self._lower
        mr = self.mr_fraction * self._width  # MR, Table 10
        self._safe_width = np.where(self._width > 0, self._width, 1.0)
        # rng.uniform(-MR, MR)'s draws as its C code makes them (low + (high - low) u, u = rng.random()),
        # without its broadcasting of array bounds (7.7 us a call, against 1 us)
        self._mr_low, self._mr_range = -mr, mr - (-mr)
        self._wrap = np.flatnonzero(self._periodic)   # the periodic columns
        self.generation = 0           # completed generations after the initial population
        self.n_evals = 0              # evaluations told so far
        self.history: list[dict[str, Any]] = []
        self.stop_reason: StopReason | None = None
        self._population = np.empty((0, d))
        self._fitness = np.empty(0)
        self._stall = Stall(self.tol)  # generations since best_f last gained more than tol
        # Step 1 (Fig. 7): a uniformly random initial population, asked first.
        self._pending: np.ndarray | None = self._rng.uniform(self._lower, self._upper, (self.pop_size, d))
        self._pending = self._bound(self._pending)

    # ------------------------------------------------------------------ ask / tell
    def ask(self) -> np.ndarray:
        """Rows (n, d) to evaluate next: the initial population, then each generation's
        offspring. Asking again before :meth:`tell` returns the same rows."""
        if self._pending is None:
            raise RuntimeError(f"optimisation is done ({self.stop_reason}); nothing to ask")
        return self._pending.copy()

    def tell(self, fitness: npt.ArrayLike) -> None:
        """Fitness of the rows of the last :meth:`ask`, in the same order (maximised).

        Non-finite values are failed evaluations. Runs selection (step 6), the stopping
        rules, and prepares the next generation's offspring (steps 3-5).
        """
        rows, values = self._told(fitness)
        n_failed = int(np.count_nonzero(np.isnan(values)))
        self.n_evals += len(rows)
        initial = self._population.shape[0] == 0
        self._select(rows, values)    # step 6 (step 2 for the initial population)
        if initial:
            self._stall.start(self.best_f)
        else:
            self.generation += 1
            self._stall.update(self.best_f)
        self.history.append(self._record(n_failed))
        self.stop_reason = self._stop_rule()
        if self.stop_reason is None:
            self._pending = self._offspring()

    # ------------------------------------------------------------------ read-outs
    @property
    def lower(self) -> np.ndarray:
        return self._lower.copy()

    @property
    def upper(self) -> np.ndarray:
        return self._upper.copy()

    @property
    def periodic(self) -> np.ndarray:
        return self._periodic.copy()

    @property
    def best_x(self) -> np.ndarray:
        """Best individual (NaN row before the first tell)."""
        if self._population.shape[0] == 0:
            return np.full(self.dim, np.nan)
        return np.array(self._population[0], dtype=float)

    @property
    def best_f(self) -> float:
        """Fitness of ``best_x``; NaN before the first tell or when every evaluation failed."""
        return float(self._fitness[0]) if self._fitness.size else math.nan

    # ------------------------------------------------------------------ state
    def state(self, *, history: bool = True, arrays: bool = False) -> dict[str, Any]:
        """Everything needed to continue the run, as plain JSON types (NaN -> None).

        ``history=False`` leaves out the per-generation records (``history``), which continuing
        does not need: a caller that stores every generation's state and record keeps each state
        O(NP) rather than O(generations), and the stored states O(generations) in all.
        ``arrays=True`` keeps the population, fitness (NaN where failed) and pending designs as numpy
        arrays of their own: quick to take and to hand to another process, made plain JSON types
        there by :func:`~finaldrive.engine.optimize.common.plain_json` (which makes the plain state here).
        """
        out = {
            "method": self.method,
            "version": STATE_VERSION,
            "config": {
                "lower": self._lower.tolist(),
                "upper": self._upper.tolist(),
                "periodic": self._periodic.tolist(),
                "pop_size": self.pop_size,
                "f": self.f,
                "cp": self.cp,
                "mp": self.mp,
                "mr_fraction": self.mr_fraction,
                "max_iter": self.max_iter,
                "max_evals": self.max_evals,
                "patience": self.patience,
                "tol": self.tol,
            },
            "population": self._population.copy(),
            "fitness": self._fitness.copy(),
            "generation": self.generation,
            "n_evals": self.n_evals,
            "stall": self._stall.count,
            "stall_ref": encode(self._stall.ref),
            "stop_reason": self.stop_reason,
            "pending": None if self._pending is None else self._pending.copy(),
            "rng": jsonable(self._rng.bit_generator.state),
        }
        if history:
            out["history"] = self._history_json()
        return out if arrays else plain_json(out)

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> DifferentialEvolution:
        """Rebuild an optimiser from :meth:`state` (also after a JSON round trip); from a state
        taken with ``history=False`` its ``history`` starts empty and gains the records to come."""
        if state.get("version") != STATE_VERSION:
            raise ValueError(f"unsupported DE state version {state.get('version')!r}")
        generator, bit_generator = generator_for(state["rng"])
        de = cls(**state["config"], seed=generator)
        bit_generator.state = state["rng"]  # __init__ drew an initial population: put the saved state back
        d = de.dim
        de._population = np.array(state["population"], dtype=float).reshape(-1, d)
        de._fitness = np.array([decode(v) for v in state["fitness"]], dtype=float)
        de.generation = int(state["generation"])
        de.n_evals = int(state["n_evals"])
        de._stall.count = int(state["stall"])
        de._stall.ref = decode(state["stall_ref"]) if "stall_ref" in state else de.best_f  # tol 0 before
        de.stop_reason = state["stop_reason"]
        pending = state["pending"]
        de._pending = None if pending is None else np.array(pending, dtype=float).reshape(-1, d)
        de.history = [{k: decode(v) for k, v in h.items()} for h in state.get("history", [])]
        return de

    # ------------------------------------------------------------------ algorithm
    def _offspring(self) -> np.ndarray:
        """Steps 3-5 of Fig. 7 for the next generation (truncated to the budget)."""
        n = self.pop_size
        if self.max_evals is not None:
            n = min(n, self.max_evals - self.n_evals)
        d, rng, pop = self.dim, self._rng, self._population
        # Step 3: donor = best + F (r1 - r2), r1 != r2.
        r1 = rng.integers(0, self.pop_size, n)
        r2 = rng.integers(0, self.pop_size - 1, n)
        r2 = r2 + (r2 >= r1)
        diff = pop[r1] - pop[r2]
        if self._wrap.size:  # short way round
            p = self._wrap
            half = 0.5 * self._width[p]
            diff[:, p] = np.mod(diff[:, p] + half, self._safe_width[p]) - half
        donor = pop[0] + self.f * diff
        # Step 4: binomial crossover, at least one donor component.
        from_donor = rng.random((n, d)) < self.cp
        from_donor[np.arange(n), rng.integers(0, d, n)] = True
        child = np.where(from_donor, donor, pop[:n])
        # Step 5: each component mutates with probability MP, uniformly within +-MR.
        mutate = rng.random((n, d)) < self.mp
        child = child + mutate * (self._mr_low + self._mr_range * rng.random((n, d)))
        return self._bound(child)

    def _select(self, rows: np.ndarray, values: np.ndarray) -> None:
        """Step 6: the NP best of offspring and parents; offspring win ties (stable sort)."""
        x = np.concatenate([rows, self._population])
        fx = np.concatenate([values, self._fitness])
        order = np.argsort(-rank_key(fx), kind="stable")[: self.pop_size]
        self._population, self._fitness = x[order], fx[order]

    def _bound(self, x: np.ndarray) -> np.ndarray:
        """Wrap periodic dimensions into [lower, upper), reflect the others into [lower, upper]."""
        lo, hi, safe_w = self._lower, self._upper, self._safe_width
        wrapped = lo + np.mod(x - lo, safe_w)
        wrapped = np.where(wrapped >= hi, lo, wrapped)  # mod can round up to the full range
        folded = hi - np.abs(np.mod(x - lo, 2.0 * safe_w) - safe_w)  # triangle wave
        outside = (x < lo) | (x > hi)
        periodic_out = self._periodic & ((x < lo) | (x >= hi))
        x = np.where(periodic_out, wrapped, np.where(outside & ~self._periodic, folded, x))
        return np.asarray(np.clip(x, lo, hi), dtype=float)

    def _record(self, n_failed: int) -> dict[str, Any]:
        finite = self._fitness[np.isfinite(self._fitness)]
        return {
            "generation": self.generation,
            "n_evals": self.n_evals,
            "best_f": self.best_f,
            "mean_f": float(finite.mean()) if finite.size else math.nan,
            "n_failed": n_failed,
        }
