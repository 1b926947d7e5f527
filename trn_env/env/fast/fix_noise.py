"""The fast tier's TERCOM fix covariance from the batch and the map: the least-absolute-deviation shift's.

A numba kernel per aircraft and fix, an independent implementation of the full navigator's model
(navigators.tercom.fix_noise.lad_fix_covariance, whose docstring gives the derivation): the MAD fix (seed 000
eqs 1-2) is a least-absolute-deviation (LAD) estimate of the shift d in r_k(d) = h_meas,k - h_map(x_k + d),
linearised at the match as r_k - g_k^T (d - d_hat) with g_k the map's slope (m/m, north / east) at the
matched point. With A = sum_k g_k g_k^T,

    Cov(d_hat) = (pi / 2) A^-1 B A^-1 + (pi / 2) sigma_t^2 min(n_post, M) A^-1 + cell^2 / 12 I

- B = sum_{|l| <= L} w_l c(l) sum_k g_k g_{k+l}^T: the residuals' autocovariance c(l) with Bartlett weights
  w_l = 1 - |l| / (L + 1) over L samples along WINDOW_POSTS post spacings (Newey & West 1987); pi / 2 the
  LAD's variance over the least-squares one for Gaussian residuals (Koenker 2005, "Quantile Regression",
  sec. 4.2);
- sigma_t the terrain the map cannot hold between its posts (navigators.measurements.ira_map_noise.
  interpolation_sigma_m), one height error per post spacing shared by the n_post samples there;
- cell^2 / 12 per axis: the search grid's quantisation.

A singular A (flat map) or a covariance that is not finite and positive definite gives no information
(NO_INFORMATION_VAR_M2 per axis, the full navigator's). The fast tier's batch is its 1 Hz profile at the
INS-indicated positions (no closest-point offsets); the residuals are centred on their mean when the MAD
removed the bias, else on their median. Lengths use the fix's metres per radian (navigator.tercom_fix).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from trn_env.terrain import kernels

NO_INFORMATION_VAR_M2 = 1e12  # as navigators.tercom.fix_noise
LAD_EFFICIENCY_LOSS = 0.5 * math.pi
WINDOW_POSTS = 2.0


@njit(cache=True)
def lad_fix_covariance(profile, n, rec, dn_m, de_m, m_per_rad, cell_m, remove_bias, terrain_sigma_m, work):
    """Covariance (c_nn, c_ne, c_ee) (m^2, north / east) of a TERCOM fix of correction (dn_m, de_m) (m)
    from the profile (meas, plat, plon: measured terrain heights (m) at the INS-indicated positions (rad),
    n points) against the map rec (terrain.kernels.MapRecord, bilinear); m_per_rad = (north, east) metres
    per radian at the fix; cell_m the search cell (m); remove_bias: the MAD was mean-removed;
    terrain_sigma_m the map's unresolved terrain (m); work: (3, >= n) scratch rows (residual, g_n, g_e).
    See the module docstring."""
    meas, plat, plon = profile
    heights, lat0, lon0, dlat, dlon, _ = rec
    m_lat, m_lon = m_per_rad
    no_info = (NO_INFORMATION_VAR_M2, 0.0, NO_INFORMATION_VAR_M2)
    r = work[0]
    g_n = work[1]
    g_e = work[2]
    m = 0
    track_m = 0.0
    last_lat = 0.0
    last_lon = 0.0
    for k in range(n):
        lat = plat[k] + dn_m / m_lat
        lon = plon[k] + de_m / m_lon
        h, dh_dlat, dh_dlon = kernels.bilinear_with_gradient(heights, lat0, lon0, dlat, dlon, lat, lon)
        if not (math.isfinite(h) and math.isfinite(dh_dlat) and math.isfinite(dh_dlon)
                and math.isfinite(meas[k])):
            continue
        if m > 0:
            track_m += math.hypot((plat[k] - last_lat) * m_lat, (plon[k] - last_lon) * m_lon)
        last_lat = plat[k]
        last_lon = plon[k]
        r[m] = meas[k] - h
        g_n[m] = dh_dlat / m_lat
        g_e[m] = dh_dlon / m_lon
        m += 1
    if m < 3:
        return no_info
    if remove_bias:
        centre = 0.0
        for k in range(m):
            centre += r[k]
        centre /= m
    else:
        centre = np.median(r[:m])
    a_nn = 0.0
    a_ne = 0.0
    a_ee = 0.0
    c0 = 0.0
    for k in range(m):
        r[k] -= centre
        a_nn += g_n[k] * g_n[k]
        a_ne += g_n[k] * g_e[k]
        a_ee += g_e[k] * g_e[k]
        c0 += r[k] * r[k]
    c0 /= m
    spacing_m = max(track_m / max(m - 1, 1), 1e-3)
    post_m = max(abs(dlat) * m_lat, abs(dlon) * m_lon)
    lag = min(m - 1, int(math.ceil(WINDOW_POSTS * post_m / spacing_m)))
    b_nn = c0 * a_nn
    b_ne = c0 * a_ne
    b_ee = c0 * a_ee
    for ell in range(1, lag + 1):
        c = 0.0
        s_nn = 0.0
        s_ne = 0.0
        s_en = 0.0
        s_ee = 0.0
        for k in range(m - ell):
            c += r[k] * r[k + ell]
            s_nn += g_n[k] * g_n[k + ell]
            s_ne += g_n[k] * g_e[k + ell]
            s_en += g_e[k] * g_n[k + ell]
            s_ee += g_e[k] * g_e[k + ell]
        w = (1.0 - ell / (lag + 1.0)) * c / (m - ell)
        b_nn += w * 2.0 * s_nn
        b_ne += w * (s_ne + s_en)
        b_ee += w * 2.0 * s_ee
    det = a_nn * a_ee - a_ne * a_ne
    if not (det > 0.0 and math.isfinite(det)):
        return no_info
    # A^-1
    i_nn = a_ee / det
    i_ne = -a_ne / det
    i_ee = a_nn / det
    # A^-1 B A^-1 (symmetric)
    t_nn = i_nn * b_nn + i_ne * b_ne
    t_ne = i_nn * b_ne + i_ne * b_ee
    t_en = i_ne * b_nn + i_ee * b_ne
    t_ee = i_ne * b_ne + i_ee * b_ee
    s_nn = t_nn * i_nn + t_ne * i_ne
    s_ne = 0.5 * ((t_nn * i_ne + t_ne * i_ee) + (t_en * i_nn + t_ee * i_ne))
    s_ee = t_en * i_ne + t_ee * i_ee
    share = terrain_sigma_m * terrain_sigma_m * min(post_m / spacing_m, float(m))
    q = cell_m * cell_m / 12.0
    c_nn = LAD_EFFICIENCY_LOSS * (s_nn + share * i_nn) + q
    c_ne = LAD_EFFICIENCY_LOSS * (s_ne + share * i_ne)
    c_ee = LAD_EFFICIENCY_LOSS * (s_ee + share * i_ee) + q
    if not (math.isfinite(c_nn) and math.isfinite(c_ne) and math.isfinite(c_ee)):
        return no_info
    if c_nn <= 0.0 or c_nn * c_ee - c_ne * c_ne <= 0.0 or max(c_nn, c_ee, abs(c_ne)) > NO_INFORMATION_VAR_M2:
        return no_info
    return c_nn, c_ne, c_ee
