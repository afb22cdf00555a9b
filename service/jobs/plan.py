"""A job spec resolved into engine objects: roads, designs or bounds, settings, vehicle."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from engine.api import SimSettings
from engine.model.road import Road
from engine.optimize.de import DifferentialEvolution
from engine.study.presets import as_road, resolve_roads, road_label
from engine.study.space import periodic_mask
from engine.study.sweep import parse_grid, table9_grid
from engine.vehicle import Vehicle, load_vehicle_dict
from service.schemas import DESpec, JobSpec


class PlanError(ValueError):
    """A spec that validates as JSON but names something the engine rejects."""

    def __init__(self, loc: tuple[str | int, ...], msg: str) -> None:
        super().__init__(msg)
        self.loc = loc
        self.msg = msg


@dataclass(frozen=True)
class NamedRoad:
    name: str
    road: Road


@dataclass(frozen=True)
class JobPlan:
    """A resolved job; a ``paper-study`` has both a sweep grid and a per-road DE."""

    kind: Literal["sweep", "de", "robust-de", "paper-study"]
    roads: tuple[NamedRoad, ...]
    settings: SimSettings
    vehicle: Vehicle | None
    seed: int
    designs: np.ndarray | None = None          # sweep / paper-study: (n, 3) rows
    lower: np.ndarray | None = None            # de / paper-study: search box, engine units
    upper: np.ndarray | None = None
    de: DESpec | None = None
    aggregate: Literal["mean", "worst"] = "mean"

    @property
    def n_runs(self) -> int:
        """Independent DE runs: one per road for ``de`` and ``paper-study``, one for ``robust-de``."""
        return 1 if self.kind == "robust-de" else len(self.roads)

    def evals_per_run(self) -> int:
        assert self.de is not None
        planned = self.de.np * (self.de.iters + 1)
        return min(planned, self.de.max_evals) if self.de.max_evals else planned

    def sweep_total(self) -> int:
        """Evaluations of the sweep part (0 for a DE)."""
        return 0 if self.designs is None else len(self.designs) * len(self.roads)

    def de_total(self) -> int:
        """Evaluations the DE part plans (0 for a sweep)."""
        return 0 if self.de is None else self.evals_per_run() * len(self.roads)

    def total(self) -> int:
        """Evaluations the job plans (DE with patience may stop earlier)."""
        return self.sweep_total() + self.de_total()

    def new_optimiser(self, run: int) -> DifferentialEvolution:
        assert self.de is not None and self.lower is not None and self.upper is not None
        return DifferentialEvolution(
            self.lower, self.upper, periodic=periodic_mask(self.lower, self.upper), pop_size=self.de.np,
            f=self.de.f, cp=self.de.cp, mp=self.de.mp, mr_fraction=self.de.mr_fraction,
            max_iter=self.de.iters, max_evals=self.de.max_evals, patience=self.de.patience,
            seed=self.seed + run,
        )


def build_plan(spec: JobSpec) -> JobPlan:
    """Resolve a normalised spec; raises :class:`PlanError` naming the offending field."""
    roads: list[NamedRoad] = []
    seen: set[Road] = set()
    for i, text in enumerate(spec.roads):
        try:
            items = resolve_roads(text)
        except ValueError as exc:
            raise PlanError(("roads", i), str(exc)) from None
        for item in items:
            road = as_road(item)
            if road not in seen:
                seen.add(road)
                roads.append(NamedRoad(road_label(item), road))
    try:
        settings = SimSettings(
            duration=spec.settings.duration, dt=spec.settings.dt, method=spec.settings.method
        )
    except ValueError as exc:
        raise PlanError(("settings",), str(exc)) from None
    vehicle = None
    if spec.vehicle is not None:
        try:
            vehicle = load_vehicle_dict(spec.vehicle)
        except ValueError as exc:
            raise PlanError(("vehicle",), str(exc)) from None
    base = JobPlan(kind=spec.kind, roads=tuple(roads), settings=settings, vehicle=vehicle, seed=spec.seed)
    if spec.kind in ("sweep", "paper-study"):
        try:
            designs = table9_grid() if spec.grid in (None, "table9") else parse_grid(spec.grid)
        except ValueError as exc:
            raise PlanError(("grid",), str(exc)) from None
        base = replace(base, designs=np.asarray(designs, dtype=float))
        if spec.kind == "sweep":
            return base
    assert spec.bounds is not None and spec.de is not None
    b = spec.bounds
    lower = np.array([math.radians(b.a2_deg[0]), b.l2_m[0], b.rws_m[0]])
    upper = np.array([math.radians(b.a2_deg[1]), b.l2_m[1], b.rws_m[1]])
    return replace(base, lower=lower, upper=upper, de=spec.de, aggregate=spec.aggregate or "mean")
