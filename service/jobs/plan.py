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
    kind: Literal["sweep", "de", "robust-de"]
    roads: tuple[NamedRoad, ...]
    settings: SimSettings
    vehicle: Vehicle | None
    seed: int
    designs: np.ndarray | None = None          # sweep: (n, 3) rows
    lower: np.ndarray | None = None            # de: search box, engine units
    upper: np.ndarray | None = None
    de: DESpec | None = None
    aggregate: Literal["mean", "worst"] = "mean"

    @property
    def n_runs(self) -> int:
        """Independent DE runs: one per road for ``de``, one for ``robust-de``."""
        return len(self.roads) if self.kind == "de" else 1

    def evals_per_run(self) -> int:
        assert self.de is not None
        planned = self.de.np * (self.de.iters + 1)
        return min(planned, self.de.max_evals) if self.de.max_evals else planned

    def total(self) -> int:
        """Evaluations the job plans (DE with patience may stop earlier)."""
        if self.kind == "sweep":
            assert self.designs is not None
            return len(self.designs) * len(self.roads)
        return self.evals_per_run() * len(self.roads)

    def new_optimiser(self, run: int) -> DifferentialEvolution:
        assert self.de is not None and self.lower is not None and self.upper is not None
        return DifferentialEvolution(
            self.lower, self.upper, periodic=[True, False, False], pop_size=self.de.np,
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
    if spec.kind == "sweep":
        try:
            designs = table9_grid() if spec.grid in (None, "table9") else parse_grid(spec.grid)
        except ValueError as exc:
            raise PlanError(("grid",), str(exc)) from None
        return replace(base, designs=np.asarray(designs, dtype=float))
    assert spec.bounds is not None and spec.de is not None
    b = spec.bounds
    lower = np.array([math.radians(b.a2_deg[0]), b.l2_m[0], b.rws_m[0]])
    upper = np.array([math.radians(b.a2_deg[1]), b.l2_m[1], b.rws_m[1]])
    return replace(base, lower=lower, upper=upper, de=spec.de, aggregate=spec.aggregate or "mean")
