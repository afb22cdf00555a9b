"""The force elements of the motorcycle, described once and used by both solvers.

Each element is a compiled function of the element's own variables (a length and its rate, the
tyre's deflection, slip speed and state, ...): it returns the force or torque and writes what the
run reports (forces, slip, powers) into the shared ``aux`` vector. Each solver only projects the
result onto its coordinates: the reference onto the 39 natural coordinates (engine.model.forces),
the fast path onto its 6 minimal coordinates (engine.fast.minimal), by virtual work.

- rear tyre: radial spring-damper with the bump stop (36), longitudinal force (38)-(52) with its
  lever arm on the wheel (engine.model.tyre);
- front tyre: radial spring-damper (37);
- suspensions: linear spring-dampers (34)-(35);
- drive: a torque between chassis and engine sprocket: constant (the paper's, the reference choice) or
  the launch drive (an engine curve through the gearbox with its limits, vehicle drive_model = 1);
- chain: the tension of the upper run from the engine sprocket's moment balance.

Gravity and inertia of the bodies (Table 2) are in engine.model.mass (natural coordinates) and
engine.fast.minimal (the same centres of mass and inertias as kinetic energy in minimal coordinates).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import params as P
from finaldrive.engine.model.tyre import (
    FZ_CONTACT_MIN,
    deformation_rate,
    effective_radius,
    lever_arm,
    magic_formula_slope,
    radial_damping_power,
    radial_force,
    transient_slip,
)

# Slots of the auxiliary vector both solvers fill at every right-hand side evaluation.
(AUX_FX, AUX_FZ_REAR, AUX_FZ_FRONT, AUX_KAPPA, AUX_VX, AUX_VSX, AUX_RE, AUX_LEVER, AUX_OMEGA, AUX_DUDT,
 AUX_SLOPE, AUX_RT, AUX_FT, AUX_P_DAMP, AUX_P_DRIVE, AUX_TENSION, AUX_TAUT, AUX_TAUT_RATE, AUX_ALPHA_DOT,
 AUX_RESID, AUX_TORQUE) = range(21)
N_AUX = 21


@jit
def rear_tyre(rt: float, rt_dot: float, vx: float, omega: float, u: float, sigma: float, p: np.ndarray,
              longitudinal: bool, aux: np.ndarray) -> tuple[float, float, float]:
    """The rear tyre at its contact point: (F_z, F_x, lever arm of F_x on the wheel).

    rt: loaded radius (20); vx: forward speed of the axle (39); omega = -beta' the wheel's spin;
    u: the tyre's deformation state (42) with sigma* held through the step (41). The vertical force
    acts along the radius, F_x horizontally at the contact point, turning the wheel with the lever
    arm. Fills aux (F_x, F_z, kappa', V_x, V_sx, R_e, lever, omega, u', dF_x/dkappa', rt) and adds
    the radial damper's power to aux[AUX_P_DAMP].
    """
    fz = radial_force(rt, rt_dot, p[P.RT0], p[P.K_RT], p[P.C_RT], p[P.RT_BOTTOMING], p[P.K_RT_BOTTOMING])  # (36)
    re = effective_radius(rt, p)                                              # (38)
    vsx = vx - re * omega                                                     # (40)
    kappa = transient_slip(u, sigma, vsx, vx, fz, p)                          # (43)
    fx, slope = magic_formula_slope(fz, kappa, p) if longitudinal else (0.0, 0.0)   # (45)
    lever = lever_arm(rt, re, p)
    aux[AUX_FX] = fx
    aux[AUX_FZ_REAR] = fz
    aux[AUX_KAPPA] = kappa
    aux[AUX_VX] = vx
    aux[AUX_VSX] = vsx
    aux[AUX_RE] = re
    aux[AUX_LEVER] = lever
    aux[AUX_OMEGA] = omega
    airborne_relax = p[P.TYRE_AIRBORNE_RELAX] != 0.0 and fz <= FZ_CONTACT_MIN  # vehicle choice: no slip off the road
    aux[AUX_DUDT] = deformation_rate(u, sigma, 0.0 if airborne_relax else vsx, vx)  # (42)
    aux[AUX_SLOPE] = slope
    aux[AUX_RT] = rt
    aux[AUX_P_DAMP] += radial_damping_power(rt, rt_dot, p[P.RT0], p[P.C_RT])
    return fz, fx, lever


@jit
def front_tyre(ft: float, ft_dot: float, p: np.ndarray, aux: np.ndarray) -> float:
    """The front tyre's vertical force, eq. (37) (no bump stop: the paper's front tyre); fills aux."""
    fz = radial_force(ft, ft_dot, p[P.FT0], p[P.K_FT], p[P.C_FT], np.inf, 0.0)
    aux[AUX_FZ_FRONT] = fz
    aux[AUX_FT] = ft
    aux[AUX_P_DAMP] += radial_damping_power(ft, ft_dot, p[P.FT0], p[P.C_FT])
    return fz


@jit
def spring_force(length: float, k: float, free_length: float, bump_length: float, p: np.ndarray) -> float:
    """A suspension spring's force along its length (positive pushes the ends apart), eqs. (34)-(35):
    -k (l - s). With the vehicle's travel stops (``suspension_stops``): beyond its unloaded length s the
    spring is fully extended and pushes no more, a top-out stop -k_stop (l - s) holds it; below
    ``bump_length`` (full compression) a bump stop k_stop (l_b - l) adds to it."""
    if p[P.SUSPENSION_STOPS] == 0.0:
        return -k * (length - free_length)
    if length > free_length:
        return -p[P.K_STOP] * (length - free_length)
    f = -k * (length - free_length)
    if length < bump_length:
        f += p[P.K_STOP] * (bump_length - length)
    return f


@jit
def spring_energy(length: float, k: float, free_length: float, bump_length: float, p: np.ndarray) -> float:
    """The energy stored in a suspension spring and its stops [J] (the potential of spring_force)."""
    if p[P.SUSPENSION_STOPS] == 0.0:
        return 0.5 * k * (length - free_length) ** 2
    if length > free_length:
        return 0.5 * p[P.K_STOP] * (length - free_length) ** 2
    e = 0.5 * k * (length - free_length) ** 2
    if length < bump_length:
        e += 0.5 * p[P.K_STOP] * (bump_length - length) ** 2
    return e


@jit
def spring_damper(length: float, rate: float, k: float, c: float, free_length: float, bump_length: float,
                  p: np.ndarray, aux: np.ndarray) -> float:
    """Suspension spring-damper, eqs. (34)-(35) (spring_force, with the vehicle's travel stops if on):
    the force along its length; adds the damper's power c l'^2 to aux[AUX_P_DAMP]."""
    aux[AUX_P_DAMP] += c * rate * rate
    return spring_force(length, k, free_length, bump_length, p) - c * rate


@jit
def engine_torque(speed_rpm: float, p: np.ndarray) -> float:
    """The launch drive's engine torque [N m] at speed_rpm: the vehicle's four-point curve, linear between
    its points, held at the first point below it, none above the last (the rev limit)."""
    if speed_rpm > p[P.ENGINE_SPEED_4]:
        return 0.0
    if speed_rpm <= p[P.ENGINE_SPEED_1]:
        return p[P.ENGINE_TORQUE_1]
    for i in range(3):
        n0, n1 = p[P.ENGINE_SPEED_1 + i], p[P.ENGINE_SPEED_1 + i + 1]
        if speed_rpm <= n1:
            t0, t1 = p[P.ENGINE_TORQUE_1 + i], p[P.ENGINE_TORQUE_1 + i + 1]
            return t0 + (t1 - t0) * (speed_rpm - n0) / (n1 - n0)
    return p[P.ENGINE_TORQUE_4]


@jit
def launch_torque(sprocket_speed: float, fz_rear: float, re: float, p: np.ndarray) -> float:
    """The launch drive's torque on the engine sprocket [N m] (vehicle drive_model = 1).

    The engine turns at the sprocket's speed relative to the chassis times the primary and first-gear
    ratios, or at launch_speed while the clutch slips below it (the clutch then passes the engine's
    torque at that speed). Its torque through the ratios is capped so that the drive force it asks of the
    rear tyre, T R_WS / (R_ES R_e), stays below two limits: the wheelie limit wheelie_force (a constant,
    from the quasi-static load transfer) and the traction limit tc_friction F_z (eq. 36's load, so the
    throttle is cut while the rear tyre is off the road). Both limits are feed-forward (no slip or pitch
    feedback: such feedback, tried, rocked the bike on its suspension and left the distance undecided to
    metres between tolerances; docs/engine.md#the-launch-drive).
    """
    ratio = p[P.PRIMARY_RATIO] * p[P.FIRST_GEAR_RATIO]
    speed_rpm = max(sprocket_speed * ratio * 30.0 / math.pi, p[P.LAUNCH_SPEED])
    force_cap = min(p[P.WHEELIE_FORCE], p[P.TC_FRICTION] * max(fz_rear, 0.0))
    return min(ratio * engine_torque(speed_rpm, p), force_cap * re / p[P.SPROCKET_RATIO])


@jit
def drive_torque(theta_dot: float, alpha_dot: float, p: np.ndarray, aux: np.ndarray) -> float:
    """The engine's torque T on the sprocket (turning it forward, alpha decreasing), its reaction on
    the chassis: the paper's constant torque, or the launch drive (reads the rear tyre's load and
    effective radius from aux: call it after rear_tyre); the drive's power T (theta' - alpha') into
    aux[AUX_P_DRIVE]."""
    if p[P.DRIVE_MODEL] == 0.0:
        t = p[P.TORQUE]
    else:
        t = launch_torque(theta_dot - alpha_dot, aux[AUX_FZ_REAR], aux[AUX_RE], p)
    aux[AUX_P_DRIVE] = t * (theta_dot - alpha_dot)
    aux[AUX_TORQUE] = t
    return t


@jit
def sprocket_chain_tension(torque: float, alpha_dd: float, p: np.ndarray) -> float:
    """Tension of the upper run from the engine sprocket's moment balance: T_c R_ES = T + I alpha''."""
    return (torque + p[P.I_SPROCKET] * alpha_dd) / p[P.R_ES]
