"""Chain slack (68) and the fitness function (67)."""

from __future__ import annotations

import math


def slack(taut_min: float, taut_max: float) -> float:
    """slack = 2 [max(L_taut) - min(L_taut)], eq. (68) [m]."""
    return 2.0 * (taut_max - taut_min)


def fitness(distance: float, squat_ratio: float, slack_m: float, *, eps1: float, eps2: float,
            sr_optimum: float, floor: float) -> float:
    """d * max{1 / (eps1 |SR - SR_opt| + 1) * 1 / (eps2 |slack| + 1); floor}, eq. (67)."""
    if not math.isfinite(distance):
        return math.nan
    penalty = 1.0 / (eps1 * abs(squat_ratio - sr_optimum) + 1.0) / (eps2 * abs(slack_m) + 1.0)
    return float(distance * max(penalty, floor))
