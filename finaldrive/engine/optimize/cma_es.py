"""CMA-ES with increasing-population restarts (IPOP), as an ask/tell optimiser of whole rounds.

The covariance matrix adaptation evolution strategy of Hansen [1], from the ``cmaes`` package [2]
(``cmaes.CMA``), maximising over a box. It searches the box scaled to the unit cube; a periodic
dimension is left unbounded and wrapped into its range when a row is asked (an angle), the
others are bounded (``cmaes`` resamples, then clips). When ``cmaes`` says a run has converged
(its own tolerances), a new run starts from a uniformly random mean with twice the population
(IPOP-CMA-ES, Auger and Hansen [3]).

Stopping rules are the DE's (engine.optimize.de): ``max_iter`` rounds after the first,
``max_evals`` (the last round is cut to the budget), and ``patience`` rounds in which the best
has not improved by more than ``tol``.

Determinism: one seed gives one run; :meth:`CMAES.state` holds the ``cmaes`` object's arrays
and random state, so ``from_state(state())`` continues bit for bit (it sets ``cmaes.CMA``'s
private attributes: tested against each ``cmaes`` release the project allows).

References
----------
[1] N. Hansen, The CMA evolution strategy: a tutorial, arXiv:1604.00772 (2016).
[2] M. Nomura, M. Shibata, cmaes: a simple yet practical Python library for CMA-ES,
    arXiv:2402.01373 (2024).
[3] A. Auger, N. Hansen, A restart CMA evolution strategy with increasing population size,
    IEEE CEC 2005, 1769-1776.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar

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
    rank_key,
    rank_of,
)

if TYPE_CHECKING:
    from cmaes import CMA

STATE_VERSION = 1
#: the arrays of a ``cmaes.CMA`` that change as it runs (everything else follows from its arguments)
_CMA_ARRAYS = ("_mean", "_C", "_p_sigma", "_pc", "_funhist_values")


class CMAES(AskTell):
    """IPOP-CMA-ES over a box (maximises); the protocol of engine.optimize.protocol.

    Parameters
    ----------
    lower, upper, periodic :
        The box and its periodic dimensions, as for the DE.
    pop_size : int, optional
        The first run's population (default: ``cmaes``'s 4 + 3 ln d); each restart doubles it.
    sigma : float
        The first step size, a fraction of each range.
    max_iter, max_evals, patience, tol, seed :
        As for the DE.
    """

    method: ClassVar[str] = "cmaes"

    def __init__(self, lower: npt.ArrayLike, upper: npt.ArrayLike, *,
                 periodic: Sequence[bool] | npt.ArrayLike | None = None, pop_size: int | None = None,
                 sigma: float = 0.3, max_iter: int = 50, max_evals: int | None = None,
                 patience: int | None = None, tol: float = 0.0, seed: int | np.random.Generator | None = 0) -> None:
        self._lower = np.array(lower, dtype=float).ravel()
        self._upper = np.array(upper, dtype=float).ravel()
        d = self._lower.size
        if d == 0 or self._upper.shape != (d,) or np.any(self._upper < self._lower):
            raise ValueError("lower and upper must be non-empty, of one length, with upper >= lower")
        self._periodic = np.zeros(d, bool) if periodic is None else np.array(periodic, dtype=bool).ravel()
        if self._periodic.size != d:
            raise ValueError(f"periodic must have {d} entries, got {self._periodic.size}")
        self.pop_size = None if pop_size is None else check_int("pop_size", pop_size, 2)
        self.sigma = check_float("sigma", sigma, 1e-6, 10.0)
        self.max_iter = check_int("max_iter", max_iter, 0)
        self.max_evals = None if max_evals is None else check_int("max_evals", max_evals, 1)
        self.patience = None if patience is None else check_int("patience", patience, 1)
        self.tol = check_float("tol", tol, 0.0, math.inf)
        self._rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self.generation = 0
        self.n_evals = 0
        self.restarts = 0
        self.history: list[dict[str, Any]] = []
        self.stop_reason: StopReason | None = None
        self._best_x = np.full(d, np.nan)
        self._best_f = math.nan
        self._stall = Stall(self.tol)
        self._population, self._fitness = np.empty((0, d)), np.empty(0)
        self._cma = self._start(self.pop_size)
        self._pending: np.ndarray | None = self._sample()

    # ------------------------------------------------------------------ ask / tell
    def ask(self) -> np.ndarray:
        """The round's rows (n, d); the same again until :meth:`tell`."""
        if self._pending is None:
            raise RuntimeError(f"optimisation is done ({self.stop_reason}); nothing to ask")
        return self._rows(self._pending)

    def tell(self, fitness: npt.ArrayLike) -> None:
        """Fitness of the last ask's rows, in order (non-finite: failed)."""
        z, values = self._told(fitness)
        rows = self._rows(z)
        first = self.n_evals == 0
        self.n_evals += len(rows)
        order = np.argsort(-rank_key(values), kind="stable")
        self._population, self._fitness = rows[order], values[order]
        if rank_of(values[order[0]]) > rank_of(self._best_f):
            self._best_x, self._best_f = rows[order[0]].copy(), float(values[order[0]])
        if first:
            self._stall.start(self._best_f)
        else:
            self.generation += 1
            self._stall.update(self._best_f)
        finite = values[np.isfinite(values)]
        self.history.append({"generation": self.generation, "n_evals": self.n_evals, "best_f": self._best_f,
                             "mean_f": float(finite.mean()) if finite.size else math.nan,
                             "n_failed": int(values.size - finite.size)})
        self.stop_reason = self._stop_rule()
        if self.stop_reason is not None:
            return
        if len(z) == self._cma.population_size:  # a round cut by the budget is never told to cmaes
            worst = float(-finite.min()) + 1.0 if finite.size else 1.0
            self._cma.tell([(zi, -v if np.isfinite(v) else worst) for zi, v in zip(z, values, strict=True)])
            if self._cma.should_stop():
                self.restarts += 1
                self._cma = self._start(2 * self._cma.population_size)
        self._pending = self._sample()

    # ------------------------------------------------------------------ read-outs
    @property
    def best_x(self) -> np.ndarray:
        return self._best_x.copy()

    @property
    def best_f(self) -> float:
        return self._best_f

    # ------------------------------------------------------------------ state
    def state(self, *, history: bool = True, arrays: bool = False) -> dict[str, Any]:
        """Everything needed to continue exactly, as JSON types (NaN -> None); ``arrays`` changes nothing
        here (a few small arrays, and few rounds: nothing to gain from keeping them)."""
        cma = self._cma
        out: dict[str, Any] = {
            "method": self.method, "version": STATE_VERSION,
            "config": {"lower": self._lower.tolist(), "upper": self._upper.tolist(),
                       "periodic": self._periodic.tolist(), "pop_size": self.pop_size, "sigma": self.sigma,
                       "max_iter": self.max_iter, "max_evals": self.max_evals, "patience": self.patience,
                       "tol": self.tol},
            "generation": self.generation, "n_evals": self.n_evals, "restarts": self.restarts,
            "stop_reason": self.stop_reason, "stall": self._stall.count, "stall_ref": encode(self._stall.ref),
            "best_x": [encode(v) for v in self._best_x.tolist()], "best_f": encode(self._best_f),
            "population": self._population.tolist(), "fitness": [encode(v) for v in self._fitness.tolist()],
            "pending": None if self._pending is None else self._pending.tolist(),
            "rng": jsonable(self._rng.bit_generator.state),
            "cma": {"popsize": cma.population_size, "sigma0": self._sigma0, "sigma": cma._sigma, "g": cma._g,
                    **{name: _array_json(getattr(cma, name)) for name in _CMA_ARRAYS},
                    "eigen": None if cma._B is None else [jsonable(cma._B), jsonable(cma._D)],
                    "random_state": jsonable(cma._rng.get_state(legacy=False))},
        }
        if history:
            out["history"] = self._history_json()
        return out

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> CMAES:
        if state.get("version") != STATE_VERSION:
            raise ValueError(f"unsupported CMA-ES state version {state.get('version')!r}")
        generator, bit_generator = generator_for(state["rng"])
        out = cls(**state["config"], seed=generator)
        bit_generator.state = state["rng"]  # __init__ drew a first mean: put the saved state back
        d = out.dim
        out.generation, out.n_evals, out.restarts = state["generation"], state["n_evals"], state["restarts"]
        out.stop_reason, out._stall.count = state["stop_reason"], state["stall"]
        out._stall.ref = decode(state["stall_ref"])
        out._best_x = np.array([decode(v) for v in state["best_x"]], dtype=float)
        out._best_f = decode(state["best_f"])
        out._population = np.array(state["population"], dtype=float).reshape(-1, d)
        out._fitness = np.array([decode(v) for v in state["fitness"]], dtype=float)
        out._pending = None if state["pending"] is None else np.array(state["pending"], dtype=float).reshape(-1, d)
        saved = state["cma"]
        cma = out._new_cma(_array_from_json(saved["_mean"]), saved["sigma0"], saved["popsize"], seed=0)
        for name in _CMA_ARRAYS:
            setattr(cma, name, _array_from_json(saved[name]))
        cma._sigma, cma._g = saved["sigma"], saved["g"]
        cma._B, cma._D = (None, None) if saved["eigen"] is None else (np.array(saved["eigen"][0]),
                                                                      np.array(saved["eigen"][1]))
        random_state = dict(saved["random_state"])
        random_state["state"] = {k: np.array(v, dtype=np.uint32) if k == "key" else v
                                 for k, v in random_state["state"].items()}
        cma._rng.set_state(random_state)
        out._cma = cma
        out.history = [{k: decode(v) for k, v in h.items()} for h in state.get("history", [])]
        return out

    # ------------------------------------------------------------------ internals
    def _start(self, pop_size: int | None) -> CMA:
        """A new run of ``cmaes`` from a uniformly random mean in the unit cube."""
        mean = self._rng.uniform(0.0, 1.0, self.dim)
        return self._new_cma(mean, self.sigma, pop_size, seed=int(self._rng.integers(2**31 - 1)))

    def _new_cma(self, mean: np.ndarray, sigma: float, pop_size: int | None, seed: int) -> CMA:
        from cmaes import CMA  # here: cmaes imports scipy, which importing the engine's facade does not

        self._sigma0 = sigma
        bounds = np.where(self._periodic[:, None], [-np.inf, np.inf], [0.0, 1.0])
        return CMA(mean=mean, sigma=sigma, bounds=bounds, population_size=pop_size, seed=seed)

    def _sample(self) -> np.ndarray:
        """The next round in unit-cube coordinates, cut to the evaluation budget."""
        n = self._cma.population_size
        if self.max_evals is not None:
            n = min(n, self.max_evals - self.n_evals)
        return np.array([self._cma.ask() for _ in range(n)])

    def _rows(self, z: np.ndarray) -> np.ndarray:
        """Unit-cube points as rows of the box (periodic dimensions wrapped into [lower, upper))."""
        z = np.where(self._periodic, np.mod(z, 1.0), np.clip(z, 0.0, 1.0))
        z = np.where(z >= 1.0, np.where(self._periodic, 0.0, 1.0), z)  # mod can round up to the full range
        return np.asarray(self._lower + z * (self._upper - self._lower), dtype=float)


def _array_json(values: np.ndarray) -> dict[str, Any]:
    """An array as JSON (non-finite entries as None: ``cmaes`` starts its history of values from
    ``np.empty``, whose garbage it overwrites before reading it)."""
    return {"shape": list(values.shape), "values": [encode(v) for v in values.ravel().tolist()]}


def _array_from_json(saved: dict[str, Any]) -> np.ndarray:
    return np.array([decode(v) for v in saved["values"]], dtype=float).reshape(saved["shape"])
