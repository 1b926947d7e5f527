"""Numba kernels of the INS/TRN error-state filter's per-tick work (navigators.filters.ins_trn_ekf).

- `predict_covariance`: the 13-state psi-angle error model's covariance propagation over all the EKF
  steps of one segment in one call (F at each step, Phi = I + F dt + (F dt)^2 / 2, P = Phi P Phi^T + Q -
  the same algebra as filterpy's KalmanFilter.predict with our Phi and Q);
- `is_positive_definite`: Cholesky test of the symmetrised matrix (what numpy.linalg.cholesky accepts);
- `collect_ira`: the IRA samples of one segment turned into TERCOM batch rows (INS state at each sample,
  baro reference height, closest point by the "conventional" or "proposed" formula of
  navigators.measurements - seed 000 eqs 9-13 and 14-36 - and eq 2's measured terrain height).

Arrays only, no Python objects; every kernel is @njit(cache=True).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...terrain.geodesy import OMEGA_EARTH_RPS, WGS84_A_M, WGS84_E2
from ..inertial.strapdown import propagate_chunk, quat_to_dcm
from ..measurements.baro import geometric_height_kernel

N_ERR = 13
G0 = 9.80665
FORMULA_CODES = {"conventional": 0, "proposed": 1}


@njit(cache=True)
def _radii(lat, h):
    s = math.sin(lat)
    w = 1.0 - WGS84_E2 * s * s
    rn = WGS84_A_M * (1.0 - WGS84_E2) / (w * math.sqrt(w)) + h
    re = WGS84_A_M / math.sqrt(w) + h
    return rn, re


@njit(cache=True)
def interp_one(x, xp, fp):
    """np.interp(x, xp, fp) for one float x and increasing xp (numpy's formula and edge rules, so the same
    bits); numba's generic np.interp costs several seconds of compile time that this does not."""
    n = xp.shape[0]
    if x != x:
        return np.nan
    if x <= xp[0]:
        return fp[0]
    if x >= xp[n - 1]:
        return fp[n - 1]
    j = np.searchsorted(xp, x, side="right") - 1
    if xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    r = slope * (x - xp[j]) + fp[j]
    if r != r:
        r = slope * (x - xp[j + 1]) + fp[j + 1]
        if r != r and fp[j] == fp[j + 1]:
            r = fp[j]
    return r


@njit(cache=True, forceinline=True)
def _history_row(t_imu, hist, t):
    """(k, finite): the INS history row of the IMU sample at searchsorted(t_imu, t) (clipped to the last)
    and whether its 10 values are finite."""
    n = t_imu.shape[0]
    k = np.searchsorted(t_imu, t)
    if k > n - 1:
        k = n - 1
    ok = True
    for j in range(10):
        if not np.isfinite(hist[k, j]):
            ok = False
    return k, ok


@njit(cache=True)
def _set_skew(F, r0, c0, v0, v1, v2, sign):
    F[r0, c0] = 0.0
    F[r0, c0 + 1] = -sign * v2
    F[r0, c0 + 2] = sign * v1
    F[r0 + 1, c0] = sign * v2
    F[r0 + 1, c0 + 1] = 0.0
    F[r0 + 1, c0 + 2] = -sign * v0
    F[r0 + 2, c0] = -sign * v1
    F[r0 + 2, c0 + 1] = sign * v0
    F[r0 + 2, c0 + 2] = 0.0


@njit(cache=True, forceinline=True)
def sparse_left_matmul(A, B, out):
    """out = A B (square), summing over the nonzero entries of A only (the error model's F and Phi are
    sparse); the same order of operations as the dense product's row-wise axpy."""
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.0
        for m in range(n):
            aim = A[i, m]
            if aim != 0.0:
                for j in range(n):
                    out[i, j] += aim * B[m, j]


@njit(cache=True)
def predict_covariance(P, Q, t_imu, f_b, hist, ins_state, last_f_b, accel_bias_b, t_ekf0, dt, n_steps, tau):
    """Propagate P (13, 13, in place) over n_steps EKF steps of dt seconds after t_ekf0 along the INS history.

    Step s uses the IMU sample at searchsorted(t_imu, t_ekf0 + s dt) (clipped) and its INS state row of
    `hist` (ins_state if that row is not finite), the specific force f_b minus the accelerometer bias
    estimate (last_f_b if the sample is not finite). Error model in ins_trn_ekf's docstring.
    """
    F = np.zeros((N_ERR, N_ERR))
    F[0, 3] = 1.0
    F[1, 4] = 1.0
    F[2, 5] = 1.0
    F[2, 2] = -3.0 / tau  # baro loop on the vertical channel (navigators.inertial.strapdown)
    Phi = np.empty((N_ERR, N_ERR))
    T = np.empty((N_ERR, N_ERR))
    U = np.empty((N_ERR, N_ERR))
    st = np.empty(10)
    fb = np.empty(3)
    for s in range(1, n_steps + 1):
        k, ok = _history_row(t_imu, hist, t_ekf0 + dt * s)
        for j in range(10):
            st[j] = hist[k, j] if ok else ins_state[j]
        okf = np.isfinite(f_b[k, 0]) and np.isfinite(f_b[k, 1]) and np.isfinite(f_b[k, 2])
        for j in range(3):
            fb[j] = (f_b[k, j] if okf else last_f_b[j]) - accel_bias_b[j]
        lat, h, vn, ve = st[0], st[2], st[3], st[4]
        C = quat_to_dcm(st[6:10])
        fn0 = C[0, 0] * fb[0] + C[0, 1] * fb[1] + C[0, 2] * fb[2]
        fn1 = C[1, 0] * fb[0] + C[1, 1] * fb[1] + C[1, 2] * fb[2]
        fn2 = C[2, 0] * fb[0] + C[2, 1] * fb[1] + C[2, 2] * fb[2]
        rn, re = _radii(lat, h)
        wie0 = OMEGA_EARTH_RPS * math.cos(lat)
        wie2 = -OMEGA_EARTH_RPS * math.sin(lat)
        wen0 = ve / re
        wen1 = -vn / rn
        wen2 = -ve * math.tan(lat) / re
        g_over_r = G0 / math.sqrt(rn * re)
        F[3, 0] = -g_over_r
        F[4, 1] = -g_over_r
        F[5, 2] = 2.0 * g_over_r - 3.0 / tau**2
        # np.int64: bare integer constants are numba literal types, one specialisation per value
        _set_skew(F, np.int64(3), np.int64(3), 2.0 * wie0 + wen0, wen1, 2.0 * wie2 + wen2, -1.0)
        _set_skew(F, np.int64(3), np.int64(6), fn0, fn1, fn2, 1.0)
        _set_skew(F, np.int64(6), np.int64(6), wie0 + wen0, wen1, wie2 + wen2, -1.0)
        for i in range(3):
            for j in range(3):
                F[3 + i, 9 + j] = C[i, j]
            F[6 + i, 12] = -C[i, 2]
        # Phi = I + F dt + (F dt)^2 / 2 (row-wise axpy over the nonzeros of F: F is sparse)
        sparse_left_matmul(F, F, T)
        for i in range(N_ERR):
            for j in range(N_ERR):
                Phi[i, j] = F[i, j] * dt + 0.5 * T[i, j] * dt * dt
            Phi[i, i] += 1.0
        # P = Phi P Phi^T + Q = Phi (Phi P)^T + Q (P symmetric), both products over the nonzeros of Phi
        sparse_left_matmul(Phi, P, T)
        for i in range(N_ERR):
            for j in range(N_ERR):
                U[i, j] = Q[i, j]
            for m in range(N_ERR):
                pim = Phi[i, m]
                if pim != 0.0:
                    for j in range(N_ERR):
                        U[i, j] += pim * T[j, m]
        for i in range(N_ERR):
            for j in range(N_ERR):
                P[i, j] = 0.5 * (U[i, j] + U[j, i])


@njit(cache=True)
def is_positive_definite(P):
    """True if P is finite and its symmetric part has a Cholesky factor (all pivots > 0)."""
    n = P.shape[0]
    L = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            if not np.isfinite(P[i, j]):
                return False
    for j in range(n):
        d = 0.5 * (P[j, j] + P[j, j])
        for m in range(j):
            d -= L[j, m] * L[j, m]
        if not d > 0.0:
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            a = 0.5 * (P[i, j] + P[j, i])
            for m in range(j):
                a -= L[i, m] * L[j, m]
            L[i, j] = a / L[j, j]
    return True


@njit(cache=True)
def _wrap(x):
    return math.atan2(math.sin(x), math.cos(x))


@njit(cache=True)
def closest_point_one(R, theta, v0, v1, v2, C, formula, out):
    """p (NED, m) from the antenna to the IRA closest point for one sample (navigators.measurements:
    formula 0 = conventional, seed 000 eqs 9-13; 1 = proposed, eqs 14-36). NaN when no solution."""
    alpha = math.atan2(-v2, math.hypot(v0, v1))  # eq 9
    beta = math.atan2(v1, v0)  # eq 10 (atan2 form)
    sa, ca, sb, cb = math.sin(alpha), math.cos(alpha), math.sin(beta), math.cos(beta)
    s1n, s1e, s1d = sa * cb, sa * sb, ca  # eq 12 (NED)
    s2n, s2e = -sb, cb
    roll = math.atan2(C[2, 1], C[2, 2])
    ref = theta - roll  # conventional angle (project signs)
    if formula == 0:
        xi = ref
    else:
        t1 = C[0, 1] * s1n + C[1, 1] * s1e + C[2, 1] * s1d  # eq 31
        t2 = C[0, 1] * s2n + C[1, 1] * s2e
        rho = math.hypot(t1, t2)
        ratio = math.sin(theta) / rho if rho > 0.0 else np.nan  # eq 32
        if not (np.isfinite(ratio) and abs(ratio) <= 1.0):
            out[0] = np.nan
            out[1] = np.nan
            out[2] = np.nan
            return False
        asn = math.asin(ratio)  # eq 34
        eta = math.atan2(t1, t2)  # eq 33
        xi_a = asn - eta  # eq 35
        xi_b = math.pi - asn - eta
        xi = xi_a if abs(_wrap(xi_a - ref)) <= abs(_wrap(xi_b - ref)) else xi_b
        xi = _wrap(xi)
    c = math.cos(xi)
    s = math.sin(xi)
    out[0] = R * (c * s1n + s * s2n)  # eq 36 / 13
    out[1] = R * (c * s1e + s * s2e)
    out[2] = R * (c * s1d)
    return True


@njit(cache=True)
def collect_ira(t0, t1, t_imu, hist, ira, decimation, baro_ref, formula, out):
    """TERCOM batch rows of the IRA samples with t0 <= t <= t1 (every `decimation`-th of them).

    Records (numba tuples): ira = (ts, rng_m, theta, valid) the IRA samples; baro_ref = (tb, hb, have_baro,
    geopotential, lag_s): valid baro times and heights (interpolated at the sample times when have_baro, else
    the INS height is the reference), geopotential: convert the baro height to geometric (US 1976 r0), lag_s:
    the barometer's first-order lag (s), compensated with the INS's vertical velocity (a lagged reading
    trails the height by lag x dh/dt: h_ref = baro - lag_s x v_down).
    out (>= n samples, 6): t, INS lat, INS lon, h_meas = h_ref - |p_d| (seed 000 eq 2), p_n, p_e.
    Returns (rows written, samples without a valid return, rows with no closest-point solution).
    """
    ts, rng_m, theta, valid = ira
    tb, hb, have_baro, geopotential, lag_s = baro_ref
    m = 0
    n_bad = 0
    n_nan = 0
    sel_count = 0
    p = np.empty(3)
    for i in range(ts.shape[0]):
        t = ts[i]
        if not (t >= t0 and t <= t1):
            continue
        if sel_count % decimation != 0:
            sel_count += 1
            continue
        sel_count += 1
        R = rng_m[i]
        th = theta[i]
        if not (valid[i] and np.isfinite(R) and np.isfinite(th) and R > 0.0):
            n_bad += 1
            continue
        k, good = _history_row(t_imu, hist, t)
        if not good:
            continue
        if have_baro:
            h_ref = interp_one(t, tb, hb)
            if geopotential:
                h_ref = geometric_height_kernel(h_ref)
            h_ref -= lag_s * hist[k, 5]
        else:
            h_ref = hist[k, 2]
        C = quat_to_dcm(hist[k, 6:10])
        if not closest_point_one(R, th, hist[k, 3], hist[k, 4], hist[k, 5], C, formula, p):
            n_nan += 1
        out[m, 0] = t
        out[m, 1] = hist[k, 0]
        out[m, 2] = hist[k, 1]
        out[m, 3] = h_ref - abs(p[2])
        out[m, 4] = p[0]
        out[m, 5] = p[1]
        m += 1
    return m, n_bad, n_nan


@njit(cache=True)
def euler_from_quat(q):
    """3-2-1 Euler angles (roll, pitch, yaw; rad) of the body -> NED quaternion q."""
    C = quat_to_dcm(q)
    c20 = min(max(C[2, 0], -1.0), 1.0)
    return math.atan2(C[2, 1], C[2, 2]), -math.asin(c20), math.atan2(C[1, 0], C[0, 0])


@njit(cache=True)
def yaw_total_variation(hist, yaw_prev):
    """Total variation (rad) of the yaw of the INS states hist (n, 10; quaternion in columns 6-9) from
    yaw_prev (NaN: from the first row): the sum of |wrapped yaw step| between successive samples, i.e. the
    integral of |yaw rate| at the IMU's rate. Non-finite rows are skipped. Returns (total, last yaw)."""
    total = 0.0
    prev = yaw_prev
    for k in range(hist.shape[0]):
        q0, q1, q2, q3 = hist[k, 6], hist[k, 7], hist[k, 8], hist[k, 9]
        yaw = math.atan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))
        if not np.isfinite(yaw):
            continue
        if np.isfinite(prev):
            total += abs(_wrap(yaw - prev))
        prev = yaw
    return total, prev


@njit(cache=True)
def last_good_row(valid, f, out):
    """Copy into out the last row of f (n, 3) that is valid and finite; False (out untouched) if none."""
    for k in range(f.shape[0] - 1, -1, -1):
        if valid[k] and np.isfinite(f[k, 0]) and np.isfinite(f[k, 1]) and np.isfinite(f[k, 2]):
            out[0] = f[k, 0]
            out[1] = f[k, 1]
            out[2] = f[k, 2]
            return True
    return False


@njit(cache=True)
def baro_prepare(valid, h_baro_m, geopotential, usable, h_geometric):
    """usable = valid & finite height; h_geometric = geometric height of the ISA pressure altitude
    (h = r0 H / (r0 - H), US 1976 r0) if geopotential, else the height itself. Returns all(usable)."""
    all_ok = True
    for i in range(h_baro_m.shape[0]):
        hb = h_baro_m[i]
        ok = valid[i] and np.isfinite(hb)
        usable[i] = ok
        all_ok = all_ok and ok
        h_geometric[i] = geometric_height_kernel(hb) if geopotential else hb
    return all_ok


@njit(cache=True)
def fused_segment(ins, imu, baro, mech, cov, ira, aiding, work):
    """One whole frame of navigators.filters.ins_trn_ekf's segment work in one call (no fix inside the frame):
    baro_prepare, ins.propagate_chunk, last_good_row, predict_covariance, is_positive_definite and (when
    collect) collect_ira - the same kernels, in the same order, as the step-by-step path.

    Records (numba tuples): ins, imu, mech as in propagate_chunk; baro = (t_baro, h_baro_raw, baro_valid)
    the frame's baro samples (ISA pressure altitude when geopotential); cov = (P, Q, last_f_b, t_ekf0,
    dt_ekf) the covariance (P in place), its process noise per EKF step, the last good specific force
    (in place), the EKF time and step; ira = (ts, rng_m, theta, valid) the IRA samples; aiding = (collect,
    decimation, formula, geopotential, baro_lag_s) (collect_ira's settings); work = (baro_usable, h_baro_geo,
    hist, rows) scratch and output arrays (hist: the INS state after each IMU sample, rows: collect_ira's).

    Returns (bad IMU samples, invalid baro samples, EKF steps, covariance PD, rows, no-returns, no-solution).
    """
    ins_state = ins[0]
    t, f_b, w_b, imu_ok = imu
    t_baro, h_baro_raw, baro_valid = baro
    accel_bias_b, _, tau_baro_s, _, _ = mech
    P, Q, last_f_b, t_ekf0, dt_ekf = cov
    collect, decimation, formula, geopotential, baro_lag_s = aiding
    baro_usable, h_baro_geo, hist, rows = work
    n_b = t_baro.shape[0]
    all_ok = baro_prepare(baro_valid, h_baro_raw, geopotential, baro_usable, h_baro_geo)
    n_baro_bad = 0
    if not all_ok:
        for i in range(n_b):
            if t_baro[i] <= t[t.shape[0] - 1] and not baro_usable[i]:
                n_baro_bad += 1
    bad = propagate_chunk(ins, imu, (t_baro, h_baro_geo, baro_usable), mech, hist)
    last_good_row(imu_ok, f_b, last_f_b)
    n_steps = int(np.floor((t[t.shape[0] - 1] - t_ekf0) / dt_ekf + 1e-9))
    pd = True
    if n_steps > 0:
        predict_covariance(P, Q, t, f_b, hist, ins_state, last_f_b, accel_bias_b, t_ekf0, dt_ekf, n_steps,
                           tau_baro_s)
        pd = is_positive_definite(P)
    m = n_ret = n_nan = 0
    if collect:
        have_baro = n_b > 0
        if all_ok:
            m, n_ret, n_nan = collect_ira(t[0], t[t.shape[0] - 1], t, hist, ira, decimation,
                                          (t_baro, h_baro_raw, have_baro, geopotential, baro_lag_s), formula,
                                          rows)
        else:
            k = 0
            tb = np.empty(n_b)
            hb = np.empty(n_b)
            for i in range(n_b):
                if baro_usable[i]:
                    tb[k] = t_baro[i]
                    hb[k] = h_baro_raw[i]
                    k += 1
            m, n_ret, n_nan = collect_ira(t[0], t[t.shape[0] - 1], t, hist, ira, decimation,
                                          (tb[:k], hb[:k], k > 0, geopotential, baro_lag_s), formula, rows)
    return bad, n_baro_bad, n_steps, pd, m, n_ret, n_nan
