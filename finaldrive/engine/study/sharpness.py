"""How sharp an optimum is: the near-optimal set, spreads of designs, and local sensitivities.

The near-optimal set is every evaluated design whose fitness (eq. 67; or a study's aggregate
score) is within a tolerance of the best: by default 0.1 % of the best fitness. Over it each
variable gets a range (a2 on the circle: the shortest arc holding every angle), compared with the
range the study explored; a variable whose near-optimal range covers most of what was explored is
not decided by the study. The sensitivities are central finite differences of distance and fitness
through the engine at the optimum (one-sided at a bound of L2 or R_WS): 7 simulations.
See docs/optimisation.md#sharpness-of-an-optimum.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from finaldrive.engine.api import Design, SimSettings

if TYPE_CHECKING:
    from finaldrive.engine.model.road import Road
    from finaldrive.engine.vehicle import Vehicle

#: Default tolerance of the near-optimal set [% of the best fitness], and the largest accepted.
DEFAULT_TOLERANCE_PCT = 0.1
MAX_TOLERANCE_PCT = 50.0
#: Finite-difference steps: a2 [deg], L2 [m], R_WS [m].
SENSITIVITY_STEPS: dict[str, float] = {"a2_deg": 1.0, "l2_m": 0.001, "rws_m": 0.001}
#: A variable whose near-optimal range covers at least this share of its explored range is
#: undetermined; below the second share it is decided, in between loosely decided.
UNDETERMINED_SHARE = 0.5
DECIDED_SHARE = 0.1
VARIABLES = ("a2_deg", "l2_m", "rws_m")
#: Below this L2 [m] the engine sprocket sits on the pivot and a2 has no effect: left out of a2's ranges.
CONCENTRIC_L2_M = 1e-4
_LABELS = {"a2_deg": ("a2", "deg", 1.0, 0), "l2_m": ("L2", "mm", 1000.0, 1), "rws_m": ("R_WS", "mm", 1000.0, 1)}


def angle_arc(degrees: np.ndarray) -> tuple[float, float]:
    """(start, end) of the shortest arc holding every angle [deg], start in [0, 360), end >= start."""
    a = np.sort(np.mod(np.asarray(degrees, dtype=float), 360.0))
    if a.size == 0:
        return math.nan, math.nan
    gaps = np.diff(np.append(a, a[0] + 360.0))
    widest = np.flatnonzero(gaps >= gaps.max() - 1e-9)
    i = int(widest[-1] if widest[-1] == a.size - 1 else widest[0])   # after the largest gap; on ties from a[0]
    start, end = float(a[(i + 1) % a.size]), float(a[i])   # the arc ends at the angle before the gap, exactly
    return start, end if end >= start else end + 360.0


def spread(designs: np.ndarray, values: np.ndarray | None = None) -> dict[str, list[float]]:
    """Range of each variable over design rows (a2 [rad], L2 [m], R_WS [m]) and of ``values`` [m]; a2's
    is the shortest arc over the designs with L2 > :data:`CONCENTRIC_L2_M` (NaN if there are none)."""
    rows = np.asarray(designs, dtype=float).reshape(-1, 3)
    if len(rows) == 0:
        return {}
    placed = rows[:, 1] > CONCENTRIC_L2_M       # a2 means nothing with the sprocket on the pivot
    out = {"a2_deg": list(angle_arc(np.degrees(rows[placed, 0]))),
           "l2_m": [float(rows[:, 1].min()), float(rows[:, 1].max())],
           "rws_m": [float(rows[:, 2].min()), float(rows[:, 2].max())]}
    if values is not None:
        v = np.asarray(values, dtype=float)
        v = v[np.isfinite(v)]
        if v.size:
            out["fitness_m"] = [float(v.min()), float(v.max())]
    return out


def _span(r: list[float]) -> float:
    return r[1] - r[0]


def near_optimal(designs: np.ndarray, fitness: np.ndarray, distance: np.ndarray | None = None,
                 tolerance_pct: float = DEFAULT_TOLERANCE_PCT) -> dict[str, Any]:
    """The near-optimal set of evaluated designs, its size, each variable's range over it and over
    every evaluated design, a verdict per variable and plain sentences. NaN fitness (failed) is left out."""
    mask, best, tol = near_mask(fitness, tolerance_pct)
    rows = np.asarray(designs, dtype=float).reshape(-1, 3)
    f = np.asarray(fitness, dtype=float)
    ok = np.isfinite(f)
    if not ok.any():
        return near_summary(tolerance_pct, math.nan, math.nan, {}, {}, 0, 0, 0)
    near, explored = spread(rows[mask], f[mask]), spread(rows[ok], f[ok])
    if distance is not None:
        d = np.asarray(distance, dtype=float)[mask]
        d = d[np.isfinite(d)]
        if d.size:
            near["distance_m"] = [float(d.min()), float(d.max())]
    return near_summary(tolerance_pct, best, tol, near, explored, int(mask.sum()), int(ok.sum()),
                        int((rows[mask, 1] <= CONCENTRIC_L2_M).sum()))


def near_summary(tolerance_pct: float, best: float, tol: float, near: dict[str, list[float]],
                 explored: dict[str, list[float]], count: int, evaluated: int, concentric: int) -> dict[str, Any]:
    """What :func:`near_optimal` reports, from the ranges (:func:`spread`) over the near-optimal set
    (``count`` designs, ``concentric`` of them with L2 = 0) and over the ``evaluated`` designs."""
    if not evaluated:
        return {"tolerance_pct": tolerance_pct, "count": 0, "evaluated": 0, "sentences": ["no successful evaluation"]}
    verdicts: dict[str, str] = {}
    sentences = []
    for name in VARIABLES:
        verdicts[name], sentence = _verdict(name, near[name], explored[name], tol, count, evaluated)
        sentences.append(sentence)
    if concentric:
        sentences.append(f"{concentric} of them {'has' if concentric == 1 else 'have'} L2 = 0 (engine sprocket on "
                         "the pivot), where a2 has no effect")
    return {"tolerance_pct": tolerance_pct, "tolerance_m": tol, "best_fitness_m": best,
            "count": count, "evaluated": evaluated, "ranges": near, "explored": explored,
            "verdicts": verdicts, "sentences": sentences}


def near_mask(fitness: np.ndarray, tolerance_pct: float = DEFAULT_TOLERANCE_PCT) -> tuple[np.ndarray, float, float]:
    """(which values are within tolerance_pct % of the best, the best, the tolerance [m]); NaN is never near."""
    if not 0 < tolerance_pct <= MAX_TOLERANCE_PCT:
        raise ValueError(f"tolerance_pct must be in (0, {MAX_TOLERANCE_PCT:g}], got {tolerance_pct}")
    f = np.asarray(fitness, dtype=float)
    ok = np.isfinite(f)
    if not ok.any():
        return np.zeros(f.shape, dtype=bool), math.nan, math.nan
    best = float(f[ok].max())
    tol = abs(best) * tolerance_pct / 100.0
    return ok & (f >= best - tol), best, tol


def _verdict(name: str, near: list[float], explored: list[float], tol: float, size: int,
             evaluated: int) -> tuple[str, str]:
    label, unit, scale, digits = _LABELS[name]
    within = f"within {1000 * tol:.3g} mm of the best fitness"
    if not math.isfinite(near[0]):
        return "undetermined", f"{label} has no effect: every design {within} has L2 = 0"
    lo, hi = (round(scale * v, digits) for v in near)
    if _span(explored) <= 0:
        return "fixed", f"{label} was not varied ({lo:g} {unit})"
    share = _span(near) / _span(explored)
    if name == "a2_deg" and hi >= 360:
        where = f"{label} from {lo:g} through 0 to {hi - 360:g} {unit}"
    else:
        where = f"{label} from {lo:g} to {hi:g} {unit}"
    if share >= UNDETERMINED_SHARE:
        return "undetermined", (f"{label} is not decided: any {where} is {within} "
                                f"({size} of {evaluated} designs, {100 * share:.0f} % of the explored range)")
    if share >= DECIDED_SHARE:
        return "loose", f"{label} is loosely decided: {where} is {within} ({100 * share:.0f} % of the explored range)"
    if size == 1:
        return "decided", f"{label} is decided: no other evaluated design is {within}"
    return "decided", f"{label} is decided: {where} is {within} ({100 * share:.0f} % of the explored range)"


def sensitivities(design: Design, road: Road, settings: SimSettings, vehicle: Vehicle,
                  lower: tuple[float, float] = (0.0, 0.0)) -> dict[str, Any]:
    """d(distance)/dx and d(fitness)/dx for x = a2, L2, R_WS at ``design``: central differences with
    :data:`SENSITIVITY_STEPS`, one-sided ones where a step would cross ``lower`` (L2, R_WS) [m] or the
    vehicle's design limits."""
    from finaldrive.engine.simulation import evaluate  # the compiled model loads only when simulating

    rows, schemes = sensitivity_stencil(design, lower, upper_limits(vehicle))
    batch = evaluate(rows, road, settings, vehicle)
    return finite_differences(schemes, batch.distance_m, batch.fitness_m)


def upper_limits(vehicle: Vehicle) -> tuple[float, float]:
    """The largest L2 and R_WS a design may have on ``vehicle`` [m] (its design limits)."""
    limits = vehicle.design_limits()
    return limits["l2_m"], limits["rws_m"]


def sensitivity_stencil(design: Design, lower: tuple[float, float] = (0.0, 0.0),
                        upper: tuple[float, float] = (math.inf, math.inf)) -> tuple[np.ndarray, dict[str, str]]:
    """The 7 designs (rows a2 [rad], L2, R_WS) whose simulations :func:`finite_differences` takes:
    ``design``, then for a2, L2, R_WS in turn the step up and the step down; ``design`` itself in place
    of a step that would cross ``lower`` or ``upper`` (L2, R_WS) [m] (a forward or backward difference);
    and each scheme."""
    h = SENSITIVITY_STEPS
    rows = [design.row()]
    schemes: dict[str, str] = {}
    offsets = {"a2_deg": (0, math.radians(h["a2_deg"])), "l2_m": (1, h["l2_m"]), "rws_m": (2, h["rws_m"])}
    for name, (k, step) in offsets.items():
        minus, plus = design.row(), design.row()
        minus[k] -= step
        plus[k] += step
        down = k == 0 or (minus[k] >= lower[k - 1] and (k == 1 or minus[k] > 0))
        up = k == 0 or plus[k] <= upper[k - 1]
        schemes[name] = "central" if down and up else "forward" if up else "backward"
        rows += [plus if up else design.row(), minus if down else design.row()]
    return np.array(rows, dtype=float), schemes


def finite_differences(schemes: dict[str, str], distance: np.ndarray, fitness: np.ndarray) -> dict[str, Any]:
    """The sensitivities from the distance and fitness [m] of the :func:`sensitivity_stencil` designs, in order."""
    h = SENSITIVITY_STEPS
    distance, fitness = np.asarray(distance, dtype=float), np.asarray(fitness, dtype=float)
    out: dict[str, Any] = {"steps": dict(h), "schemes": dict(schemes), "simulations": len(distance),
                           "distance_m": float(distance[0]), "fitness_m": float(fitness[0])}
    per = {"a2_deg": ("a2", "deg"), "l2_m": ("l2", "m"), "rws_m": ("rws", "m")}  # units of docs/fields.md
    for i, name in enumerate(VARIABLES):
        var, unit = per[name]
        width = (2.0 if schemes[name] == "central" else 1.0) * h[name]  # one-sided: the design is one end
        for what, values in (("distance", distance), ("fitness", fitness)):
            out[f"d{what}_d{var}_m_per_{unit}"] = float((values[1 + 2 * i] - values[2 + 2 * i]) / width)
    return out


def sensitivity_sentences(s: dict[str, Any], tolerance_m: float) -> list[str]:
    """Each variable's derivatives and, to first order, how far it moves the fitness by the tolerance
    (none within the Table 8 box width: the fitness hardly depends on it here)."""
    out = []
    for name, var, key, unit, scale, width in (("a2", "a2", "deg", "deg", 1.0, 360.0),
                                               ("L2", "l2", "m", "mm", 1000.0, 200.0),
                                               ("R_WS", "rws", "m", "mm", 1000.0, 100.0)):
        step = scale * s["steps"][f"{var}_{key}"]
        g = s[f"dfitness_d{var}_m_per_{key}"] / scale   # per shown unit
        gd = s[f"ddistance_d{var}_m_per_{key}"] / scale
        reach = tolerance_m / abs(g) if math.isfinite(g) and g != 0 else math.inf
        effect = (f"{reach:.3g} {unit} moves the fitness by the tolerance" if reach <= width else
                  f"no change within {width:g} {unit} moves the fitness by the tolerance (first order)")
        out.append(f"d fitness / d {name} = {1000 * g:+.3g} mm/{unit}, d distance / d {name} = {1000 * gd:+.3g} "
                   f"mm/{unit} (step {step:g} {unit}): {effect}")
    return out
