"""The rear suspension's ends of travel: full extension (the rear spring at its unloaded length s_rs,
Table 5) and full compression (the axle ``rear_wheel_travel`` higher in the chassis frame, a
vehicle-file choice). Used by the travel curves (engine.travel) and the travel stops (engine.setup)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from finaldrive.engine.model import libm

if TYPE_CHECKING:
    from finaldrive.engine.vehicle import Vehicle


class TravelError(ValueError):
    """A vehicle whose rear suspension cannot reach the ends of its travel."""


def extension_angle(v: Vehicle) -> float:
    """Swingarm angle in the chassis frame [rad] where the rear spring (3-7, eq. 13) has its unloaded
    length: |r_3->7|^2 = L3^2 + L7^2 - 2 L3 L7 cos(a3 - phi), the root nearest phi0 - theta0."""
    l3, l7, s = v["L3"], v["L7"], v["s_rs"]
    c = (l3 * l3 + l7 * l7 - s * s) / (2.0 * l3 * l7)
    if abs(c) > 1.0:
        raise TravelError(f"the rear spring (s_rs = {s} m) cannot reach its unloaded length between points 3 and 7")
    design = v["phi0"] - v["theta0"]
    roots = (v["a3"] + libm.acos(c), v["a3"] - libm.acos(c))
    return min((design + math.remainder(r - design, math.tau) for r in roots), key=lambda r: abs(r - design))


def angle_at(travel: float, extended: float, v: Vehicle) -> float:
    """Swingarm angle in the chassis frame whose axle is ``travel`` above full extension."""
    y = v["L_SA"] * libm.sin(extended) + travel
    if abs(y) > v["L_SA"]:
        raise TravelError(f"a swingarm of {v['L_SA']} m cannot lift its axle {travel} m above full extension")
    angle = math.pi - libm.asin(y / v["L_SA"]) if libm.cos(extended) < 0 else libm.asin(y / v["L_SA"])
    return extended + math.remainder(angle - extended, math.tau)


def spring_length(angle: float, v: Vehicle) -> float:
    """The rear spring's length (points 3-7, eq. 13) with the swingarm at ``angle`` in the chassis frame [m]."""
    return math.sqrt(v["L3"] ** 2 + v["L7"] ** 2 - 2.0 * v["L3"] * v["L7"] * libm.cos(v["a3"] - angle))


def compressed_spring_length(v: Vehicle) -> float:
    """The rear spring's length at full compression, ``rear_wheel_travel`` above full extension [m]: where
    the travel stops' bump stop engages (vehicle ``suspension_stops``)."""
    return spring_length(angle_at(v["rear_wheel_travel"], extension_angle(v), v), v)
