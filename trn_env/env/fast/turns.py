"""The fast tier's turns: the tilt the gyros' misalignment and scale factors build (truth), and the full
navigator's turn term in the fast filter's covariance.

A coordinated turn rotates the body about the navigation frame's down axis; the gyros see that rate through
their scale factors S and misalignment M (trn_env.sensors.imu draws them per episode from the IMU grade:
gyro_scale_factor_ppm, gyro_misalignment_rad), so every turn builds an attitude error. Its horizontal part
(the tilt) turns with the heading as it is built, so a turn undone by the opposite turn undoes it and a full
circle closes it (turn_truth_step); the fast INS's acceleration error takes g0 times it
(trn_env.env.fast.navigator.ins_step).

The full navigator's filter does not carry S and M and enters them as a random walk in the angle turned
(navigators.filters.ins_trn_propagation.InsTrnPropagation._turn_noise, its variances per rad from
apply_imu_spec; ins_tercom's turn_angle "excursion": the growth of the largest net heading change since the
reset, navigators.core.imu_spec.TurnAngle); turn_noise ports it onto the fast filter's acceleration error
(the tilt's share g0^2 on P22).

Simplifications against the full navigator's 13-state filter and strapdown INS: the heading error the turns
build (the z gyro's scale factor, the bank's share of the misalignment) is left out of the truth, and the
turn term's heading share out of the filter: the full filter carries the heading and estimates it in the
turns that build it (the turn's specific force makes it observable), which the fast filter, with no heading
state, cannot, so that carried uncorrected it would act in every later turn. The accelerometers' scale
factor and misalignment are left out; the accelerometer bias and the gyro-bias tilt stay in the navigation
frame (they do not turn with the body); the bank's share k takes level pitch.
"""

from __future__ import annotations

import math

from numba import njit

from trn_env.env.fast import rng as frng
from trn_env.env.fast.navigator import G0_MPS2, NP_TURN_HEAD2, NP_TURN_TILT2
from trn_env.env.fast.state import (
    HDG_MAX,
    HDG_NET,
    MIS_XY,
    MIS_XZ,
    MIS_YZ,
    MIS_ZY,
    P22,
    SF_Y,
    SF_Z,
    TURN_PSI_E,
    TURN_PSI_N,
)


@njit(cache=True)
def turn_truth_step(X, i, dpsi, bank, psi_mid):
    """The tilt aircraft i's gyro misalignment and scale factors build (truth) over a step that turned the
    heading by dpsi (rad) in a coordinated bank `bank` (rad, level pitch) at heading psi_mid (rad, the step's
    mean).

    The body turns about the navigation frame's down axis, in the body frame d = (0, sin bank, cos bank), at
    the heading rate r: w_b = r d, and the gyros measure (I + S + M) w_b (trn_env.sensors.imu: S diagonal,
    M off-diagonal). The error e = (S + M) d per rad turned, rotated to the navigation frame
    (C_bn = R_z(psi) R_x(bank)), is the attitude error's rate, psi' = -C_bn e r; its horizontal part (the
    tilt) turns with the heading, so the tilt a turn builds is undone by the turn back and stays bounded
    on a full circle. Its down part (the heading, s_y sin^2 + s_z cos^2 + (m_yz + m_zy) sin cos per rad)
    is left out (module docstring)."""
    sb = math.sin(bank)
    cb = math.cos(bank)
    e_x = X[i, MIS_XY] * sb + X[i, MIS_XZ] * cb
    w = cb * (X[i, SF_Y] * sb + X[i, MIS_YZ] * cb) - sb * (X[i, MIS_ZY] * sb + X[i, SF_Z] * cb)
    cp = math.cos(psi_mid)
    sp = math.sin(psi_mid)
    X[i, TURN_PSI_N] -= (cp * e_x - sp * w) * dpsi
    X[i, TURN_PSI_E] -= (sp * e_x + cp * w) * dpsi


@njit(cache=True)
def turn_noise(X, i, dpsi, bank, nav):
    """The filter's turn term for aircraft i over a step that turned the heading by dpsi (rad), ending in a
    coordinated bank `bank` (rad).

    Ported from the full navigator's InsTrnPropagation._turn_noise (navigators.filters.ins_trn_propagation;
    turn_angle "excursion", ins_tercom's default; the variances per rad from its apply_imu_spec): the gyro
    misalignment m and scale factor s build, per rad of growth of the largest net heading change since the
    reset (navigators.core.imu_spec.TurnAngle), a tilt variance (m^2 + s^2 (1 - k) / 2) TURN_REFERENCE_RAD
    on each tilt axis, k = sum_i d_i^4 = cos^4 bank + sin^4 bank (d the down axis in the body frame, level
    pitch). The fast filter's acceleration error is g0 x tilt plus the accelerometer bias, so the tilt
    variance enters P22 times g0^2. The turn term's heading share ((s^2 k + m^2 (1 - k)) TURN_REFERENCE_RAD)
    is left out (module docstring)."""
    X[i, HDG_NET] += dpsi
    grow = abs(X[i, HDG_NET]) - X[i, HDG_MAX]
    if grow > 0.0:
        X[i, HDG_MAX] += grow
        c2 = math.cos(bank) ** 2
        k = c2 * c2 + (1.0 - c2) * (1.0 - c2)
        X[i, P22] += G0_MPS2 * G0_MPS2 * (nav[NP_TURN_TILT2] + 0.5 * nav[NP_TURN_HEAD2] * (1.0 - k)) * grow


@njit(cache=True)
def draw_turn_errors(X, i, state, mis_rad, sf):
    """Episode draws of aircraft i's gyro misalignment (4 entries, sigma mis_rad) and scale factors (y, z;
    sigma sf, a fraction), in this order, one normal each (trn_env.sensors.imu's draws), and the tilt they
    have built, zero."""
    drawn = (MIS_XY, MIS_XZ, MIS_YZ, MIS_ZY, SF_Y, SF_Z)
    scale = (mis_rad, mis_rad, mis_rad, mis_rad, sf, sf)
    for k in range(len(drawn)):
        X[i, drawn[k]] = scale[k] * frng.normal(state, i)
    X[i, TURN_PSI_N] = 0.0
    X[i, TURN_PSI_E] = 0.0
