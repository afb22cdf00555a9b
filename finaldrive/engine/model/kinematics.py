"""Position analysis and final-drive geometry: assembling q, the chain tangent, the taut run,
the chain length (69) and the squat ratio.

Given the six independent coordinates (x1, y1, theta, phi, fs, beta) and alpha, every other
coordinate follows in closed form from eqs. (1)-(33) (the upper chain run is the common
external tangent of the pitch circles, eqs. 24-29 and 31). The lower run, used by the two-run
chain (docs/engine.md#chain-overrun), is the other common external tangent: the mirror of
eqs. (24)-(29) and (31) about the line of centres.
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm, params as P
from finaldrive.engine.model.coordinates import (
    ALPHA,
    BETA,
    FS,
    FT,
    GAMMA,
    N_COORDS,
    PHI,
    RS,
    RT,
    THETA,
    X1,
    X2,
    X3,
    X4,
    X5,
    X6,
    X7,
    X8,
    X9,
    X10,
    X11,
    X12,
    X13,
    X14,
    X15,
    Y1,
    Y2,
    Y3,
    Y4,
    Y5,
    Y6,
    Y7,
    Y8,
    Y9,
    Y10,
    Y11,
    Y12,
    Y13,
    Y14,
    Y15,
)
from finaldrive.engine.model.road import Road
from finaldrive.engine.model.road_height import road_height

#: The first guess of an equilibrium presses both tyres this far into the road [m] so both springs act.
GUESS_PRELOAD = 0.005


class GeometryError(ValueError):
    """A design whose final drive cannot be assembled (e.g. sprockets overlapping)."""


@jit
def tangent_angle(x2: float, y2: float, x6: float, y6: float, res: float, rws: float, run: int = 1) -> float:
    """gamma: angle of the radii to the tangent points of the upper run (run = 1, eqs. 24-29, 31) or of
    the lower run (run = -1, their mirror about the line of centres); NaN when the sprockets' centres
    are too close to carry a chain.

    Eq. (31) with points 10, 11 at angle gamma gives |r_2->6| cos(gamma - delta) = R_ES - R_WS,
    delta the direction of r_2->6; the upper run is the root gamma = delta - acos(.), the lower
    run the other root, delta + acos(.).
    """
    dx, dy = x6 - x2, y6 - y2
    dist = libm.hypot(dx, dy)
    if dist <= abs(rws - res):
        return math.nan
    gamma = libm.atan2(dy, dx) - run * libm.acos((res - rws) / dist)
    return float(libm.atan2(libm.sin(gamma), libm.cos(gamma)))


@jit(one_form=True)   # the two-run chain's setup (whole_chain_length) and its runs (chain_runs.slack) call it
def loop_length(dist: float, res: float, rws: float) -> float:
    """Length of the chain's closed loop with both runs taut, sprocket centres dist apart: both
    straight runs (eqs. 24-29 and their mirror, sqrt(dist^2 - k^2) each) and both wraps,
    pi (R_ES + R_WS) + 2 k asin(k / dist), k = R_ES - R_WS (the open-belt length)."""
    k = res - rws
    return float(math.pi * (res + rws) + 2.0 * k * libm.asin(k / dist) + 2.0 * math.sqrt(dist * dist - k * k))


def free_play_slack(taut: float, free_play: float) -> float:
    """How much longer the chain is than its loop of two taut runs when its slack run of length taut
    moves free_play up and down at its midpoint: sqrt(taut^2 + free_play^2) - taut (the run pushed to
    either side of its straight line becomes two straight halves)."""
    return math.sqrt(taut * taut + free_play * free_play) - taut


def whole_chain_length(q: np.ndarray, p: np.ndarray) -> float:
    """The two-run chain's whole length at pose q: the loop of both taut runs and the slack of the
    vehicle's chain_free_play measured at that pose."""
    dist = libm.hypot(q[X6] - q[X2], q[Y6] - q[Y2])
    return float(loop_length(dist, p[P.R_ES], p[P.R_WS])) + free_play_slack(taut_length(q), p[P.CHAIN_FREE_PLAY])


@jit
def fill_pose(p: np.ndarray, kind: int, rp: np.ndarray, x1: float, y1: float, theta: float, phi: float,
              fs: float, beta: float, alpha: float, q: np.ndarray) -> bool:
    """assemble's body, compiled (the road packed); False if no chain fits between the sprockets."""
    q[X1], q[Y1], q[THETA], q[PHI], q[FS], q[BETA], q[ALPHA] = x1, y1, theta, phi, fs, beta, alpha
    q[X2], q[Y2] = x1 + p[P.L2] * libm.cos(theta + p[P.A2]), y1 + p[P.L2] * libm.sin(theta + p[P.A2])  # (1)-(8)
    q[X3], q[Y3] = x1 + p[P.L3] * libm.cos(theta + p[P.A3]), y1 + p[P.L3] * libm.sin(theta + p[P.A3])
    q[X4], q[Y4] = x1 + p[P.L4] * libm.cos(theta + p[P.A4]), y1 + p[P.L4] * libm.sin(theta + p[P.A4])
    q[X5], q[Y5] = x1 + p[P.L5] * libm.cos(theta + p[P.A5]), y1 + p[P.L5] * libm.sin(theta + p[P.A5])
    cp, sp = libm.cos(phi), libm.sin(phi)
    q[X6], q[Y6] = x1 + p[P.L_SA] * cp, y1 + p[P.L_SA] * sp            # (9)-(12)
    q[X7], q[Y7] = x1 + p[P.L7] * cp, y1 + p[P.L7] * sp
    q[RS] = libm.hypot(q[X3] - q[X7], q[Y3] - q[Y7])                    # (13)
    ux, uy = q[X5] - q[X4], q[Y5] - q[Y4]
    n = libm.hypot(ux, uy)
    ux, uy = ux / n, uy / n
    q[X12], q[Y12] = q[X4] + fs * ux, q[Y4] + fs * uy                   # (14), (17)
    q[X13], q[Y13] = q[X12] + p[P.L8] * ux, q[Y12] + p[P.L8] * uy       # (15), (16)
    q[X14], q[Y14] = q[X6], road_height(kind, rp, q[X6])[0]             # (18), (32)
    q[X15], q[Y15] = q[X13], road_height(kind, rp, q[X13])[0]           # (19), (33)
    q[RT] = q[Y6] - q[Y14]                                              # (20)
    q[FT] = q[Y13] - q[Y15]                                             # (21)
    gamma = tangent_angle(q[X2], q[Y2], q[X6], q[Y6], p[P.R_ES], p[P.R_WS])
    q[GAMMA] = gamma
    res, rws = p[P.R_ES], p[P.R_WS]
    q[X8], q[Y8] = q[X2] + res * libm.cos(alpha), q[Y2] + res * libm.sin(alpha)    # (22)-(29)
    q[X10], q[Y10] = q[X2] + res * libm.cos(gamma), q[Y2] + res * libm.sin(gamma)
    q[X9], q[Y9] = q[X6] + rws * libm.cos(beta), q[Y6] + rws * libm.sin(beta)
    q[X11], q[Y11] = q[X6] + rws * libm.cos(gamma), q[Y6] + rws * libm.sin(gamma)
    return not math.isnan(gamma)


def assemble(p: np.ndarray, road: Road, x1: float, y1: float, theta: float, phi: float,
             fs: float, beta: float, alpha: float) -> np.ndarray:
    """All 39 coordinates from the independent ones (satisfies eqs. 1-29, 31-33; eq. 30
    holds when alpha is consistent with the chain length P[L_CHAIN])."""
    q = np.zeros(N_COORDS)
    kind, rp = road.packed()
    if not fill_pose(p, kind, rp, float(x1), float(y1), float(theta), float(phi), float(fs), float(beta),
                     float(alpha), q):
        raise GeometryError(
            f"sprocket centres {libm.hypot(q[X6] - q[X2], q[Y6] - q[Y2]):.4f} m apart cannot carry a chain "
            f"between radii {p[P.R_ES]:.4f} m and {p[P.R_WS]:.4f} m")
    return q


def pose_from_minimal(z: np.ndarray, p: np.ndarray, road: Road, play: float = 0.0) -> np.ndarray:
    """All 39 coordinates from z = (x1, y1, theta, phi, fs, beta), alpha from the chain
    length P[L_CHAIN] through eq. (30), turned by play (the two-run chain's e: the engine
    sprocket's turn beyond the upper run's engagement)."""
    x1, y1, theta, phi, fs, beta = (float(v) for v in z[:6])
    q = assemble(p, road, x1, y1, theta, phi, fs, beta, 0.0)
    gamma = q[GAMMA]
    alpha = gamma - (p[P.L_CHAIN] - taut_length(q) - (beta - gamma) * p[P.R_WS]) / p[P.R_ES]
    return assemble(p, road, x1, y1, theta, phi, fs, beta, alpha + play)


def taut_length(q: np.ndarray) -> float:
    """L_taut: the straight upper run between points 10 and 11 (eq. 68)."""
    return float(libm.hypot(q[X10] - q[X11], q[Y10] - q[Y11]))


def chain_length(q: np.ndarray, p: np.ndarray) -> float:
    """L of eq. (69) at pose q."""
    return float((q[GAMMA] - q[ALPHA]) * p[P.R_ES] + taut_length(q)
                 + (q[BETA] - q[GAMMA]) * p[P.R_WS])


def design_pose(p: np.ndarray) -> np.ndarray:
    """The design pose on flat ground: theta = theta0, phi = phi0, both tyres unloaded (rt0, ft0),
    rear contact point at x = 0, sprocket reference points opposite the tangent points."""
    phi0, theta0 = p[P.PHI0], p[P.THETA0]
    x1 = -p[P.L_SA] * libm.cos(phi0)
    y1 = p[P.RT0] - p[P.L_SA] * libm.sin(phi0)
    # fork slide fs so that the front axle is ft0 above the ground
    y4 = y1 + p[P.L4] * libm.sin(theta0 + p[P.A4])
    y5 = y1 + p[P.L5] * libm.sin(theta0 + p[P.A5])
    x4 = x1 + p[P.L4] * libm.cos(theta0 + p[P.A4])
    x5 = x1 + p[P.L5] * libm.cos(theta0 + p[P.A5])
    uy = (y5 - y4) / libm.hypot(x5 - x4, y5 - y4)
    fs = (p[P.FT0] - y4) / uy - p[P.L8]
    flat = Road()
    q = assemble(p, flat, x1, y1, theta0, phi0, fs, 0.0, 0.0)
    return assemble(p, flat, x1, y1, theta0, phi0, fs, q[GAMMA] + math.pi, q[GAMMA] - math.pi)


def squat_line(q: np.ndarray, contact_x: float, contact_y: float) -> tuple[float, float]:
    """(run, rise) from the rear contact point to X, the intersection of the chain's upper run
    (10-11) with the swingarm line (1-6); parallel lines put X at infinity along the swingarm."""
    ax, ay = q[X10], q[Y10]
    dx, dy = q[X11] - ax, q[Y11] - ay                 # chain line direction
    bx, by = q[X1], q[Y1]
    ex, ey = q[X6] - bx, q[Y6] - by                   # swingarm line direction
    det = dx * (-ey) - dy * (-ex)
    if abs(det) < 1e-12 * libm.hypot(dx, dy) * libm.hypot(ex, ey):
        return float(ex), float(ey)
    s = ((bx - ax) * (-ey) - (by - ay) * (-ex)) / det
    return float(ax + s * dx - contact_x), float(ay + s * dy - contact_y)


def squat_ratio_at(q: np.ndarray, p: np.ndarray, contact_x: float, contact_y: float) -> float:
    """SR = K / tan(tau) (the reading of Cossalter's squat ratio in docs/engine.md#reading-notes-squat-ratio).

    tan(tau) is the slope of the line from the rear contact point to X (:func:`squat_line`).
    """
    run, rise = squat_line(q, contact_x, contact_y)
    if rise == 0.0:
        return math.inf
    return float(p[P.SQUAT_K] * run / rise)


def design_squat_ratio(p: np.ndarray, pose: np.ndarray | None = None) -> float:
    """Squat ratio at the design pose (theta = 0, phi = phi0, unloaded tyres; pose: design_pose(p))."""
    q = design_pose(p) if pose is None else pose
    return squat_ratio_at(q, p, q[X6], q[Y6] - p[P.RT0])


def first_guess(p: np.ndarray, road: Road, pose: np.ndarray | None = None) -> np.ndarray:
    """A start for the static equilibrium, (y1, theta, phi, fs): the design pose (pose:
    design_pose(p)) pitched onto the road about the rear contact point, both tyres preloaded."""
    q0 = design_pose(p) if pose is None else pose
    wheelbase = q0[X15] - q0[X14]
    h_rear, h_front = float(road.height_at(0.0)), float(road.height_at(wheelbase))
    pitch = libm.atan2(h_front - h_rear, wheelbase)
    y1 = q0[X1] * libm.sin(pitch) + q0[Y1] * libm.cos(pitch) + h_rear - GUESS_PRELOAD
    return np.array([y1, q0[THETA] + pitch, q0[PHI] + pitch, q0[FS]])
