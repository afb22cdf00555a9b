"""The design space: the DE search box of Table 8 and the DE parameters of Table 10.

Both are frozen values with the paper's numbers as defaults; they validate themselves and
raise :class:`SpaceError` naming the field, so the command line and the REST API share one
definition of every default and every rule (the API takes its limits from ``DE_LIMITS``).
Designs are rows (a2 [rad], L2 [m], R_WS [m]); the box is given in a2 [deg], L2 [m], R_WS [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from finaldrive.engine.optimize import DifferentialEvolution

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


#: (lowest, highest) value of each DE parameter anyone may ask for (a request beyond is refused).
DE_LIMITS: dict[str, tuple[float, float]] = {
    "np": (4, 10_000),           # best/1 needs the best and two others
    "f": (0.0, 2.0),
    "cp": (0.0, 1.0),
    "mp": (0.0, 1.0),
    "mr_fraction": (0.0, 1.0),
    "iters": (0, 100_000),
    "patience": (1, 100_000),
    "max_evals": (4, 100_000_000),
}


@dataclass(frozen=True)
class DESettings:
    """The paper's DE parameters, Table 10 (section 4, Fig. 7).

    np: population size NP; f: differential weight F; cp: crossover probability CP;
    mp: mutation probability MP; mr_fraction: mutation range MR over (upper - lower);
    iters: generations after the initial population (IterMax); patience: stop after this
    many generations without improvement; max_evals: evaluation budget of one DE run.
    """

    np: int = 50
    f: float = 0.6
    cp: float = 0.6
    mp: float = 0.1
    mr_fraction: float = 0.2
    iters: int = 50
    patience: int | None = None
    max_evals: int | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            lo, hi = DE_LIMITS[f.name]
            integral = f.name in ("np", "iters", "patience", "max_evals")
            if isinstance(value, bool) or not isinstance(value, (int, float)) or (integral and value != int(value)):
                raise SpaceError(f.name, f"must be {'an integer' if integral else 'a number'}, got {_show(value)}")
            if not (_finite(value) and lo <= value <= hi):
                raise SpaceError(f.name, f"must be in [{lo:g}, {hi:g}], got {_show(value)}")
        if self.max_evals is not None and self.max_evals < self.np:
            raise SpaceError("max_evals", f"must be >= np ({self.np}), got {self.max_evals}")

    def evals_per_run(self) -> int:
        """Evaluations one DE run plans: NP + IterMax NP (Table 10: 2,550), within max_evals."""
        planned = self.np * (self.iters + 1)
        return min(planned, self.max_evals) if self.max_evals else planned

    def optimiser(self, bounds: Bounds, seed: int) -> DifferentialEvolution:
        """A new DE over ``bounds`` (engine units)."""
        return DifferentialEvolution(
            bounds.lower, bounds.upper, periodic=bounds.periodic, pop_size=self.np, f=self.f, cp=self.cp,
            mp=self.mp, mr_fraction=self.mr_fraction, max_iter=self.iters, max_evals=self.max_evals,
            patience=self.patience, seed=seed,
        )


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
