"""Layout of the packed parameter vector P read by the compiled model.

P[NAME] is the value of the vehicle parameter NAME (see engine/data/vehicle.json for units and
sources), then the design (a2, L2, R_WS, R_ES, chain length L of eq. 69) and the augmented
Lagrangian constants (alpha, xi, omega of eqs. 57-58). Generated once; keep in this order.
"""

from __future__ import annotations

L3 = 0
A3 = 1
L4 = 2
A4 = 3
L5 = 4
A5 = 5
L7 = 6
L_SA = 7
THETA0 = 8
PHI0 = 9
RT0 = 10
FT0 = 11
L8 = 12
K_RS = 13
C_RS = 14
S_RS = 15
K_FS = 16
C_FS = 17
S_FS = 18
K_RT = 19
C_RT = 20
K_FT = 21
C_FT = 22
M_CHASSIS = 23
I_CHASSIS = 24
M_SWINGARM = 25
I_SWINGARM = 26
M_SPROCKET = 27
I_SPROCKET = 28
M_REAR_WHEEL = 29
I_REAR_WHEEL = 30
M_FORK = 31
I_FORK = 32
M_FRONT_WHEEL = 33
SWINGARM_COG_FRACTION = 34
FORK_COG_FRACTION = 35
CHASSIS_COG_X = 36
CHASSIS_COG_Y = 37
PCX1 = 38
PDX1 = 39
PDX2 = 40
PEX1 = 41
PEX2 = 42
PEX3 = 43
PEX4 = 44
PKX1 = 45
PKX2 = 46
PKX3 = 47
FZ0 = 48
K_VLOW0 = 49
SIGMA_K0 = 50
SIGMA_MIN = 51
EPS_F = 52
V_LOW = 53
TORQUE = 54
SPROCKET_RATIO = 55
GRAVITY = 56
EPS1 = 57
EPS2 = 58
SR_OPTIMUM = 59
FLOOR = 60
SQUAT_K = 61
A2 = 62
L2 = 63
R_WS = 64
R_ES = 65
L_CHAIN = 66
AL_ALPHA = 67
AL_XI = 68
AL_OMEGA = 69

VEHICLE_KEYS: tuple[str, ...] = ('L3', 'a3', 'L4', 'a4', 'L5', 'a5', 'L7', 'L_SA', 'theta0', 'phi0', 'rt0', 'ft0', 'L8', 'k_rs', 'c_rs', 's_rs', 'k_fs', 'c_fs', 's_fs', 'k_rt', 'c_rt', 'k_ft', 'c_ft', 'm_chassis', 'I_chassis', 'm_swingarm', 'I_swingarm', 'm_sprocket', 'I_sprocket', 'm_rear_wheel', 'I_rear_wheel', 'm_fork', 'I_fork', 'm_front_wheel', 'swingarm_cog_fraction', 'fork_cog_fraction', 'chassis_cog_x', 'chassis_cog_y', 'pCx1', 'pDx1', 'pDx2', 'pEx1', 'pEx2', 'pEx3', 'pEx4', 'pKx1', 'pKx2', 'pKx3', 'Fz0', 'K_vlow0', 'sigma_k0', 'sigma_min', 'eps_F', 'V_low', 'torque', 'sprocket_ratio', 'gravity', 'eps1', 'eps2', 'sr_optimum', 'floor', 'squat_K')
N_VEHICLE = 62
N_PARAMS = 70
