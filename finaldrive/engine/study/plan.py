"""A study resolved from user input: its roads, its design grid or search box, and its runs.

One definition for the command line and the job service. Kinds:

- ``sweep``: a design grid (Table 9 by default) on every road;
- ``de``: the paper's DE (Table 10) on each road separately (run i on road i, seed + i);
- ``robust-de``: one DE whose designs are scored over all the roads (``aggregate``);
- ``paper-study``: the sweep and the per-road DE on the same roads (paper section 5);
- ``designs``: explicit designs on each road (e.g. the finite-difference stencils at a job's best).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from finaldrive.engine.optimize import restore
from finaldrive.engine.study.presets import NamedRoad, ProfileResolver, resolve_roads
from finaldrive.engine.study.runs import DERun, SweepRun
from finaldrive.engine.study.scoring import AGGREGATES, Aggregate
from finaldrive.engine.study.space import Bounds, DESettings, SpaceError
from finaldrive.engine.study.sweep import parse_grid, table9_grid
from finaldrive.engine.vehicle import Vehicle, default_vehicle

StudyKind = Literal["sweep", "de", "robust-de", "paper-study", "designs"]
STUDY_KINDS: tuple[str, ...] = ("sweep", "de", "robust-de", "paper-study", "designs")
#: Run index of a study's sweep (DE runs are 0, 1, ...).
SWEEP_RUN = -1
#: Step of a paper-study's sweep evaluations, apart from the DE generations 0, 1, ...
PAPER_SWEEP_STEP = -1

Run = SweepRun | DERun

#: Where each design limit comes from (vehicle file, group design_limits).
_LIMIT_SOURCE = {"l2_m": "l2_max", "rws_m": "rt0 - rws_tyre_margin"}
_RWS_MIN_SOURCE = "an engine sprocket of min_sprocket_teeth teeth of the chain_pitch, times sprocket_ratio"


class PlanError(ValueError):
    """Input that names something the study cannot use; ``loc`` is the field's path."""

    def __init__(self, loc: tuple[str | int, ...], msg: str) -> None:
        super().__init__(f"{'.'.join(map(str, loc))}: {msg}" if loc else msg)
        self.loc = loc
        self.msg = msg


@dataclass(frozen=True)
class StudyPlan:
    """What a study evaluates; :meth:`runs` builds (or resumes) its runs."""

    kind: StudyKind
    roads: tuple[NamedRoad, ...]
    designs: np.ndarray | None = None      # sweep / paper-study: the grid, (n, 3)
    road_designs: tuple[np.ndarray, ...] | None = None  # designs: each road's own, (n_i, 3)
    bounds: Bounds | None = None           # de / robust-de / paper-study
    de: DESettings | None = None
    aggregate: Aggregate = "mean"          # robust-de
    seed: int = 0

    @property
    def n_de_runs(self) -> int:
        """Independent DE runs: one a road (de, paper-study), one for robust-de, none for a sweep."""
        if self.de is None:
            return 0
        return 1 if self.kind == "robust-de" else len(self.roads)

    @property
    def sweep_step(self) -> int:
        return PAPER_SWEEP_STEP if self.kind == "paper-study" else 0

    def sweep_total(self) -> int:
        if self.road_designs is not None:
            return sum(len(d) for d in self.road_designs)
        return 0 if self.designs is None else len(self.designs) * len(self.roads)

    def de_total(self) -> int:
        """Evaluations the DE runs plan (robust: each design on every road)."""
        if self.de is None:
            return 0
        per_design = len(self.roads) if self.kind == "robust-de" else 1
        return self.n_de_runs * self.de.evals_per_run() * per_design

    def total(self) -> int:
        """Evaluations the study plans (a DE with patience may stop earlier)."""
        return self.sweep_total() + self.de_total()

    def de_roads(self, run: int) -> list[int]:
        return list(range(len(self.roads))) if self.kind == "robust-de" else [run]

    def runs(self, *, sweep_done: set[tuple[int, int]] | None = None,
             de_states: Mapping[int, tuple[dict[str, Any], int]] | None = None) -> list[Run]:
        """The study's runs, fresh, or resumed from what is stored.

        ``sweep_done``: (road, candidate) pairs of the sweep already evaluated;
        ``de_states``: optimiser run index -> (optimiser state, rounds told).
        """
        out: list[Run] = []
        for i, designs in enumerate(self.road_designs or ()):  # a run a road: SWEEP_RUN, SWEEP_RUN - 1, ...
            out.append(SweepRun(SWEEP_RUN - i, [i], designs, done=sweep_done))
        if self.designs is not None:
            out.append(SweepRun(SWEEP_RUN, range(len(self.roads)), self.designs, step=self.sweep_step,
                                done=sweep_done))
        assert self.de is not None or self.n_de_runs == 0
        for i in range(self.n_de_runs):
            stored = (de_states or {}).get(i)
            if stored is not None:
                optimiser, generation = restore(stored[0]), stored[1]
            else:
                assert self.de is not None and self.bounds is not None
                optimiser, generation = self.de.build(self.bounds, self.seed + i), 0
            out.append(DERun(i, optimiser, self.de_roads(i), aggregate=self.aggregate, generation=generation))
        return out


def plan_study(
    kind: str, roads: Sequence[str], *, grid: str | np.ndarray | None = None, bounds: Bounds | None = None,
    de: DESettings | None = None, aggregate: str | None = None, seed: int = 0,
    profiles: ProfileResolver | None = None, vehicle: Vehicle | None = None,
    road_designs: Sequence[np.ndarray] | None = None,
) -> StudyPlan:
    """Resolve a study; raises :class:`PlanError` naming the field (``roads``, ``grid``, ...).

    Missing parts take the paper's values: Table 9 grid, Table 8 box, Table 10 DE, mean aggregate.
    Every design the study can evaluate must fit ``vehicle`` (default: the paper's bike; see
    :meth:`Vehicle.design_limits`): each grid row, and the box's upper L2 and R_WS.
    """
    if kind not in STUDY_KINDS:
        raise PlanError(("kind",), f"unknown study {kind!r}: expected one of {', '.join(STUDY_KINDS)}")
    named: list[NamedRoad] = []
    for i, text in enumerate(roads):
        try:
            found = resolve_roads(text, profiles)
        except ValueError as exc:
            raise PlanError(("roads", i), str(exc)) from None
        named += [r for r in found if r.road not in {n.road for n in named}]
    if not named:
        raise PlanError(("roads",), "give at least one road")
    if (kind == "designs") != (road_designs is not None):
        raise PlanError(("designs",), "required for (and only for) a designs study")
    if road_designs is not None:
        return _designs_plan(tuple(named), road_designs, seed, vehicle)
    sweeping = kind in ("sweep", "paper-study")
    if not sweeping and grid is not None:
        raise PlanError(("grid",), f"not used by a {kind} study")
    if kind == "sweep" and (bounds is not None or de is not None):
        raise PlanError(("bounds" if bounds is not None else "de",), "not used by a sweep")
    if aggregate is not None and kind != "robust-de":
        raise PlanError(("aggregate",), "only for robust-de")
    if aggregate is not None and aggregate not in AGGREGATES:
        raise PlanError(("aggregate",), f"expected one of {', '.join(AGGREGATES)}")
    designs = None
    if sweeping:
        try:
            if grid is None or (isinstance(grid, str) and grid.strip().lower() == "table9"):
                designs = table9_grid()
            elif isinstance(grid, str):
                designs = parse_grid(grid)
            else:
                designs = np.asarray(grid, dtype=float)
                if designs.ndim != 2 or designs.shape[1] != 3 or len(designs) == 0:
                    raise ValueError(f"designs must have shape (n >= 1, 3), got {designs.shape}")
        except ValueError as exc:
            raise PlanError(("grid",), str(exc)) from None
    v = vehicle or default_vehicle()
    limits, rws_min = v.design_limits(), v.rws_min()
    if designs is not None:
        for column, name in ((1, "l2_m"), (2, "rws_m")):
            beyond = np.flatnonzero(designs[:, column] > limits[name])
            if beyond.size:
                i = int(beyond[0])
                raise PlanError(("grid",), f"design {i} has {name} = {designs[i, column]:g} m, more than the "
                                f"vehicle's limit of {limits[name]:g} m ({_LIMIT_SOURCE[name]})")
        below = np.flatnonzero(designs[:, 2] < rws_min)
        if below.size:
            i = int(below[0])
            raise PlanError(("grid",), f"design {i} has rws_m = {designs[i, 2]:g} m, less than the vehicle's "
                            f"smallest of {rws_min:.4g} m ({_RWS_MIN_SOURCE})")
    box = bounds or Bounds()
    for field in ("l2_m", "rws_m"):
        if kind != "sweep" and getattr(box, field)[1] > limits[field]:
            raise PlanError(("bounds", field), f"upper bound {getattr(box, field)[1]:g} m is more than the "
                            f"vehicle's limit of {limits[field]:g} m ({_LIMIT_SOURCE[field]})")
    if kind != "sweep" and box.rws_m[0] < rws_min:
        raise PlanError(("bounds", "rws_m"), f"lower bound {box.rws_m[0]:g} m is less than the vehicle's smallest "
                        f"R_WS of {rws_min:.4g} m ({_RWS_MIN_SOURCE})")
    if kind == "sweep":
        return StudyPlan("sweep", tuple(named), designs=designs, seed=seed)
    settings = de or (DESettings.paper() if kind == "paper-study" else DESettings())
    try:
        return StudyPlan(kind, tuple(named), designs=designs, bounds=bounds or Bounds(), de=settings,  # type: ignore[arg-type]
                         aggregate=aggregate or "mean", seed=seed)  # type: ignore[arg-type]
    except SpaceError as exc:
        raise PlanError((exc.field,), exc.msg) from None


def _designs_plan(roads: tuple[NamedRoad, ...], road_designs: Sequence[np.ndarray], seed: int,
                  vehicle: Vehicle | None) -> StudyPlan:
    """A designs study: one list of designs (rows a2 [rad], L2, R_WS) for each road, in order."""
    if len(road_designs) != len(roads):
        raise PlanError(("designs",), f"{len(road_designs)} lists of designs for {len(roads)} roads")
    v = vehicle or default_vehicle()
    limits = v.design_limits()
    out = []
    for i, designs in enumerate(road_designs):
        rows = np.asarray(designs, dtype=float)
        if rows.ndim != 2 or rows.shape[1] != 3 or len(rows) == 0 or not np.all(np.isfinite(rows)):
            raise PlanError(("designs", i), "expected at least one design of three finite numbers")
        for column, name in ((1, "l2_m"), (2, "rws_m")):
            low = 0.0 if name == "l2_m" else v.rws_min()
            if np.any(rows[:, column] < low) or np.any(rows[:, column] > limits[name]):
                raise PlanError(("designs", i), f"{name} must be in [{low:.4g}, {limits[name]:g}] m "
                                f"({_LIMIT_SOURCE[name]})")
        out.append(rows)
    return StudyPlan("designs", roads, road_designs=tuple(out), seed=seed)
