"""Named indexes of the navigators' INS error states (computed minus true), as pyins names them.

The 13-state error of the INS + TERCOM EKF (seed 000 section 4.3; navigators.filters.ins_trn_ekf):

    DRN, DRE, DRD     0-2    position error north, east, down (m)
    DVN, DVE, DVD     3-5    velocity error NED (m/s)
    PSIN, PSIE, PSID  6-8    attitude error psi (rad; C_true = (I + [psi x]) C_computed)
    BAX, BAY, BAZ     9-11   accelerometer bias, body FRD (m/s^2)
    BGZ               12     z-gyro bias (rad/s)

The 15-state error of seed 002 eqs 16-22 (navigators.inertial.error_model_15) keeps its own block starts
(I_POS, I_VEL, I_ATT, I_BA, I_BG there).
"""

from __future__ import annotations

DRN, DRE, DRD = 0, 1, 2
DVN, DVE, DVD = 3, 4, 5
PSIN, PSIE, PSID = 6, 7, 8
BAX, BAY, BAZ = 9, 10, 11
BGZ = 12
N_EKF13 = 13

POS = slice(DRN, DRD + 1)
VEL = slice(DVN, DVD + 1)
ATT = slice(PSIN, PSID + 1)
ACC_BIAS = slice(BAX, BAZ + 1)
# the states a loosely coupled GNSS fix observes: north, east position and NED velocity
GNSS_STATES = (DRN, DRE, DVN, DVE, DVD)
