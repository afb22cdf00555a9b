"""/v1/health: the store, the schedulers' heartbeats, and what the service runs with.

Answers 503 (with the same body) when the store cannot be written (the probe's write transaction
fails, or a live scheduler reports that its last write of results failed) or no scheduler is
alive: a load balancer or a supervisor then knows jobs would not progress.
"""

from __future__ import annotations

import time

import anyio
from fastapi import APIRouter, Response
from sqlalchemy import text
from sqlalchemy.exc import SQLAlchemyError

from finaldrive.service.api.deps import ServicesDep
from finaldrive.service.db.leases import schedulers
from finaldrive.service.db.repository import count_active
from finaldrive.service.schemas import HealthOut, SchedulerOut, StoreOut
from finaldrive.service.services import Services

router = APIRouter(prefix="/health", tags=["health"])


def _check(services: Services) -> HealthOut:
    start = time.perf_counter()
    alive_within = services.settings.lease_seconds
    try:
        with services.db.write(timeout_s=1.0) as session:  # a real write transaction: the lock must be free
            session.execute(text("UPDATE jobs SET id = id WHERE id = -1"))
            active = count_active(session)
            rows = schedulers(session)
        store = StoreOut(writable=True, latency_s=round(time.perf_counter() - start, 4))
    except SQLAlchemyError:
        store = StoreOut(writable=False, latency_s=round(time.perf_counter() - start, 4))
        active, rows = None, []
    found = [SchedulerOut(id=row.id, host=row.host, pid=row.pid, executor=row.executor, capacity=row.capacity,
                          heartbeat_age_s=round(age, 3), alive=age <= alive_within, store_error=row.store_error,
                          tasks_per_s=row.tasks_per_s, evaluations_per_s=row.evaluations_per_s,
                          busy_share=row.busy_share, in_flight_tasks=row.in_flight_tasks,
                          backlog_designs=row.backlog_designs)
             for row, age in rows]
    if any(s.alive and s.store_error for s in found):  # results cannot be stored, though the probe passed
        store = StoreOut(writable=False, latency_s=store.latency_s)
    ok = store.writable and any(s.alive for s in found)
    return HealthOut(status="ok" if ok else "unavailable", store=store, schedulers=found,
                     schema_revision=services.schema_revision, engine_version=services.engine_version,
                     active_jobs=active)


@router.get("", response_model=HealthOut, responses={503: {"model": HealthOut, "description": "the store cannot be "
            "written, or no scheduler is alive"}}, summary="Service health: the store and the schedulers")
async def health(services: ServicesDep, response: Response) -> HealthOut:
    out = await anyio.to_thread.run_sync(_check, services)
    if out.status != "ok":
        response.status_code = 503
        response.headers["Retry-After"] = "5"
    return out
