"""What every optimiser shares: the ranking of failures, the stopping rules, argument checks and
the JSON encoding of states (numpy and the standard library only)."""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

StopReason = Literal["max_iter", "max_evals", "patience"]


class AskTell:
    """What the methods share around their own algorithm: taking a tell's values, the read-outs of
    the rows kept, the stopping rules, and the history in a state (the attributes below are set by
    each method's ``__init__``)."""

    _lower: np.ndarray
    _pending: np.ndarray | None
    _population: np.ndarray
    _fitness: np.ndarray
    _stall: Stall
    generation: int
    n_evals: int
    history: list[dict[str, Any]]
    stop_reason: StopReason | None
    max_iter: int
    max_evals: int | None
    patience: int | None

    def _told(self, fitness: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(the pending rows, their values as floats, non-finite -> NaN); nothing is pending after."""
        if self._pending is None:
            raise RuntimeError("tell() without a pending ask()")
        values = np.array(fitness, dtype=float).ravel()
        if values.size != len(self._pending):
            raise ValueError(f"expected {len(self._pending)} fitness values, got {values.size}")
        values[~np.isfinite(values)] = np.nan
        rows, self._pending = self._pending, None
        return rows, values

    @property
    def done(self) -> bool:
        """True once a stopping rule fired (see ``stop_reason``)."""
        return self.stop_reason is not None

    @property
    def dim(self) -> int:
        """d, the number of variables."""
        return self._lower.size

    @property
    def population(self) -> np.ndarray:
        """The rows the method keeps, best first; empty before the first tell."""
        return self._population.copy()

    @property
    def fitness(self) -> np.ndarray:
        """Fitness of ``population`` (NaN = failed)."""
        return self._fitness.copy()

    def _stop_rule(self) -> StopReason | None:
        """The stopping rules, checked after each tell in this order."""
        if self.generation >= self.max_iter:
            return "max_iter"
        if self.max_evals is not None and self.n_evals >= self.max_evals:
            return "max_evals"
        if self.patience is not None and self._stall.count >= self.patience:
            return "patience"
        return None

    def _history_json(self) -> list[dict[str, Any]]:
        return [{k: encode(v) for k, v in h.items()} for h in self.history]


def generator_for(rng_state: dict[str, Any]) -> tuple[np.random.Generator, Any]:
    """A generator on a new bit generator of the saved state's kind, and that bit generator (set its
    ``state`` to ``rng_state`` once the optimiser built on it has drawn its start)."""
    bit_generator = getattr(np.random, rng_state["bit_generator"])()
    return np.random.Generator(bit_generator), bit_generator


class Stall:
    """Rounds since the best fitness last gained more than ``tol`` (``patience``'s count)."""

    def __init__(self, tol: float) -> None:
        self.tol = tol
        self.count = 0
        self.ref = math.nan  # the best at that gain

    def start(self, best: float) -> None:
        """The first round's best: the reference for the rounds to come."""
        self.ref = best

    def update(self, best: float) -> None:
        """A later round's best: a gain of more than ``tol`` restarts the count."""
        if rank_of(best) > rank_of(self.ref) + self.tol:
            self.count, self.ref = 0, best
        else:
            self.count += 1


#: The largest float: where rank_key puts an infinity (as numpy's ``nan_to_num`` does).
_FMAX = float(np.finfo(float).max)


def rank_key(values: npt.ArrayLike) -> np.ndarray:
    """Ranking key: failed (NaN) ranks below every finite value (numpy's ``nan_to_num`` with
    ``nan=-inf``, +-inf made +-the largest float, in three ufuncs: ``nan_to_num`` cost a DE's tell
    15 us a call, issue 27)."""
    x = np.asarray(values, dtype=float)
    return np.where(np.isnan(x), -np.inf, np.minimum(np.maximum(x, -_FMAX), _FMAX))


def rank_of(value: float) -> float:
    """:func:`rank_key` of one value, without numpy."""
    return -math.inf if math.isnan(value) else min(max(float(value), -_FMAX), _FMAX)


def check_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def check_float(name: str, value: Any, low: float, high: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and low <= v <= high):
        raise ValueError(f"{name} must be in [{low}, {high}], got {value!r}")
    return v


def encode(v: Any) -> Any:
    """A float for JSON: NaN and infinities as None."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def decode(v: Any) -> Any:
    return math.nan if v is None else v


def jsonable(obj: Any) -> Any:
    """numpy arrays and scalars inside a random state -> lists and Python numbers."""
    if isinstance(obj, dict):
        return {k: jsonable(v) for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def plain_json(obj: Any) -> Any:
    """A state taken with numpy arrays in it (``state(arrays=True)``) as plain JSON types: arrays and
    numpy scalars as lists and Python numbers, NaN and infinities as None (a plain state unchanged)."""
    if isinstance(obj, dict):
        return {k: plain_json(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [plain_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind != "f":
            return obj.tolist()
        values = obj.astype(object)
        values[~np.isfinite(obj)] = None
        return values.tolist()
    if isinstance(obj, np.generic):
        obj = obj.item()
    return encode(obj)
