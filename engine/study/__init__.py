"""Studies over designs and roads: the paper's road presets, sweep grids, robust scores.

- :mod:`engine.study.presets`: the 23 roads of the paper with their reference optima.
- :mod:`engine.study.sweep`: Table 9 and user design grids, sweep plans.
- :mod:`engine.study.robust`: scores over several roads (beyond the paper).

See docs/optimisation.md.
"""

from engine.study.presets import PRESETS, RoadPreset, as_road, preset_group, resolve_roads, road_label
from engine.study.robust import Regret, aggregate, best_per_road, regret
from engine.study.sweep import (
    TABLE9_DEFAULT_RWS_M,
    parse_grid,
    plan_sweep,
    product_grid,
    table9_grid,
)

__all__ = [
    "PRESETS",
    "Regret",
    "RoadPreset",
    "TABLE9_DEFAULT_RWS_M",
    "aggregate",
    "as_road",
    "best_per_road",
    "parse_grid",
    "plan_sweep",
    "preset_group",
    "product_grid",
    "regret",
    "resolve_roads",
    "road_label",
    "table9_grid",
]
