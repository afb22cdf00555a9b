"""What both solvers report: the codes of a run and the columns of its time series."""

from __future__ import annotations

# Codes of a run (0 = ok); engine.simulation turns the failures into reasons. PAUSED: the compiled
# loop did its share of steps and returns its whole state; called again it continues exactly.
OK, NONFINITE, RESIDUAL, CORRECTOR, REAR_AIRBORNE, FRONT_AIRBORNE, PAUSED = 0, 1, 2, 3, 4, 5, 6

# Columns of the time series, unit in the name (engine.simulation turns x1_m into distance_m and
# theta_rad into pitch_deg; docs/fields.md).
SERIES_COLUMNS = ("t_s", "x1_m", "theta_rad", "chain_tension_n", "fz_rear_n", "fz_front_n", "kappa",
                  "fx_n", "effective_radius_m", "wheel_speed_rad_s", "sprocket_speed_rad_s", "taut_length_m",
                  "tyre_u_m", "sigma_m", "residual_m", "drive_torque_nm")
N_SERIES = len(SERIES_COLUMNS)
