"""Small fixed-size algebra of the tracker's per-epoch bookkeeping as numba kernels (seed 001 navigator).

Each of these ran as a dozen numpy calls on 2- to 25-element arrays per epoch, where the Python call cost
far more than the arithmetic: the 4-state (centroid north/east m, velocity bias north/east m/s) fix update
of reference_frame "ne", the north/east velocity change of speed / track references over a transect, the
aiding corrected by the north/east bias, and the INS attitude rows of a frame. Same formulas as before;
sums run in plain order (numpy's pairwise sums may differ in the last bits).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def ne_fix_gain(X, Ro, r_n, r_e, X_out, dx_out):  # pragma: no cover - numba
    """Kalman fix of the 4-state filter with the position-only measurement H = [I2 0], R = Ro (2 x 2):
    K = X H^T (H X H^T + Ro)^-1, dx = K r, X_out = (I - K H) X (I - K H)^T + K Ro K^T (Joseph form).
    Returns False (X_out, dx_out untouched) when H X H^T + Ro is singular."""
    a = X[0, 0] + Ro[0, 0]
    b = X[0, 1] + Ro[0, 1]
    c = X[1, 0] + Ro[1, 0]
    d = X[1, 1] + Ro[1, 1]
    det = a * d - b * c
    if det == 0.0:
        return False
    i00, i01, i10, i11 = d / det, -b / det, -c / det, a / det
    K = np.empty((4, 2))
    for i in range(4):
        K[i, 0] = X[i, 0] * i00 + X[i, 1] * i10
        K[i, 1] = X[i, 0] * i01 + X[i, 1] * i11
        dx_out[i] = K[i, 0] * r_n + K[i, 1] * r_e
    IK = np.eye(4)
    for i in range(4):
        IK[i, 0] -= K[i, 0]
        IK[i, 1] -= K[i, 1]
    A = np.zeros((4, 4))  # IK X
    for i in range(4):
        for j in range(4):
            s = 0.0
            for k in range(4):
                s += IK[i, k] * X[k, j]
            A[i, j] = s
    KR = np.empty((4, 2))
    for i in range(4):
        KR[i, 0] = K[i, 0] * Ro[0, 0] + K[i, 1] * Ro[1, 0]
        KR[i, 1] = K[i, 0] * Ro[0, 1] + K[i, 1] * Ro[1, 1]
    for i in range(4):
        for j in range(4):
            s = 0.0
            for k in range(4):
                s += A[i, k] * IK[j, k]
            X_out[i, j] = s + KR[i, 0] * K[j, 0] + KR[i, 1] * K[j, 1]
    return True


@njit(cache=True)
def ne_predict(X, T, walk_m2, bias_walk_m2ps2):  # pragma: no cover - numba
    """One sample (T s) of the 4-state filter's prediction in place: X <- F X F^T + Q with F = [[I, T I],
    [0, I]] (the centroid moves on the velocity bias), Q = diag(walk, walk, bias walk, bias walk); the rows,
    then the columns, as the numpy slices X[:2] += T X[2:], X[:, :2] += T X[:, 2:] did."""
    for i in range(2):
        for j in range(4):
            X[i, j] += T * X[i + 2, j]
    for i in range(4):
        for j in range(2):
            X[i, j] += T * X[i, j + 2]
    X[0, 0] += walk_m2
    X[1, 1] += walk_m2
    X[2, 2] += bias_walk_m2ps2
    X[3, 3] += bias_walk_m2ps2


@njit(cache=True)
def ne_change(b_v, b_psi, m_v, m_psi):  # pragma: no cover - numba
    """(north, east) mean over the samples of (m_v + b_v) u(m_psi + b_psi) - m_v u(m_psi) (m/s)."""
    sn = 0.0
    se = 0.0
    n = m_v.size
    for i in range(n):
        v, p = m_v[i], m_psi[i]
        sn += (v + b_v) * math.cos(p + b_psi) - v * math.cos(p)
        se += (v + b_v) * math.sin(p + b_psi) - v * math.sin(p)
    return sn / n, se / n


@njit(cache=True)
def corrected_aiding(m_v, m_psi, e_n, e_e, v_out, psi_out):  # pragma: no cover - numba
    """The aiding (speed m/s, track rad) of each sample with the north/east bias (e_n, e_e) m/s added."""
    for i in range(m_v.size):
        vn = m_v[i] * math.cos(m_psi[i]) + e_n
        ve = m_v[i] * math.sin(m_psi[i]) + e_e
        v_out[i] = math.hypot(vn, ve)
        psi_out[i] = math.atan2(ve, vn)


@njit(cache=True)
def ins_rows(hist, step, out):  # pragma: no cover - numba
    """Every step-th row of a strapdown history (lat, lon, h, v_ned, q_bn [w, x, y, z], ...) as (v_n, v_e,
    roll, pitch, yaw) rad in out[k, :5] and out[k, 5] = 1 when the row is finite (roll / pitch NaN when not):
    strapdown.euler_from_C_bn of quat_to_dcm, the rows of C_bn it needs only. Returns the row count."""
    m = 0
    for r in range(0, hist.shape[0], step):
        ok = True
        for j in range(hist.shape[1]):
            if not math.isfinite(hist[r, j]):
                ok = False
                break
        w, x, y, z = hist[r, 6], hist[r, 7], hist[r, 8], hist[r, 9]
        c20 = 2.0 * (x * z - w * y)
        c21 = 2.0 * (y * z + w * x)
        c22 = w * w - x * x - y * y + z * z
        out[m, 0] = hist[r, 3]
        out[m, 1] = hist[r, 4]
        if ok:
            out[m, 2] = math.atan2(c21, c22)
            out[m, 3] = -math.asin(min(max(c20, -1.0), 1.0))
        else:
            out[m, 2] = math.nan
            out[m, 3] = math.nan
        out[m, 4] = math.atan2(2.0 * (x * y + w * z), w * w + x * x - y * y - z * z)
        out[m, 5] = 1.0 if ok else 0.0
        m += 1
    return m
