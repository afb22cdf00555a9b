"""The design space: the search box of Table 8, and the optimiser's settings (Table 10 as a preset).

Both are frozen values with the paper's numbers as defaults; they validate themselves and
raise :class:`SpaceError` naming the field, so the command line and the REST API share one
definition of every default and every rule (the API takes its limits from ``DE_LIMITS``).
Designs are rows (a2 [rad], L2 [m], R_WS [m]); the box is given in a2 [deg], L2 [m], R_WS [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from finaldrive.engine.optimize import OPTIMISERS, Optimiser

Interval = tuple[float, float]


class SpaceError(ValueError):
    """A bound or DE parameter that is not allowed; ``field`` names it."""

    def __init__(self, field: str, msg: str) -> None:
        super().__init__(f"{field}: {msg}")
        self.field = field
        self.msg = msg


@dataclass(frozen=True)
class Bounds:
    """The DE search box, Table 8: a2 [deg] (periodic over a full turn), L2 [m], R_WS [m]."""

    a2_deg: Interval = (0.0, 360.0)
    l2_m: Interval = (0.0, 0.2)
    rws_m: Interval = (0.05, 0.15)

    def __post_init__(self) -> None:
        for f in fields(self):
            lo, hi = getattr(self, f.name)
            if not (_finite(lo) and _finite(hi)):
                raise SpaceError(f.name, f"bounds must be finite numbers, got {_show(lo)}, {_show(hi)}")
            if lo > hi:
                raise SpaceError(f.name, f"lower bound {lo:g} is above upper bound {hi:g}")
        lo, hi = self.a2_deg
        if lo == hi:
            raise SpaceError("a2_deg", "the periodic angle needs lower < upper")
        if hi - lo > 360.0:
            raise SpaceError("a2_deg", "the range may not exceed 360 deg")
        if self.l2_m[0] < 0:
            raise SpaceError("l2_m", "must be >= 0 m")
        if self.rws_m[0] <= 0:
            raise SpaceError("rws_m", "must be > 0 m")

    @property
    def lower(self) -> np.ndarray:
        """Lower corner in engine units (a2 [rad], L2 [m], R_WS [m])."""
        return np.array([math.radians(self.a2_deg[0]), self.l2_m[0], self.rws_m[0]])

    @property
    def upper(self) -> np.ndarray:
        return np.array([math.radians(self.a2_deg[1]), self.l2_m[1], self.rws_m[1]])

    @property
    def periodic(self) -> list[bool]:
        """a2 wraps around only when its range is the whole circle; L2 and R_WS never do."""
        return [math.isclose(self.a2_deg[1] - self.a2_deg[0], 360.0), False, False]

    @classmethod
    def parse(cls, text: str | None) -> Bounds:
        """``a2_deg=LO:HI,l2_m=LO:HI,rws_m=LO:HI`` (any subset; the rest from Table 8)."""
        box: dict[str, Interval] = {}
        names = [f.name for f in fields(cls)]
        for raw in (text or "").split(","):
            if not raw.strip():
                continue
            name, _, values = (s.strip() for s in raw.partition("="))
            if name not in names:
                raise SpaceError(name or raw.strip(), f"unknown variable: expected one of {', '.join(names)}")
            try:
                lo, hi = (float(v) for v in values.split(":"))
            except ValueError:
                raise SpaceError(name, f"{values!r}: expected LOWER:UPPER") from None
            box[name] = (lo, hi)
        return cls(**box)

    def spec(self) -> str:
        """The inverse of :meth:`parse`."""
        return ",".join(f"{f.name}={getattr(self, f.name)[0]:g}:{getattr(self, f.name)[1]:g}" for f in fields(self))


#: (lowest, highest) value of each optimiser parameter anyone may ask for (a request beyond is refused).
DE_LIMITS: dict[str, tuple[float, float]] = {
    "np": (4, 10_000),           # best/1 needs the best and two others
    "f": (0.0, 2.0),
    "cp": (0.0, 1.0),
    "mp": (0.0, 1.0),
    "mr_fraction": (0.0, 1.0),
    "sigma": (1e-3, 1.0),
    "iters": (0, 100_000),
    "patience": (1, 100_000),
    "tol_m": (0.0, 1.0),
    "max_evals": (4, 100_000_000),
}

#: The settings that are whole numbers, and those that may be None (no limit).
DE_INTEGRAL = ("np", "iters", "patience", "max_evals")
DE_OPTIONAL = ("patience", "max_evals")

#: What each setting means (the API's and the command line's help), and which method uses it.
DE_HELP: dict[str, str] = {
    "optimiser": "the method: de (the paper's differential evolution) or cmaes (IPOP-CMA-ES)",
    "np": "population size: de's NP; cmaes's first population (each restart doubles it)",
    "f": "de: differential weight F",
    "cp": "de: crossover probability CP",
    "mp": "de: mutation probability MP",
    "mr_fraction": "de: mutation range MR, a fraction of each range",
    "sigma": "cmaes: first step size, a fraction of each range",
    "iters": "rounds (generations) after the first",
    "patience": "stop after this many rounds in which the best fitness gained no more than tol_m",
    "tol_m": "the fitness gain that counts as progress for patience (the objective's noise) [m]",
    "max_evals": "evaluation budget of one run (>= np)",
}

#: The named starting points of the settings: ``default`` (stops once converged) and ``paper``
#: (Table 10: 50 generations of 50, no early stop; reproduces the paper study).
DE_PRESETS = ("default", "paper")


@dataclass(frozen=True)
class DESettings:
    """An optimiser run's settings (docs/optimisation.md); the fields are :data:`DE_HELP`'s.

    The defaults stop a run once it has converged: DE with NP 16 and F 0.8 (Table 10's CP, MP and
    MR), at most 100 generations, stopping after 15 generations that gained no more than 0.2 mm
    (the fitness's noise: a 1e-9 change of a design moves it up to 0.21 mm on sine:0.04:3);
    measured in docs/optimisation.md (bench/bench_optimisers.py). :meth:`paper` gives Table 10. ``f``, ``cp``,
    ``mp`` and ``mr_fraction`` are the DE's, ``sigma`` is CMA-ES's.
    """

    optimiser: str = "de"
    np: int = 16
    f: float = 0.8
    cp: float = 0.6
    mp: float = 0.1
    mr_fraction: float = 0.2
    sigma: float = 0.3
    iters: int = 100
    patience: int | None = 15
    tol_m: float = 2e-4
    max_evals: int | None = None

    def __post_init__(self) -> None:
        if self.optimiser not in OPTIMISERS:
            raise SpaceError("optimiser", f"unknown method {_show(self.optimiser)}: expected one of "
                             f"{', '.join(OPTIMISERS)}")
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None or f.name == "optimiser":
                continue
            lo, hi = DE_LIMITS[f.name]
            integral = f.name in DE_INTEGRAL
            if isinstance(value, bool) or not isinstance(value, (int, float)) or (integral and value != int(value)):
                raise SpaceError(f.name, f"must be {'an integer' if integral else 'a number'}, got {_show(value)}")
            if not (_finite(value) and lo <= value <= hi):
                raise SpaceError(f.name, f"must be in [{lo:g}, {hi:g}], got {_show(value)}")
        if self.max_evals is not None and self.max_evals < self.np:
            raise SpaceError("max_evals", f"must be >= np ({self.np}), got {self.max_evals}")

    @classmethod
    def paper(cls) -> DESettings:
        """The paper's DE, Table 10: NP 50, F 0.6, CP 0.6, MP 0.1, MR 0.2, 50 generations, no early stop."""
        return cls(np=50, f=0.6, iters=50, patience=None, tol_m=0.0)

    @classmethod
    def preset(cls, name: str, **given: Any) -> DESettings:
        """The preset ``name`` (:data:`DE_PRESETS`) with the ``given`` fields."""
        if name not in DE_PRESETS:
            raise SpaceError("preset", f"unknown preset {_show(name)}: expected one of {', '.join(DE_PRESETS)}")
        base = cls.paper() if name == "paper" else cls()
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(given) - names)
        if unknown:
            raise SpaceError(unknown[0], "not a setting of the optimiser")
        return replace(base, **given)

    def evals_per_run(self) -> int:
        """Evaluations one run plans at most: np (iters + 1) (Table 10: 2,550), within max_evals.
        A run that converges stops earlier."""
        planned = self.np * (self.iters + 1)
        return min(planned, self.max_evals) if self.max_evals else planned

    def build(self, bounds: Bounds, seed: int) -> Optimiser:
        """A new optimiser of this method over ``bounds`` (engine units)."""
        common: dict[str, Any] = {"periodic": bounds.periodic, "pop_size": self.np, "max_iter": self.iters,
                                  "max_evals": self.max_evals, "patience": self.patience, "tol": self.tol_m,
                                  "seed": seed}
        own: dict[str, dict[str, Any]] = {
            "de": {"f": self.f, "cp": self.cp, "mp": self.mp, "mr_fraction": self.mr_fraction},
            "cmaes": {"sigma": self.sigma},
        }
        method: Any = OPTIMISERS[self.optimiser]  # each method's constructor takes its own settings
        return method(bounds.lower, bounds.upper, **common, **own.get(self.optimiser, {}))  # type: ignore[no-any-return]


def _show(v: object) -> str:
    """A value for a message, never longer than 24 characters."""
    text = repr(v)
    return text if len(text) <= 24 else text[:21] + "..."


def _finite(v: float) -> bool:
    """A real number that is finite as a float (an int like 10**400 is not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False
