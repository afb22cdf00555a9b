"""The DE search space (Table 8) in engine units, and which variables wrap."""

from __future__ import annotations

import math

import numpy as np

#: Table 8: a2 [rad], L2 [m], R_WS [m].
TABLE8_LOWER = np.array([0.0, 0.0, 0.05])
TABLE8_UPPER = np.array([2.0 * math.pi, 0.2, 0.15])


def periodic_mask(lower: np.ndarray, upper: np.ndarray) -> list[bool]:
    """a2 wraps around only when its range is the whole circle; L2 and R_WS never do."""
    return [math.isclose(float(upper[0] - lower[0]), 2.0 * math.pi), False, False]
