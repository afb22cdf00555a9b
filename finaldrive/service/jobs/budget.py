"""A job's budget of CPU time, enforced while it runs (FINALDRIVE_MAX_JOB_CPU_HOURS).

The estimate at submission (finaldrive.engine.cost) refuses a job that would cost more than the
budget; the scheduler also measures what each job costs and stops one that reaches its budget.
The measure is the wall time of each simulation on its worker (the stored ``wall_s``: one thread
a simulation, so at least its CPU time), summed over the job's simulations, those of earlier
schedulers included (a resumed job); cache hits cost nothing. The scheduler then cancels the
job's simulations in flight, stores what arrived and finishes it ``failed``
(:meth:`Budget.error`): it stops within the simulations it had in flight.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from finaldrive.engine import BatchResult, Request
from finaldrive.service.db.models import Evaluation

OnResult = Callable[..., None]


class Budget:
    """The simulation time a job has cost [s] against its limit [s] (``math.inf``: none)."""

    def __init__(self, limit_s: float = math.inf, spent_s: float = 0.0) -> None:
        self.limit_s = limit_s
        self.spent_s = spent_s

    def charge(self, batch: BatchResult) -> None:
        """Add the simulations of a batch (a worker's failures record no time: nothing to add)."""
        self.spent_s += float(np.nansum(batch.wall_s))

    def metered(self, on_result: OnResult) -> OnResult:
        """``on_result(part, batch, ...)`` that charges each batch first."""
        def charged(part: Request, batch: BatchResult, *args: Any, **kwargs: Any) -> None:
            self.charge(batch)
            on_result(part, batch, *args, **kwargs)
        return charged

    @property
    def exceeded(self) -> bool:
        return self.spent_s > self.limit_s

    def error(self) -> str:
        """The job's error when it was stopped at its budget."""
        return (f"stopped at its CPU budget of {self.limit_s / 3600:g} CPU-hours (FINALDRIVE_MAX_JOB_CPU_HOURS): "
                f"its simulations took {self.spent_s / 3600:.3g} CPU-hours; the results stored so far are kept")


def spent_s(session: Session, job_id: int) -> float:
    """The simulation time the job's stored evaluations cost [s] (cached ones cost nothing)."""
    total = session.scalar(select(func.sum(Evaluation.wall_s)).where(Evaluation.job_id == job_id,
                                                                      Evaluation.cached.is_(False)))
    return float(total or 0.0)
