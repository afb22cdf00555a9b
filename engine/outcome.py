"""What both solvers report: failure codes of a run and the columns of its time series."""

from __future__ import annotations

# Failure codes of a run (0 = ok); engine.simulation turns them into reasons.
OK, NONFINITE, RESIDUAL, CORRECTOR, REAR_AIRBORNE, FRONT_AIRBORNE = 0, 1, 2, 3, 4, 5

# Columns of the time series (engine.simulation names them).
SERIES_COLUMNS = ("t", "x1", "theta", "chain_tension", "fz_rear", "fz_front", "kappa",
                  "fx", "effective_radius", "wheel_speed", "sprocket_speed", "taut_length",
                  "tyre_u", "sigma", "residual")
N_SERIES = len(SERIES_COLUMNS)
