"""What simulations cost, estimated before running them (to refuse a job that would run for days).

The estimate counts integration steps and prices them with per-step CPU times measured on the
reference machine of docs/performance.md (a 2-core x86-64, one core a simulation); they are
upper quantiles over random designs on the paper's roughest road, so the estimate errs high.
The fast path adapts its steps: its count is an estimate; the reference method's is exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from finaldrive.engine.api import SimSettings

#: Fast path: accepted steps per simulated second (adaptive; about 900 on sine:0.04:2, fewer on smoother roads).
FAST_STEPS_PER_SIMULATED_S = 1000.0
#: Fast path: CPU seconds per step (right-hand sides, the linear solve, step control).
FAST_CPU_S_PER_STEP = 4.0e-6
#: Reference method: CPU seconds per step of the augmented Lagrangian with the ABM corrector (eqs. 57-66).
REFERENCE_CPU_S_PER_STEP = 1.0e-4


@dataclass(frozen=True)
class Cost:
    """Estimated integration steps and CPU time [s] of a number of simulations."""

    steps: float
    cpu_s: float

    def __str__(self) -> str:
        return f"{self.steps:.3g} integration steps, about {self.cpu_s / 3600:.3g} CPU-hours"


def estimate_cost(settings: SimSettings, simulations: int) -> Cost:
    """The cost of ``simulations`` runs with ``settings``."""
    if settings.method == "reference":
        steps = float(math.ceil(settings.duration / settings.dt - 1e-9))
        per_step = REFERENCE_CPU_S_PER_STEP
    else:
        steps = settings.duration * FAST_STEPS_PER_SIMULATED_S
        per_step = FAST_CPU_S_PER_STEP
    return Cost(steps * simulations, steps * per_step * simulations)
