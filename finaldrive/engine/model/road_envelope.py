"""The road a rigid ring feels: a tyre of radius R cannot follow a dip narrower than itself, so the
model's point contact (eqs. 18-21, 32-33) overstates short features. The envelope is the classic
rigid-ring (rigid-tread-band) filter of tyre enveloping models (Zegelaar's and MF-Swift's basic
curves start from it): the ring rolls over the road without penetrating it, and the road the point
contact then follows is the ring centre's height minus R (docs/engine.md#road-enveloping).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.model.road import PROFILE_MAX_POINTS, Road, RoadError

#: Spacing of the enveloped profile's points and of the ring's offsets [m]. The largest of the ring's
#: heights over offsets this far apart misses the exact one by at most (kappa + 1.5 / R) step^2 / 8, kappa
#: the road's largest curvature (1.5 / R: the ring's own, where it touches at up to 0.55 R from its
#: lowest point): 7 micrometres on sine:0.04:0.5, 16 on a bump of 4 cm and sigma 5 cm; and the profile's
#: straight pieces cut the envelope's curves by at most 1.5 step^2 / (8 R), 4 micrometres.
ENVELOPE_STEP_M = 0.0025


def enveloped(road: Road, radius: float, start_m: float, end_m: float, step_m: float = ENVELOPE_STEP_M) -> Road:
    """``road`` under a rigid ring of ``radius`` [m], as a profile from ``start_m`` to ``end_m``: at each
    x the ring's centre is as low as the road lets it, c(x) = max over |u| <= R of y(x + u) + sqrt(R^2 - u^2),
    and the enveloped road is c(x) - R. Where the road's curvature stays below 1/R it keeps the crests'
    and troughs' heights (the ring touches them at their lowest and highest points); it bridges a dip
    narrower than the ring and rounds a crest sharper than it."""
    if not (radius > 0.0 and math.isfinite(radius)):
        raise RoadError(f"envelope: the ring's radius must be a positive number of metres, got {radius!r}")
    if not (step_m > 0.0 and end_m > start_m):
        raise RoadError(f"envelope: need start_m < end_m and step_m > 0, got {start_m}, {end_m}, {step_m}")
    points = math.ceil((end_m - start_m) / step_m) + 1
    if points > PROFILE_MAX_POINTS:
        raise RoadError(f"envelope: {end_m - start_m:g} m at {step_m:g} m is {points} points, more than a profile's "
                        f"{PROFILE_MAX_POINTS}: a shorter run or a coarser step")
    xs = start_m + step_m * np.arange(points)
    reach = math.floor(radius / step_m)
    u = step_m * np.arange(-reach, reach + 1)
    lift = np.sqrt(radius * radius - u * u)                  # the ring's lower half above its lowest point
    fine = road.height_at(start_m + step_m * np.arange(-reach, points + reach))
    centre = np.full(points, -np.inf)
    for k in range(u.size):                                 # the ring's contact with the road at offset u[k]
        np.maximum(centre, fine[k:k + points] + lift[k], out=centre)
    return Road.from_points(xs, centre - radius, name=f"{road.spec}~ring{radius:g}")
