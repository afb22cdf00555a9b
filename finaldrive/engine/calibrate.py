"""Calibration of the values the paper leaves open (docs/engine.md#reading-notes-reference-choices).

- chassis + rider centre of mass: so that at static equilibrium on flat ground the rear tyre
  carries ``target_rear_share`` of the weight and the bike's centre of mass is
  ``target_cog_height`` high (Table 3);
- drive torque: so that the calibration design (Table 11's flat optimum) travels
  ``target_distance`` in 3.5 s on the flat road.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from finaldrive.engine.api import Design, SimSettings
from finaldrive.engine.fast.equilibrium import static_equilibrium
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import FT, RT, THETA, X14, X15
from finaldrive.engine.model.mass import centre_of_mass
from finaldrive.engine.model.road import Road
from finaldrive.engine.setup import pack_parameters
from finaldrive.engine.simulation import simulate
from finaldrive.engine.vehicle import Vehicle, VehicleError


@dataclass(frozen=True)
class StaticLoads:
    """The bike standing on flat ground."""

    rear_share: float     # rear tyre load / total tyre load
    cog_height: float     # whole-bike centre of mass above the ground [m]
    cog_x: float          # ... ahead of the rear contact point [m]
    wheelbase: float      # contact point to contact point [m]
    rear_load: float      # [N]
    front_load: float     # [N]
    total_mass: float     # [kg]
    q: np.ndarray         # the equilibrium pose


def calibration_design(vehicle: Vehicle) -> Design:
    return Design.from_deg(vehicle["calibration_a2_deg"], vehicle["calibration_l2"],
                           vehicle["calibration_rws"])


def static_loads(vehicle: Vehicle, design: Design | None = None) -> StaticLoads:
    """Static equilibrium on flat ground and the loads it gives."""
    p = pack_parameters(vehicle, design or calibration_design(vehicle), SimSettings())
    q = static_equilibrium(p, Road())
    rear = -p[P.K_RT] * (q[RT] - p[P.RT0])
    front = -p[P.K_FT] * (q[FT] - p[P.FT0])
    mass, xg, yg = centre_of_mass(q, p)
    return StaticLoads(rear / (rear + front), yg, xg - q[X14], q[X15] - q[X14], rear, front, mass, q)


def solve_chassis_cog(vehicle: Vehicle, tol: float = 1e-10, max_iter: int = 50) -> Vehicle:
    """The vehicle with chassis_cog_x/y moved to meet the Table 3 targets (fixed point)."""
    share, height = vehicle["target_rear_share"], vehicle["target_cog_height"]
    for _ in range(max_iter):
        loads = static_loads(vehicle)
        q = loads.q
        # where the whole-bike centre of mass must be, in the world frame
        x_target = q[X14] + (1.0 - share) * loads.wheelbase
        y_target = height
        m_ch = vehicle["m_chassis"]
        dx = (x_target - (q[X14] + loads.cog_x)) * loads.total_mass / m_ch
        dy = (y_target - loads.cog_height) * loads.total_mass / m_ch
        if math.hypot(dx, dy) < tol:
            return vehicle
        th = q[THETA]  # world shift -> chassis frame
        vehicle = vehicle.replace(
            chassis_cog_x=vehicle["chassis_cog_x"] + dx * math.cos(th) + dy * math.sin(th),
            chassis_cog_y=vehicle["chassis_cog_y"] - dx * math.sin(th) + dy * math.cos(th))
    raise RuntimeError("chassis centre of mass calibration did not converge")


def solve_torque(vehicle: Vehicle, settings: SimSettings = SimSettings(),
                 bracket: tuple[float, float] = (100.0, 200.0), xtol: float = 1e-4) -> Vehicle:
    """The vehicle with the drive torque that makes the calibration design travel
    target_distance on the flat road in settings.duration. The paper's drive only: the launch drive
    (drive_model = 1) does not read the torque (VehicleError)."""
    if vehicle["drive_model"] != 0.0:
        raise VehicleError("vehicle parameter 'drive_model': the torque is calibrated for the paper's drive (0); "
                           "the launch drive does not use it")
    design = calibration_design(vehicle)
    target = vehicle["target_distance"]

    def miss(torque: float) -> float:
        r = simulate(design, Road(), settings, vehicle.replace(torque=torque))
        if not r.ok:
            raise RuntimeError(f"calibration run failed at torque {torque:g} N m: {r.reason}")
        return r.distance_m - target

    return vehicle.replace(torque=brentq(miss, *bracket, xtol=xtol))


__all__ = ["StaticLoads", "calibration_design", "solve_chassis_cog", "solve_torque", "static_loads"]
