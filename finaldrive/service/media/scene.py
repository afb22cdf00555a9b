"""The 2D scene of a simulated motorcycle, frame by frame, as plain numpy (no drawing library).

Shared by the Rerun recording (service/media/recording.py) and the matplotlib frame render
(service/media/plots.py), so both show exactly the same lines. Points are the natural
coordinates of engine/model/coordinates.py, in metres; ``offset`` shifts a run vertically
so that several geometries can ride the same road one above the other.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from finaldrive.engine import Design, Road, coordinate_index, point_positions

#: Tyre force arrows: metres of arrow per newton.
FORCE_SCALE_M_PER_N = 1.0 / 5000.0
#: Vertical distance between geometries shown side by side [m].
ROW_OFFSET_M = 1.6
#: Road drawn beyond the contact points' travel, either side [m]: more than a zoomed view shows.
ROAD_MARGIN_M = 3.0
#: Spacing of the road profile's points [m].
ROAD_STEP_M = 0.01
_CIRCLE = np.linspace(0.0, 2.0 * np.pi, 49)


@dataclass(frozen=True)
class Run:
    """One simulated geometry: its label, design, engine series (``series=True``) and its scalar
    outcome (distance, squat ratio, slack, fitness and the run's exact extremes and energy ledger)."""

    label: str
    design: Design
    series: dict[str, np.ndarray]
    outcome: dict[str, float] = field(default_factory=dict)


_RT, _FT, _BETA, _ALPHA = (coordinate_index(n) for n in ("rt", "ft", "beta", "alpha"))


def _pt(q: np.ndarray, k: int, dy: float) -> np.ndarray:
    return np.asarray(point_positions(q)[k - 1] + np.array([0.0, dy]), dtype=float)


def circle(centre: np.ndarray, radius: float) -> np.ndarray:
    return centre + radius * np.column_stack([np.cos(_CIRCLE), np.sin(_CIRCLE)])


def _mark(centre: np.ndarray, radius: float, angle: float) -> np.ndarray:
    """A radius drawn at ``angle``: shows the body's rotation."""
    return np.array([centre, centre + radius * np.array([np.cos(angle), np.sin(angle)])])


def frame(run: Run, k: int, r_es: float, offset: float = 0.0) -> dict[str, list[np.ndarray]]:
    """Line strips (each an (n, 2) array) of every part at series row ``k``.

    The front wheel has no spin coordinate in the model; its mark turns as if it rolled
    without slip (front axle travel / tyre radius).
    """
    s = run.series
    q = s["q"][k]
    p = {k + 1: xy + np.array([0.0, offset]) for k, xy in enumerate(point_positions(q))}
    rt, ft = float(q[_RT]), float(q[_FT])
    front_roll = -(point_positions(q)[12, 0] - point_positions(s["q"][0])[12, 0]) / ft
    return {
        "chassis": [np.array([p[1], p[2], p[3], p[4], p[5], p[1]])],
        "swingarm": [np.array([p[1], p[7], p[6]])],
        "damper": [np.array([p[3], p[7]])],
        "fork": [np.array([p[4], p[5], p[12], p[13]])],
        "rear_wheel": [circle(p[6], rt), _mark(p[6], rt, float(q[_BETA]))],
        "front_wheel": [circle(p[13], ft), _mark(p[13], ft, front_roll)],
        "engine_sprocket": [circle(p[2], r_es), _mark(p[2], r_es, float(q[_ALPHA]))],
        "wheel_sprocket": [circle(p[6], run.design.rws), _mark(p[6], run.design.rws, float(q[_BETA]))],
        "chain": [np.array([p[10], p[11]])],
    }


def tyre_forces(run: Run, k: int, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Arrow origins and vectors [m]: rear Fz, rear Fx, front Fz at the contact points."""
    s, q = run.series, run.series["q"][k]
    rear, front = _pt(q, 14, offset), _pt(q, 15, offset)
    vectors = np.array([[0.0, s["fz_rear_n"][k]], [s["fx_n"][k], 0.0], [0.0, s["fz_front_n"][k]]])
    return np.array([rear, rear, front]), vectors * FORCE_SCALE_M_PER_N


def force_labels(run: Run, k: int, offset: float = 0.0) -> tuple[np.ndarray, list[str]]:
    """Tyre-force label anchors (the rear and front contact points) and texts, one per wheel:
    a viewer that draws each label under its anchor keeps them under the road, apart whatever the forces."""
    s, q = run.series, run.series["q"][k]
    texts = [f"Fz {s['fz_rear_n'][k] / 1e3:.1f} kN, Fx {s['fx_n'][k] / 1e3:.1f} kN",
             f"Fz {s['fz_front_n'][k] / 1e3:.1f} kN"]
    return np.array([_pt(q, 14, offset), _pt(q, 15, offset)]), texts


def reference_x(runs: Sequence[Run]) -> np.ndarray:
    """Per series row, the mean over ``runs`` of the point midway between the axles [m]: a zoomed
    view follows it, the same for every run, so their relative advance stays visible."""
    axles = [point_positions(r.series["q"])[:, [5, 12], 0] for r in runs]
    return np.asarray(np.mean([a.mean(axis=1) for a in axles], axis=0), dtype=float)


def road_strip(road: Road, runs: Sequence[Run], offset: float = 0.0) -> np.ndarray:
    """The road profile under every run's travel, :data:`ROAD_MARGIN_M` either side."""
    xs = np.concatenate([point_positions(r.series["q"])[:, 13:15, 0].ravel() for r in runs])
    lo, hi = xs.min() - ROAD_MARGIN_M, xs.max() + ROAD_MARGIN_M
    x = np.linspace(lo, hi, int(np.ceil((hi - lo) / ROAD_STEP_M)) + 1)
    return np.column_stack([x, road.height_at(x) + offset])
