"""Model bands of a finished job's best designs (engine.study.model_band): whether their ranking survives
the documented modelling alternatives.

The API process never simulates. For each alternative, the job's best distinct designs of each road it
applies to (service.api.bands.top_designs: at most ``TIE_CANDIDATES`` a road) are simulated by a scheduler
as one small job of kind ``designs``, with the alternative's vehicle (and, for a road alternative, its
road), queued once per finished job (Idempotency-Key ``model-band:<alternative>:<job id>``). Their stored
evaluations against the job's own give each road's ranking under each alternative. ``road_enveloped``
is left out here: its road is a profile computed from the job's road (``finaldrive model-band`` runs it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from finaldrive.engine import (
    ALTERNATIVES,
    Alternative,
    Road,
    RoadError,
    SimSettings,
    default_vehicle,
    load_vehicle_dict,
    ranking_change,
)
from finaldrive.service.api.bands import designs_results, number_or_nan, top_designs
from finaldrive.service.api.problems import ApiProblem
from finaldrive.service.api.sharpness import own_designs_job
from finaldrive.service.db.models import TERMINAL_STATES, EvalStatus, Job, JobRoad, JobState
from finaldrive.service.db.repository import job_by_idempotency_key
from finaldrive.service.schemas import JobSpec, VehicleFile
from finaldrive.service.services import Services

#: The Idempotency-Key prefix of a job's model-band jobs.
MODEL_BAND_KEY_PREFIX = "model-band:"
#: Why an alternative is not run through the service.
NOT_HERE = {"road_enveloped": "its road is a profile computed from the job's road: `finaldrive model-band` runs it"}


def model_band_key(job_id: int, name: str) -> str:
    """The Idempotency-Key of a job's model-band job for the alternative ``name``."""
    return f"{MODEL_BAND_KEY_PREFIX}{name}:{job_id}"


@dataclass(frozen=True)
class Planned:
    """An alternative for a job: its vehicle file, the job's road indices it applies to with the road each is
    simulated on (in its designs job's order), and the job's other roads with why not."""

    alternative: Alternative
    vehicle: VehicleFile
    roads: tuple[tuple[int, str], ...]
    road_skips: tuple[tuple[int, str], ...]


def planned(job: Job, roads: list[JobRoad]) -> tuple[list[Planned], dict[str, str]]:
    """The alternatives that apply to the job (each with the roads it applies to), and the others with why not."""
    source = JobSpec.model_validate(job.spec)
    vehicle = load_vehicle_dict(source.vehicle.model_dump()) if source.vehicle is not None else default_vehicle()
    settings = SimSettings(duration=source.settings.duration, dt=source.settings.dt, method=source.settings.method,
                           fast_tolerance=source.settings.fast_tolerance)
    out, skipped = [], {}
    for alt in ALTERNATIVES:
        if alt.name in NOT_HERE:
            skipped[alt.name] = NOT_HERE[alt.name]
            continue
        applied: list[tuple[int, str]] = []
        road_skips: list[tuple[int, str]] = []
        changed_vehicle = None
        try:
            for road in roads:
                try:
                    parsed = Road.parse(road.spec)
                except (RoadError, ValueError):   # a measured profile: no road alternative applies to it
                    if alt.changes == "road":
                        road_skips.append((road.road_index, "a measured profile"))
                        continue
                    parsed = Road()               # a vehicle alternative does not read the road
                changed = alt.change(parsed, vehicle, settings)
                if changed is None:
                    road_skips.append((road.road_index, "does not apply to this road"))
                    continue
                spec = road.spec if alt.changes == "vehicle" else changed[0].spec
                if spec in {s for _, s in applied}:
                    road_skips.append((road.road_index, f"the same road as another of the job's under it ({spec})"))
                    continue
                applied.append((road.road_index, spec))
                changed_vehicle = changed[1]
        except ValueError as exc:                 # the change refused by the vehicle's own rules
            skipped[alt.name] = f"not for this vehicle: {exc}"
            continue
        if not applied or changed_vehicle is None:
            skipped[alt.name] = f"does not apply to this job's vehicle, settings or roads ({alt.what})"
            continue
        out.append(Planned(alt, VehicleFile.model_validate(changed_vehicle.to_dict()), tuple(applied),
                           tuple(road_skips)))
    return out, skipped


def model_band_jobs(services: Services, job: Job) -> tuple[dict[str, Job], dict[str, str]]:
    """The job's model-band jobs (alternative -> its ``designs`` job), queued now unless they exist, and
    the alternatives left out with why (409 while ``job`` has not finished, or with no successful evaluation)."""
    if job.state not in {s.value for s in TERMINAL_STATES}:
        raise ApiProblem(409, f"job {job.id} is {job.state}: ask for its model bands once it has finished",
                         slug="not-finished")
    with services.db.read() as session:
        tops = {road.road_index: (road, top) for road, top in top_designs(session, job) if top}
        alternatives, skipped = planned(job, [road for road, _ in tops.values()])
        existing = {p.alternative.name: job_by_idempotency_key(session, model_band_key(job.id, p.alternative.name))
                    for p in alternatives}
    if not tops:
        raise ApiProblem(409, f"job {job.id} has no successful evaluation to rank", slug="no-result")
    source = JobSpec.model_validate(job.spec)
    out = {}
    for p in alternatives:
        name = p.alternative.name
        spec = JobSpec(kind="designs", roads=[spec for _, spec in p.roads], settings=source.settings,
                       vehicle=p.vehicle, designs=[[row[:3] for row in tops[index][1]] for index, _ in p.roads])
        out[name] = own_designs_job(services, job, model_band_key(job.id, name), spec, existing[name], "model_band")
    return out, skipped


def stored_model_bands(session: Session, job: Job, jobs: dict[str, Job],
                       skipped: dict[str, str]) -> dict[int, dict[str, Any]]:
    """Each road's model bands (by the job's road index) from the model-band jobs' evaluations, once each has
    finished: ``{"model_bands": {designs, baseline, alternatives: {name: {what, road, ranking_change's record}},
    skipped, skipped_reasons}}``; ``skipped``: the alternatives left out on the road (engine.model_bands' field),
    with why in ``skipped_reasons`` (an alternative whose job did not succeed among them, with its state)."""
    tops = {road.road_index: (road, top) for road, top in top_designs(session, job) if top}
    alternatives = {p.alternative.name: p for p in planned(job, [road for road, _ in tops.values()])[0]}
    out: dict[int, dict[str, Any]] = {}
    for index, (_, top) in tops.items():
        base = np.array([f for _, _, _, f, _ in top])
        record: dict[str, Any] = {
            "designs": [{"a2_deg": a2, "l2_m": l2, "rws_m": rws} for a2, l2, rws, _, _ in top],
            "baseline": ranking_change(base, np.array([d for *_, d in top]), [""] * len(top), base),
            "alternatives": {}, "skipped": [], "skipped_reasons": dict(skipped)}
        out[index] = {"model_bands": record}
    for name, designs_job in jobs.items():
        p = alternatives.get(name)
        if p is None:
            continue
        if designs_job.state != JobState.succeeded.value:
            why = f"its job {designs_job.id} {designs_job.state}"
            why += f": {designs_job.error}" if designs_job.error else ""
            for entry in out.values():
                entry["model_bands"]["skipped_reasons"][name] = why
            continue
        rows = dict(designs_results(session, designs_job))
        applies = dict(p.roads)
        for position, (index, road_spec) in enumerate(p.roads):
            top = tops[index][1]
            fitness, distance, failed = [], [], []
            for candidate in range(len(top)):
                row = rows.get((position, candidate))
                if row is None:
                    fitness.append(math.nan)
                    distance.append(math.nan)
                    failed.append("not simulated")
                    continue
                ok = row.status == EvalStatus.ok.value and row.fitness_m is not None
                fitness.append(float(row.fitness_m) if ok else math.nan)
                distance.append(number_or_nan(row.distance_m))
                failed.append("" if ok else row.reason or "failed")
            base = np.array([f for _, _, _, f, _ in top])
            out[index]["model_bands"]["alternatives"][name] = {
                "what": p.alternative.what, "road": road_spec,
                **ranking_change(np.array(fitness), np.array(distance), failed, base)}
        road_skips = dict(p.road_skips)
        for index in out:
            if index not in applies:
                why = road_skips.get(index, "does not apply to this road")
                out[index]["model_bands"]["skipped_reasons"][name] = why
    for entry in out.values():
        record = entry["model_bands"]
        record["skipped"] = [a.name for a in ALTERNATIVES if a.name in record["skipped_reasons"]]
    return out
