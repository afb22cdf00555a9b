"""Kinematics over the rear suspension's travel, without simulating, and the squat a simulation shows.

The travel curve holds the chassis at theta0 on flat ground and turns the swingarm from full
extension (the rear spring at its unloaded length s_rs, Table 5) to full compression (the rear axle
``rear_wheel_travel`` higher in the chassis frame; a vehicle-file choice, the paper gives none).
Every point is the design pose of eqs. (1)-(29) with phi0 set to that swingarm angle, so the squat
ratio of a point is what `finaldrive geometry` gives at that pose. docs/engine.md#travel-kinematics.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from finaldrive.engine.api import Design, SimSettings
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import PHI, THETA, X1, X4, X5, X6, X10, X11, X14, X15, Y1, Y4, Y5, Y6, Y10, Y11
from finaldrive.engine.model.kinematics import design_pose, squat_line, taut_length, whole_chain_length
from finaldrive.engine.model.rear_travel import angle_at, extension_angle, spring_length
from finaldrive.engine.model.road import Road
from finaldrive.engine.vehicle import Vehicle, sprocket_teeth

#: Points of a travel curve: default and largest.
TRAVEL_POINTS = 25
MAX_TRAVEL_POINTS = 201

ANTI_SQUAT_DEFINITION = ("anti_squat_pct = 100 tan(tau) / tan(sigma) (textbook; Cossalter, Motorcycle Dynamics): "
                         "tan(tau) the slope of the squat line (rear contact point to X), tan(sigma) = h / p with h "
                         "the centre of mass height (vehicle target_cog_height, Table 3) and p the wheelbase at the "
                         "design pose; squat_ratio = K / tan(tau) is the paper's reading (docs/engine.md)")
ANTI_RISE_DEFINITION = ("anti_rise_pct = 100 tan(lambda) / tan(sigma) (Foale, Motorcycle Handling and Chassis "
                        "Design; a rear brake caliper on the swingarm): tan(lambda) the slope of the line from the "
                        "rear contact point to the swingarm pivot, tan(sigma) as for anti-squat")
ANTI_DIVE_DEFINITION = ("anti_dive_pct = -100 tan(epsilon) / tan(sigma) (a telescopic fork, the front brake caliper on "
                        "its slider; Cossalter, Motorcycle Dynamics; Foale): epsilon the fork axis's angle from the "
                        "vertical (fork_angle_deg, points 4-5, eq. 14), tan(sigma) as for anti-squat; negative: the "
                        "braking force's component along the fork compresses it beyond the load transfer")
#: Half the swingarm-angle step of the leverage ratio's central difference [rad].
_LEVERAGE_STEP = 1e-6


def _travel_of(angle: float, extended: float, v: Vehicle) -> float:
    return float(v["L_SA"] * (math.sin(angle) - math.sin(extended)))


def _pose_quantities(p: np.ndarray, angle: float, tan_sigma: float) -> dict[str, float]:
    """Squat ratio, anti-squat, taut run and sprocket-pivot geometry with the swingarm at ``angle``
    (chassis frame) in the design pose (theta0, unloaded tyres on flat ground)."""
    q = design_pose(_with_angle(p, angle))
    run, rise = squat_line(q, q[X6], q[Y6] - p[P.RT0])
    pivot_slope = (q[Y1] - (q[Y6] - p[P.RT0])) / (q[X1] - q[X6])   # rear contact point to the pivot
    ux, uy = q[X10] - q[X11], q[Y10] - q[Y11]            # the upper run, rear to front
    n = math.hypot(ux, uy)
    above = ((q[X1] - q[X11]) * uy - (q[Y1] - q[Y11]) * ux) / n
    return {
        "swingarm_angle_deg": math.degrees(angle),
        "squat_ratio": math.inf if rise == 0.0 else float(p[P.SQUAT_K] * run / rise),
        "anti_squat_pct": 100.0 * (rise / run) / tan_sigma,
        "anti_rise_pct": float(100.0 * pivot_slope / tan_sigma),
        "taut_length_m": taut_length(q),
        "centre_distance_m": math.hypot(q[X6] - (q[X1] + p[P.L2] * math.cos(p[P.THETA0] + p[P.A2])),
                                        q[Y6] - (q[Y1] + p[P.L2] * math.sin(p[P.THETA0] + p[P.A2]))),
        "chain_angle_deg": math.degrees(math.atan2(uy, ux) - p[P.THETA0]),
        "chain_above_pivot_m": above,
    }


def travel_kinematics(design: Design, vehicle: Vehicle, points: int = TRAVEL_POINTS) -> dict[str, Any]:
    """Squat ratio, anti-squat and anti-rise %, chain growth (change of the taut run, eq. 68, from full
    extension) and the kickback it gives, the rear spring's length and leverage ratio, and the
    sprocket-pivot geometry from full extension to full compression, with the design pose and the
    static sag (equilibrium on flat ground) as points of their own; the sprockets' teeth (pitch radii
    and chain_pitch, not rounded) and the whole chain's length in links at the design pose; the fork's
    angle and anti-dive (the fork's axis is fixed in the chassis: one value for the whole travel)."""
    from finaldrive.engine.simulation import pack_parameters, prepare  # the solvers' machinery: only here

    if not 2 <= points <= MAX_TRAVEL_POINTS:
        raise ValueError(f"points must be in [2, {MAX_TRAVEL_POINTS}], got {points}")
    v = vehicle
    p = pack_parameters(v, design, SimSettings())
    extended = extension_angle(v)
    full = v["rear_wheel_travel"]
    compressed = angle_at(full, extended, v)
    design_q = design_pose(p)
    wheelbase = float(design_q[X15] - design_q[X14])
    tan_sigma = v["target_cog_height"] / wheelbase
    base = taut_length(design_pose(_with_angle(p, extended)))
    fork_x, fork_y = design_q[X5] - design_q[X4], design_q[Y5] - design_q[Y4]   # down the fork (eq. 14)
    fork_angle = math.atan2(fork_x, -fork_y)            # from the vertical, + with the axle ahead of the head

    def point(angle: float) -> dict[str, float]:
        out = {"travel_m": _travel_of(angle, extended, v), **_pose_quantities(p, angle, tan_sigma)}
        out["chain_growth_m"] = out["taut_length_m"] - base
        # the engine sprocket held, the growth turns the wheel back by growth / R_WS
        out["kickback_deg"] = math.degrees(out["chain_growth_m"] / design.rws)
        out["spring_length_m"] = spring_length(angle, v)
        h = _LEVERAGE_STEP   # wheel travel per unit of spring compression, central difference in the angle
        out["leverage_ratio"] = ((_travel_of(angle + h, extended, v) - _travel_of(angle - h, extended, v))
                                 / (spring_length(angle - h, v) - spring_length(angle + h, v)))
        return out

    q0 = prepare(design, Road(), SimSettings(), v).q0
    sag_angle = float(q0[PHI] - q0[THETA])
    design_angle = v["phi0"] - v["theta0"]
    return {
        "a2_deg": design.a2_deg, "l2_m": design.l2, "rws_m": design.rws,
        "engine_sprocket_x_m": design.l2 * math.cos(design.a2),
        "engine_sprocket_y_m": design.l2 * math.sin(design.a2),
        "rear_wheel_travel_m": full,
        "extension_angle_deg": math.degrees(extended), "compression_angle_deg": math.degrees(compressed),
        "cog_height_m": v["target_cog_height"], "wheelbase_m": wheelbase,
        "anti_squat_definition": ANTI_SQUAT_DEFINITION, "anti_rise_definition": ANTI_RISE_DEFINITION,
        "fork_angle_deg": math.degrees(fork_angle), "anti_dive_pct": -100.0 * math.tan(fork_angle) / tan_sigma,
        "anti_dive_definition": ANTI_DIVE_DEFINITION,
        "chain_pitch_m": v["chain_pitch"],
        "engine_sprocket_teeth": sprocket_teeth(p[P.R_ES], v["chain_pitch"]),
        "wheel_sprocket_teeth": sprocket_teeth(p[P.R_WS], v["chain_pitch"]),
        "chain_links": whole_chain_length(design_q, p) / v["chain_pitch"],
        "curve": [point(angle_at(t, extended, v)) for t in np.linspace(0.0, full, points)],
        "design_pose": point(design_angle),
        "static_sag": {**point(sag_angle), "sag_pct": 100.0 * _travel_of(sag_angle, extended, v) / full},
    }


def _with_angle(p: np.ndarray, angle: float) -> np.ndarray:
    pose = p.copy()
    pose[P.PHI0] = p[P.THETA0] + angle
    return pose


def drive_squat(design: Design, road: Road, settings: SimSettings, vehicle: Vehicle) -> dict[str, Any]:
    """The squat one simulation shows under drive: the rear travel (as in :func:`travel_kinematics`)
    and the chassis pitch over the run, beside their values at the static equilibrium on the road."""
    from finaldrive.engine.simulation import simulate

    result = simulate(design, road, settings.with_(series=True), vehicle)
    out: dict[str, Any] = {"road": road.spec, "status": result.status, "reason": result.reason,
                           "distance_m": result.distance_m, "duration": settings.duration}
    if not result.ok or result.series is None:
        return out
    q = result.series["q"]
    extended = extension_angle(vehicle)
    travel = vehicle["L_SA"] * (np.sin(q[:, PHI] - q[:, THETA]) - math.sin(extended))
    pitch = np.degrees(q[:, THETA] - q[0, THETA])
    out.update({
        "travel_static_m": float(travel[0]),
        "travel_mean_m": float(travel.mean()), "travel_min_m": float(travel.min()), "travel_max_m": float(travel.max()),
        "squat_mean_m": float(travel.mean() - travel[0]),
        "pitch_mean_deg": float(pitch.mean()), "pitch_min_deg": float(pitch.min()), "pitch_max_deg": float(pitch.max()),
    })
    return out
