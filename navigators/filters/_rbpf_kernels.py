"""Numba kernels of the RBPF (navigators.filters.rbpf): the marginalized particle filter's per-particle
algebra over arrays (seed 002 eqs 5-15; Schoen, Gustafsson & Nordlund 2005, seed 002 ref [3]).

Shapes: xn (N, 3) nonlinear state (position error, m: north, east, up), xl (N, 12) each particle's Kalman
mean (dv_ned, eps_ned, accelerometer bias error, gyro bias error), P (N, 12, 12) its covariance,
logw (N,) log weights. Phi (15, 15) the error model's transition over the update interval in these units.
"""

from __future__ import annotations

import numpy as np
from numba import njit

NL = 12


@njit(cache=True)
def _chol3(A, L):
    """Cholesky of a 3 x 3 SPD matrix into L (lower); False if not positive definite."""
    a00 = A[0, 0]
    if not a00 > 0.0:
        return False
    L[0, 0] = np.sqrt(a00)
    L[1, 0] = A[1, 0] / L[0, 0]
    L[2, 0] = A[2, 0] / L[0, 0]
    d1 = A[1, 1] - L[1, 0] * L[1, 0]
    if not d1 > 0.0:
        return False
    L[1, 1] = np.sqrt(d1)
    L[2, 1] = (A[2, 1] - L[2, 0] * L[1, 0]) / L[1, 1]
    d2 = A[2, 2] - L[2, 0] * L[2, 0] - L[2, 1] * L[2, 1]
    if not d2 > 0.0:
        return False
    L[2, 2] = np.sqrt(d2)
    L[0, 1] = L[0, 2] = L[1, 2] = 0.0
    return True


@njit(cache=True)
def _inv3(A, out):
    a, b, c = A[0, 0], A[0, 1], A[0, 2]
    d, e, f = A[1, 0], A[1, 1], A[1, 2]
    g, h, i = A[2, 0], A[2, 1], A[2, 2]
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if not (det != 0.0 and np.isfinite(det)):
        return False
    inv = 1.0 / det
    out[0, 0] = (e * i - f * h) * inv
    out[0, 1] = (c * h - b * i) * inv
    out[0, 2] = (b * f - c * e) * inv
    out[1, 0] = (f * g - d * i) * inv
    out[1, 1] = (a * i - c * g) * inv
    out[1, 2] = (c * d - a * f) * inv
    out[2, 0] = (d * h - e * g) * inv
    out[2, 1] = (b * g - a * h) * inv
    out[2, 2] = (a * e - b * d) * inv
    return True


@njit(cache=True)
def time_update(xn, xl, P, Phi, qn_var, ql_var, w):
    """Marginalized time update over one interval (seed 002 eqs 5-8, 13-15), in place.
    With Phi = [[A, B], [Cm, D]] (n = 3 rows first): f^n = A xn, F^n = B, f^l = Cm xn, F^l = D;
    Q^n = diag(qn_var), Q^l = diag(ql_var) (Table 1: no off-diagonal terms). w (N, 3) standard normals.
    Returns the number of particles whose N was not positive definite (they get Q^n alone)."""
    npart = xn.shape[0]
    bad = 0
    PB = np.empty((NL, 3))
    Nm = np.empty((3, 3))
    Lc = np.empty((3, 3))
    Ni = np.empty((3, 3))
    DP = np.empty((NL, NL))
    DPB = np.empty((NL, 3))
    Lg = np.empty((NL, 3))
    LN = np.empty((NL, 3))
    xn_new = np.empty(3)
    mean_n = np.empty(3)
    xl_new = np.empty(NL)
    # rows of D that are unit rows (the bias states of eq 18 are constant): D P and D P D^T copy them
    ident = np.zeros(NL, np.bool_)
    for i in range(NL):
        unit = True
        for m in range(NL):
            if Phi[3 + i, 3 + m] != (1.0 if m == i else 0.0):
                unit = False
                break
        ident[i] = unit
    for k in range(npart):
        Pk = P[k]
        # PB = P B^T
        for i in range(NL):
            for j in range(3):
                s = 0.0
                for m in range(NL):
                    s += Pk[i, m] * Phi[j, 3 + m]
                PB[i, j] = s
        # eq 13: N = B P B^T + Q^n
        for i in range(3):
            for j in range(3):
                s = 0.0
                for m in range(NL):
                    s += Phi[i, 3 + m] * PB[m, j]
                Nm[i, j] = s
            Nm[i, i] += qn_var[i]
        for i in range(3):
            for j in range(i):
                a = 0.5 * (Nm[i, j] + Nm[j, i])
                Nm[i, j] = a
                Nm[j, i] = a
        if not _chol3(Nm, Lc):
            bad += 1
            for i in range(3):
                for j in range(3):
                    Nm[i, j] = 0.0
                Nm[i, i] = qn_var[i]
            _chol3(Nm, Lc)
        # eq 5: xn_{t+1} ~ N(A xn + B xl, N)
        for i in range(3):
            s = 0.0
            for m in range(3):
                s += Phi[i, m] * xn[k, m]
            mean_n[i] = s
            s2 = 0.0
            for m in range(NL):
                s2 += Phi[i, 3 + m] * xl[k, m]
            xn_new[i] = s + s2
        for i in range(3):
            s = 0.0
            for m in range(i + 1):
                s += Lc[i, m] * w[k, m]
            xn_new[i] += s
        # eq 14: L = D P B^T N^-1
        _inv3(Nm, Ni)
        for i in range(NL):
            if ident[i]:
                for j in range(NL):
                    DP[i, j] = Pk[i, j]
                for j in range(3):
                    DPB[i, j] = PB[i, j]
                continue
            for j in range(NL):
                s = 0.0
                for m in range(NL):
                    s += Phi[3 + i, 3 + m] * Pk[m, j]
                DP[i, j] = s
            for j in range(3):
                s = 0.0
                for m in range(NL):
                    s += Phi[3 + i, 3 + m] * PB[m, j]
                DPB[i, j] = s
        for i in range(NL):
            for j in range(3):
                Lg[i, j] = DPB[i, 0] * Ni[0, j] + DPB[i, 1] * Ni[1, j] + DPB[i, 2] * Ni[2, j]
        # eq 15: z = xn_{t+1} - f^n;  eq 6: xl = f^l + D xl + L (z - B xl)
        for i in range(3):
            s2 = 0.0
            for m in range(NL):
                s2 += Phi[i, 3 + m] * xl[k, m]
            mean_n[i] = xn_new[i] - mean_n[i] - s2     # z - B xl
        for i in range(NL):
            s = 0.0
            for m in range(3):
                s += Phi[3 + i, m] * xn[k, m]
            for m in range(NL):
                s += Phi[3 + i, 3 + m] * xl[k, m]
            s += Lg[i, 0] * mean_n[0] + Lg[i, 1] * mean_n[1] + Lg[i, 2] * mean_n[2]
            xl_new[i] = s
        # eq 7: P = D P D^T + Q^l - L N L^T
        for i in range(NL):
            for j in range(3):
                LN[i, j] = Lg[i, 0] * Nm[0, j] + Lg[i, 1] * Nm[1, j] + Lg[i, 2] * Nm[2, j]
        for i in range(NL):
            for j in range(i, NL):
                if ident[j]:
                    s = DP[i, j]
                else:
                    s = 0.0
                    for m in range(NL):
                        s += DP[i, m] * Phi[3 + j, 3 + m]
                s -= LN[i, 0] * Lg[j, 0] + LN[i, 1] * Lg[j, 1] + LN[i, 2] * Lg[j, 2]
                if i == j:
                    s += ql_var[i]
                Pk[i, j] = s
                Pk[j, i] = s
        for i in range(3):
            xn[k, i] = xn_new[i]
        for i in range(NL):
            xl[k, i] = xl_new[i]
    return bad


@njit(cache=True, forceinline=True)
def _mul_ab(A, B, out, n, m, p, transpose_b):
    """out[:n, :m] = A[:n, :p] B[:p, :m] (transpose_b: A B[:m, :p]^T), each sum in index order."""
    for i in range(n):
        for a in range(m):
            s = 0.0
            for j in range(p):
                s += A[i, j] * (B[a, j] if transpose_b else B[j, a])
            out[i, a] = s


@njit(cache=True)
def linear_update(xl, P, H, e, r_var, logw, ok, ll):
    """Kalman update of each particle's linear part with its own H (N, m, 12) and innovation e (N, m)
    = y - h(xn) (before subtracting H xl), measurement variances r_var (m,) (seed 002 eqs 9-12); adds the
    log of the predictive density of eq 9 to logw and writes it to ll (N,). ok (N,) False: the particle has
    no prediction (no return, off the map): ll = -inf, no update. Returns the number of those."""
    npart = xl.shape[0]
    m = H.shape[1]
    PHt = np.empty((NL, m))
    S = np.empty((m, m))
    Si = np.empty((m, m))
    nu = np.empty(m)
    K = np.empty((NL, m))
    n_bad = 0
    for k in range(npart):
        if not ok[k]:
            ll[k] = -np.inf
            logw[k] = -np.inf
            n_bad += 1
            continue
        Pk = P[k]
        Hk = H[k]
        for a in range(m):
            s = e[k, a]
            for j in range(NL):
                s -= Hk[a, j] * xl[k, j]
            nu[a] = s
        _mul_ab(Pk, Hk, PHt, NL, m, NL, True)       # P H^T
        _mul_ab(Hk, PHt, S, m, m, NL, False)        # S = H P H^T + R
        for a in range(m):
            S[a, a] += r_var[a]
        # S^-1 and log det (m <= 3: explicit)
        if m == 1:
            det = S[0, 0]
            Si[0, 0] = 1.0 / det
        elif m == 2:
            det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
            Si[0, 0] = S[1, 1] / det
            Si[1, 1] = S[0, 0] / det
            Si[0, 1] = -S[0, 1] / det
            Si[1, 0] = -S[1, 0] / det
        else:
            if not _inv3(S, Si):
                det = np.nan
            else:
                det = (S[0, 0] * (S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1])
                       - S[0, 1] * (S[1, 0] * S[2, 2] - S[1, 2] * S[2, 0])
                       + S[0, 2] * (S[1, 0] * S[2, 1] - S[1, 1] * S[2, 0]))
        if not (det > 0.0):
            ll[k] = -np.inf
            logw[k] = -np.inf
            n_bad += 1
            continue
        q = 0.0
        for a in range(m):
            for b in range(m):
                q += nu[a] * Si[a, b] * nu[b]
        lk = -0.5 * (q + np.log(det) + m * np.log(2.0 * np.pi))
        ll[k] = lk
        logw[k] += lk
        # eq 10-11: K = P H^T S^-1, xl += K nu, P -= K S K^T (= K H P)
        _mul_ab(PHt, Si, K, NL, m, m, False)
        for i in range(NL):
            s = 0.0
            for a in range(m):
                s += K[i, a] * nu[a]
            xl[k, i] += s
        for i in range(NL):
            for j in range(i, NL):
                s = 0.0
                for a in range(m):
                    s += K[i, a] * PHt[j, a]
                v = Pk[i, j] - s
                Pk[i, j] = v
                Pk[j, i] = v
    return n_bad


@njit(cache=True)
def position_loglik(xn, y, r_var, logw, ll):
    """Weights from a direct measurement of the nonlinear state: y (3,) = INS minus measured position
    (m, north east up), variances r_var (3,); adds log N(y; xn, R) to logw (GNSS position)."""
    c = -0.5 * (np.log(r_var[0]) + np.log(r_var[1]) + np.log(r_var[2]) + 3.0 * np.log(2.0 * np.pi))
    for k in range(xn.shape[0]):
        q = 0.0
        for a in range(3):
            d = y[a] - xn[k, a]
            q += d * d / r_var[a]
        ll[k] = c - 0.5 * q
        logw[k] += ll[k]


@njit(cache=True)
def gather(xn, xl, P, idx):
    """Particles idx of (xn, xl, P), as new arrays."""
    n = idx.shape[0]
    xn2 = np.empty((n, 3))
    xl2 = np.empty((n, NL))
    P2 = np.empty((n, NL, NL))
    for i in range(n):
        j = idx[i]
        xn2[i] = xn[j]
        xl2[i] = xl[j]
        P2[i] = P[j]
    return xn2, xl2, P2


@njit(cache=True)
def moments(xn, xl, P, w):
    """Weighted mean (15,) and covariance (15, 15) of the mixture: particles' xn with their Kalman parts."""
    n = xn.shape[0]
    mu = np.zeros(15)
    for k in range(n):
        for i in range(3):
            mu[i] += w[k] * xn[k, i]
        for i in range(NL):
            mu[3 + i] += w[k] * xl[k, i]
    C = np.zeros((15, 15))
    d = np.empty(15)
    for k in range(n):
        wk = w[k]
        if wk == 0.0:
            continue
        for i in range(3):
            d[i] = xn[k, i] - mu[i]
        for i in range(NL):
            d[3 + i] = xl[k, i] - mu[3 + i]
        for i in range(15):
            for j in range(i, 15):
                v = d[i] * d[j]
                if i >= 3 and j >= 3:
                    v += P[k, i - 3, j - 3]
                C[i, j] += wk * v
    for i in range(15):
        for j in range(i):
            C[i, j] = C[j, i]
    return mu, C


@njit(cache=True)
def shift(xn, xl, mu):
    """Subtract the mean (fed back into the INS) from every particle."""
    for k in range(xn.shape[0]):
        for i in range(3):
            xn[k, i] -= mu[i]
        for i in range(NL):
            xl[k, i] -= mu[3 + i]


@njit(cache=True)
def predictive_moments(H, xl, P, r_var, pred, ok, wp):
    """Mean (m,) and covariance (m, m) of the mixture's predictive density of y (eq 9 summed over the
    particles with weights wp): each particle N(pred + H xl, H P H^T + R)."""
    n = H.shape[0]
    m = H.shape[1]
    yh = np.zeros((n, m))
    ybar = np.zeros(m)
    S = np.zeros((m, m))
    for k in range(n):
        if not ok[k]:
            continue
        for a in range(m):
            s = pred[k, a]
            for j in range(NL):
                s += H[k, a, j] * xl[k, j]
            yh[k, a] = s
            ybar[a] += wp[k] * s
    PHt = np.empty((NL, m))
    for k in range(n):
        if not ok[k] or wp[k] == 0.0:
            continue
        for i in range(NL):
            for a in range(m):
                s = 0.0
                for j in range(NL):
                    s += P[k, i, j] * H[k, a, j]
                PHt[i, a] = s
        for a in range(m):
            for b in range(m):
                s = 0.0
                for j in range(NL):
                    s += H[k, a, j] * PHt[j, b]
                if a == b:
                    s += r_var[a]
                S[a, b] += wp[k] * (s + (yh[k, a] - ybar[a]) * (yh[k, b] - ybar[b]))
    return ybar, S
