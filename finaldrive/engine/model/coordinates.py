"""The 39 coordinates of Table 1: 30 natural (points 1-15) and 9 mixed.

q[point_x(k)], q[point_y(k)] are the coordinates of point k (1-based, as in Fig. 3).
Use the named constants below; never bare indices.
"""

from __future__ import annotations

import numpy as np

N_POINTS = 15
N_COORDS = 39
N_CONSTRAINTS = 33


def point_x(k: int) -> int:
    """Index of x_k (point k, 1-based)."""
    return 2 * (k - 1)


def point_y(k: int) -> int:
    """Index of y_k (point k, 1-based)."""
    return 2 * (k - 1) + 1


# Points (Table 1, Fig. 3)
X1, Y1 = 0, 1      # swingarm axis (pivot)
X2, Y2 = 2, 3      # engine (sprocket) axis
X3, Y3 = 4, 5      # upper damper pin
X4, Y4 = 6, 7      # upper triple clamp
X5, Y5 = 8, 9      # lower triple clamp
X6, Y6 = 10, 11    # rear wheel axis
X7, Y7 = 12, 13    # lower damper pin
X8, Y8 = 14, 15    # engine sprocket reference point
X9, Y9 = 16, 17    # rear wheel (sprocket) reference point
X10, Y10 = 18, 19  # engine sprocket tangent point of the upper chain run
X11, Y11 = 20, 21  # wheel sprocket tangent point of the upper chain run
X12, Y12 = 22, 23  # upper point of the lower fork
X13, Y13 = 24, 25  # front wheel axis
X14, Y14 = 26, 27  # rear tyre contact point
X15, Y15 = 28, 29  # front tyre contact point
# Mixed coordinates (Table 1)
RS = 30     # rear suspension length
FS = 31     # front suspension length
RT = 32     # rear tyre radius
FT = 33     # front tyre radius
THETA = 34  # chassis angle
ALPHA = 35  # engine sprocket angle
BETA = 36   # wheel sprocket angle
GAMMA = 37  # upper chain angle (angle of the radius to the tangent points)
PHI = 38    # swingarm angle (absolute, from the horizontal)

NAMES: tuple[str, ...] = (
    *tuple(f"{axis}{k}" for k in range(1, N_POINTS + 1) for axis in ("x", "y")),
    "rs",
    "fs",
    "rt",
    "ft",
    "theta",
    "alpha",
    "beta",
    "gamma",
    "phi",
)


def coordinate_index(name: str) -> int:
    """Index in q of a coordinate named as in :data:`NAMES` (``"x13"``, ``"rt"``, ``"beta"``, ...)."""
    try:
        return NAMES.index(name)
    except ValueError:
        raise KeyError(f"no coordinate {name!r}; expected one of {', '.join(NAMES)}") from None


def point_positions(q: np.ndarray) -> np.ndarray:
    """Positions of points 1-15 from q (..., 39) as (..., 15, 2); entry k - 1 is point k (Fig. 3)."""
    q = np.asarray(q, dtype=float)
    return q[..., : 2 * N_POINTS].reshape((*q.shape[:-1], N_POINTS, 2))
