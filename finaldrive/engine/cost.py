"""What simulations cost, estimated before running them (to refuse a job that would run for days).

The estimate counts integration steps and prices them with per-step CPU times measured on the
reference machine of docs/performance.md (a 2-core x86-64, one core a simulation), taken high.

The reference method's steps are exact (``duration / dt``). The fast path adapts its steps: at
most its largest step ``fast_max_step`` (half of it on profiles and with the two-run chain) on a
smooth stretch, shorter ones for each feature of the road it drives over. The estimate is

    steps = START_STEPS + duration / h_max + K * features

where ``features`` counts the road's shortest features within the distance the vehicle can
cover in ``duration`` (its drive force over its mass, plus what the road's height can give it):
a sine's wavelengths, a profile's points, a bump once; and ``K``, the steps a feature takes, is
an upper envelope of measurements over random designs (docs/service.md#bounded-cost) with a margin.
It is an estimate, not a proof: the scheduler also stops a job at its budget of measured time.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass

from finaldrive.engine.api import SimSettings
from finaldrive.engine.model.road import Road
from finaldrive.engine.vehicle import Vehicle, default_vehicle

#: Fast path: CPU seconds a step (right-hand sides, the linear solve, step control, rejected tries;
#: measured 1.2-3.2 us on the reference machine, a 100,000-point profile included).
FAST_CPU_S_PER_STEP = 4.0e-6
#: CPU seconds a simulation takes besides its steps: the static equilibrium it starts from (measured
#: up to 16 ms, on a 100,000-point profile) and the rest of its set-up.
SETUP_CPU_S = 0.02
#: Steps the fast path takes to grow its first step (1 ms) to h_max, beyond duration / h_max (measured ~100).
START_STEPS = 500.0
#: Reference method: CPU seconds per step of the augmented Lagrangian with the ABM corrector (eqs. 57-66).
REFERENCE_CPU_S_PER_STEP = 1.0e-4
#: Steps a sine wavelength takes: SINE_STEPS * (H / 1 mm)^0.5 * (lambda / 1 m)^0.3 (^0.5 above 1 m),
#: at least 1.2x every measurement (2.7-4.7 a wavelength on 1 mm waves of 5-20 cm, up to 61 on 4 cm x 5 m).
SINE_STEPS = 10.0
#: Steps a profile's point within reach takes (measured up to 9.6, on 5 mm noise every 6 cm; a
#: vehicle stuck on a rough stretch steps on, so every point within reach counts).
PROFILE_STEPS_PER_POINT = 20.0
#: Steps a bump takes beyond the smooth road's (measured up to 3,100, on a 5 cm bump 1 cm wide).
BUMP_STEPS = 10_000.0
#: The vehicle's drive force over its mass is taken this much higher (the tyre's rolling radius
#: shrinks under load; measured acceleration 3.4 m/s^2 against 3.7 from the nominal radius).
DRIVE_MARGIN = 1.25
#: Reach beyond the rear contact point's travel: the wheelbase and a margin [m].
REACH_MARGIN_M = 5.0


@dataclass(frozen=True)
class Cost:
    """Estimated integration steps and CPU time [s] of a number of simulations."""

    steps: float
    cpu_s: float

    def __str__(self) -> str:
        return f"{self.steps:.3g} integration steps, about {self.cpu_s / 3600:.3g} CPU-hours"


def estimate_cost(settings: SimSettings, simulations: int, roads: Sequence[Road] = (),
                  vehicle: Vehicle | None = None) -> Cost:
    """The cost of ``simulations`` runs with ``settings``, each priced on the costliest of ``roads``
    (none: a flat road) with ``vehicle`` (default: the paper's)."""
    if settings.method == "reference":
        steps = float(math.ceil(settings.duration / settings.dt - 1e-9))
        return Cost(steps * simulations, (steps * REFERENCE_CPU_S_PER_STEP + SETUP_CPU_S) * simulations)
    vehicle = vehicle or default_vehicle()
    steps = max((fast_steps(settings, road, vehicle) for road in roads or (Road(),)), default=0.0)
    return Cost(steps * simulations, (steps * FAST_CPU_S_PER_STEP + SETUP_CPU_S) * simulations)


def reach_m(duration: float, vehicle: Vehicle, height_range_m: float) -> float:
    """How far along the road the vehicle can get in ``duration`` from rest [m]: its drive force
    (torque x sprocket ratio / tyre radius, x DRIVE_MARGIN) over its mass, plus the speed a drop
    of ``height_range_m`` can give."""
    mass = sum(vehicle[k] for k in ("m_chassis", "m_swingarm", "m_sprocket", "m_rear_wheel", "m_fork",
                                    "m_front_wheel"))
    accel = DRIVE_MARGIN * abs(vehicle["torque"]) * vehicle["sprocket_ratio"] / vehicle["rt0"] / mass
    v_drop = math.sqrt(2.0 * vehicle["gravity"] * height_range_m)
    return 0.5 * accel * duration**2 + v_drop * duration + REACH_MARGIN_M


def fast_steps(settings: SimSettings, road: Road, vehicle: Vehicle) -> float:
    """Upper estimate of the fast path's steps (accepted and rejected alike) on ``road``: with the engine
    sprocket's own state (two chain runs: ROS2's halved step; the elastic chain: its torsional mode and
    snatches, 1.2-1.7x the rigid chain's time, docs/engine.md) as many as at half the largest step."""
    own_sprocket = vehicle["chain_runs"] == 2.0 or vehicle["chain_compliance"] == 1.0
    h_max = settings.fast_max_step * (0.5 if road.kind == "profile" or own_sprocket else 1.0)
    smooth = START_STEPS + settings.duration / h_max
    if road.kind == "sine":
        lam, height = road.wavelength, abs(road.height)
        per_wave = SINE_STEPS * math.sqrt(height / 1e-3) * math.pow(lam, 0.3 if lam < 1.0 else 0.5)
        return smooth + per_wave * reach_m(settings.duration, vehicle, 2.0 * height) / lam
    if road.kind == "bump":
        return smooth + BUMP_STEPS
    if road.kind == "profile":
        span = max(road.ys) - min(road.ys)
        reach = reach_m(settings.duration, vehicle, span)
        points = bisect.bisect_right(road.xs, reach) - bisect.bisect_left(road.xs, -REACH_MARGIN_M)
        return smooth + PROFILE_STEPS_PER_POINT * points
    return smooth
