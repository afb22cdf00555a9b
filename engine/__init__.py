"""finaldrive's simulation engine: the paper's 2D multibody motorcycle and its solver.

The public surface is small: ``simulate`` one design, ``evaluate`` a batch, and the values
they take and return. Nothing here reads files or the environment except ``load_vehicle``.
"""

from engine.api import (
    STATUS_FAILED, STATUS_OK, BatchResult, Design, DesignError, SimResult, SimSettings,
)
from engine.model.road import Road, RoadError
from engine.simulate import evaluate, simulate
from engine.vehicle import Vehicle, VehicleError, default_vehicle, load_vehicle, load_vehicle_dict

#: Bumped whenever a change alters simulation results (part of the result-cache key).
ENGINE_VERSION = "0.1.0"

__all__ = [
    "BatchResult", "Design", "DesignError", "ENGINE_VERSION", "Road", "RoadError",
    "STATUS_FAILED", "STATUS_OK", "SimResult", "SimSettings", "Vehicle", "VehicleError",
    "default_vehicle", "evaluate", "load_vehicle", "load_vehicle_dict", "simulate",
]
