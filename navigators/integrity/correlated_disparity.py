"""The DEM monitor's window statistics under spatially correlated map error, and their exact distributions.

Seed 003's test (eq 4) sums N squared disparities over sigma^2 and compares the sum with the chi-square
quantile (96 for P_fa = 1e-4 at N = 50). That needs independent disparities. A real map's error is
correlated along the track (terrain.map_error: covariance sigma^2 rho(d), rho exponential or Gaussian in
the distance d between the epochs' positions), so the window's disparities p ~ N(0, Sigma) with

    Sigma_ij = sigma_r^2 rho(d_ij) + sigma_b^2 + delta_ij w_i + c_ij

(sigma_r: the map's random error, sigma_b: its bias part, common to the window; w_i: white variances of
the epoch (radar-altimeter noise, GNSS height); c_ij: the navigator's own position error when it is the
height source, slowly varying over a window and so common to it: sqrt(P_dd,i P_dd,j) + g_i' P g_j with g
the map's slope and P the horizontal covariance). Eq 4's sum is then a
generalised chi-square (a weighted sum of chi2(1) with the eigenvalues of D^-1/2 Sigma D^-1/2) whose tail
at 96 is far above 1e-4.

The monitor whitens instead: T_w = p' Sigma^-1 p = |L^-1 p|^2 (L the Cholesky factor of Sigma, built per
window from the epochs' own positions and variances, `whitened_statistic`), which is chi2(N) for any
spacing, speed or correlation, so the threshold stays chi2.isf(P_fa, N) (96 at 1e-4). The alternative,
keeping eq 4's sum and raising its threshold to the generalised chi-square's quantile (`gchi2_isf`), holds
only for the design spacing; both pay in detection, since a map error correlated over kilometres looks
like a bias over a 50-epoch window: the script scripts/integrity_statistics.py measures both.

Exact tails: `gchi2_sf` is Imhof's (1961, Biometrika 48, eq 3.2) inversion integral of the characteristic
function of sum lambda_j (z_j + delta_j)^2 (noncentral with delta), evaluated with scipy's adaptive
quadrature; `gchi2_isf` inverts it. `quadratic_form_eigen` turns (M, Sigma, mu) of Q = p' M p,
p ~ N(mu, Sigma) into (lambda, delta). `kalman_readings` writes seed 003 eq 5's filtered statistic under
its readings as such quadratic forms, so each reading's false-alarm and detection probabilities are exact.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def whitened_statistic(ring, start, n, sig_r2, sig_b2, corr_len_m, func, tau_h_s=0.0, tau_v_s=0.0):
    """p' Sigma^-1 p over the n epochs of a ring buffer (oldest at row `start`, wrapping), Sigma as in the
    module docstring; func 0: exponential, 1: Gaussian correlation. ring columns: p (m), lat, lon (rad),
    white variance (m^2), then the navigator's height-source terms (zero for GNSS epochs): its down variance
    P_dd, the map's slope g_n, g_e and its horizontal covariance P_nn, P_ne, P_ee; then the epoch's time (s).
    The navigator's error between epochs i and j: rho_v sqrt(P_dd,i P_dd,j) + rho_h g_i' (P_i + P_j) / 2 g_j,
    its vertical and horizontal errors first-order Gauss-Markov in time, rho = exp(-|t_i - t_j| / tau) with
    tau = tau_v_s, tau_h_s (0: constant over the window, rho = 1); the slope under it changes from epoch to
    epoch. Distances through the WGS84 meridian / prime-vertical radii at the first epoch.

    Returns (T_w, T_b): T_w = p' Sigma^-1 p (chi2(N) without a fault) and T_b = (1' Sigma^-1 p)^2 /
    (1' Sigma^-1 1), the generalised likelihood-ratio test of a bias common to the window (chi2(1));
    NaN, NaN if Sigma is not positive definite."""
    m = ring.shape[0]
    S = np.empty((n, n))
    v = np.empty(n)
    a_m = 6378137.0
    e2 = 6.69437999014e-3
    s0 = math.sin(ring[start % m, 1])
    w = 1.0 - e2 * s0 * s0
    rn = a_m * (1.0 - e2) / (w * math.sqrt(w))
    re = a_m / math.sqrt(w) * math.cos(ring[start % m, 1])
    for i in range(n):
        ii = (start + i) % m
        v[i] = ring[ii, 0]
        for j in range(i + 1):
            jj = (start + j) % m
            d = math.hypot((ring[ii, 1] - ring[jj, 1]) * rn, (ring[ii, 2] - ring[jj, 2]) * re)
            if corr_len_m <= 0.0:
                rho = 1.0 if i == j else 0.0
            elif func == 0:
                rho = math.exp(-d / corr_len_m)
            else:
                rho = math.exp(-0.5 * (d / corr_len_m) ** 2)
            dt = abs(ring[ii, 10] - ring[jj, 10])
            rho_h = math.exp(-dt / tau_h_s) if tau_h_s > 0.0 else 1.0
            rho_v = math.exp(-dt / tau_v_s) if tau_v_s > 0.0 else 1.0
            pnn = 0.5 * (ring[ii, 7] + ring[jj, 7]) * rho_h
            pne = 0.5 * (ring[ii, 8] + ring[jj, 8]) * rho_h
            pee = 0.5 * (ring[ii, 9] + ring[jj, 9]) * rho_h
            gi_n, gi_e, gj_n, gj_e = ring[ii, 5], ring[ii, 6], ring[jj, 5], ring[jj, 6]
            c = (sig_r2 * rho + sig_b2 + rho_v * math.sqrt(ring[ii, 4] * ring[jj, 4])
                 + gi_n * (pnn * gj_n + pne * gj_e) + gi_e * (pne * gj_n + pee * gj_e))
            if i == j:
                c += ring[ii, 3]
            S[i, j] = c
            S[j, i] = c
    # Cholesky and forward substitution in place (no LAPACK: the same result on every machine)
    for j in range(n):
        s = S[j, j]
        for k in range(j):
            s -= S[j, k] * S[j, k]
        if not s > 0.0:
            return np.nan, np.nan
        S[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            t = S[i, j]
            for k in range(j):
                t -= S[i, k] * S[j, k]
            S[i, j] = t / S[j, j]
    u = np.empty(n)
    tot = 0.0
    uy = 0.0
    uu = 0.0
    for i in range(n):
        t = v[i]
        t1 = 1.0
        for k in range(i):
            t -= S[i, k] * v[k]
            t1 -= S[i, k] * u[k]
        v[i] = t / S[i, i]
        u[i] = t1 / S[i, i]
        tot += v[i] * v[i]
        uy += u[i] * v[i]
        uu += u[i] * u[i]
    return tot, uy * uy / uu


def window_covariance(d_m: np.ndarray, sig_r: float, corr_len_m: float, function: str = "exponential",
                      white_var: float | np.ndarray = 0.0, sig_b: float = 0.0,
                      common_sigma: float | np.ndarray = 0.0) -> np.ndarray:
    """Sigma of the module docstring for epochs at along-track positions d_m (m), numpy (for studies)."""
    from ...terrain.map_error import correlation
    d = np.asarray(d_m, float)
    D = np.abs(d[:, None] - d[None, :])
    c = np.broadcast_to(np.asarray(common_sigma, float), d.shape)
    S = sig_r**2 * correlation(D, corr_len_m, function) + sig_b**2 + np.outer(c, c)
    S[np.diag_indices_from(S)] += np.broadcast_to(np.asarray(white_var, float), d.shape)
    return S


def quadratic_form_eigen(M: np.ndarray, Sigma: np.ndarray, mu: np.ndarray | None = None):
    """(lambda, delta) with p' M p = sum lambda_j (z_j + delta_j)^2, z ~ N(0, I), for p ~ N(mu, Sigma)."""
    L = np.linalg.cholesky(Sigma)
    A = L.T @ M @ L
    lam, U = np.linalg.eigh(0.5 * (A + A.T))
    if mu is None:
        return lam, np.zeros_like(lam)
    return lam, U.T @ np.linalg.solve(L, np.asarray(mu, float))


def gchi2_sf(x: float, lam: np.ndarray, delta: np.ndarray | None = None) -> float:
    """P(sum lambda_j (z_j + delta_j)^2 > x) by Imhof's integral (lambda > 0 terms; zeros dropped)."""
    from scipy.integrate import quad
    lam = np.asarray(lam, float)
    dl = np.zeros_like(lam) if delta is None else np.asarray(delta, float)
    keep = np.abs(lam) > 1e-12 * np.max(np.abs(lam))
    lam, dl2 = lam[keep], dl[keep] ** 2

    def f(u):
        lu = lam * u
        theta = 0.5 * np.sum(np.arctan(lu) + dl2 * lu / (1.0 + lu * lu)) - 0.5 * x * u
        logrho = 0.25 * np.sum(np.log1p(lu * lu)) + 0.5 * np.sum(dl2 * lu * lu / (1.0 + lu * lu))
        return math.sin(theta) / (u * math.exp(logrho))

    scale = 1.0 / np.max(lam)
    total = 0.0
    a = 0.0
    step = 2.0 * scale
    for _ in range(400):        # integrate interval by interval until the envelope is negligible
        b = a + step
        val, _ = quad(f, a, b, limit=200, epsabs=1e-15, epsrel=1e-10)
        total += val
        lu = lam * b
        env = math.exp(-(0.25 * np.sum(np.log1p(lu * lu)) + 0.5 * np.sum(dl2 * lu * lu / (1 + lu * lu)))) / b
        if env * step < 1e-14:
            break
        a = b
        step *= 1.5
    return float(min(max(0.5 + total / math.pi, 0.0), 1.0))


def gchi2_isf(p: float, lam: np.ndarray, delta: np.ndarray | None = None) -> float:
    """The x with gchi2_sf(x) = p (bracketed root of log sf)."""
    from scipy.optimize import brentq
    lam = np.asarray(lam, float)
    mean = float(np.sum(lam))
    sd = math.sqrt(2.0 * float(np.sum(lam * lam)))
    lo, hi = max(mean - 2 * sd, 1e-9), mean + 10 * sd
    while gchi2_sf(hi, lam, delta) > p:
        hi *= 1.5
    return float(brentq(lambda x: math.log(max(gchi2_sf(x, lam, delta), 1e-300)) - math.log(p), lo, hi,
                        xtol=1e-6 * hi))


# ------------------------------------------------------------------------------ seed 003 eq 5 readings

KALMAN_READINGS = ("rw_posterior", "rw_population", "gm_posterior", "innovation")


def _steady_gain(phi: float, q: float, r: float) -> tuple[float, float, float]:
    """(K, P posterior, P prior) of the steady-state scalar filter x_k = phi x_{k-1} + w (var q), z = x + v
    (var r)."""
    P = q
    for _ in range(100000):
        Pm = phi * phi * P + q
        Pn = (1.0 - Pm / (Pm + r)) * Pm
        if abs(Pn - P) <= 1e-15 * max(P, 1e-300):
            P = Pn
            break
        P = Pn
    Pm = phi * phi * P + q
    return Pm / (Pm + r), P, Pm


def kalman_reading(reading: str, n: int, burn: int, ratio: float, phi: float = 1.0) -> np.ndarray:
    """M of T_KF = p' M p over burn + n disparities (unit sigma) for a reading of seed 003 eq 5, the steady
    state filter started at zero burn samples before the window:

    rw_posterior:  x_hat of a random-walk filter (q = ratio r), P its posterior variance (eq 5 as written);
    rw_population: the same x_hat, P the stationary variance of x_hat when the disparities are white
                   ("the variance of the complete population of filtered estimates");
    gm_posterior:  x_hat of a zero-mean first-order Gauss-Markov state (phi, stationary variance ratio r),
                   P its posterior variance;
    innovation:    the random-walk filter's innovations p_k - x_hat_{k-1} over their variance P- + r (the
                   filter absorbs a bias; the statistic tests what is left)."""
    k_tot = burn + n
    if reading in ("rw_posterior", "rw_population", "innovation"):
        K, P, Pm = _steady_gain(1.0, ratio, 1.0)
        a = 1.0 - K
    elif reading == "gm_posterior":
        K, P, Pm = _steady_gain(phi, ratio * (1.0 - phi * phi), 1.0)
        a = phi * (1.0 - K)
    else:
        raise ValueError(f"reading: must be one of {KALMAN_READINGS}, got {reading!r}")
    X = np.zeros((k_tot, k_tot))       # x_hat_k = sum_j X[k, j] p_j
    for k in range(k_tot):
        if k:
            X[k] = a * X[k - 1]
        X[k, k] += K
    if reading == "innovation":
        R = np.eye(k_tot)
        R[1:] -= X[:-1] if phi == 1.0 else phi * X[:-1]
        rows = R[burn:]
        return rows.T @ rows / (Pm + 1.0)
    rows = X[burn:]
    if reading == "rw_population":
        P = K / (2.0 - K)              # stationary variance of x_hat: K^2 / (1 - (1 - K)^2)
    return rows.T @ rows / P
