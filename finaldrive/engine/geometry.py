"""A design's static final-drive quantities, without simulating."""

from __future__ import annotations

import math
from typing import Any

from finaldrive.engine.api import Design, SimSettings
from finaldrive.engine.jit.kernel import interpreted
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import PHI, THETA
from finaldrive.engine.model.kinematics import taut_length
from finaldrive.engine.model.road import Road
from finaldrive.engine.setup import prepare
from finaldrive.engine.vehicle import Vehicle


def static_geometry(design: Design, vehicle: Vehicle) -> dict[str, Any]:
    """SR at the design pose, chain length L (69) and taut run at static equilibrium on flat
    ground, R_ES, the engine sprocket centre relative to the swingarm pivot (chassis frame) and the
    swingarm's angle at that equilibrium (pivot to rear axle, phi - theta: the frame of a2).

    Runs the compiled model as plain Python unless it is compiled already in this process: one
    equilibrium does not repay loading numba (about a second)."""
    with interpreted():
        setup = prepare(design, Road(), SimSettings(), vehicle)
    return {
        "a2_deg": design.a2_deg,
        "l2_m": design.l2,
        "rws_m": design.rws,
        "res_m": float(setup.p[P.R_ES]),
        "squat_ratio": setup.squat_ratio,
        "chain_length_m": float(setup.p[P.L_CHAIN]),
        "taut_length_m": taut_length(setup.q0),
        "engine_sprocket_x_m": design.l2 * math.cos(design.a2),
        "engine_sprocket_y_m": design.l2 * math.sin(design.a2),
        "swingarm_angle_deg": math.degrees(setup.q0[PHI] - setup.q0[THETA]),
    }
