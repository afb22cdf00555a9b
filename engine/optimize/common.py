"""What every optimiser shares: the ranking of failures, the stopping rules, argument checks and
the JSON encoding of states (numpy and the standard library only)."""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

StopReason = Literal["max_iter", "max_evals", "patience"]


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
        if rank_key(best) > rank_key(self.ref) + self.tol:
            self.count, self.ref = 0, best
        else:
            self.count += 1


def stop_rule(generation: int, n_evals: int, stall: int, *, max_iter: int, max_evals: int | None,
              patience: int | None) -> StopReason | None:
    """The stopping rules, checked after each tell in this order."""
    if generation >= max_iter:
        return "max_iter"
    if max_evals is not None and n_evals >= max_evals:
        return "max_evals"
    if patience is not None and stall >= patience:
        return "patience"
    return None


def rank_key(values: npt.ArrayLike) -> np.ndarray:
    """Ranking key: failed (NaN) ranks below every finite value."""
    return np.asarray(np.nan_to_num(np.asarray(values, dtype=float), nan=-np.inf), dtype=float)


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
