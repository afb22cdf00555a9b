"""The engine's one interface: a design (or a batch of designs) and a road in, results out.

Everything here is a frozen, picklable value; nothing reads files or the environment.
Designs are rows (a2 [rad], L2 [m], R_WS [m]); R_ES = R_WS / ratio (Table 8: ratio 2.0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from finaldrive.engine import record
from finaldrive.engine.record import DIAGNOSTICS, VALUES

STATUS_OK = "ok"
STATUS_FAILED = "failed"

Method = Literal["fast", "reference"]


class DesignError(ValueError):
    """A design that is not physical (names the variable)."""


@dataclass(frozen=True, slots=True)
class Design:
    """Final-drive design variables (Table 8).

    a2: angle of r_{1->2} in the chassis frame [rad] (wraps around 2 pi);
    l2: distance from the swingarm pivot to the engine sprocket axis [m];
    rws: wheel sprocket pitch radius R_WS [m].
    """

    a2: float
    l2: float
    rws: float

    def __post_init__(self) -> None:
        for name in ("a2", "l2", "rws"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise DesignError(f"{name} must be a finite number, got {v!r}")
        if self.l2 < 0:
            raise DesignError(f"l2 must be >= 0 m, got {self.l2}")
        if self.rws <= 0:
            raise DesignError(f"rws must be > 0 m, got {self.rws}")

    @classmethod
    def from_deg(cls, a2_deg: float, l2: float, rws: float) -> Design:
        return cls(math.radians(a2_deg), l2, rws)

    @property
    def a2_deg(self) -> float:
        return math.degrees(self.a2)

    def row(self) -> np.ndarray:
        return np.array([self.a2, self.l2, self.rws])


@dataclass(frozen=True, slots=True)
class SimSettings:
    """How to simulate. Defaults are documented in docs/engine.md.

    method: ``reference`` is the paper's augmented Lagrangian + trapezoidal start +
    ABM predictor-corrector with under-relaxation (eqs. 57-66) in the 39 natural
    coordinates; ``fast`` is the same model in 6 minimal coordinates with a linearly
    implicit Rosenbrock-W step (engine.fast), validated against the reference.
    """

    duration: float = 3.5            # simulated time [s] (paper: 3.5 s)
    method: Method = "fast"
    dt: float = 1.0e-3               # reference: time step [s] (paper: not given);
                                     # fast: series rows every series_stride * dt
    fast_tolerance: float = 5.0e-5   # fast: local error tolerance (m, rad; 10x for rates)
    fast_max_step: float = 8.0e-3    # fast: largest step [s] (ROS34PW2; ROS2 half of it)
    trapezoidal_steps: int = 4       # paper section 3.3, step 3
    under_relaxation: float = 0.7    # nu of eq. (65) (paper: 0.7)
    penalty_alpha: float = 1.0e5     # alpha of eqs. (57)-(58) (paper: 1e5)
    baumgarte_xi: float = 1.0        # xi of eq. (57) (paper: 1)
    baumgarte_omega: float = 10.0    # omega of eq. (57) (paper: 10)
    corrector_tol: float = 1.0e-9    # eq. (66) error bound on q [m, rad]
    corrector_max_iter: int = 30     # corrector iterations before a step is a failure
    lambda_tol: float = 1.0e-10      # augmented Lagrangian iteration tolerance on q'' (relative)
    lambda_max_iter: int = 20        # eq. (58) iterations per evaluation
    max_constraint_residual: float = 1.0e-3  # max|Phi| beyond which the run has diverged
    max_airborne_time: float = 0.5   # s a wheel may stay off the road before the run fails
    series: bool = False             # keep time series (Fig. 13 quantities)
    series_stride: int = 10          # series rows every stride * dt (fast: steps land there too)
    tyre_longitudinal: bool = True   # False only for verification
    fast_ros2: bool = False          # fast: ROS2 on every road, for verification (else ROS34PW2 where
                                     # engine.fast.rosenbrock.high_order allows it)
    max_wall_s: float | None = 60.0  # wall-time limit of one simulation [s] (None: none); changes no
                                     # result that finishes within it (not part of a result's identity)

    def __post_init__(self) -> None:
        if not (self.duration > 0 and math.isfinite(self.duration)):
            raise ValueError("duration must be > 0 s")
        if not (0 < self.dt <= 0.01):
            raise ValueError("dt must be in (0, 0.01] s")
        if self.method not in ("fast", "reference"):
            raise ValueError(f"method must be 'fast' or 'reference', got {self.method!r}")
        if self.trapezoidal_steps < 1 or self.corrector_max_iter < 1 or self.lambda_max_iter < 1:
            raise ValueError("step and iteration counts must be >= 1")
        if not (self.fast_tolerance > 0 and self.fast_max_step > 0):
            raise ValueError("fast_tolerance and fast_max_step must be > 0")
        if not 0 < self.under_relaxation <= 1:
            raise ValueError("under_relaxation must be in (0, 1]")
        if self.penalty_alpha <= 0 or self.baumgarte_omega < 0 or self.baumgarte_xi < 0:
            raise ValueError("penalty_alpha must be > 0, baumgarte xi and omega >= 0")
        if self.series_stride < 1:
            raise ValueError("series_stride must be >= 1")
        if self.max_wall_s is not None and not self.max_wall_s > 0:
            raise ValueError("max_wall_s must be > 0 s or None")

    def steps(self) -> tuple[int, float]:
        """(number of steps, step) covering the duration exactly with a step <= dt."""
        n = max(1, math.ceil(self.duration / self.dt - 1e-9))
        return n, self.duration / n

    def with_(self, **changes: object) -> SimSettings:
        return replace(self, **changes)  # type: ignore[arg-type]


@dataclass(frozen=True, eq=False)
class SimResult:
    """One simulation's outcome: ``status``, ``reason`` and one result record (``values``, in
    :data:`~finaldrive.engine.record.VALUES` order, read by name: ``result.distance_m``); NaN
    where the run produced no value (a failed run's distance and diagnostics)."""

    status: str
    reason: str
    values: np.ndarray
    series: dict[str, np.ndarray] | None = None

    @classmethod
    def of(cls, status: str, reason: str, series: dict[str, np.ndarray] | None = None,
           **values: float) -> SimResult:
        """A result from its values by name (those left out are NaN)."""
        return cls(status, reason, record.values_of(**values), series)

    def __getattr__(self, name: str) -> float:
        column = record.COLUMN.get(name)
        if column is None:
            raise AttributeError(name)
        return float(self.__dict__["values"][column])

    def diagnostics(self) -> dict[str, float]:
        """The diagnostics (:data:`DIAGNOSTICS`) by name."""
        return {name: getattr(self, name) for name in DIAGNOSTICS}

    @property
    def ok(self) -> bool:
        return self.status == STATUS_OK

    def summary(self) -> dict[str, float | str]:
        """The record as a JSON-ready dict (the outputs' names)."""
        return {"status": self.status, "reason": self.reason,
                **{name: float(v) for name, v in zip(VALUES, self.values.tolist(), strict=True)}}


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Results of a batch, one row per input design, in order: the designs, each one's status and
    reason, and a block of result records (``values``: (n, len(VALUES)) float64, columns in
    :data:`~finaldrive.engine.record.VALUES` order; a column by name: ``batch.fitness_m``)."""

    designs: np.ndarray          # (n, 3): a2 [rad], L2 [m], R_WS [m]
    values: np.ndarray
    status: tuple[str, ...]
    reason: tuple[str, ...]

    def __getattr__(self, name: str) -> np.ndarray:
        column = record.COLUMN.get(name)
        if column is None:
            raise AttributeError(name)
        values: np.ndarray = self.__dict__["values"][:, column]
        return values

    def __len__(self) -> int:
        return len(self.status)

    @property
    def ok(self) -> np.ndarray:
        return np.array([s == STATUS_OK for s in self.status], dtype=bool)

    def result(self, i: int) -> SimResult:
        return SimResult(self.status[i], self.reason[i], self.values[i].copy())

    @classmethod
    def of(cls, designs: np.ndarray, status: tuple[str, ...], reason: tuple[str, ...],
           **columns: np.ndarray | float) -> BatchResult:
        """A batch from its value columns by name (those left out are NaN)."""
        rows = np.asarray(designs, dtype=float).reshape(-1, 3)
        values = record.empty(len(rows))
        for name, column in columns.items():
            values[:, record.COLUMN[name]] = column  # a KeyError names a value the record does not declare
        return cls(rows, values, status, reason)

    @classmethod
    def from_results(cls, designs: np.ndarray, results: list[SimResult]) -> BatchResult:
        values = np.array([r.values for r in results], dtype=record.DTYPE).reshape(-1, len(VALUES))
        return cls(np.asarray(designs, dtype=float).reshape(-1, 3), values,
                   tuple(r.status for r in results), tuple(r.reason for r in results))

    @classmethod
    def failed(cls, designs: np.ndarray, reason: str) -> BatchResult:
        """Every design failed, for ``reason`` (e.g. its worker was lost); 0 s of wall time."""
        rows = np.asarray(designs, dtype=float).reshape(-1, 3)
        values = record.empty(len(rows))
        values[:, record.COLUMN["wall_s"]] = 0.0
        return cls(rows, values, (STATUS_FAILED,) * len(rows), (reason,) * len(rows))

    def rows(self, index: slice) -> BatchResult:
        """The results of a range of rows, in order."""
        return BatchResult(self.designs[index], self.values[index], self.status[index], self.reason[index])

    @classmethod
    def concat(cls, parts: list[BatchResult]) -> BatchResult:
        """Join batches in the given order."""
        if not parts:
            return cls.from_results(np.zeros((0, 3)), [])
        return cls(np.concatenate([p.designs for p in parts]), np.concatenate([p.values for p in parts]),
                   tuple(s for p in parts for s in p.status), tuple(s for p in parts for s in p.reason))
