"""Compiled road height y = h(x) and its derivatives for eqs. (32)-(33)."""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm
from finaldrive.engine.model.road import BUMP, FLAT, PROFILE, SINE


@jit
def road_height(kind: int, rp: np.ndarray, x: float) -> tuple[float, float, float]:
    """(h, dh/dx, d2h/dx2) at x for the packed road (Road.packed)."""
    if kind == FLAT:
        return 0.0, 0.0, 0.0
    if kind == SINE:  # eq. (32a), with a phase rp[2] (0 in the paper)
        k = 2.0 * math.pi / rp[1]
        s, c = libm.sincos(k * x + rp[2])
        return rp[0] * s, rp[0] * k * c, -rp[0] * k * k * s
    if kind == BUMP:  # eq. (32b)
        d = x - rp[2]
        s2 = rp[1] * rp[1]
        g = rp[0] * libm.exp(-d * d / (2.0 * s2))
        return g, -d / s2 * g, (d * d / (s2 * s2) - 1.0 / s2) * g
    if kind == PROFILE:  # piecewise linear, constant beyond the ends
        n = int(rp[0])
        xs = rp[1:1 + n]
        ys = rp[1 + n:1 + 2 * n]
        if x <= xs[0]:
            return ys[0], 0.0, 0.0
        if x >= xs[n - 1]:
            return ys[n - 1], 0.0, 0.0
        i = np.searchsorted(xs, x) - 1
        slope = (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i])
        return ys[i] + slope * (x - xs[i]), slope, 0.0
    return math.nan, math.nan, math.nan
