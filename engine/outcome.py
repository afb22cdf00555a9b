"""What both solvers report: the codes of a run and the columns of its time series."""

from __future__ import annotations

# Codes of a run (0 = ok); engine.simulation turns the failures into reasons. PAUSED: the compiled
# loop did its share of steps and returns its whole state; called again it continues exactly.
OK, NONFINITE, RESIDUAL, CORRECTOR, REAR_AIRBORNE, FRONT_AIRBORNE, PAUSED = 0, 1, 2, 3, 4, 5, 6

# Columns of the time series (engine.simulation names them).
SERIES_COLUMNS = ("t", "x1", "theta", "chain_tension", "fz_rear", "fz_front", "kappa",
                  "fx", "effective_radius", "wheel_speed", "sprocket_speed", "taut_length",
                  "tyre_u", "sigma", "residual")
N_SERIES = len(SERIES_COLUMNS)
