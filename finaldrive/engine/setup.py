"""What a run needs before it starts: the packed parameters, the static equilibrium on the road,
the chain length L of eq. (69) and the squat ratio.

Imports nothing compiled eagerly: the static geometry (engine.geometry) uses it without numba.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from finaldrive.engine.api import Design, SimSettings
from finaldrive.engine.fast.equilibrium import static_equilibrium
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import BETA, FS, PHI, THETA, X1, Y1
from finaldrive.engine.model.kinematics import chain_length, design_pose, design_squat_ratio, whole_chain_length
from finaldrive.engine.model.rear_travel import compressed_spring_length
from finaldrive.engine.model.road import Road
from finaldrive.engine.solver.equilibrium import reference_equilibrium
from finaldrive.engine.vehicle import Vehicle

#: The natural coordinates that are the fast path's minimal coordinates z, in order.
MINIMAL_COORDS = (X1, Y1, THETA, PHI, FS, BETA)


def pack_parameters(vehicle: Vehicle, design: Design, settings: SimSettings) -> np.ndarray:
    """The model's parameter vector P (engine.model.params); the chain length is filled later."""
    p = np.zeros(P.N_PARAMS)
    p[:P.N_VEHICLE] = vehicle.packed()
    p[P.A2], p[P.L2], p[P.R_WS] = design.a2, design.l2, design.rws
    p[P.R_ES] = design.rws / vehicle["sprocket_ratio"]   # section 4: R_WS / R_ES fixed
    p[P.AL_ALPHA], p[P.AL_XI], p[P.AL_OMEGA] = (
        settings.penalty_alpha, settings.baumgarte_xi, settings.baumgarte_omega)
    if vehicle["suspension_stops"]:
        p[P.RS_BUMP] = compressed_spring_length(vehicle)
        p[P.FS_BUMP] = vehicle["s_fs"] - vehicle["fork_travel"]
    return p


@dataclass(frozen=True)
class Setup:
    """Everything a run needs that does not change with time."""

    p: np.ndarray       # parameters incl. the chain length L (69)
    q0: np.ndarray      # static equilibrium on the road
    squat_ratio: float  # at the design pose


def prepare(design: Design, road: Road, settings: SimSettings, vehicle: Vehicle) -> Setup:
    """Parameters, static equilibrium and the chain length L of eq. (69) at t = 0 (with two chain
    runs also the whole chain's length). Each method finds the equilibrium of its own model (the
    reference in its 39 natural coordinates). Raises DesignError for a design beyond the vehicle's
    limits (Vehicle.check_design), ValueError for the two-run chain with the reference method."""
    vehicle.check_method(settings.method)
    vehicle.check_design(design)
    p = pack_parameters(vehicle, design, settings)
    pose = design_pose(p)
    equilibrium = reference_equilibrium if settings.method == "reference" else static_equilibrium
    q0 = equilibrium(p, road, pose)
    p[P.L_CHAIN] = chain_length(q0, p)
    if vehicle["chain_runs"] == 2:  # only the two-run chain reads the whole chain's length
        p[P.L_LOOP] = whole_chain_length(q0, p)
    return Setup(p=p, q0=q0, squat_ratio=float(design_squat_ratio(p, pose)))
