"""Bodies, the constant mass matrix M of eq. (54) and the constant gravity forces.

Each rigid body is carried by two basic points i, j of the natural coordinates; a material
point is r = r_i + a (r_j - r_i) + b R (r_j - r_i) with R the +90 deg rotation, so M is
constant (section 6): M_ii = (m - 2 m a_G + J) I, M_ij = (m a_G - J) I + m b_G R,
M_jj = J I, with J = I_i / L_ij^2 and I_i the polar inertia about point i.

The front wheel is a point mass at point 13 (the paper does not turn it, section 2.1); with the
vehicle's ``front_wheel_spin`` it also rolls, at the angular speed x_13' / ft0, and its rotational
energy I_front_wheel x_13'^2 / (2 ft0^2) adds :func:`front_wheel_spin_mass` to M at x_13 alone.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm, params as P
from finaldrive.engine.model.coordinates import FS, FT, N_COORDS, RS, RT, X1, X2, X5, X6, X8, X9, X12, X13, Y13
from finaldrive.engine.model.elements import spring_energy
from finaldrive.engine.model.linalg import dot
from finaldrive.engine.model.tyre import radial_energy

_ROT = np.array([[0.0, -1.0], [1.0, 0.0]])


class Body(NamedTuple):
    """A rigid body on basic points i -> j (coordinate indices of their x), Table 2 (a named tuple: a
    run's setup and end build the list three times, and a frozen dataclass took 5 us a body)."""

    name: str
    i: int
    j: int
    length: float  # |r_i -> r_j|
    a_g: float     # centre of mass along i -> j, in units of length
    b_g: float     # centre of mass normal to i -> j (to the left), in units of length
    mass: float
    inertia: float  # about the centre of mass


def bodies(p: np.ndarray) -> list[Body]:
    """The six bodies of section 2.1 for the packed parameters p (front wheel: a point mass)."""
    a5 = p[P.A5]
    cx, cy = p[P.CHASSIS_COG_X], p[P.CHASSIS_COG_Y]
    # chassis centre of mass from the chassis frame to the frame along 1 -> 5
    xl = cx * libm.cos(a5) + cy * libm.sin(a5)
    yl = -cx * libm.sin(a5) + cy * libm.cos(a5)
    return [
        Body("chassis", X1, X5, p[P.L5], xl / p[P.L5], yl / p[P.L5], p[P.M_CHASSIS], p[P.I_CHASSIS]),
        Body("swingarm", X1, X6, p[P.L_SA], p[P.SWINGARM_COG_FRACTION], 0.0, p[P.M_SWINGARM], p[P.I_SWINGARM]),
        Body("engine_sprocket", X2, X8, p[P.R_ES], 0.0, 0.0, p[P.M_SPROCKET], p[P.I_SPROCKET]),
        Body("rear_wheel", X6, X9, p[P.R_WS], 0.0, 0.0, p[P.M_REAR_WHEEL], p[P.I_REAR_WHEEL]),
        Body("lower_fork", X12, X13, p[P.L8], p[P.FORK_COG_FRACTION], 0.0, p[P.M_FORK], p[P.I_FORK]),
    ]


@jit
def front_wheel_spin_mass(p: np.ndarray) -> float:
    """The front wheel's rotational inertia as a mass along x [kg]: I_front_wheel / ft0^2 when it turns
    (front_wheel_spin = 1, rolling at x_13' / ft0 on its unloaded radius), else 0 (the paper)."""
    return float(p[P.FRONT_WHEEL_SPIN] * p[P.I_FRONT_WHEEL] / (p[P.FT0] * p[P.FT0]))


def mass_matrix(p: np.ndarray) -> np.ndarray:
    """The constant 39 x 39 mass matrix M."""
    M = np.zeros((N_COORDS, N_COORDS))
    eye = np.eye(2)
    for b in bodies(p):
        J = (b.inertia + b.mass * b.length**2 * (b.a_g**2 + b.b_g**2)) / b.length**2
        si, sj = slice(b.i, b.i + 2), slice(b.j, b.j + 2)
        M[si, si] += (b.mass - 2.0 * b.mass * b.a_g + J) * eye
        M[si, sj] += (b.mass * b.a_g - J) * eye + b.mass * b.b_g * _ROT
        M[sj, si] += (b.mass * b.a_g - J) * eye + b.mass * b.b_g * _ROT.T
        M[sj, sj] += J * eye
    M[X13:X13 + 2, X13:X13 + 2] += p[P.M_FRONT_WHEEL] * eye
    M[X13, X13] += front_wheel_spin_mass(p)
    return M


def gravity_forces(p: np.ndarray) -> np.ndarray:
    """Generalized gravity forces (constant in natural coordinates)."""
    q = [0.0] * N_COORDS   # summed as Python floats: numpy's item access cost 1 us a term
    g = float(p[P.GRAVITY])
    for b in bodies(p):
        w = float(b.mass) * g
        q[b.i] += b.b_g * w
        q[b.i + 1] += -(1.0 - b.a_g) * w
        q[b.j] += -b.b_g * w
        q[b.j + 1] += -b.a_g * w
    q[Y13] += -float(p[P.M_FRONT_WHEEL]) * g
    return np.array(q)


def centre_of_mass(q: np.ndarray, p: np.ndarray) -> tuple[float, float, float]:
    """(total mass, x_G, y_G) of the whole motorcycle at pose q."""
    total, sx, sy = p[P.M_FRONT_WHEEL], p[P.M_FRONT_WHEEL] * q[X13], p[P.M_FRONT_WHEEL] * q[Y13]
    for b in bodies(p):
        ri, rj = q[b.i:b.i + 2], q[b.j:b.j + 2]
        d = rj - ri
        g = ri + b.a_g * d + b.b_g * np.array([-d[1], d[0]])   # the normal: d turned by +90 deg
        total += b.mass
        sx += b.mass * g[0]
        sy += b.mass * g[1]
    return total, sx / total, sy / total



def potential_energy(q: np.ndarray, p: np.ndarray, qg: np.ndarray | None = None) -> float:
    """Potential energy at pose q [J]: gravity (V = -Q_g . q, Q_g constant: pass gravity_forces(p)
    to save its cost) and the springs of the suspensions (34)-(35) and tyres (36)-(37), the rear
    bump stop included. The sprocket angles alpha, beta do not enter it (both centres of mass sit
    on their axes)."""
    if qg is None:
        qg = gravity_forces(p)
    springs = (spring_energy(q[RS], p[P.K_RS], p[P.S_RS], p[P.RS_BUMP], p)
               + spring_energy(q[FS], p[P.K_FS], p[P.S_FS], p[P.FS_BUMP], p))
    springs += radial_energy(q[RT], p[P.RT0], p[P.K_RT], p[P.RT_BOTTOMING], p[P.K_RT_BOTTOMING])
    springs += radial_energy(q[FT], p[P.FT0], p[P.K_FT], math.inf, 0.0)
    return float(-dot(qg, q) + springs)
