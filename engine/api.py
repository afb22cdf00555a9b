"""The engine's one interface: a design (or a batch of designs) and a road in, results out.

Everything here is a frozen, picklable value; nothing reads files or the environment.
Designs are rows (a2 [rad], L2 [m], R_WS [m]); R_ES = R_WS / ratio (Table 8: ratio 2.0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal

import numpy as np

STATUS_OK = "ok"
STATUS_FAILED = "failed"

#: What every result reports besides distance, SR, slack and fitness, tracked at every integrator
#: step (never read off the output series; docs/engine.md#extremes-and-the-energy-ledger), units in
#: the names: the extremes of the chain tension, of the tyre loads and of the slip |kappa'|, the time
#: each wheel spends off the road and the upper chain run in compression, the largest tyre
#: compressions, and the energy ledger [J] (drive work = kinetic + potential energy + damper
#: dissipation + tyre slip work - lever-arm work + residual; slip work = carcass energy + tyre
#: dissipation), with the smallest tyre dissipation rate seen [W] (>= 0: the tyre creates no energy).
#: What a run reports besides its fitness: extremes tracked at every accepted step, and its energy
#: ledger (docs/engine.md, "Extremes and the energy ledger"); name -> meaning, the unit in the name.
DIAGNOSTIC_MEANINGS: dict[str, str] = {
    "chain_tension_max_n": "largest tension of the chain's upper run [N]",
    "chain_tension_min_n": "smallest chain tension: negative when the upper run pushes (the paper's chain) or the "
                           "lower run pulls (two runs) [N]",
    "chain_compression_s": "time in overrun: the upper run pushing (the paper's chain) or not taut (two runs) [s]",
    "fz_rear_max_n": "largest vertical load of the rear tyre [N]",
    "fz_rear_min_n": ("smallest vertical load of the rear tyre: 0 when airborne, negative while its damper "
                      "pulls as the tyre springs back (eqs. 36-37 as printed) [N]"),
    "fz_front_max_n": "largest vertical load of the front tyre [N]",
    "fz_front_min_n": ("smallest vertical load of the front tyre: 0 when airborne, negative while its damper "
                      "pulls as the tyre springs back (eqs. 36-37 as printed) [N]"),
    "slip_max": "largest |kappa'|, the rear tyre's transient longitudinal slip [-]",
    "airborne_rear_s": "time the rear wheel spends off the road [s]",
    "airborne_front_s": "time the front wheel spends off the road [s]",
    "tyre_compression_rear_max_m": "largest radial compression of the rear tyre [m]",
    "tyre_compression_front_max_m": "largest radial compression of the front tyre [m]",
    "drive_work_j": "work of the drive torque [J]",
    "kinetic_energy_j": "kinetic energy at the end [J]",
    "potential_energy_j": "change of the potential energy (gravity, springs, bump stop) [J]",
    "damper_dissipation_j": "energy the suspension and tyre dampers (and the two-run chain's impacts) dissipated [J]",
    "tyre_slip_work_j": "work the longitudinal tyre force took by slip: carcass energy + dissipation [J]",
    "tyre_carcass_energy_j": "energy stored in the tyre carcass's deflection at the end [J]",
    "tyre_dissipation_j": "energy the tyre dissipated by slip (>= 0) [J]",
    "tyre_lever_work_j": "work the tyre force created through a lever arm other than R_e (0 by default) [J]",
    "ledger_residual_j": "drive + lever work - (kinetic + potential + dampers + slip): the ledger's error [J]",
    "tyre_dissipation_min_w": "smallest slip dissipation power at any step (>= 0: no energy created) [W]",
}
DIAGNOSTICS: tuple[str, ...] = tuple(DIAGNOSTIC_MEANINGS)


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


@dataclass(frozen=True)
class SimResult:
    """One simulation's outcome. Lengths in m (slack_m too), SR dimensionless; the diagnostics
    (:data:`DIAGNOSTICS`) carry their units in their names and are NaN for a failed run."""

    status: str
    reason: str
    distance_m: float
    squat_ratio: float
    slack_m: float
    fitness_m: float
    chain_length_m: float
    wall_s: float
    series: dict[str, np.ndarray] | None = field(default=None, compare=False)
    chain_tension_max_n: float = math.nan
    chain_tension_min_n: float = math.nan
    chain_compression_s: float = math.nan
    fz_rear_max_n: float = math.nan
    fz_rear_min_n: float = math.nan
    fz_front_max_n: float = math.nan
    fz_front_min_n: float = math.nan
    slip_max: float = math.nan
    airborne_rear_s: float = math.nan
    airborne_front_s: float = math.nan
    tyre_compression_rear_max_m: float = math.nan
    tyre_compression_front_max_m: float = math.nan
    drive_work_j: float = math.nan
    kinetic_energy_j: float = math.nan
    potential_energy_j: float = math.nan
    damper_dissipation_j: float = math.nan
    tyre_slip_work_j: float = math.nan
    tyre_carcass_energy_j: float = math.nan
    tyre_dissipation_j: float = math.nan
    tyre_lever_work_j: float = math.nan
    ledger_residual_j: float = math.nan
    tyre_dissipation_min_w: float = math.nan

    def diagnostics(self) -> dict[str, float]:
        """The diagnostics (:data:`DIAGNOSTICS`) by name."""
        return {name: getattr(self, name) for name in DIAGNOSTICS}

    @property
    def ok(self) -> bool:
        return self.status == STATUS_OK

    def summary(self) -> dict[str, float | str]:
        """The scalar outputs as a JSON-ready dict (CLI keys)."""
        return {
            "status": self.status,
            "reason": self.reason,
            "distance_m": self.distance_m,
            "squat_ratio": self.squat_ratio,
            "slack_m": self.slack_m,
            "fitness_m": self.fitness_m,
            "chain_length_m": self.chain_length_m,
            "wall_s": self.wall_s,
            **self.diagnostics(),
        }


def _unset() -> np.ndarray:
    return np.zeros(0)


@dataclass(frozen=True)
class BatchResult:
    """Results of a batch, one entry per input design row, in order. The diagnostics
    (:data:`DIAGNOSTICS`) are arrays too; left out, they are NaN."""

    designs: np.ndarray          # (n, 3): a2 [rad], L2 [m], R_WS [m]
    distance_m: np.ndarray
    squat_ratio: np.ndarray
    slack_m: np.ndarray
    fitness_m: np.ndarray
    chain_length_m: np.ndarray
    wall_s: np.ndarray
    status: tuple[str, ...]
    reason: tuple[str, ...]
    chain_tension_max_n: np.ndarray = field(default_factory=_unset)
    chain_tension_min_n: np.ndarray = field(default_factory=_unset)
    chain_compression_s: np.ndarray = field(default_factory=_unset)
    fz_rear_max_n: np.ndarray = field(default_factory=_unset)
    fz_rear_min_n: np.ndarray = field(default_factory=_unset)
    fz_front_max_n: np.ndarray = field(default_factory=_unset)
    fz_front_min_n: np.ndarray = field(default_factory=_unset)
    slip_max: np.ndarray = field(default_factory=_unset)
    airborne_rear_s: np.ndarray = field(default_factory=_unset)
    airborne_front_s: np.ndarray = field(default_factory=_unset)
    tyre_compression_rear_max_m: np.ndarray = field(default_factory=_unset)
    tyre_compression_front_max_m: np.ndarray = field(default_factory=_unset)
    drive_work_j: np.ndarray = field(default_factory=_unset)
    kinetic_energy_j: np.ndarray = field(default_factory=_unset)
    potential_energy_j: np.ndarray = field(default_factory=_unset)
    damper_dissipation_j: np.ndarray = field(default_factory=_unset)
    tyre_slip_work_j: np.ndarray = field(default_factory=_unset)
    tyre_carcass_energy_j: np.ndarray = field(default_factory=_unset)
    tyre_dissipation_j: np.ndarray = field(default_factory=_unset)
    tyre_lever_work_j: np.ndarray = field(default_factory=_unset)
    ledger_residual_j: np.ndarray = field(default_factory=_unset)
    tyre_dissipation_min_w: np.ndarray = field(default_factory=_unset)

    def __post_init__(self) -> None:
        n = len(self.status)
        for name in DIAGNOSTICS:  # results built without diagnostics (older callers): NaN
            if getattr(self, name).size == 0 and n > 0:
                object.__setattr__(self, name, np.full(n, math.nan))

    def __len__(self) -> int:
        return len(self.status)

    @property
    def ok(self) -> np.ndarray:
        return np.array([s == STATUS_OK for s in self.status], dtype=bool)

    def result(self, i: int) -> SimResult:
        return SimResult(
            status=self.status[i], reason=self.reason[i],
            distance_m=float(self.distance_m[i]), squat_ratio=float(self.squat_ratio[i]),
            slack_m=float(self.slack_m[i]), fitness_m=float(self.fitness_m[i]),
            chain_length_m=float(self.chain_length_m[i]), wall_s=float(self.wall_s[i]),
            **self._diagnostics_of(i),
        )

    def _diagnostics_of(self, i: int) -> dict[str, Any]:
        return {name: float(getattr(self, name)[i]) for name in DIAGNOSTICS}

    @classmethod
    def from_results(cls, designs: np.ndarray, results: list[SimResult]) -> BatchResult:
        def col(name: str) -> np.ndarray:
            return np.array([getattr(r, name) for r in results], dtype=float)

        return cls(
            designs=np.asarray(designs, dtype=float).reshape(-1, 3),
            distance_m=col("distance_m"), squat_ratio=col("squat_ratio"),
            slack_m=col("slack_m"), fitness_m=col("fitness_m"),
            chain_length_m=col("chain_length_m"), wall_s=col("wall_s"),
            status=tuple(r.status for r in results), reason=tuple(r.reason for r in results),
            **{name: col(name) for name in DIAGNOSTICS},
        )

    @classmethod
    def failed(cls, designs: np.ndarray, reason: str) -> BatchResult:
        """Every design failed, for ``reason`` (e.g. its worker was lost)."""
        rows = np.asarray(designs, dtype=float).reshape(-1, 3)
        n = len(rows)
        return cls(designs=rows, distance_m=np.full(n, np.nan), squat_ratio=np.full(n, np.nan),
                   slack_m=np.full(n, np.nan), fitness_m=np.full(n, np.nan), chain_length_m=np.full(n, np.nan),
                   wall_s=np.zeros(n), status=(STATUS_FAILED,) * n, reason=(reason,) * n)

    def rows(self, index: slice) -> BatchResult:
        """The results of a range of rows, in order."""
        return BatchResult(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @classmethod
    def concat(cls, parts: list[BatchResult]) -> BatchResult:
        """Join batches in the given order."""
        if not parts:
            return cls.from_results(np.zeros((0, 3)), [])
        arrays = {
            f.name: np.concatenate([getattr(p, f.name) for p in parts])
            for f in fields(cls) if f.name not in ("status", "reason")
        }
        return cls(
            **arrays,
            status=tuple(s for p in parts for s in p.status),
            reason=tuple(s for p in parts for s in p.reason),
        )
