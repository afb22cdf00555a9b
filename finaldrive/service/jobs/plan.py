"""A job spec resolved into engine objects: the study (roads, grid or box, runs), settings, vehicle."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from finaldrive.engine import (
    Bounds,
    PlanError,
    ProfileResolver,
    SimSettings,
    SpaceError,
    StudyPlan,
    Vehicle,
    load_vehicle_dict,
    plan_study,
)
from finaldrive.service.schemas import JobSpec

__all__ = ["JobPlan", "PlanError", "build_plan"]


@dataclass(frozen=True)
class JobPlan:
    """A resolved job: its study and how each design is simulated."""

    study: StudyPlan
    settings: SimSettings
    vehicle: Vehicle | None

    def total(self) -> int:
        return self.study.total()


def build_plan(spec: JobSpec, *, profiles: ProfileResolver | None = None,
               max_simulation_s: float | None = None) -> JobPlan:
    """Resolve a normalised spec; raises :class:`PlanError` naming the offending field.

    ``profiles`` resolves ``profile:ID`` roads (from the store); ``max_simulation_s``: the wall-time
    limit of each simulation (a service setting, not the job's).
    """
    vehicle = None
    if spec.vehicle is not None:
        try:
            vehicle = load_vehicle_dict(spec.vehicle.model_dump())
        except ValueError as exc:
            raise PlanError(("vehicle",), str(exc)) from None
    try:
        bounds = None if spec.bounds is None else Bounds(**spec.bounds.model_dump())
        de = None if spec.de is None else spec.de.settings(spec.default_preset)
    except SpaceError as exc:
        raise PlanError(("bounds" if exc.field in Bounds.__dataclass_fields__ else "de", exc.field), exc.msg) from None
    road_designs = None if spec.designs is None else [
        np.array([(math.radians(a2), l2, rws) for a2, l2, rws in designs]) for designs in spec.designs]
    study = plan_study(spec.kind, spec.roads, grid=spec.grid, bounds=bounds, de=de, aggregate=spec.aggregate,
                       seed=spec.seed, profiles=profiles, vehicle=vehicle, road_designs=road_designs)
    try:
        settings = SimSettings(duration=spec.settings.duration, dt=spec.settings.dt, method=spec.settings.method,
                               fast_tolerance=spec.settings.fast_tolerance, max_wall_s=max_simulation_s)
    except ValueError as exc:
        raise PlanError(("settings",), str(exc)) from None
    if vehicle is not None:
        try:
            vehicle.check_method(settings.method)
        except ValueError as exc:
            raise PlanError(("settings", "method"), str(exc)) from None
    return JobPlan(study, settings, vehicle)
