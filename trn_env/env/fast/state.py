"""Column layout of the fast tier's per-aircraft state matrix X (N aircraft x N_STATE, float64).

One row per sub-env; the numba kernels index columns by these module constants (compile-time constants).
Frames: latitude/longitude in radians (WGS84 geodetic), heights in m above MSL (the DEM datum), north/east
in m in the aircraft's local level frame, angles in rad (track and heading clockwise from north).
"""

from __future__ import annotations

# truth
LAT, LON, H, PSI, BANK, VS, VS_TGT, GUST_N, GUST_E = range(9)
T, DIST_FLOWN = 9, 10
# inertial error sources (truth, per episode): accelerometer bias, tilt rate, initial tilt (north, east)
BA_N, BA_E, BG_N, BG_E, TILT_N, TILT_E = range(11, 17)
# navigation error (estimate minus truth): position (m), velocity (m/s), the filter's acceleration
# compensation (m/s^2, fed back), baro height error (m)
EP_N, EP_E, EV_N, EV_E, CA_N, CA_E, BARO = range(17, 24)
# the filter's covariance over (position, velocity, acceleration error), the same for north and east
P00, P01, P02, P11, P12, P22 = range(24, 30)
# commands (guidance targets)
TRK_CMD, AGL_CMD, OFFSET_FRAC = range(30, 33)
# navigator bookkeeping
T_LAST_FIX, N_PROF, REJECTS, N_FIXES, NEXT_SAMPLE_T = range(33, 38)
# episode
GOAL_LAT, GOAL_LON, D_EST_START, END, START_LAT, START_LON = range(38, 44)
# heading error (truth, rad) at the start and its drift rate (the z gyro's bias, rad/s)
YAW0, BG_Z = 44, 45
# bias instabilities (truth, first-order Gauss-Markov): accelerometer (m/s^2), gyro (rad/s) and the tilt it
# has integrated (rad), north and east
BI_A_N, BI_A_E, BI_G_N, BI_G_E, TILT_GM_N, TILT_GM_E = range(46, 52)
# the innovation test (navigators.integrity.innovation_monitor): the last NIS values (a ring of up to
# MAX_WINDOW), how many were added this episode, and whether the test is out of band ("degraded")
MAX_WINDOW = 8
NIS0 = 52
N_NIS, DEGRADED = 60, 61
# the true airspeed's departure from the held one (m/s): the speed traded against the vertical speed
# (envelope.KINGAIR_ENVELOPE.tas_per_vs), lagged
DTAS = 62
# the true airspeed's slow wander (m/s, first-order Gauss-Markov: envelope.KINGAIR_ENVELOPE.tas_wander_mps)
TAS_WANDER = 63
# the filter's turn term (navigator.turn_noise): the net heading change since the reset and its largest
# excursion (rad)
HDG_NET, HDG_MAX = 64, 65
# the gyros' misalignment (rad: the x gyro's to y and z, the y gyro's to z, the z gyro's to y) and scale
# factors (y, z; per episode, truth) and the tilt (psi, rad, north and east) they have built in the turns
# (navigator.turn_truth_step)
MIS_XY, MIS_XZ, MIS_YZ, MIS_ZY, SF_Y, SF_Z, TURN_PSI_N, TURN_PSI_E = range(66, 74)
N_STATE = 74

# END codes (0 = running); names in END_NAMES
END_NAMES = ("", "arrived", "terrain_collision", "off_map", "time_limit", "goal", "diverged")
ARRIVED, COLLISION, OFF_MAP, TIME_LIMIT, GOAL, DIVERGED = 1, 2, 3, 4, 5, 6
