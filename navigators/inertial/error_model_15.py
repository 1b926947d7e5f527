"""The 15-state INS error model of seed 002 (eqs 16-22, after Titterton & Weston ch. 12), discretised.

State (seed 002 eq 17), computed minus true:

    0-2    dL, dlambda (rad), dh (m, up)           position error
    3-5    dv_n, dv_e, dv_d (m/s)                  velocity error
    6-8    eps_n, eps_e, eps_d (rad)               attitude error, C_computed = (I - [eps x]) C_true
                                                   (StrapdownIns.correct's convention)
    9-11   df_x, df_y, df_z (m/s^2, body)          accelerometer bias error = estimated - true bias
    12-14  dw_x, dw_y, dw_z (rad/s, body)          gyro bias error = estimated - true bias

With those signs the bias columns of eq 18 (-C_bn on the velocity row, +C_bn on the attitude row) follow:
an INS that subtracts an estimated bias b_est from the samples sees a residual sensor error b - b_est =
-(df, dw); velocity error grows as C_bn (b - b_est), the psi-angle error as -C_bn (gyro error).

Departure: eq 20 as printed has no gravity-gradient term; Titterton's model (seed 002 ref [5]) has
d(dv_d)/dt = ... - 2 g / (r + h) dh (gravity falls with height), which makes the free vertical channel
unstable with time constant sqrt((r + h) / 2 g) ~ 9.5 min. Eq 21's A_ev[2, 1] is printed +tan(L)/(r+h);
the sign is corrected (see system_matrix). The mechanisation in
navigators.inertial.strapdown has it, so `gravity_gradient=True` (default) adds it; False is eq 20 as printed.

Discretisation: Phi = I + A dt + (A dt)^2 / 2 over each INS step (50 Hz, seed 002 Table 1), multiplied up to
the filter's update interval by `transition_over_history` (numba, along the INS state history).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...terrain.geodesy import OMEGA_EARTH_RPS, WGS84_A_M, WGS84_E2
from .strapdown import gravity_ned, quat_to_dcm

N_ERR15 = 15
I_POS, I_VEL, I_ATT, I_BA, I_BG = 0, 3, 6, 9, 12


@njit(cache=True)
def _skew_into(A, r0, c0, w0, w1, w2, sign):
    A[r0 + 0, c0 + 1] = -sign * w2
    A[r0 + 0, c0 + 2] = sign * w1
    A[r0 + 1, c0 + 0] = sign * w2
    A[r0 + 1, c0 + 2] = -sign * w0
    A[r0 + 2, c0 + 0] = -sign * w1
    A[r0 + 2, c0 + 1] = sign * w0


@njit(cache=True)
def system_matrix(lat, h, v_ned, f_ned, C_bn, gravity_gradient):
    """A(t) of seed 002 eq 18 (15 x 15) at geodetic latitude lat (rad), height h (m), velocity v_ned (m/s),
    specific force in NED f_ned (m/s^2), attitude C_bn. r_L + h uses the mean radius sqrt(M N) as eqs 19-21
    write one radius r_L."""
    A = np.zeros((15, 15))
    sl = np.sin(lat)
    cl = np.cos(lat)
    tl = sl / cl
    w = 1.0 - WGS84_E2 * sl * sl
    r_m = WGS84_A_M * (1.0 - WGS84_E2) / (w * np.sqrt(w))
    r_n = WGS84_A_M / np.sqrt(w)
    r = np.sqrt(r_m * r_n) + h
    r2 = r * r
    vn, ve, vd = v_ned[0], v_ned[1], v_ned[2]
    wie = OMEGA_EARTH_RPS
    # eq 19: A_rr, A_rv
    A[0, 2] = -vn / r2
    A[1, 0] = ve * sl / (r * cl * cl)
    A[1, 2] = -ve / (r2 * cl)
    A[0, 3] = 1.0 / r
    A[1, 4] = 1.0 / (r * cl)
    A[2, 5] = -1.0
    # eq 20: A_vr
    A[3, 0] = -2.0 * ve * wie * cl - ve * ve / (r * cl * cl)
    A[3, 2] = -vn * vd / r2 + ve * ve * tl * tl / r2
    A[4, 0] = 2.0 * wie * (vn * cl - vd * sl) + ve * vn / (r * cl * cl)
    A[4, 2] = -ve * vd / r2 - vn * ve * tl * tl / r2
    A[5, 0] = 2.0 * ve * wie * sl
    A[5, 2] = (ve * ve + vn * vn) / r2
    if gravity_gradient:  # Titterton's -2g/(r+h) dh (see the module docstring); h up, v_d down
        g = gravity_ned(lat, h, 1)
        A[5, 2] -= 2.0 * g[2] / r
    # eq 20: A_vv
    A[3, 3] = vd / r
    A[3, 4] = -2.0 * wie * sl - 2.0 * ve * tl / r
    A[3, 5] = vn / r
    A[4, 3] = 2.0 * wie * sl + ve * tl / r
    A[4, 4] = (vd + vn * tl) / r
    A[4, 5] = 2.0 * wie * cl + ve / r
    A[5, 3] = -2.0 * vn / r
    A[5, 4] = -2.0 * wie * cl - 2.0 * ve / r
    # eq 21: A_ve = [f^n x]
    _skew_into(A, 3, 6, f_ned[0], f_ned[1], f_ned[2], 1.0)
    # eq 21: A_er, A_ev
    A[6, 0] = -wie * sl
    A[6, 2] = -ve / r2
    A[7, 2] = vn / r2
    A[8, 0] = -wie * cl - ve / (r * cl * cl)
    A[8, 2] = ve * tl / r2
    A[6, 4] = 1.0 / r
    A[7, 3] = -1.0 / r
    # eq 21 prints +tan(L)/(r+h); the transport rate's down component is -v_e tan(L)/(r+h), so its
    # sensitivity to dv_e is negative (two INS runs agree: tests/test_error_model_15.py)
    A[8, 4] = -tl / r
    # eq 21: A_ee = -[w_in^n x], w_in = w_ie + w_en
    w_n = wie * cl + ve / r
    w_e = -vn / r
    w_d = -wie * sl - ve * tl / r
    _skew_into(A, 6, 6, w_n, w_e, w_d, -1.0)
    # eq 18: bias columns -C_bn (velocity), +C_bn (attitude)
    for i in range(3):
        for j in range(3):
            A[3 + i, 9 + j] = -C_bn[i, j]
            A[6 + i, 12 + j] = C_bn[i, j]
    return A


@njit(cache=True)
def noise_input_matrix(C_bn):
    """B of seed 002 eq 22 (15 x 6): accelerometer noise into velocity (C_bn), gyro noise into attitude
    (-C_bn)."""
    B = np.zeros((15, 6))
    for i in range(3):
        for j in range(3):
            B[3 + i, j] = C_bn[i, j]
            B[6 + i, 3 + j] = -C_bn[i, j]
    return B


@njit(cache=True)
def step_transition(A, dt):
    """Phi = I + A dt + (A dt)^2 / 2 (second-order discretisation of eq 16 over one INS step)."""
    Ad = A * dt
    Phi = np.eye(15) + Ad + 0.5 * (Ad @ Ad)
    return Phi


@njit(cache=True)
def transition_over_history(hist, f_b, accel_bias_b, i0, i1, dt_step, gravity_gradient):
    """Product of the per-step transitions along an INS history (rows i0..i1-1 of hist (n, 10) = lat, lon,
    h, v_ned, q_bn after each IMU sample, f_b (n, 3) the specific-force samples): Phi over the interval.
    dt_step <= 0: use the time differences of consecutive rows (hist has no time; caller passes dt)."""
    Phi = np.eye(15)
    for k in range(i0, i1):
        C = quat_to_dcm(hist[k, 6:10])
        fb = f_b[k] - accel_bias_b
        f_n = C @ fb
        A = system_matrix(hist[k, 0], hist[k, 2], hist[k, 3:6], f_n, C, gravity_gradient)
        Phi = step_transition(A, dt_step) @ Phi
    return Phi


def discretise(A: np.ndarray, B: np.ndarray, q_psd: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, Q_d) of eq 16 over dt_s by Van Loan's method (matrix exponential; scipy), for white noise w of
    power spectral density diag(q_psd) (6,: accelerometer (m/s^2)^2/Hz, gyro (rad/s)^2/Hz)."""
    from scipy.linalg import expm

    n = A.shape[0]
    G = B @ np.diag(np.asarray(q_psd, float)) @ B.T
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = G
    M[n:, n:] = A.T
    E = expm(M * dt_s)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    return Phi, 0.5 * (Qd + Qd.T)


__all__ = ["I_ATT", "I_BA", "I_BG", "I_POS", "I_VEL", "N_ERR15", "discretise", "noise_input_matrix",
           "step_transition", "system_matrix", "transition_over_history"]
